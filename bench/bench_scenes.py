"""Multi-body benchmark scenes: body-body contacts, chains and the contact solver.

Scenes (issue 3, item 7): 5 boxes + 5 fingers, 20 boxes + 5 fingers, a tray with 12
objects, a 100-body pile. Each scene is a plain dict of numbers (`scene_spec(name)`):
every body is a box (half extents, mass, pose, friction), every finger a sphere on a
spring to a fixed HIP, so bench/run_bench.py can rebuild the same scene in MuJoCo and
PyBullet. `build_world(spec, threads=N)` builds it in graspcore.

    .venv/bin/python bench/bench_scenes.py [--steps 1000] [--repeats 5]

prints a Markdown table of the step time with 1 and 2 threads.
"""
from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

DT = 1e-3
GRAVITY = (0.0, 0.0, -9.81)
TABLE_HALF = (0.5, 0.5, 0.05)        # static slab, top face at z = 0
MU_S, MU_D = 0.8, 0.6
TIP, STIFFNESS, DAMPING, SQUEEZE = 0.008, 1000.0, 2.0, 0.003

SCENES = ("5 boxes + 5 fingers", "20 boxes + 5 fingers", "tray + 12 objects", "100-body pile")


def _body(half, mass, position, orientation=(1.0, 0.0, 0.0, 0.0), static=False, mu_s=MU_S, mu_d=MU_D):
    return {"half": [float(h) for h in half], "mass": float(mass), "position": [float(p) for p in position],
            "orientation": [float(q) for q in orientation], "static": bool(static),
            "mu_s": float(mu_s), "mu_d": float(mu_d)}


def _table():
    return _body(TABLE_HALF, 0.0, (0.0, 0.0, -TABLE_HALF[2]), static=True)


def _finger(hip, stiffness=STIFFNESS, damping=DAMPING):
    return {"radius": TIP, "stiffness": float(stiffness), "damping": float(damping),
            "hip": [float(h) for h in hip]}


def _five_finger_grasp(center, half):
    """A 5-finger grasp of a cube (thumb on +x, two fingers on -x, a pair on +-y), the HIPs
    SQUEEZE inside the surface the fingertip touches."""
    c = np.asarray(center, float)
    touches = [((half, 0.0, 0.0), (1, 0, 0)),
               ((-half, -0.5 * half, 0.0), (-1, 0, 0)), ((-half, 0.5 * half, 0.0), (-1, 0, 0)),
               ((0.0, half, 0.0), (0, 1, 0)), ((0.0, -half, 0.0), (0, -1, 0))]
    return [_finger(c + np.asarray(p) + (TIP - SQUEEZE) * np.asarray(n, float)) for p, n in touches]


def _boxes_on_table(count, rng, size=0.02):
    """`count` cubes on the table: stacks of three, then single cubes, on a grid with gaps."""
    bodies = []
    spots = [(x, y) for y in np.arange(-0.36, 0.37, 0.08) for x in np.arange(-0.36, 0.37, 0.08)
             if abs(x) > 0.1 or abs(y) > 0.1]                   # keep the centre for the grasp
    stacks = count // 6
    i = 0
    for s in range(stacks):
        x, y = spots[i]
        i += 1
        for level in range(3):
            bodies.append(_body((size,) * 3, 0.1, (x, y, size + 2 * size * level)))
    while len(bodies) < count:
        x, y = spots[i]
        i += 1
        yaw = rng.uniform(0, math.pi / 2)
        bodies.append(_body((size,) * 3, 0.1, (x, y, size), (math.cos(yaw / 2), 0, 0, math.sin(yaw / 2))))
    return bodies


def scene_spec(name: str) -> dict:
    """The scene as plain numbers: dt, gravity, bodies (boxes), fingers (HIPs fixed), the
    warm-up time before timing, and a one-line description."""
    rng = np.random.default_rng(3)
    spec = {"name": name, "dt": DT, "gravity": list(GRAVITY), "bodies": [_table()], "fingers": []}
    if name in ("5 boxes + 5 fingers", "20 boxes + 5 fingers"):
        n = 5 if name.startswith("5 ") else 20
        held = (0.0, 0.0, 0.08)                                  # a 6 cm cube held 5 cm above the table
        spec["bodies"].append(_body((0.03,) * 3, 0.2, held))
        spec["fingers"] = _five_finger_grasp(held, 0.03)
        spec["bodies"] += _boxes_on_table(n - 1, rng)
        spec["warmup_s"] = 0.5
        spec["description"] = (f"one 6 cm cube held in the air by 5 fingers, {n - 1} 4 cm cubes on the table "
                               "(stacks of three and single ones)")
    elif name == "tray + 12 objects":
        tx, ty, tz, lift = 0.12, 0.08, 0.005, 0.05
        spec["bodies"].append(_body((tx, ty, tz), 0.3, (0.0, 0.0, lift + tz), mu_s=0.6, mu_d=0.5))
        for i in range(4):
            for j in range(3):
                spec["bodies"].append(_body((0.015,) * 3, 0.04, (-0.09 + 0.06 * i, -0.05 + 0.05 * j,
                                                                  lift + 2 * tz + 0.015), mu_s=0.6, mu_d=0.5))
        # Two fingers on each end of the tray, pinching it (stiffer: the tray and load weigh ~8 N).
        spec["fingers"] = [_finger((sx * (tx + TIP - 0.004), y, lift + tz), stiffness=4000.0, damping=5.0)
                           for sx in (-1, 1) for y in (-0.04, 0.04)]
        spec["warmup_s"] = 0.5
        spec["description"] = "a 24 x 16 x 1 cm tray with 12 cubes, pinched at its ends by 4 fingers, 5 cm up"
    elif name == "100-body pile":
        for i in range(100):
            angle = rng.uniform(0, math.pi)
            axis = rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            q = (math.cos(angle / 2), *(math.sin(angle / 2) * axis))
            half = (0.02, 0.015, 0.01) if i % 2 else (0.015, 0.015, 0.015)
            # 4 layers of 5 x 5, 6 cm apart (more than any box's diagonal): nothing overlaps
            # at the start, so every engine drops the same 100 boxes.
            layer, cell = divmod(i, 25)
            pos = (0.06 * (cell % 5 - 2) + rng.uniform(-0.005, 0.005),
                   0.06 * (cell // 5 - 2) + rng.uniform(-0.005, 0.005), 0.035 + 0.06 * layer)
            spec["bodies"].append(_body(half, 0.05, pos, q))
        spec["warmup_s"] = 1.5
        spec["description"] = "100 boxes dropped in a heap on the table (timed after 1.5 s of falling)"
    else:
        raise ValueError(f"name: one of {SCENES}")
    return spec


def box_points(half) -> np.ndarray:
    hx, hy, hz = half
    return np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)], float)


def build_world(spec: dict, threads: int = 1, **world_kw):
    """The scene in graspcore: (world, body ids, finger ids)."""
    import graspcore

    w = graspcore.World(gravity=tuple(spec["gravity"]), threads=threads,
                        max_bodies=max(256, len(spec["bodies"]) + 1), **world_kw)
    bodies = [w.add_body(box_points(b["half"]), mass=b["mass"] if not b["static"] else 1.0,
                         position=tuple(b["position"]), orientation=tuple(b["orientation"]),
                         static=b["static"], mu_s=b["mu_s"], mu_d=b["mu_d"]) for b in spec["bodies"]]
    fingers = [w.add_finger(radius=f["radius"], stiffness=f["stiffness"], damping=f["damping"],
                            position=tuple(f["hip"])) for f in spec["fingers"]]
    return w, bodies, fingers


def time_scene(spec: dict, threads: int, steps: int, repeats: int) -> dict:
    """Warm up (settle), then seconds per step for each repeat of `steps` steps (all in C)."""
    w, bodies, fingers = build_world(spec, threads=threads)
    w.step(spec["dt"], steps=int(round(spec.get("warmup_s", 0.0) / spec["dt"])))
    per_step = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        w.step(spec["dt"], steps=steps)
        per_step.append((time.perf_counter() - t0) / steps)
    return {"per_step": per_step, "contacts": len(w.contacts()), "chains": w.chain_count(),
            "hash": w.state_hash(), "held": [w.finger_state(f) for f in fingers]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args(argv)
    print("| scene | bodies | contact points | chains | " +
          " | ".join(f"{t} thread{'s' if t > 1 else ''} [us/step]" for t in args.threads) +
          " | same state |")
    print("|---|---:|---:|---:|" + "---:|" * len(args.threads) + "---|")
    for name in SCENES:
        spec = scene_spec(name)
        results = [time_scene(spec, t, args.steps, args.repeats) for t in args.threads]
        cells = [f"{statistics.median(r['per_step']) * 1e6:.1f} (min {min(r['per_step']) * 1e6:.1f})"
                 for r in results]
        same = "yes" if len({r["hash"] for r in results}) == 1 else "NO"
        print(f"| {name} | {len(spec['bodies']) - 1} | {results[0]['contacts']} | {results[0]['chains']} | "
              + " | ".join(cells) + f" | {same} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
