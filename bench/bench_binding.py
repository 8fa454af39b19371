"""The binding's cost per call, for two builds of graspcore side by side: the held box (3
fingers) stepped one call at a time as the live loop and the EXEC session drive it (set_hips,
step, body_pose, finger_force, finger_state), the table-driven accessors alone, and a
finger's keyword arguments (add_finger). Each build runs in its own process; the runs are
interleaved, repeat by repeat, so both see the same machine load.

    .venv/bin/python bench/bench_binding.py [--baseline SITE_DIR] [--repeats 11]

SITE_DIR holds another build's graspcore (pip install --target); without it only this venv's
build is measured. Results: docs/benchmarks.md "Binding".
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))

# One repeat, run in a child process whose graspcore is the build asked for; prints JSON of
# nanoseconds per call (per step for the stepping rows).
CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
import numpy as np
import bench_core_scenes as core
import graspcore

def per_call(fn, n):
    t = time.perf_counter_ns()
    fn(n)
    return (time.perf_counter_ns() - t) / n

spec = core.scene_spec(3)
w, b = core.build_world(spec)
w.step(core.DT, steps=500)
hips = np.asarray(spec["hips"], float)
n = int(sys.argv[2])

def live_ticks(n):
    for _ in range(n):
        w.set_hips(hips)
        w.step(core.DT)
        w.body_pose(b)
        for f in range(3):
            w.finger_force(f)
            w.finger_state(f)

def steps_alone(n):
    for _ in range(n):
        w.step(core.DT)

def accessors(n):
    for _ in range(n):
        w.body_pose(b); w.body_velocity(b); w.god_object(0); w.finger_contact(0); w.state_hash(); w.time

def set_accessors(n):
    for _ in range(n):
        w.set_hip(0, hips[0]); w.set_body_friction(b, 0.8, 0.6, 0.0)

def add_fingers(n):
    for _ in range(n // 100):
        v = graspcore.World(max_fingers=100)
        for _ in range(100):
            v.add_finger(radius=0.008, stiffness=1000.0, damping=2.0, position=(0.0, 0.0, 0.1))

out = {"step + queries (a live tick)": per_call(live_ticks, n), "step alone": per_call(steps_alone, n),
       "6 queries": per_call(accessors, n), "2 setters": per_call(set_accessors, n),
       "add_finger(4 keywords)": per_call(add_fingers, max(100, n // 10))}
print(json.dumps(out))
"""


def run(site: str | None, calls: int) -> dict:
    env = dict(os.environ)
    paths = [HERE] + ([site] if site else [])
    env["PYTHONPATH"] = os.pathsep.join(paths + [env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", CHILD, site or HERE, str(calls)], env=env, check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", help="site directory of the graspcore build to compare with")
    ap.add_argument("--repeats", type=int, default=11)
    ap.add_argument("--calls", type=int, default=20000)
    args = ap.parse_args(argv)
    builds = {"this build": None} | ({"baseline": args.baseline} if args.baseline else {})
    samples = {name: [] for name in builds}
    for _ in range(args.repeats):
        for name, site in builds.items():
            samples[name].append(run(site, args.calls))
    rows = list(samples["this build"][0])
    # The fastest repeat of each: the machine is shared, and load only ever adds time.
    print("| call | " + " | ".join(f"{name}, ns (fastest repeat)" for name in builds)
          + (" | this / baseline |" if args.baseline else " |"))
    print("|---|" + "---|" * (len(builds) + (1 if args.baseline else 0)))
    for row in rows:
        best = {name: min(s[row] for s in samples[name]) for name in builds}
        cells = " | ".join(f"{best[name]:.0f}" for name in builds)
        ratio = f" | {best['this build'] / best['baseline']:.2f} |" if args.baseline else " |"
        print(f"| {row} | {cells}{ratio}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
