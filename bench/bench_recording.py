"""Recording benchmarks; prints a Markdown section (docs/benchmarks.md, "Recording").

1. Recorder cost in the runtime, 20 bodies + 10 fingers (3 bodies held) and the sample
   scene's 2 + 2: on the real-time haptic loop, what recording a tick costs (``log_us``, timed
   in the loop) beside the tick's own work (``work_us``), medians over 2 s; and the
   manual-clock runtime (the same tick code on this thread) with and without the tick log,
   interleaved repeats. Target: <= 2 % of the tick.
2. A 10-minute session, 20 bodies and 10 fingers at 1 kHz (synthetic motion: 4 bodies and
   the fingers moving, the rest at rest), written with zstd: baking it at 60 fps (open +
   bake) beside ``keyframe_insert`` on a slice of it in the same run. Target: < 2 s.
3. Opening and summarising the same file (``grasp-lab info``). Target: < 1 s.
4. File size per second of session, zstd / lz4 / none, for both scenes.

Usage: .venv/bin/python bench/bench_recording.py [--minutes 10] [--keep DIR]
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
sys.path.insert(0, ROOT)


def box(h):
    return np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)], dtype=float)


def many_world(graspcore):
    """20 boxes on a table (3 of them pinched by two fingers each), 10 fingers."""
    w = graspcore.World()
    w.add_body(box(0.5) * [1, 1, 0.02], static=True, position=(0, 0, -0.01))
    for i in range(19):
        w.add_body(box(0.02), mass=0.05, position=(-0.4 + 0.1 * (i % 9), -0.3 + 0.15 * (i // 9), 0.02))
    hips = []
    for k in range(3):
        x, y = -0.4 + 0.1 * k, -0.3
        hips += [(x - 0.025, y, 0.02), (x + 0.025, y, 0.02)]
    hips += [(0.3, 0.4, 0.3), (0.35, 0.4, 0.3), (0.4, 0.4, 0.3), (0.45, 0.4, 0.3)]
    for h in hips:
        w.add_finger(radius=0.005, damping=2.0, position=h)
    return w, np.array(hips)


def sample_world(graspcore):
    import recordings
    from addon.engine import scene
    desc, S = recordings.pinch_desc()
    handle = scene.build_world(desc, graspcore)
    return handle.world, np.array(S.hip_positions(1.2))      # mid-lift grip


def recorder_cost(graspcore, make, ticks=2000, repeats=7):
    """Per-tick cost of the manual-clock runtime without and with the tick log, µs: two equal
    worlds, repeats interleaved, each ring reused as in a session (its pages touched at start)."""
    worlds = {False: make(graspcore), True: make(graspcore)}
    worlds[True][0].set_tick_log(ticks + 256)
    out = np.zeros(ticks + 256, worlds[True][0].tick_dtype())
    times = {False: [], True: []}
    for _ in range(repeats):
        for logging, (w, hips) in worlds.items():
            w.start(realtime=False, haptic_rate=1000.0)
            w.push_hips(hips, 0.0)
            w.advance(200)                     # grasp settles, bodies adopted
            w.drain_ticks(out)
            t0 = time.perf_counter()
            w.advance(ticks)
            times[logging].append((time.perf_counter() - t0) / ticks * 1e6)
            w.drain_ticks(out)
            w.stop()
    return statistics.median(times[False]), statistics.median(times[True]), worlds[True][0]


def realtime_work(graspcore, make, seconds=2.0):
    """Median / p99 of the real-time haptic tick's own work (records' work_us), µs."""
    w, hips = make(graspcore)
    w.set_tick_log(int(seconds * 1000) + 500)
    w.start(priority=0)
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        w.push_hips(hips, time.perf_counter() - t0)
        time.sleep(0.005)
    w.stop()
    out = np.zeros(int(seconds * 1000) + 500, w.tick_dtype())
    rec = w.drain_ticks(out)
    work = rec["work_us"][10:].astype(np.float64)
    log = rec["log_us"][10:].astype(np.float64)
    return (float(np.median(work)), float(np.percentile(work, 99)), float(np.median(log)),
            float(np.percentile(log, 99)), int(w.tick_log_overflow()))


def synthetic_session(path, minutes, compression, n_bodies=20, n_fingers=10, block=100):
    """A recording of a 1 kHz session: 4 bodies and the fingers moving, the rest at rest, in
    chunks of 100 ticks (the live recorder closes one every 100 ms)."""
    from addon.engine import recording, scene
    desc = scene.SceneDesc()
    for i in range(n_bodies):
        mp = scene.MassProperties(0.05, 6.4e-5, np.zeros(3), np.eye(3) * 1.3e-5)
        desc.bodies.append(scene.BodyDesc(f"Body {i:02d}", False, [box(0.02)], [],
                                          np.array([0.1 * i, 0.0, 0.02]), np.array([1.0, 0, 0, 0]),
                                          mass=0.05, mass_properties=mp))
    for j in range(n_fingers):
        desc.fingers.append(scene.FingerDesc(f"Finger {j}", np.array([0.1 * j, 0.1, 0.05]), channel=j))
    header = recording.make_header(desc, mode="exec", haptic_rate=1000.0, fps=60.0)
    w = recording.RecordingWriter(str(path), header, compression=compression)
    dtype = w.dtype
    n = int(minutes * 60 * 1000) + 1
    moving = np.arange(4)
    for start in range(0, n, block):
        k = np.arange(start, min(n, start + block))
        t = k * 1e-3
        r = np.zeros(len(k), dtype)
        r["tick"], r["time"], r["object_time"] = k, t, t
        r["state_hash"] = k.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)   # wraps: a varied hash
        r["period_us"], r["work_us"], r["flags"] = 1000.0, 40.0, 1
        r["pose"][:, :, 0] = 0.1 * np.arange(n_bodies)
        r["pose"][:, :, 2] = 0.02
        r["pose"][:, :, 3] = 1.0
        phase = 0.3 * t[:, None] + moving[None, :]
        r["pose"][:, moving, 0] += 0.05 * np.sin(phase)
        r["pose"][:, moving, 2] += 0.1 * (1 - np.cos(phase))
        r["pose"][:, moving, 3] = np.cos(phase / 2)
        r["pose"][:, moving, 6] = np.sin(phase / 2)
        r["velocity"][:, moving, 0] = 0.015 * np.cos(phase)
        r["wrench"][:, :, 2] = -0.05 * 9.81
        fp = 0.3 * t[:, None] + np.arange(n_fingers)[None, :]
        r["hip"][:, :, 0] = 0.1 * np.arange(n_fingers) + 0.02 * np.sin(fp)
        r["hip"][:, :, 1] = 0.1
        r["hip"][:, :, 2] = 0.05 + 0.02 * np.cos(fp)
        r["god_object"] = r["hip"]
        r["contact"] = -1
        w.write_ticks(r)
        w.flush()
    w.close()
    return n


def bake_scene(bpy, n_bodies=20, n_fingers=10):
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.frame_start = 60, 1
    import grasp_env
    for i in range(n_bodies):
        obj = grasp_env.add_cube(bpy, f"Body {i:02d}", 0.04, (0.1 * i, 0.0, 0.02))
        obj.grasp_lab.role = "DYNAMIC"
    for j in range(n_fingers):
        f = bpy.data.objects.new(f"Finger {j}", None)
        scene.collection.objects.link(f)
        f.grasp_lab.role = "FINGER"
    return scene


def keyframe_insert_slice(bpy, frames=600):
    """keyframe_insert of one body's location + rotation + scale at every frame of a slice."""
    obj = bpy.data.objects["Body 00"]
    obj.animation_data_clear()
    obj.rotation_mode = "QUATERNION"
    t0 = time.perf_counter()
    for f in range(1, frames + 1):
        obj.location.x = 0.001 * f
        for path in ("location", "rotation_quaternion", "scale"):
            obj.keyframe_insert(path, frame=f)
    return (time.perf_counter() - t0) / (frames * 10)      # per key (10 channels a frame)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--keep", default=None, help="keep the files in this folder")
    args = ap.parse_args(argv)
    import grasp_env
    grasp_env.isolate()
    import bpy
    grasp_env.enable()
    gc = grasp_env.graspcore()
    rec_mod = grasp_env.submodule("engine.recording")
    bake_mod = grasp_env.submodule("bake")
    tmp = args.keep or tempfile.mkdtemp(prefix="grasp_bench_rec_")
    os.makedirs(tmp, exist_ok=True)
    rows, targets = [], []
    try:
        # 1. recorder cost
        for label, make in (("20 bodies + 10 fingers", many_world), ("sample scene, 2 + 2", sample_world)):
            off, on, w = recorder_cost(gc, make)
            work50, work99, log50, log99, overflow = realtime_work(gc, make)
            rows.append((f"real-time haptic tick, {label}: its work / recording it (median; p99)",
                         f"{work50:.1f} / {log50:.2f} µs ({work99:.1f} / {log99:.2f}); "
                         f"{w.tick_dtype().itemsize} B a record, {overflow} dropped"))
            rows.append((f"manual-clock runtime tick (haptic + object ticks), {label}: without / with the "
                         f"tick log (median of 7, interleaved)", f"{off:.2f} / {on:.2f} µs ({on - off:+.2f} µs)"))
            share = log50 / work50 * 100 if work50 > 0 else float("inf")
            targets.append((f"recorder cost ≤ 2 % of the haptic tick, {label}",
                            f"{share:.1f} % ({log50:.2f} of {work50:.1f} µs)", share <= 2.0))
        # 2-4. the 10-minute session
        sizes = {}
        for c in ("zstd", "lz4", "none"):
            p = os.path.join(tmp, f"size_{c}.mcap")
            n = synthetic_session(p, 10 / 60, c)
            sizes[c] = os.path.getsize(p) / ((n - 1) / 1000)
        path = os.path.join(tmp, "ten_minutes.mcap")
        t0 = time.perf_counter()
        n = synthetic_session(path, args.minutes, "lz4")
        t_write = time.perf_counter() - t0
        size = os.path.getsize(path)
        # A recorded session's file is long on disk when it is baked: not the kernel writing
        # back the 240 MB just generated on the other core while the bake is timed.
        os.sync()
        t0 = time.perf_counter()
        summary = rec_mod.summarize(path)
        t_info = time.perf_counter() - t0
        assert summary["ticks"] == n and not summary["damage"]
        scene = bake_scene(bpy)
        t0 = time.perf_counter()
        rec = rec_mod.open_recording(path, fps=scene.render.fps, previous=True)   # as the operator reads it
        t_open = time.perf_counter() - t0
        t0 = time.perf_counter()
        report = bake_mod.bake_recording(bpy.context, rec)
        t_bake = time.perf_counter() - t0
        per_key = keyframe_insert_slice(bpy)
        rows.append((f"{args.minutes:g}-minute session, 20 bodies + 10 fingers at 1 kHz: ticks, file (lz4), "
                     f"written in", f"{n}, {size / 1e6:.0f} MB, {t_write:.1f} s"))
        rows.append(("bake at 60 fps: open (the ticks at frames) + bake", f"{t_open:.2f} + {t_bake:.2f} s, "
                     f"{report.frames} frames, {report.keys} keys"))
        rows.append(("keyframe_insert, same run (one body, 600 frames × 10 channels)",
                     f"{per_key * 1e6:.1f} µs a key: {per_key * report.keys:.0f} s for the bake's {report.keys} keys"))
        rows.append(("open + summarise (grasp-lab info)", f"{t_info:.2f} s"))
        for c in ("zstd", "lz4", "none"):
            rows.append((f"file size per second of session, 20 bodies + 10 fingers, {c}", f"{sizes[c] / 1e6:.2f} MB/s"))
        for c in ("zstd", "lz4", "none"):
            import recordings
            p = os.path.join(tmp, f"sample_{c}.mcap")
            recordings.record_exec(p, gc, seconds=6.0, compression=c)
            rows.append((f"file size per second of session, sample scene (2 + 2, real physics), {c}",
                         f"{os.path.getsize(p) / 6.0 / 1e3:.0f} kB/s"))
        targets.append((f"bake a {args.minutes:g}-minute session (20 bodies, 10 fingers) at 60 fps < 2 s: "
                        f"the keys, from the recording read", f"{t_bake:.2f} s", t_bake < 2.0))
        targets.append(("the same, reading its ticks from the file first (lz4: decompressing every chunk)",
                        f"{t_open + t_bake:.2f} s ({t_open:.2f} + {t_bake:.2f})", t_open + t_bake < 2.0))
        targets.append(("open and summarise the same file < 1 s", f"{t_info:.2f} s", t_info < 1.0))
    finally:
        if not args.keep:
            shutil.rmtree(tmp, ignore_errors=True)
    print("## Recording\n")
    import mcap
    print(f"`bench/bench_recording.py`: bpy {bpy.app.version_string}, mcap {getattr(mcap, '__version__', '')}, "
          f"numpy {np.__version__}, load average {' '.join(open('/proc/loadavg').read().split()[:3])}.\n")
    print("| target | result | met |")
    print("|---|---|---|")
    for name, value, met in targets:
        print(f"| {name} | {value} | {'yes' if met else '**no**'} |")
    print()
    print("| measurement | value |")
    print("|---|---|")
    for name, value in rows:
        print(f"| {name} | {value} |")
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
