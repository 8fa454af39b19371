"""Viewer channel benchmarks (docs/viewers.md); prints a Markdown section (docs/benchmarks.md,
"Viewer channels").

Whether every recording can carry the Foxglove channels, or a copy is written afterwards
(``grasp-lab export --foxglove``): what one display update's channels cost to build and
write (numbers of the frame, SceneUpdate, FrameTransforms, plot channels, into an MCAP
file through foxglove-sdk), beside what the recorder itself does for the same display
period in the same run (write the period's tick records and derive its events), for the
sample scene (2 bodies + 2 fingers, a real EXEC recording) and 20 bodies + 10 fingers
(synthetic motion, every finger pressing). Then the export's speed and the copy's size per
second of session beside the recording's.

Usage: .venv/bin/python bench/bench_viewer.py [--seconds 20]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
sys.path.insert(0, os.path.join(ROOT, "bench"))
sys.path.insert(0, ROOT)


def pressing(rec):
    """Every finger on a body, pushing (synthetic sessions have free fingers): arrows and
    plot numbers as in a grasp."""
    t = rec.ticks
    nb = len(rec.body_names)
    t["contact"][:] = np.arange(t["contact"].shape[1]) % nb
    t["state"][:] = 1
    t["normal"][:, :, 2] = 1.0
    t["force"][:, :, 0] = 0.3
    t["force"][:, :, 2] = 2.0
    t["god_object"][:, :, 2] += 0.002


def per_frame_costs(rec, tmp, repeats=3):
    """µs per display update: the viewer channels (frame numbers + messages + MCAP write) and
    the recorder's work for the same period (tick records written, events derived)."""
    import foxglove
    from foxglove.mcap import MCAPWriteOptions

    from addon.engine import recording, viewer
    model = viewer.SceneModel(rec.header)
    rate = model.display_rate
    times = np.arange(0, int(rec.ticks["time"][-1] * rate)) / rate
    idx = rec.sample(times)
    viewer_us = []
    for r in range(repeats):
        ctx = foxglove.Context()
        with open(os.path.join(tmp, f"v{r}.mcap"), "wb") as fh:
            w = foxglove.open_mcap(fh, context=ctx, writer_options=MCAPWriteOptions(profile=""))
            ch = viewer.FoxgloveChannels(model, ctx)
            for k, i in enumerate(idx):
                t0 = time.perf_counter()
                fr = viewer.frames_of(model, rec, rec.ticks[i:i + 1], times[k:k + 1])[0]
                ch.log_frame(fr)
                viewer_us.append((time.perf_counter() - t0) * 1e6)
            w.close()
    per = int(round(rec.haptic_rate / rate))
    rec_us = []
    for r in range(repeats):
        writer = recording.RecordingWriter(os.path.join(tmp, f"r{r}.mcap"), rec.header, compression="lz4")
        events = recording.EventDetector(rec.header)
        for start in range(0, len(rec.ticks) - per, per):
            block = rec.ticks[start:start + per]
            t0 = time.perf_counter()
            writer.write_ticks(block)
            for tick, t, kind, subject, detail in events(block):
                writer.event(t, kind, subject, detail, tick=tick)
            rec_us.append((time.perf_counter() - t0) * 1e6)
        writer.close()
    return viewer_us, rec_us, rate


def pct(a, q):
    return float(np.percentile(a, q))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="synthetic session length")
    args = ap.parse_args(argv)
    import bench_recording
    import graspcore as gc
    import recordings

    from addon.engine import viewer
    from addon.engine.recording import open_recording
    tmp = tempfile.mkdtemp(prefix="grasp_bench_viewer_")
    sample = os.path.join(tmp, "sample.mcap")
    recordings.record_exec(sample, gc, seconds=6.0)
    many = os.path.join(tmp, "many.mcap")
    bench_recording.synthetic_session(many, args.seconds / 60.0, "lz4")
    rows = []
    for label, path, synthetic in (("sample scene, 2 + 2", sample, False),
                                   ("20 bodies + 10 fingers", many, True)):
        rec = open_recording(path)
        if synthetic:
            pressing(rec)
        v, r, rate = per_frame_costs(rec, tmp)
        rows.append((f"one display update's viewer channels, {label} (median / p95)",
                     f"{statistics.median(v):.0f} / {pct(v, 95):.0f} µs"))
        rows.append((f"the recorder's work for the same {1e3 / rate:.1f} ms of ticks, {label} (median / p95)",
                     f"{statistics.median(r):.0f} / {pct(r, 95):.0f} µs"))
        rows.append((f"viewer channels / recorder, {label}",
                     f"{statistics.median(v) / statistics.median(r):.1f} x"))
        out = os.path.join(tmp, "copy.mcap")
        t0 = time.perf_counter()
        done = viewer.export_foxglove(rec, out)
        spent = time.perf_counter() - t0
        duration = float(rec.ticks["time"][-1] - rec.ticks["time"][0])
        rows.append((f"export --foxglove, {label}: time per second of session",
                     f"{spent / duration * 1e3:.0f} ms ({done['frames']} frames at {rate:g} Hz)"))
        rows.append((f"file per second of session, {label}: viewer copy / recording",
                     f"{done['bytes'] / duration / 1e3:.1f} / {os.path.getsize(path) / duration / 1e3:.1f} kB"))
    print("| what | measured |\n| --- | --- |")
    for k, val in rows:
        print(f"| {k} | {val} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
