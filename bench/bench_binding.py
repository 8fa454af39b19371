"""The binding's cost per call, for two builds of graspcore side by side in one process: the
held box (3 fingers) stepped one call at a time as the live loop and the EXEC session drive it
(set_hips, step, body_pose, finger_force, finger_state), the table-driven accessors alone,
stats(), and a finger's keyword arguments (add_finger). The builds take turns, sample by
sample, so both see the same machine load; each row is the fastest sample of each (load only
ever adds time).

    .venv/bin/python bench/bench_binding.py [--baseline SITE_DIR] [--samples 200]

SITE_DIR holds another build's graspcore (pip install --target DIR graspcore-*.whl): it is
imported as ``graspcore_baseline``. Without it only this venv's build is measured. Results:
docs/benchmarks.md "Binding".
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import bench_core_scenes as core  # noqa: E402


def load_baseline(site: str):
    """The other build's package under another name (its _core is found by file, not by name)."""
    folder = tempfile.mkdtemp(prefix="graspcore_baseline_")
    os.symlink(os.path.join(os.path.abspath(site), "graspcore"), os.path.join(folder, "graspcore_baseline"))
    sys.path.insert(0, folder)
    return importlib.import_module("graspcore_baseline")


class Cases:
    """The calls measured, on one build's held-box world."""

    def __init__(self, gc):
        self.gc = gc
        self.spec = core.scene_spec(3)
        self.hips = np.asarray(self.spec["hips"], float)
        w = gc.World(gravity=tuple(self.spec["gravity"]))
        h = self.spec["half"]
        box = np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)], float)
        self.body = w.add_body(box, mass=self.spec["mass"], mu_s=self.spec["mu_s"], mu_d=self.spec["mu_d"])
        for p in self.hips:
            w.add_finger(radius=self.spec["tip"], stiffness=self.spec["stiffness"], damping=self.spec["damping"],
                         position=tuple(p))
        w.set_hips(self.hips)
        w.step(core.DT, steps=500)
        self.w = w

    def live_tick(self, n):
        w, b, hips = self.w, self.body, self.hips
        for _ in range(n):
            w.set_hips(hips)
            w.step(core.DT)
            w.body_pose(b)
            for f in range(3):
                w.finger_force(f)
                w.finger_state(f)

    def set_hips(self, n):
        w, hips = self.w, self.hips
        for _ in range(n):
            w.set_hips(hips)

    def finger_queries(self, n):
        w = self.w
        for _ in range(n):
            for f in range(3):
                w.finger_force(f)
                w.finger_state(f)

    def step(self, n):
        for _ in range(n):
            self.w.step(core.DT)

    def six_queries(self, n):
        w, b = self.w, self.body
        for _ in range(n):
            w.body_pose(b), w.body_velocity(b), w.god_object(0), w.finger_contact(0), w.state_hash(), w.time

    def two_setters(self, n):
        w, b, p = self.w, self.body, self.hips[0]
        for _ in range(n):
            w.set_hip(0, p), w.set_body_friction(b, self.spec["mu_s"], self.spec["mu_d"], 0.0)

    def add_finger(self, n):
        v = self.gc.World(max_fingers=n)
        for _ in range(n):
            v.add_finger(radius=0.008, stiffness=1000.0, damping=2.0, position=(0.0, 0.0, 0.1))

    def stats(self, n):
        w = self.gc.World()
        w.add_finger()
        w.start(realtime=False)
        for _ in range(n):
            w.stats()
        w.stop()


ROWS = {"step + queries (a live tick)": ("live_tick", 200), "step alone": ("step", 500),
        "set_hips": ("set_hips", 1000), "3 finger_force + 3 finger_state": ("finger_queries", 300),
        "6 queries": ("six_queries", 500), "2 setters": ("two_setters", 1000),
        "add_finger (4 keywords)": ("add_finger", 30), "stats()": ("stats", 200)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", help="site directory of the graspcore build to compare with")
    ap.add_argument("--samples", type=int, default=200)
    args = ap.parse_args(argv)
    import graspcore
    builds = {"this build": Cases(graspcore)}
    if args.baseline:
        builds["baseline"] = Cases(load_baseline(args.baseline))
    best = {row: {name: float("inf") for name in builds} for row in ROWS}
    order = list(builds.items())
    for _ in range(args.samples):
        order.reverse()     # each build goes first in every other sample
        for row, (case, n) in ROWS.items():
            for name, cases in order:
                t = time.perf_counter_ns()
                getattr(cases, case)(n)
                best[row][name] = min(best[row][name], (time.perf_counter_ns() - t) / n)
    print("| call | " + " | ".join(f"{name}, ns per call" for name in builds)
          + (" | this / baseline |" if args.baseline else " |"))
    print("|---|" + "---|" * (len(builds) + (1 if args.baseline else 0)))
    for row in ROWS:
        cells = " | ".join(f"{best[row][name]:.0f}" for name in builds)
        ratio = f" | {best[row]['this build'] / best[row]['baseline']:.2f} |" if args.baseline else " |"
        print(f"| {row} | {cells}{ratio}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
