"""Grasp analysis benchmark; prints a Markdown section (docs/benchmarks.md, "Grasp analysis").

A 10-minute session recorded by the project's recorder (EXEC, 1 kHz): two boxes held in the
air, one by three fingers (in force closure), one pinched by two, the hands carrying them
up and down and side to side so that every tick's contacts differ. Then, timed:

1. ``grasp-lab analyze REC --csv DIR --every 33`` (every display-rate tick, 30 Hz) as a
   command in its own process, and its parts in this one: reading the ticks it needs, the
   analysis (graspcore.grasp_quality_batch and grasp_mu_min), the CSV tables. Target < 10 s.
2. Beside it in the same run: the same ticks through ``analysis.analyse`` one snapshot at a
   time (the live HUD's call: also the per-snapshot cost, target < 0.5 ms for 2 bodies and 5
   fingers; with the volume and without, ``volume=False``), and the contact sets' quality through scipy's ConvexHull (qhull, the usual way),
   on a sample of them.

Usage: .venv/bin/python bench/bench_analysis.py [--minutes 10] [--keep DIR]
"""
from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
sys.path.insert(0, ROOT)

SIDE, R, SQUEEZE = 0.06, 0.01, 0.003
X = SIDE / 2 + R - SQUEEZE


def held_boxes_scene():
    import trimesh
    from addon.engine import scene
    d = scene.SceneDesc()
    tm = trimesh.creation.box((SIDE,) * 3)
    mesh = scene.MeshData(np.array(tm.vertices), np.array(tm.faces), source="box")
    for name, x0 in (("Three", 0.0), ("Pinch", 0.3)):
        d.bodies.append(scene.BodyDesc(name, False, [mesh.vertices], [mesh], np.array([x0, 0, 0.3]),
                                       np.array([1.0, 0, 0, 0]), mass=0.2, mu_s=0.8, mu_d=0.6))
    offsets = [(X, 0.015, 0), (X, -0.015, 0), (-(X - SQUEEZE), 0, 0), (0.3 + X, 0, 0), (0.3 - X, 0, 0)]
    for i, o in enumerate(offsets):
        d.fingers.append(scene.FingerDesc(f"Finger {i}", np.array(o) + [0, 0, 0.3], R, 1000.0, 2.0, i))
    return scene.prepare(d), np.array(offsets) + [0, 0, 0.3]


def record(path, minutes):
    import graspcore
    import recordings
    desc, start = held_boxes_scene()

    def hips(t):      # carried up and down (10 cm, 4 s period) and sideways (5 cm, 7 s period)
        return start + [0.05 * np.sin(2 * np.pi * t / 7), 0.0, 0.05 * (1 - np.cos(2 * np.pi * t / 4))]
    recordings.record_scene(path, graspcore, desc, hips, minutes * 60.0, fps=30)


def scipy_quality(points, normals, mu, center, radius, edges=8):
    """GraspIt's way: the edge wrenches' hull by qhull; epsilon the nearest facet's distance."""
    from scipy.spatial import ConvexHull
    w = []
    for p, n, m in zip(points, normals, mu):
        a = np.eye(3)[np.argmin(np.abs(n))]
        t1 = np.cross(n, a)
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(n, t1)
        for j in range(edges):
            f = n + m * (np.cos(2 * np.pi * j / edges) * t1 + np.sin(2 * np.pi * j / edges) * t2)
            w.append(np.concatenate([f, np.cross(p - center, f) / radius]))
    try:
        h = ConvexHull(np.array(w))
    except Exception:
        return 0.0, 0.0
    return (float(-h.equations[:, -1].max()) if (h.equations[:, -1] < 0).all() else 0.0), h.volume


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--every", type=int, default=33)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--keep", metavar="DIR")
    args = ap.parse_args(argv)
    import graspcore
    from addon.engine import analysis, export, recording
    tmp = args.keep or tempfile.mkdtemp(prefix="grasp_lab_bench_analysis_")
    os.makedirs(tmp, exist_ok=True)
    path = os.path.join(tmp, f"held_{args.minutes:g}min.mcap")
    t0 = time.perf_counter()
    made = None
    if not os.path.exists(path):
        record(path, args.minutes)
        made = time.perf_counter() - t0
    size = os.path.getsize(path)
    os.sync()
    every = args.every
    out_dir = os.path.join(tmp, "csv")

    # 1. The command, in its own process (Python start, imports, read, analysis, CSV, summary).
    launcher = os.path.join(ROOT, ".venv", "bin", "grasp-lab")
    walls = []
    for _ in range(args.repeats):
        w0 = time.perf_counter()
        res = subprocess.run([launcher, "analyze", path, "--csv", out_dir, "--every", str(every)],
                             capture_output=True, text=True)
        walls.append(time.perf_counter() - w0)
    # A command that fails (the core refusing a contact set) is reported, its parts still timed.
    command_error = res.stderr.strip() if res.returncode != 0 else ""
    command_out = res.stdout
    # Its parts, here.
    parts = {"read": [], "analysis": [], "csv": []}
    real_mu_min = analysis._mu_min
    for _ in range(args.repeats):
        a = time.perf_counter()
        rec = recording.open_recording(path, every=every)
        b = time.perf_counter()
        try:
            table = analysis.analyse_recording(rec, every=every)
        except analysis.GraspAnalysisError:        # the same failure as the command's: time the rest
            analysis._mu_min = lambda core, point, normal, starts, *rest: np.zeros(len(starts))
            try:
                table = analysis.analyse_recording(rec, every=every)
            finally:
                analysis._mu_min = real_mu_min
        c = time.perf_counter()
        export.export_analysis_csv(rec, table, out_dir)
        d = time.perf_counter()
        parts["read"].append(b - a)
        parts["analysis"].append(c - b)
        parts["csv"].append(d - c)
    med = {k: statistics.median(v) for k, v in parts.items()}
    analysed = int(np.count_nonzero(rec.ticks["tick"] % every == 0))
    sets, contacts = len(table.body), len(table.finger)
    # Split of the analysis: the quality batch and mu_min alone, on the same sets.
    starts, counts = table.first, table.count
    a = time.perf_counter()
    graspcore.grasp_quality_batch(table.point, table.normal, table.mu, counts, table.center, table.radius)
    t_batch = time.perf_counter() - a
    a = time.perf_counter()
    mu_failed = []
    for i, (s, c) in enumerate(zip(starts, counts)):
        try:
            graspcore.grasp_mu_min(table.point[s:s + c], table.normal[s:s + c], table.center[i], table.radius[i])
        except ValueError as ex:
            mu_failed.append((i, str(ex)))
    t_mu = time.perf_counter() - a

    # The same without mu_min (bench only: grasp_mu_min left out), to show what the rest costs.
    analysis._mu_min = lambda core, point, normal, starts, *rest: np.zeros(len(starts))
    try:
        a = time.perf_counter()
        analysis.analyse_recording(rec, every=every)
        t_rest = time.perf_counter() - a
    finally:
        analysis._mu_min = real_mu_min

    # 2. Peers: one snapshot at a time (the live call), and scipy's qhull on a sample of the sets.
    models = analysis.body_models(rec.header["scene"])
    radii = [f["radius"] for f in rec.header["scene"]["fingers"]]
    rows = np.flatnonzero(rec.ticks["tick"] % every == 0)
    acc = analysis.recorded_accelerations(models, rec.ticks, rows)
    per = []
    for k, r in enumerate(rows[:1000]):
        t = rec.ticks[r]
        a = time.perf_counter()
        try:
            analysis.analyse(models, t["pose"], t["god_object"], t["force"], t["normal"], t["state"],
                             t["contact"], radii, accelerations=acc[k])
        except analysis.GraspAnalysisError:
            continue
        per.append(time.perf_counter() - a)
    per_snapshot = statistics.median(per)
    per_fast = []
    for k, r in enumerate(rows[:1000]):
        t = rec.ticks[r]
        a = time.perf_counter()
        try:
            analysis.analyse(models, t["pose"], t["god_object"], t["force"], t["normal"], t["state"],
                             t["contact"], radii, accelerations=acc[k], volume=False)
        except analysis.GraspAnalysisError:
            continue
        per_fast.append(time.perf_counter() - a)
    per_snapshot_fast = statistics.median(per_fast)
    analysis._mu_min = lambda core, point, normal, starts, *rest: np.zeros(len(starts))
    per_rest = []
    try:
        for k, r in enumerate(rows[:1000]):
            t = rec.ticks[r]
            a = time.perf_counter()
            analysis.analyse(models, t["pose"], t["god_object"], t["force"], t["normal"], t["state"],
                             t["contact"], radii, accelerations=acc[k])
            per_rest.append(time.perf_counter() - a)
    finally:
        analysis._mu_min = real_mu_min
    per_snapshot_rest = statistics.median(per_rest)
    sample = np.linspace(0, sets - 1, min(sets, 600)).astype(int)
    a = time.perf_counter()
    worst = 0.0
    for i in sample:
        s, c = starts[i], counts[i]
        eps, vol = scipy_quality(table.point[s:s + c], table.normal[s:s + c], table.mu[s:s + c], table.center[i],
                                 table.radius[i])
        q = table.quality[i]
        worst = max(worst, abs(eps - q["epsilon"]) / max(q["epsilon"], 1e-300) if q["epsilon"] else abs(eps))
    t_scipy_set = (time.perf_counter() - a) / len(sample)
    t_batch_set = t_batch / sets

    held = {n: int(np.count_nonzero(table.body == b)) for b, n in enumerate(rec.body_names)}
    closure = {n: int(np.count_nonzero(table.quality["force_closure"][table.body == b]))
               for b, n in enumerate(rec.body_names)}
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    load = os.getloadavg()
    print("## Grasp analysis\n")
    print(f"Run on {when} by `bench/bench_analysis.py` ({platform.machine()}, {os.cpu_count()} CPUs, "
          f"{platform.platform()}, load average at the end {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; the machine "
          f"was shared with other jobs). The recording: a {args.minutes:g}-minute EXEC session of two 0.2 kg boxes "
          f"held in the air, one by three fingers, one pinched by two, carried up and down and sideways (made by "
          f"the project's recorder{f' in {made:.0f} s' if made else ' (in an earlier run)'}; {int(rec.ticks['tick'][-1]) + 1} ticks, {size / 1e6:.0f} MB lz4). "
          f"`grasp-lab analyze --every {every}` analyses every {every}-th tick (display rate, 30 Hz): "
          f"{analysed} ticks, {sets} held-body samples, {contacts} contacts, cones of 8 edges.\n")
    print("| what | time | target | met |\n|---|---|---|---|")
    if command_error:
        print(f"| `grasp-lab analyze REC --csv DIR --every {every}`, its own process | failed after "
              f"{statistics.median(walls):.2f} s: {command_error.splitlines()[-1]} | < 10 s | no |")
    else:
        print(f"| `grasp-lab analyze REC --csv DIR --every {every}`, its own process (median of {args.repeats}; "
              f"min {min(walls):.2f} s) | {statistics.median(walls):.2f} s | < 10 s | "
              f"{'yes' if statistics.median(walls) < 10 else 'no'} |")
    print(f"| of which, in one process: reading the ticks (every {every}-th and the one before) | "
          f"{med['read']:.2f} s | | |")
    if command_error:
        print("| analysis (`analyse_recording`) | fails at the same set as the command | | |")
    else:
        print(f"| analysis (`analyse_recording`: forces, quality batch, mu_min, grip/load) | {med['analysis']:.2f} s "
              f"| | |")
    print(f"| of which `grasp_quality_batch` over the {sets} sets | {t_batch:.3f} s ({1e6 * t_batch_set:.1f} µs a set) | | |")
    failed = f"; {len(mu_failed)} sets refused (\"{mu_failed[0][1]}\")" if mu_failed else ""
    print(f"| of which `grasp_mu_min` per set | {t_mu:.2f} s ({1e6 * t_mu / sets:.0f} µs a set{failed}) | | |")
    print(f"| the analysis with `grasp_mu_min` left out (bench only) | {t_rest:.2f} s | | |")
    print(f"| writing grasp.csv and contacts.csv | {med['csv']:.2f} s | | |")
    without = med["read"] + t_rest + med["csv"]
    print(f"| read + analysis without `grasp_mu_min` + CSV, in one process | {without:.2f} s | < 10 s | "
          f"{'yes' if without < 10 else 'no'} |")
    print(f"| `analysis.analyse`, one snapshot (2 bodies, 5 fingers; the live call), median of "
          f"{len(per)} | {1e3 * per_snapshot:.3f} ms | < 0.5 ms | {'yes' if per_snapshot < 5e-4 else 'no'} |")
    print(f"| the same with `volume=False` (the core's fast path: no 6-D hull, the volume not computed) | "
          f"{1e3 * per_snapshot_fast:.3f} ms | < 0.5 ms | {'yes' if per_snapshot_fast < 5e-4 else 'no'} |")
    print(f"| the same with `grasp_mu_min` left out (bench only) | {1e3 * per_snapshot_rest:.3f} ms | | |")
    print(f"| peer: scipy `ConvexHull` (qhull) quality of a set, {len(sample)} of the same sets | "
          f"{1e6 * t_scipy_set:.0f} µs a set: {t_scipy_set / t_batch_set:.0f}x the batch's | | |")
    print()
    print(f"Held: " + ", ".join(f"{n} {held[n]} samples, {closure[n]} in force closure" for n in rec.body_names)
          + f". Largest relative difference of epsilon from qhull's on the sample: {worst:.1e}.\n")
    total = (med["read"] + t_rest + med["csv"] + t_mu) if command_error else statistics.median(walls)
    if command_error:
        print("Read + analysis without `grasp_mu_min` + CSV + `grasp_mu_min` of every set the core answers: "
              f"{total:.2f} s in one process (the command adds Python's start, about 1 s).\n")
    else:
        print("The command's summary:\n\n```\n" + command_out.strip() + "\n```")
    # For run_bench.py's targets table.
    print(f"<!-- target analyze_s={total:.3f} mu_min_s={t_mu:.3f} failed={1 if command_error else 0} "
          f"minutes={args.minutes:g} snapshot_ms={1e3 * per_snapshot:.3f} fast_ms={1e3 * per_snapshot_fast:.3f} -->")
    if not args.keep:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
