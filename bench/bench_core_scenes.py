"""Benchmark grasp scenes for the graspcore side (runs in .venv).

The scene geometry is shared with bench/scenes_mujoco.py through `scene_spec()`, a
plain dict of numbers, so both engines see the same box, the same fingertips and the
same HIPs. This file never imports mujoco; scenes_mujoco.py never imports graspcore.
"""
from __future__ import annotations

import time

import numpy as np

DT = 1e-3            # s, both engines
HALF = 0.03          # box half extent, m (6 cm box)
MASS = 0.2           # kg
TIP = 0.008          # fingertip radius, m
STIFFNESS = 1000.0   # N/m, finger spring (HIP <-> fingertip)
DAMPING = 2.0        # N s/m, finger damper (as in sample_scenes/pinch_and_lift.py)
SQUEEZE = 0.003      # HIPs 3 mm inside the surface the fingertip touches
MU_S, MU_D = 0.8, 0.6
GRAVITY = (0.0, 0.0, -9.81)

# Contact points on the box surface (box frame, box at the origin) and the outward
# normal of the face they are on. The HIP is the fingertip centre at touch
# (point + TIP * n) moved SQUEEZE inward along -n.
_GRASPS = {
    # 2 fingers: opposed pinch on the +x/-x face centres (the creep scene).
    2: [((HALF, 0.0, 0.0), (1, 0, 0)), ((-HALF, 0.0, 0.0), (-1, 0, 0))],
    # 3 fingers: thumb on +x, two fingers on -x side by side.
    3: [((HALF, 0.0, 0.0), (1, 0, 0)),
        ((-HALF, -0.015, 0.0), (-1, 0, 0)), ((-HALF, 0.015, 0.0), (-1, 0, 0))],
    # 5 fingers: the 3-finger grasp plus an opposed pair on the +y/-y face centres.
    5: [((HALF, 0.0, 0.0), (1, 0, 0)),
        ((-HALF, -0.015, 0.0), (-1, 0, 0)), ((-HALF, 0.015, 0.0), (-1, 0, 0)),
        ((0.0, HALF, 0.0), (0, 1, 0)), ((0.0, -HALF, 0.0), (0, -1, 0))],
}


def scene_spec(n_fingers: int) -> dict:
    """Everything both engines need to build the held-box scene with n fingers."""
    hips = []
    for p, n in _GRASPS[n_fingers]:
        p, n = np.asarray(p, float), np.asarray(n, float)
        hips.append((p + (TIP - SQUEEZE) * n).tolist())
    return {
        "dt": DT, "half": HALF, "mass": MASS, "tip": TIP, "stiffness": STIFFNESS,
        "damping": DAMPING, "squeeze": SQUEEZE, "mu_s": MU_S, "mu_d": MU_D,
        "gravity": list(GRAVITY), "hips": hips,
    }


def box_points(h: float) -> np.ndarray:
    return np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)], float)


def build_world(spec: dict, *, static_box: bool = False, fingers_free: bool = False, **world_kw):
    """The held box. `fingers_free` moves every HIP 10 cm out (no contact);
    `static_box` makes the box static (xFCA alone, no finger-body coupling)."""
    import graspcore

    w = graspcore.World(gravity=tuple(spec["gravity"]), **world_kw)
    b = w.add_body(box_points(spec["half"]), mass=spec["mass"], static=static_box,
                   mu_s=spec["mu_s"], mu_d=spec["mu_d"])
    hips = np.array(spec["hips"], float).reshape(-1, 3)
    if fingers_free:
        hips = hips * (1.0 + 0.1 / np.maximum(np.linalg.norm(hips, axis=1, keepdims=True), 1e-9))
        hips[:, 2] += 0.1
    for h in hips:
        w.add_finger(radius=spec["tip"], stiffness=spec["stiffness"], damping=spec["damping"],
                     position=tuple(h))
    if len(hips):
        w.set_hips(hips)
    return w, b


def time_steps(w, steps: int, repeats: int, dt: float = DT) -> list[float]:
    """Seconds per step for each repeat of `steps` steps, all inside C (w.step(dt, steps=N))."""
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        w.step(dt, steps=steps)
        out.append((time.perf_counter() - t0) / steps)
    return out


def box_position(w, b) -> np.ndarray:
    return np.array(w.body_pose(b)[0], float)


def timed_grasp(n_fingers: int, steps: int, repeats: int, warmup_s: float = 2.0) -> dict:
    """Held box with n fingers: warm up (settle), then time; report the box motion
    during the timed window so the reader can see the grasp held."""
    spec = scene_spec(n_fingers)
    w, b = build_world(spec)
    w.step(DT, steps=int(round(warmup_s / DT)))
    p0 = box_position(w, b)
    per_step = time_steps(w, steps, repeats)
    p1 = box_position(w, b)
    states = [w.finger_state(f) for f in range(n_fingers)]
    return {"per_step": per_step, "drift_m": float(np.linalg.norm(p1 - p0)),
            "box_after_warmup": p0.tolist(), "states": states,
            "sim_time_s": float(w.time)}


def creep(settle_s: float = 2.0, hold_s: float = 10.0) -> dict:
    """Two-finger pinch, gravity on: settle, then the box displacement over hold_s."""
    spec = scene_spec(2)
    w, b = build_world(spec)
    w.step(DT, steps=int(round(settle_s / DT)))
    p0 = box_position(w, b)
    n = int(round(hold_s / DT))
    chunk = 100
    max_dev = 0.0
    for _ in range(n // chunk):
        w.step(DT, steps=chunk)
        max_dev = max(max_dev, float(np.linalg.norm(box_position(w, b) - p0)))
    p1 = box_position(w, b)
    d = p1 - p0
    return {"displacement_m": float(np.linalg.norm(d)), "dz_m": float(d[2]),
            "max_deviation_m": max_dev, "sag_at_settle_m": float(-p0[2]),
            "states": [w.finger_state(f) for f in range(2)]}


def per_finger_profile(steps: int, repeats: int) -> list[dict]:
    """Where the step time goes: the same world with 0..5 fingers, free, on a static
    box, and holding the dynamic box."""
    rows = []

    def run(label, n, **kw):
        spec = scene_spec(n) if n in _GRASPS else dict(scene_spec(3), hips=scene_spec(5)["hips"][:n])
        if n == 0:
            spec = dict(scene_spec(3), hips=[])
        w, _ = build_world(spec, **kw)
        w.step(DT, steps=500)  # settle
        per = time_steps(w, steps, repeats)
        rows.append({"case": label, "fingers": n, "per_step": per,
                     "states": [w.finger_state(f) for f in range(n)]})

    run("no fingers, static box", 0, static_box=True)
    run("no fingers, dynamic box (falls freely)", 0)
    run("no fingers, dynamic box, gyroscopic term off", 0, gyroscopic=False)
    for n in (1, 3, 5):
        run(f"{n} finger(s) free (no contact), dynamic box", n, fingers_free=True)
    for n in (1, 3, 5):
        run(f"{n} finger(s) pressing a static box", n, static_box=True)
    for n in (2, 3, 5):
        run(f"{n} fingers holding the dynamic box", n)
    run("5 fingers holding the dynamic box, gyroscopic term off", 5, gyroscopic=False)
    return rows
