"""What an area contact costs the grasp analysis, and the tick record (#15 item 4,
docs/analysis.md "Area contacts").

1. The grasp quality of one contact set on the fast path (graspcore.grasp_quality, volume=False)
   and the whole live call (analysis.analyse, volume=False, no memo: a fresh set every time,
   mu_min included), for the same bodies held by area contacts and by point contacts: a plate on a
   palm (a 4-corner patch against its pressure centroid as one point), a box pinched by two square
   pads (8 corners) against two sphere fingertips and two soft fingertips (torsion generators).
   Interleaved repeats, medians, ratios to the point contacts of the same scene.
2. The tick record's size with the `patch` field and without (the layout before it).

Runs in .venv: `.venv/bin/python bench/bench_area_analysis.py [--repeats N] [--json out.json]`.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time

import numpy as np

import graspcore

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
from addon.engine import analysis  # noqa: E402

DT = 1e-3
MU = (0.8, 0.6)


def box(hx, hy, hz, center=(0.0, 0.0, 0.0)):
    return np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)], float) + center


def model(points, mass):
    radius = float(np.max(np.linalg.norm(points, axis=1)))
    return analysis.BodyModel("Body", mass, np.zeros(3), MU[0], MU[1], radius, False)


def plate_on_palm():
    w = graspcore.World()
    w.add_finger(radius=0.0, stiffness=1000.0, damping=2.0, position=(0, 0, -0.01), points=box(0.045, 0.04, 0.01))
    pts = box(0.1, 0.1, 0.005)
    w.add_body(pts, mass=0.4, position=(0, 0, 0.005), mu_s=MU[0], mu_d=MU[1])
    w.step(DT, steps=500)
    return w, model(pts, 0.4), np.zeros(1), None


def pinch(kind):
    """A 6 cm box without gravity squeezed 3 mm along x by two pads, spheres or soft spheres."""
    w = graspcore.World(gravity=(0, 0, 0))
    pts = box(0.03, 0.03, 0.03)
    w.add_body(pts, mass=0.2, mu_s=MU[0], mu_d=MU[1])
    torsions = None
    for s in (1, -1):
        if kind == "pads":
            f = w.add_finger(radius=0.0, stiffness=1000.0, damping=2.0, position=(s * 0.04, 0, 0),
                             points=box(0.002, 0.01, 0.01))
            reach = 0.002
        else:
            f = w.add_finger(radius=0.008, stiffness=1000.0, damping=2.0, position=(s * 0.045, 0, 0),
                             torsion=0.005 if kind == "soft" else 0.0)
            reach = 0.008
        start, end = s * (0.03 + reach + 0.005), s * (0.03 + reach - 0.003)
        w.set_hip(f, (start, 0, 0))
    for i in range(1, 301):
        u = min(i / 200, 1.0)
        for f, s in enumerate((1, -1)):
            reach = 0.002 if kind == "pads" else 0.008
            a, b = s * (0.03 + reach + 0.005), s * (0.03 + reach - 0.003)
            w.set_hip(f, (a + u * (b - a), 0, 0))
        w.step(DT)
    if kind == "soft":
        torsions = np.array([0.005, 0.005])
    return w, model(pts, 0.2), np.full(2, 0.0 if kind == "pads" else 0.008), torsions


def three_fingertips():
    """The box held in closure by point contacts: two fingertips on its +x face at y = +-12 mm, one
    on its -x face squeezed twice as deep (forces and torques about z balance)."""
    w = graspcore.World(gravity=(0, 0, 0))
    pts = box(0.03, 0.03, 0.03)
    w.add_body(pts, mass=0.2, mu_s=MU[0], mu_d=MU[1])
    ends = [((0.043, 0.012), 0.035), ((0.043, -0.012), 0.035), ((-0.043, 0.0), -0.032)]
    for (x, y), _ in ends:
        w.add_finger(radius=0.008, stiffness=1000.0, damping=2.0, position=(x, y, 0))
    for i in range(1, 301):
        u = min(i / 200, 1.0)
        for f, ((x, y), x_end) in enumerate(ends):
            w.set_hip(f, (x + u * (x_end - x), y, 0))
        w.step(DT)
    return w, model(pts, 0.2), np.full(3, 0.008), None


def arrays(w, radii, torsions, area=True):
    """The live snapshot's arrays, as the HUD's monitor hands them to analysis.analyse."""
    s = w.snapshot()
    return dict(poses=s["poses"], god_objects=s["god_objects"], forces=s["spring_forces"], normals=s["normals"],
                states=s["finger_states"], contact_bodies=s["contact_bodies"], finger_radii=radii,
                patches=s["patches"] if area else None, torsions=torsions)


def wrench_set(kw, m):
    """The grasp wrench space's contacts of the snapshot, as analyse_arrays builds them."""
    table = analysis.analyse_arrays([m], kw["poses"][None], kw["god_objects"][None], kw["forces"][None],
                                    kw["normals"][None], kw["states"][None], kw["contact_bodies"][None],
                                    kw["finger_radii"], with_mu_min=False, volume=False,
                                    patches=None if kw["patches"] is None else kw["patches"][None],
                                    torsions=kw["torsions"])
    pts, nrm, mu, rho, _ = analysis.wrench_contacts(
        table.point, table.normal, table.mu, table.finger,
        None if kw["patches"] is None else kw["patches"][table.finger], kw["torsions"])
    return pts, nrm, mu, rho, table.center[0], table.radius[0], bool(table.quality["force_closure"][0])


def time_us(fn, n):
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t0) / n * 1e6


def cases():
    w, m, radii, _ = plate_on_palm()
    out = {"plate on a palm: patch (4 corners)": (arrays(w, radii, None), m),
           "plate on a palm: its pressure centroid as one point": (arrays(w, radii, None, area=False), m)}
    for kind, name in (("pads", "box pinched by two square pads (2 x 4 corners)"),
                       ("spheres", "box pinched by two sphere fingertips"),
                       ("soft", "box pinched by two soft fingertips (rho 5 mm)")):
        w, m, radii, rho = pinch(kind)
        out[name] = (arrays(w, radii, rho), m)
    w, m, radii, rho = three_fingertips()
    out["box held by three sphere fingertips (point contacts in closure)"] = (arrays(w, radii, rho), m)
    return out


def run(repeats: int, inner: int) -> dict:
    found = cases()
    calls = {}
    for name, (kw, m) in found.items():
        pts, nrm, mu, rho, center, radius, closed = wrench_set(kw, m)

        def quality(pts=pts, nrm=nrm, mu=mu, rho=rho, center=center, radius=radius):
            graspcore.grasp_quality(pts, nrm, mu, center, radius, volume=False, torsion=rho)

        def live(kw=kw, m=m):
            analysis.analyse([m], kw["poses"], kw["god_objects"], kw["forces"], kw["normals"], kw["states"],
                             kw["contact_bodies"], kw["finger_radii"], volume=False, patches=kw["patches"],
                             torsions=kw["torsions"])
        calls[name] = (quality, live, len(pts), closed)
    samples = {name: ([], []) for name in calls}
    for _ in range(repeats):        # interleaved
        for name, (quality, live, _, _) in calls.items():
            samples[name][0].append(time_us(quality, inner))
            samples[name][1].append(time_us(live, max(1, inner // 10)))
    return {name: {"wrench_contacts": calls[name][2], "force_closure": calls[name][3],
                   "quality_us": statistics.median(samples[name][0]),
                   "analyse_us": statistics.median(samples[name][1])} for name in calls}


def record_sizes() -> dict:
    out = {}
    for nb, nf in ((2, 2), (20, 10)):
        size = graspcore.tick_dtype(nb, nf).itemsize
        out[f"{nb} bodies, {nf} fingers"] = {"with_patch": size,
                                            "before": size - 4 * 2 * graspcore._core.FINGER_PATCH_CORNERS * nf}
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--json")
    ap.add_argument("--repeats", type=int, default=11)
    ap.add_argument("--inner", type=int, default=200)
    args = ap.parse_args()
    result = {
        "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} logical cores",
        "load_start": os.getloadavg(),
        "git": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=HERE).stdout.strip(),
        "analysis": run(args.repeats, args.inner),
        "record": record_sizes(),
    }
    result["load_end"] = os.getloadavg()
    print(f"{result['date_utc']}, {result['machine']}, git {result['git']}, load {result['load_start']} / "
          f"{result['load_end']}")
    print("| contact set | GWS contacts | force closure | grasp_quality fast path, µs | analysis.analyse, µs |")
    print("|---|---|---|---|---|")
    for name, r in result["analysis"].items():
        print(f"| {name} | {r['wrench_contacts']} | {'yes' if r['force_closure'] else 'no'} | "
              f"{r['quality_us']:.1f} | {r['analyse_us']:.0f} |")
    for name, r in result["record"].items():
        print(f"record, {name}: {r['before']} -> {r['with_patch']} bytes "
              f"(+{100 * (r['with_patch'] / r['before'] - 1):.1f} %)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=2)


if __name__ == "__main__":
    main()
