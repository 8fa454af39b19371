"""Held box, 3 and 5 fingers: graspcore beside MuJoCo with actuated fingertips (the model of
the main held-box table) and with mocap-sphere fingertips (kinematic spheres at the HIPs,
elliptic cones, impratio 10: MuJoCo integrates only the box, as graspcore does).

Run by bench/run_bench.py (`make bench`), which appends its section to docs/benchmarks.md;
alone (it makes .venv-bench if needed):

    .venv/bin/python bench/bench_held.py [--steps 5000] [--repeats 21]
"""
from __future__ import annotations

import argparse
import datetime as _dt
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import bench_core_scenes as core  # noqa: E402

VARIANTS = ("recommended", "mocap")
FINGERS = (3, 5)
TARGETS = {"recommended": 0.25, "mocap": 0.3}   # ours / MuJoCo, docs/benchmarks.md


def measure(mj, steps: int, repeats: int) -> list[dict]:
    """Interleaved repeats: graspcore, then each MuJoCo variant, per repeat."""
    rows = []
    for n in FINGERS:
        spec = core.scene_spec(n)
        w, b = core.build_world(spec)
        w.step(core.DT, steps=2000)
        p0 = core.box_position(w, b)
        for v in VARIANTS:
            mj(cmd="setup", key=f"held{n}/{v}", spec=spec, variant=v, warmup_s=2.0)
        ours, theirs, moved, ncon = [], {v: [] for v in VARIANTS}, {v: 0.0 for v in VARIANTS}, {v: 99 for v in VARIANTS}
        for _ in range(repeats):
            ours += core.time_steps(w, steps, 1)
            for v in VARIANTS:
                r = mj(cmd="time", key=f"held{n}/{v}", steps=steps)
                theirs[v].append(r["per_step"])
                moved[v] = max(moved[v], r["moved_m"])
                ncon[v] = min(ncon[v], r["ncon"])
        for v in VARIANTS:
            mj(cmd="drop", key=f"held{n}/{v}")
        rows.append({"fingers": n, "ours": float(np.median(ours)),
                     "ours_moved_m": float(np.linalg.norm(core.box_position(w, b) - p0)),
                     "ours_states": [w.finger_state(f) for f in range(n)],
                     "mujoco": {v: float(np.median(theirs[v])) for v in VARIANTS},
                     "mujoco_moved_m": moved, "mujoco_ncon_min": ncon})
    return rows


def section(rows: list[dict], steps: int, repeats: int) -> str:
    us = lambda s: f"{s * 1e6:.2f}"  # noqa: E731
    lines = [
        "## Held box against mocap-sphere fingertips",
        "",
        f"`bench/bench_held.py`, {_dt.date.today().isoformat()}: the held-box scene of the table above (3 and 5 "
        f"fingers, dt = 1 ms, 2 s settled, {steps} steps per repeat, {repeats} interleaved repeats, medians). "
        "*actuated*: MuJoCo's fingertips are 10 g spheres on slide joints pulled to the HIPs by position "
        "actuators (the model above). *mocap*: MuJoCo's fingertips are mocap spheres placed at the HIPs "
        "(kinematic, no DOF; elliptic cones, impratio 10, the same contact settings), so MuJoCo integrates "
        "only the box, as graspcore does; its grip comes from its soft contact on the 3 mm overlap.",
        "",
        "| Fingers | graspcore µs/step | MuJoCo actuated µs/step | ratio | MuJoCo mocap µs/step | ratio "
        "| graspcore box moved | MuJoCo mocap box moved / repeat (fewest contacts) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        ra = r["ours"] / r["mujoco"]["recommended"]
        rm = r["ours"] / r["mujoco"]["mocap"]
        lines.append(f"| {r['fingers']} | {us(r['ours'])} | {us(r['mujoco']['recommended'])} | **{ra:.2f}×** "
                     f"| {us(r['mujoco']['mocap'])} | **{rm:.2f}×** | {r['ours_moved_m'] * 1e6:.2g} µm "
                     f"| {r['mujoco_moved_m']['mocap'] * 1e6:.3g} µm ({r['mujoco_ncon_min']['mocap']}) |")
    lines += ["", "| Target | Result | |", "|---|---|---|"]
    for r in rows:
        for v, name in (("mocap", "mocap-sphere"), ("recommended", "actuated")):
            ratio = r["ours"] / r["mujoco"][v]
            ok = ratio <= TARGETS[v]
            lines.append(f"| Held box, {r['fingers']} fingers, ≤ {TARGETS[v]}× MuJoCo ({name} fingertips) "
                         f"| {ratio:.2f}× ({us(r['ours'])} vs {us(r['mujoco'][v])} µs) | {'**met**' if ok else '**MISSED**'} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    import run_bench

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=5000)
    ap.add_argument("--repeats", type=int, default=21)
    args = ap.parse_args(argv)
    mj = run_bench.MuJoCo(run_bench.ensure_bench_venv())
    try:
        rows = measure(mj, args.steps, args.repeats)
    finally:
        mj.close()
    print(section(rows, args.steps, args.repeats))
    return 0


if __name__ == "__main__":
    sys.exit(main())
