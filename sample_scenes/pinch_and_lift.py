"""Headless pinch-and-lift with the core alone (the first part of `make demo`).

A 200 g box, 6 cm on a side, is pinched by two fingertips (8 mm spheres, 1000 N/m)
that close on it, lift it 5 cm, hold it, shake it sideways and let it drop. Prints a compact
table over time and writes the full 1 kHz trajectory to build/demo/core_only.csv.
The second part, the Blender sample scene through the extension, is demo_session.py.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys

import numpy as np

import graspcore

DT = 1e-3
HALF = 0.03          # box half extent, m
TIP = 0.008          # fingertip radius, m
SQUEEZE = 0.003      # how far the HIPs go inside the surface, m


def box_points(h):
    return np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)])


def hip_x(t):
    """Half distance between the two HIPs: close in 20 ms, open after 4 s."""
    open_x, closed_x = HALF + TIP + 0.0005, HALF + TIP - SQUEEZE
    if t < 0.02:
        return open_x + (closed_x - open_x) * t / 0.02
    if t < 4.0:
        return closed_x
    return closed_x + (open_x + 0.01 - closed_x) * min((t - 4.0) / 0.1, 1.0)


def hip_offset(t):
    """Lift 5 cm between 0.3 s and 1.3 s, shake sideways (1 cm, 2 Hz) from 2.5 s to 3.5 s."""
    lift = 0.05 * min(max((t - 0.3) / 1.0, 0.0), 1.0)
    shake = 0.01 * np.sin(2 * np.pi * 2.0 * (t - 2.5)) if 2.5 <= t < 3.5 else 0.0
    return np.array([0.0, shake, lift])


def build_world():
    world = graspcore.World(gravity=(0, 0, -9.81))
    box = world.add_body(box_points(HALF), mass=0.2, mu_s=0.8, mu_d=0.6)
    x = hip_x(0.0)
    fingers = [world.add_finger(radius=TIP, stiffness=1000.0, damping=2.0, position=(sx * x, 0, 0))
               for sx in (-1.0, 1.0)]
    return world, box, fingers


def run(duration=4.5, out_csv=None, every=0.2, stream=sys.stdout):
    world, box, fingers = build_world()
    hips = np.zeros((2, 3))
    rows = []
    print(f"{'t [s]':>6} {'box z [mm]':>11} {'box y [mm]':>11} {'grip [N]':>9} {'lift [N]':>9}  fingers",
          file=stream)
    steps = int(round(duration / DT))
    for i in range(steps + 1):
        t = i * DT
        x, offset = hip_x(t), hip_offset(t)
        hips[0] = offset + (-x, 0, 0)
        hips[1] = offset + (x, 0, 0)
        world.set_hips(hips)
        world.step(DT)
        pos = world.body_pose(box)[0]
        forces = world.finger_forces
        grip = 0.5 * (forces[0, 0] - forces[1, 0])  # squeeze: the inward components
        lift = -forces[:, 2].sum()                   # what the fingers carry
        states = [world.finger_state(f) for f in fingers]
        rows.append((round(world.time, 6), *pos, grip, lift, *states))
        if i % int(round(every / DT)) == 0:
            print(f"{world.time:6.2f} {pos[2] * 1e3:11.3f} {pos[1] * 1e3:11.3f} {-grip:9.3f} {lift:9.3f}  "
                  + " ".join(f"{s:5}" for s in states), file=stream)
    if out_csv:
        os.makedirs(os.path.dirname(out_csv) or ".", exist_ok=True)
        with open(out_csv, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(["t", "box_x", "box_y", "box_z", "grip_N", "lift_N", "finger0", "finger1"])
            writer.writerows(rows)
        print(f"trajectory: {out_csv} ({len(rows)} rows at {1 / DT:.0f} Hz)", file=stream)
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=4.5)
    parser.add_argument("--csv", default=os.path.join("build", "demo", "core_only.csv"))
    args = parser.parse_args(argv)
    rows = run(args.duration, args.csv)
    held = [r for r in rows if 2.0 <= r[0] < 2.5]
    if held:
        z = np.array([r[3] for r in held])
        print(f"held from 2.0 s to 2.5 s: box z {z.mean() * 1e3:.3f} mm, drift {np.ptp(z) * 1e6:.3f} um")


if __name__ == "__main__":
    main()
