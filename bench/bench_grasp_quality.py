"""Grasp quality benchmark; prints a Markdown section (docs/benchmarks.md, "Grasp quality").

graspcore.grasp_quality beside scipy's ConvexHull (qhull, what grasp-analysis code calls) on
the same seeded contact sets in the same run: 3, 5 and 10 contacts x 8 and 16 cone edges,
random mu in [0.1, 1.5]. Repeats alternate between the two so both see the same machine load.

- scipy: ``ConvexHull(W)`` on the 6-D edge wrenches, built beforehand (not timed): the hull
  alone, which is what the closure test, epsilon and volume need.
- graspcore: the whole ``grasp_quality`` call: argument checks, the cones, the rank, the 6-D
  hull with epsilon, volume and weakest direction, and the two 3-D hulls of the force-only and
  torque-only conditions.

Per set the median of its repeats; per row the median over the sets, and the ratio of the
medians. Target: graspcore >= 100x faster at 8 edges. Then the batch: grasp_quality_batch
over many sets in one call beside a Python loop of single calls.

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


def compare(contacts: int, edges: int, sets: int, repeats: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    ours, theirs, facets, closed = [], [], [], 0
    for _ in range(sets):
        p, n, mu, c, r = random_grasp(rng, contacts)
        w = edge_wrenches(p, n, mu, c, r, edges)
        res = graspcore.grasp_quality(p, n, mu, c, r, edges)  # warm: the workspace grows once
        facets.append(res["facets"])
        closed += res["force_closure"]
        a, b = [], []
        for _ in range(repeats):
            b.append(time_once(lambda: ConvexHull(w)))
            a.append(time_once(lambda: graspcore.grasp_quality(p, n, mu, c, r, edges)))
        ours.append(statistics.median(a))
        theirs.append(statistics.median(b))
    o, t = statistics.median(ours), statistics.median(theirs)
    return dict(contacts=contacts, edges=edges, sets=sets, repeats=repeats, ours_us=o * 1e6, scipy_us=t * 1e6,
                ratio=t / o, facets=statistics.median(facets), closed=closed)


def batch(contacts: int, edges: int, sets: int, repeats: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    grasps = [random_grasp(rng, contacts) for _ in range(sets)]
    args = (np.concatenate([g[0] for g in grasps]), np.concatenate([g[1] for g in grasps]),
            np.concatenate([g[2] for g in grasps]), [contacts] * sets, np.array([g[3] for g in grasps]),
            [g[4] for g in grasps], edges)
    graspcore.grasp_quality_batch(*args)
    tb, tl = [], []
    for _ in range(repeats):
        tb.append(time_once(lambda: graspcore.grasp_quality_batch(*args)))
        tl.append(time_once(lambda: [graspcore.grasp_quality(*g, edges) for g in grasps]))
    b, loop = min(tb), min(tl)
    return dict(contacts=contacts, edges=edges, sets=sets, batch_us=b / sets * 1e6, loop_us=loop / sets * 1e6,
                per_second=sets / b)


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
            print(f"[grasp] {contacts} x {edges}: {rows[-1]['ours_us']:.0f} vs {rows[-1]['scipy_us']:.0f} us",
                  file=sys.stderr, flush=True)
    batches = [batch(c, 8, 50 if args.quick else 500, 2 if args.quick else 5, seed=7 + c) for c in (3, 5)]
    load_end = os.getloadavg()

    now = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    out = [
        "## Grasp quality: graspcore.grasp_quality vs scipy ConvexHull (qhull)", "",
        f"`bench/bench_grasp_quality.py` on {now}: {cpu_name()}, {os.cpu_count()} logical cores, "
        f"Python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}; load average "
        f"{' '.join(f'{x:.2f}' for x in load_start)} at start, {' '.join(f'{x:.2f}' for x in load_end)} at end "
        "(the two alternate repeat by repeat, so load inflates both alike). Seeded random grasps, mu in "
        "[0.1, 1.5]. scipy: `ConvexHull` of the 6-D edge wrenches, built beforehand and not timed; graspcore: "
        "the whole `grasp_quality` call (checks, cones, rank, the 6-D hull with epsilon, volume and weakest "
        "direction, and the force-only and torque-only 3-D hulls). Median over the sets of each set's median.", "",
        "| contacts x edges | sets in closure | hull facets (median) | graspcore µs | scipy µs | ratio |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        out.append(f"| {r['contacts']} x {r['edges']} | {r['closed']} of {r['sets']} | {r['facets']:.0f} | "
                   f"{r['ours_us']:.0f} | {r['scipy_us']:.0f} | {r['ratio']:.0f}× |")
    out += ["", "Batch (`grasp_quality_batch`, one call, the GIL released throughout) beside a Python loop of "
            "single calls, 8 edges, best of the repeats:", "",
            "| contacts | sets | batch µs per grasp | loop µs per grasp | grasps per second (batch) |",
            "|---|---|---|---|---|"]
    for b in batches:
        out.append(f"| {b['contacts']} | {b['sets']} | {b['batch_us']:.0f} | {b['loop_us']:.0f} | "
                   f"{b['per_second']:.0f} |")
    print("\n".join(out))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(rows=rows, batches=batches, target=TARGET), fh)
    return 0


if __name__ == "__main__":
    sys.exit(main())
