"""Grasp quality benchmark; prints a Markdown section (docs/benchmarks.md, "Grasp quality").

graspcore.grasp_quality beside scipy's ConvexHull (qhull, what grasp-analysis code calls) on
the same seeded contact sets in the same run: 3, 5 and 10 contacts x 8 and 16 cone edges,
random mu in [0.1, 1.5]. Each repeat times all four below, one after the other, so all see
the same machine load; each timing is a burst of back-to-back calls of about 2 ms or one
call (whichever is longer), divided by the count (timeit's way: a single call of a few µs
right after a few ms of qhull runs several times slower, on this VM even an empty Python
call does, and that measures the switch, not the work). The fast path's first call after
scipy is reported beside it.

- scipy: ``ConvexHull(W)`` on the 6-D edge wrenches, built beforehand (not timed): the hull
  alone, which is what the closure test, epsilon and volume need.
- full: the whole ``grasp_quality(..., volume=True)`` call (the default): argument checks, the
  cones, the rank, the 6-D hull with epsilon, volume and weakest direction, and the two 3-D
  hulls of the force-only and torque-only conditions.
- fast: ``grasp_quality(..., volume=False)``: the same answers but the volume, with no hull
  (the closure LP and the support-function search).
- mu_min: ``grasp_mu_min`` of the same contacts (mu_max 10).

Per set the median of its repeats; per row the median over the sets, and the ratios of the
medians. One more row: the live session's held box (HELD_BOX), the fast path's worst case here. Target: the fast path >= 100x faster than scipy at 8 edges. Then the live analysis's
core work per display update (2 bodies x 5 contacts: grasp_quality without volume and
grasp_mu_min for each), and the batch: grasp_quality_batch over many sets in one call beside
a Python loop of single calls, with and without the volume.

Usage: .venv/bin/python bench/bench_grasp_quality.py [--quick] [--json FILE]
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import statistics
import sys
import time

import numpy as np
import scipy
from scipy.spatial import ConvexHull

import graspcore

TARGET = 100.0


def tangent_frame(n):
    a = np.zeros(3)
    a[int(np.argmin(np.abs(n)))] = 1.0
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(n, t1)


def edge_wrenches(points, normals, mu, center, radius, edges):
    """The documented cone convention (docs/api.md), written out for scipy."""
    rows = []
    for p, n, m in zip(points, normals, mu):
        t1, t2 = tangent_frame(n)
        for j in range(edges):
            angle = 2 * np.pi * j / edges
            f = n + m * (np.cos(angle) * t1 + np.sin(angle) * t2)
            rows.append(np.concatenate([f, np.cross(p - center, f) / radius]))
    return np.array(rows)


def random_grasp(rng, contacts):
    d = rng.normal(size=(contacts, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    points = d * rng.uniform(0.6, 1.4, size=(contacts, 1))
    normals = -d + 0.35 * rng.normal(size=(contacts, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    return points, normals, rng.uniform(0.1, 1.5, size=contacts), 0.1 * rng.normal(size=3), float(rng.uniform(1, 2))


def time_once(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def burst_size(fn, budget: float = 2e-3) -> int:
    """Calls of fn that take about budget seconds (at least 1), from a warm estimate."""
    fn()
    return max(1, int(budget / max(min(time_once(fn) for _ in range(3)), 1e-7)))


def time_burst(fn, count: int) -> float:
    """Seconds per call over count back-to-back calls."""
    t0 = time.perf_counter()
    for _ in range(count):
        fn()
    return (time.perf_counter() - t0) / count


# The live session's held box (bench_live_grasp.py's scene, one display update): 5 fingertips on
# a 6 cm box, contacts 0.4 mm off the centre's plane, normals tilted by 4e-3, mirror-symmetric.
# Its GWS is round about the origin (12 facets within 1 % of epsilon), so the support search
# grows its inner hull to 34 of the 40 wrenches (2,400 facets made) before the nearest facet
# supports them all.
HELD_BOX = (np.array([[0.0305997, 0.0, -0.00054295], [-0.02939982, -0.015, -0.00030271],
                      [-0.02939982, 0.015, -0.00030271], [0.00059994, 0.03, -0.00042283],
                      [0.00059994, -0.03, -0.00042283]]),
            np.array([[-0.99999198, 0.0, 0.00400405], [0.99999198, 0.0, -0.00400405],
                      [0.99999198, 0.0, -0.00400405], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0]]),
            np.full(5, 0.8), np.array([0.00059994, 0.0, -0.00042283]), 0.05196152)


def compare(contacts: int, edges: int, sets: int, repeats: int, seed: int, grasps=None, label="") -> dict:
    """grasps: these contact sets instead of `sets` random ones."""
    rng = np.random.default_rng(seed)
    full, fast, theirs, mu_mins, cold, facets, closed = [], [], [], [], [], [], 0
    for k in range(sets if grasps is None else len(grasps)):
        p, n, mu, c, r = random_grasp(rng, contacts) if grasps is None else grasps[k]
        w = edge_wrenches(p, n, mu, c, r, edges)
        res = graspcore.grasp_quality(p, n, mu, c, r, edges)  # warm: the workspace grows once
        quick = graspcore.grasp_quality(p, n, mu, c, r, edges, volume=False)
        if quick["force_closure"] != res["force_closure"] or quick["epsilon"] != pytest_approx(res["epsilon"]):
            raise SystemExit(f"fast path differs from the full path: {quick} vs {res}")
        facets.append(res["facets"])
        closed += res["force_closure"]
        run_scipy = lambda: ConvexHull(w)
        run_full = lambda: graspcore.grasp_quality(p, n, mu, c, r, edges)
        run_fast = lambda: graspcore.grasp_quality(p, n, mu, c, r, edges, volume=False)
        run_mu_min = lambda: graspcore.grasp_mu_min(p, n, c, r, edges)
        counts = [burst_size(fn) for fn in (run_scipy, run_full, run_fast, run_mu_min)]
        a, b, f, m, cf = [], [], [], [], []
        for _ in range(repeats):
            b.append(time_burst(run_scipy, counts[0]))
            cf.append(time_once(run_fast))
            a.append(time_burst(run_full, counts[1]))
            f.append(time_burst(run_fast, counts[2]))
            m.append(time_burst(run_mu_min, counts[3]))
        full.append(statistics.median(a))
        fast.append(statistics.median(f))
        theirs.append(statistics.median(b))
        mu_mins.append(statistics.median(m))
        cold.append(statistics.median(cf))
    o, q, t = statistics.median(full), statistics.median(fast), statistics.median(theirs)
    return dict(contacts=contacts, edges=edges, sets=len(full), repeats=repeats, label=label, full_us=o * 1e6, fast_us=q * 1e6,
                scipy_us=t * 1e6, ratio_full=t / o, ratio=t / q, mu_min_us=statistics.median(mu_mins) * 1e6,
                fast_cold_us=statistics.median(cold) * 1e6, facets=statistics.median(facets), closed=closed)


def pytest_approx(x: float):
    """Equal within 1e-9 relative (the tests' tolerance), for the sanity check above."""
    class Near:
        def __eq__(self, y):
            return abs(y - x) <= 1e-9 * abs(x)
    return Near()


def live_update(snapshots: int, seed: int) -> dict:
    """The analysis's core work per display update: 2 held bodies x 5 contacts, each
    grasp_quality(volume=False) and grasp_mu_min, as the live HUD calls them."""
    rng = np.random.default_rng(seed)
    bodies = [[random_grasp(rng, 5) for _ in range(2)] for _ in range(snapshots)]

    def update(pair):
        for p, n, mu, c, r in pair:
            graspcore.grasp_quality(p, n, mu, c, r, 8, volume=False)
            graspcore.grasp_mu_min(p, n, c, r, 8)
    update(bodies[0])
    times = sorted(time_once(lambda: update(pair)) for pair in bodies)
    return dict(snapshots=snapshots, median_us=statistics.median(times) * 1e6,
                p99_us=times[int(0.99 * (len(times) - 1))] * 1e6, max_us=times[-1] * 1e6)


def batch(contacts: int, edges: int, sets: int, repeats: int, seed: int, volume: bool) -> dict:
    rng = np.random.default_rng(seed)
    grasps = [random_grasp(rng, contacts) for _ in range(sets)]
    args = (np.concatenate([g[0] for g in grasps]), np.concatenate([g[1] for g in grasps]),
            np.concatenate([g[2] for g in grasps]), [contacts] * sets, np.array([g[3] for g in grasps]),
            [g[4] for g in grasps], edges)
    graspcore.grasp_quality_batch(*args, volume=volume)
    tb, tl = [], []
    for _ in range(repeats):
        tb.append(time_once(lambda: graspcore.grasp_quality_batch(*args, volume=volume)))
        tl.append(time_once(lambda: [graspcore.grasp_quality(*g, edges, volume=volume) for g in grasps]))
    b, loop = min(tb), min(tl)
    return dict(contacts=contacts, edges=edges, sets=sets, volume=volume, batch_us=b / sets * 1e6,
                loop_us=loop / sets * 1e6, per_second=sets / b)


def cpu_name() -> str:
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="few sets and repeats (checking the script)")
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args(argv)
    load_start = os.getloadavg()
    rows = []
    for edges in (8, 16):
        for contacts in (3, 5, 10):
            sets = (3 if args.quick else (20 if edges == 8 else 8))
            repeats = 3 if args.quick else (7 if edges == 8 else 3)
            rows.append(compare(contacts, edges, sets, repeats, seed=100 * contacts + edges))
            r = rows[-1]
            print(f"[grasp] {contacts} x {edges}: full {r['full_us']:.0f}, fast {r['fast_us']:.0f}, "
                  f"scipy {r['scipy_us']:.0f}, mu_min {r['mu_min_us']:.0f} us", file=sys.stderr, flush=True)
    rows.append(compare(5, 8, 1, 3 if args.quick else 15, seed=0, grasps=[HELD_BOX],
                        label="held box (the live session's)"))
    live = live_update(100 if args.quick else 2000, seed=11)
    batches = [batch(c, 8, 50 if args.quick else 500, 2 if args.quick else 5, seed=7 + c, volume=v)
               for v in (True, False) for c in (3, 5)]
    load_end = os.getloadavg()

    now = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    out = [
        "## Grasp quality: graspcore.grasp_quality vs scipy ConvexHull (qhull)", "",
        f"`bench/bench_grasp_quality.py` on {now}: {cpu_name()}, {os.cpu_count()} logical cores, "
        f"Python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}; load average "
        f"{' '.join(f'{x:.2f}' for x in load_start)} at start, {' '.join(f'{x:.2f}' for x in load_end)} at end "
        "(all alternate within each repeat, so load inflates them alike). Seeded random grasps, mu in "
        "[0.1, 1.5]. scipy: `ConvexHull` of the 6-D edge wrenches, built beforehand and not timed; full: "
        "the whole `grasp_quality` call with the volume (checks, cones, rank, the 6-D hull with epsilon, volume "
        "and weakest direction, and the force-only and torque-only 3-D hulls); fast: `grasp_quality(..., "
        "volume=False)`, every answer but the volume, no hull (closure LP, support-function search); mu_min: "
        "`grasp_mu_min` of the same contacts. The four alternate within each repeat, each timed over a burst "
        "of back-to-back calls of about 2 ms (one scipy call may be longer); *fast, first call* is one call "
        "right after scipy's (below). Median over the sets of each set's median.", "",
        "| contacts x edges | sets in closure | hull facets (median) | full µs | fast µs | scipy µs | "
        "scipy / full | scipy / fast | mu_min µs | fast, first call after scipy µs |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        out.append(f"| {r['contacts']} x {r['edges']}{', ' + r['label'] if r.get('label') else ''} | {r['closed']} of {r['sets']} | {r['facets']:.0f} | "
                   f"{r['full_us']:.0f} | {r['fast_us']:.1f} | {r['scipy_us']:.0f} | {r['ratio_full']:.0f}× | "
                   f"**{r['ratio']:.0f}×** | {r['mu_min_us']:.0f} | {r['fast_cold_us']:.0f} |")
    out += ["", f"Live analysis, the core's part of one display update: 2 held bodies × 5 contacts, each "
            f"`grasp_quality(volume=False)` and `grasp_mu_min` from Python, {live['snapshots']} random "
            f"snapshots: median {live['median_us']:.0f} µs, 99th percentile {live['p99_us']:.0f} µs, "
            f"largest {live['max_us']:.0f} µs (budget 500 µs for the whole analysis).", "",
            "Batch (`grasp_quality_batch`, one call, the GIL released throughout) beside a Python loop of "
            "single calls, 8 edges, best of the repeats:", "",
            "| contacts | volume | sets | batch µs per grasp | loop µs per grasp | grasps per second (batch) |",
            "|---|---|---|---|---|---|"]
    for b in batches:
        out.append(f"| {b['contacts']} | {b['volume']} | {b['sets']} | {b['batch_us']:.1f} | {b['loop_us']:.1f} | "
                   f"{b['per_second']:.0f} |")
    print("\n".join(out))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(rows=rows, batches=batches, live=live, target=TARGET), fh)
    return 0


if __name__ == "__main__":
    sys.exit(main())
