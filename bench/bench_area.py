"""Area contacts (#15, docs/physics.md "Area contacts"): the issue's target and what an area
contact costs.

1. A 0.4 kg plate (20 x 20 x 1 cm) on a 9 x 8 cm convex palm, lifted 10 cm over 1 s and carried
   10 cm over the next second (minimum-jerk), held 1 s: largest tilt and slide on the palm; and
   the same with the area term off (the palm as one point contact: a 1 cm sphere finger at its
   centre, what Grasp Lab had before).
2. Step time (dt = 1 ms, all inside C): a finger pressed on a static table as a sphere (one
   point) and as a flat pad (four points); the plate resting level on the palm against the plate
   on three sphere fingers (the way to hold it level with point contacts). Interleaved repeats,
   medians, ratios.
3. `--held`: the held box of bench_core_scenes (3 and 5 sphere fingers), per step, for running
   under two builds in one session (sphere fingers' cost unchanged).

Runs in .venv: `.venv/bin/python bench/bench_area.py [--json out.json]`.
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
sys.path.insert(0, HERE)
import bench_core_scenes as bcs  # noqa: E402

DT = 1e-3
G = 9.81
K = 1000.0


def box(hx, hy, hz, center=(0.0, 0.0, 0.0)):
    return np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)], float) + center


def tilt_deg(w, body):
    qw, qx, qy, qz = w.body_pose(body)[1]
    r22 = 1 - 2 * (qx * qx + qy * qy)
    return float(np.degrees(np.arccos(np.clip(r22, -1, 1))))


def min_jerk(u):
    u = min(max(u, 0.0), 1.0)
    return 10 * u**3 - 15 * u**4 + 6 * u**5


def carry(area: bool) -> dict:
    w = graspcore.World()
    if area:
        palm = w.add_finger(radius=0.0, stiffness=K, damping=2.0, position=(0, 0, -0.01), points=box(0.045, 0.04, 0.01))
    else:
        palm = w.add_finger(radius=0.01, stiffness=K, damping=2.0, position=(0, 0, -0.01))
    plate = w.add_body(box(0.1, 0.1, 0.005), mass=0.4, position=(0, 0, 0.005))
    w.step(DT, steps=300)
    hip0 = np.array(w.finger_pose(palm)[0])
    rel0 = np.array(w.body_pose(plate)[0]) - hip0
    worst_tilt = worst_slide = 0.0
    tipped_at = None
    for i in range(3000):
        t = (i + 1) * DT
        hip = hip0 + [0.1 * min_jerk(t - 1.0), 0, 0.1 * min_jerk(t)]
        w.set_hip(palm, hip)
        w.step(DT)
        tilt = tilt_deg(w, plate)
        worst_tilt = max(worst_tilt, tilt)
        worst_slide = max(worst_slide, float(np.linalg.norm((np.array(w.body_pose(plate)[0]) - hip - rel0)[:2])))
        if tipped_at is None and tilt > 10.0:
            tipped_at = t
    return {"max_tilt_deg": worst_tilt, "max_slide_m": worst_slide, "final_tilt_deg": tilt_deg(w, plate),
            "tilt_over_10deg_at_s": tipped_at, "contacts_at_end": len(w.finger_contacts(palm))}


def pressed_on_table(pad: bool):
    w = graspcore.World(gravity=(0, 0, 0))
    w.add_body(box(0.2, 0.2, 0.05, center=(0, 0, -0.05)), static=True)
    if pad:
        f = w.add_finger(radius=0.0, position=(0, 0, 0.01), points=box(0.02, 0.02, 0.005, center=(0, 0, 0.005)))
    else:
        f = w.add_finger(radius=0.008, position=(0, 0, 0.02))
    for i in range(1, 21):
        w.set_hip(f, (0, 0, (0.01 if pad else 0.02) * (1 - i / 20) + ((-0.002) if pad else 0.006) * i / 20))
        w.step(DT)
    return w, len(w.finger_contacts(f))


def plate_rest(on_palm: bool):
    w = graspcore.World()
    if on_palm:
        f = w.add_finger(radius=0.0, stiffness=K, damping=2.0, position=(0, 0, -0.01), points=box(0.045, 0.04, 0.01))
    else:
        for ang in (0.0, 2 * np.pi / 3, 4 * np.pi / 3):
            f = w.add_finger(radius=0.008, stiffness=K, damping=2.0,
                             position=(0.05 * np.cos(ang), 0.05 * np.sin(ang), -0.008))
    plate = w.add_body(box(0.1, 0.1, 0.005), mass=0.4, position=(0, 0, 0.005))
    w.step(DT, steps=1000)
    points = sum(len(w.finger_contacts(i)) for i in range(w.finger_count))
    return w, points, tilt_deg(w, plate)


def per_step_us(w, steps=2000):
    t0 = time.perf_counter()
    w.step(DT, steps=steps)
    return (time.perf_counter() - t0) / steps * 1e6


def timing(repeats: int) -> dict:
    cases = {
        "table, sphere finger": lambda: pressed_on_table(False),
        "table, pad (convex finger)": lambda: pressed_on_table(True),
        "plate on 3 sphere fingers": lambda: plate_rest(False)[:2],
        "plate on a palm (convex finger)": lambda: plate_rest(True)[:2],
    }
    worlds = {name: make() for name, make in cases.items()}
    samples = {name: [] for name in cases}
    for _ in range(repeats):  # interleaved
        for name, (w, _) in worlds.items():
            samples[name].append(per_step_us(w))
    out = {}
    for name, (w, points) in worlds.items():
        out[name] = {"median_us": statistics.median(samples[name]), "min_us": min(samples[name]),
                     "contact_points": points}
    return out


def held(repeats: int) -> dict:
    out = {}
    for n in (3, 5):
        res = bcs.timed_grasp(n, steps=2000, repeats=repeats)
        out[f"held box, {n} sphere fingers"] = {"median_us": statistics.median(res["per_step"]) * 1e6,
                                               "min_us": min(res["per_step"]) * 1e6}
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--json")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--held", action="store_true", help="only the held-box sphere-finger step times")
    args = ap.parse_args()
    if args.held:
        res = held(args.repeats)
        print(json.dumps(res))
        return
    result = {
        "date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} logical cores",
        "load_start": os.getloadavg(),
        "git": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=HERE).stdout.strip(),
        "carry_area": carry(True),
        "carry_point": carry(False),
        "timing": timing(args.repeats),
    }
    result["load_end"] = os.getloadavg()
    a, p = result["carry_area"], result["carry_point"]
    print(f"plate on a palm, lifted 10 cm and carried 10 cm in 2 s: max tilt {a['max_tilt_deg']:.4f} deg, "
          f"slide {a['max_slide_m'] * 1000:.3f} mm")
    print(f"area term off (one point): max tilt {p['max_tilt_deg']:.1f} deg, over 10 deg at {p['tilt_over_10deg_at_s']} s")
    for name, r in result["timing"].items():
        print(f"{name:34s} {r['median_us']:7.2f} us/step (min {r['min_us']:.2f}), {r['contact_points']} contact points")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=2)


if __name__ == "__main__":
    main()
