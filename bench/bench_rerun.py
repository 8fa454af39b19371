"""Rerun copy benchmarks (docs/viewers.md); prints a Markdown section (docs/benchmarks.md,
"Sessions in Rerun").

``grasp-lab export --rerun`` of a 10-minute recording of the sample scene (a real EXEC
recording: the pinch and lift, then the box held to the end) at the display rate, against
its target (under 10 s), and the .rrd's size per second of session; the same for 20 bodies
+ 10 fingers (synthetic motion, every finger pressing, as bench_viewer.py). The time is the
best of three, with and without the grasp analysis (the copy's plots of closure, epsilon,
load, slip margin and the weakest-wrench arrows), so what the Rerun side itself costs shows.

The live view in Rerun: what one display update's frame costs its thread, the numbers and
the ``log`` calls (into Rerun's in-memory sink: the network is the SDK's own thread).

Usage: .venv/bin/python bench/bench_rerun.py [--minutes 10]
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
sys.path.insert(0, os.path.join(ROOT, "bench"))
sys.path.insert(0, ROOT)

TARGET_S = 10.0


def timed(rec, out, repeats=3):
    """Best of ``repeats`` (s) of the copy with the analysis, and without it; the last answer."""
    from addon.engine import rerun_view, viewer
    full, bare = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        done = rerun_view.export_rerun(rec, out)
        full.append(time.perf_counter() - t0)
        with_analysis = viewer.SceneModel.grasp_numbers
        viewer.SceneModel.grasp_numbers = lambda self, rec, rows: None
        try:
            t0 = time.perf_counter()
            rerun_view.export_rerun(rec, out)
            bare.append(time.perf_counter() - t0)
        finally:
            viewer.SceneModel.grasp_numbers = with_analysis
    return min(full), min(bare), done


def live_costs(rec, frames=300):
    """µs per live update's frame logged (RerunLogger.log_batch of one frame: plain ``log``
    calls) into an in-memory sink, and the same frame's numbers (frame_batch) alone."""
    import numpy as np

    from addon.engine import rerun_view, viewer
    rr = rerun_view._sdk()
    model = viewer.SceneModel(rec.header)
    stream = rr.RecordingStream(rerun_view.APPLICATION_ID, send_properties=False)
    memory = stream.memory_recording()     # kept: dropping it drops the sink
    logger = rerun_view.RerunLogger(model, stream)
    logger.static()
    rows = np.linspace(0, len(rec.ticks) - 1, frames).astype(int)
    numbers, logged = [], []
    for r in rows:
        t0 = time.perf_counter()
        b = viewer.frame_batch(model, rec, rec.ticks[r:r + 1], rec.ticks["time"][r:r + 1])
        t1 = time.perf_counter()
        logger.log_batch(b)
        logged.append((time.perf_counter() - t1) * 1e6)
        numbers.append((t1 - t0) * 1e6)
    stream.flush(blocking=True)
    assert len(memory.drain_as_bytes()) > 0
    return numbers, logged


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="session length (default 10)")
    args = ap.parse_args(argv)
    import bench_recording
    import graspcore as gc
    import recordings
    from bench_viewer import pct, pressing

    from addon.engine.recording import open_recording
    from addon.engine.rerun_view import RERUN_VERSION
    tmp = tempfile.mkdtemp(prefix="grasp_bench_rerun_")
    rows, targets = [], []
    try:
        sample = os.path.join(tmp, "sample.mcap")
        recordings.record_exec(sample, gc, seconds=args.minutes * 60.0)
        many = os.path.join(tmp, "many.mcap")
        bench_recording.synthetic_session(many, 1.0, "lz4")
        for label, path, synthetic in ((f"sample scene, 2 + 2, {args.minutes:g} min", sample, False),
                                       ("20 bodies + 10 fingers, 1 min", many, True)):
            rec = open_recording(path)
            if synthetic:
                pressing(rec)
            duration = float(rec.ticks["time"][-1] - rec.ticks["time"][0])
            out = os.path.join(tmp, "copy.rrd")
            spent, bare, done = timed(rec, out)
            rows.append((f"export --rerun, {label}: time (with / without the grasp analysis)",
                         f"{spent:.2f} / {bare:.2f} s ({done['frames']} frames at {done['rate']:g} Hz; "
                         f"{spent / duration * 1e3:.1f} ms per second of session)"))
            rows.append((f".rrd per second of session, {label}: Rerun copy / recording",
                         f"{done['bytes'] / duration / 1e3:.1f} / {os.path.getsize(path) / duration / 1e3:.1f} kB"))
            numbers, logged = live_costs(rec)
            rows.append((f"live view in Rerun, {label}: one update's frame numbers / its log calls (median / p95)",
                         f"{statistics.median(numbers):.0f} / {pct(numbers, 95):.0f} µs; "
                         f"{statistics.median(logged):.0f} / {pct(logged, 95):.0f} µs"))
            if not synthetic:
                targets.append((f"export --rerun of a {args.minutes:g}-minute recording at the display rate "
                                f"< {TARGET_S:g} s", f"{spent:.2f} s", spent < TARGET_S))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print("### Sessions in Rerun\n")
    print(f"`bench/bench_rerun.py`: rerun-sdk {RERUN_VERSION}. `grasp-lab export --rerun` writes the viewer "
          "frames (the numbers the Foxglove copy and the bake show) as whole columns (`send_columns`), 4096 "
          "frames a batch; best of three runs.\n")
    print("| target | result | met |")
    print("|---|---|---|")
    for name, value, met in targets:
        print(f"| {name} | {value} | {'yes' if met else '**no**'} |")
    print()
    print("| measurement | value |\n|---|---|")
    for k, val in rows:
        print(f"| {k} | {val} |")
    return 0 if all(met for *_, met in targets) else 1


if __name__ == "__main__":
    sys.exit(main())
