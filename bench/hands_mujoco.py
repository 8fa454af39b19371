"""MuJoCo side of bench/bench_hands.py (runs in .venv-bench, never imports graspcore): the two-hand
scene of bench/hands_spec.py. One JSON request per line on stdin, one reply per line on stdout.

Model: the table a box geom of the world; each box a free body with a box geom (its mass given);
each phalanx and palm a free body with a capsule geom from its head to its tail (the finger's
radius, 10 g, gravcomp) driven by a mocap body through a weld whose solref is the coupling of a
graspcore finger (stiffness 1000 N/m, damping 2 N s/m on 10 g: timeconst 2 pi sqrt(m/k), damping
ratio c / 2 sqrt(k m)); the mocap bodies follow the hands' poses. Fingers collide with bodies,
not with each other. Options as in bench/multibody_mujoco.py: elliptic cones, impratio 10,
implicitfast, Newton, condim 4, friction mu 0.005 0.0001, solref 0.002 1, dt 1 ms.
"""
from __future__ import annotations

import json
import math
import sys
import time

import mujoco
import numpy as np

import hands_spec

FINGER_MASS = 0.01


def _f(xs) -> str:
    return " ".join(f"{float(x):.9g}" for x in xs)


def _quat(r) -> np.ndarray:
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(r, dtype=np.float64).ravel())
    return q


def model_xml(spec: dict, dt: float) -> str:
    k, c = spec["stiffness"], spec["damping"]
    timeconst = 2 * math.pi * math.sqrt(FINGER_MASS / k)
    dampratio = max(c / (2 * math.sqrt(k * FINGER_MASS)), 1e-3)
    mu = spec["mu"]
    geom = f'friction="{mu:.9g} 0.005 0.0001" condim="4" solref="0.002 1"'
    t = spec["table"]
    bodies = [f'    <geom name="table" type="box" size="{_f(t["half"])}" pos="{_f(t["position"])}" {geom} '
              f'contype="1" conaffinity="1"/>']
    for i, b in enumerate(spec["boxes"]):
        bodies.append(f'    <body name="box{i}" pos="{_f(b["position"])}"><freejoint/>'
                      f'<geom type="box" size="{_f(b["half"])}" mass="{spec["box_mass"]}" {geom} '
                      f'contype="1" conaffinity="1"/></body>')
    pos, rot = hands_spec.poses(0.0)
    welds = []
    for i, (f, p, r) in enumerate(zip(spec["fingers"], pos, rot)):
        q = _quat(r)
        bodies.append(f'    <body name="target{i}" mocap="true" pos="{_f(p)}" quat="{_f(q)}"/>')
        bodies.append(f'    <body name="finger{i}" pos="{_f(p)}" quat="{_f(q)}" gravcomp="1"><freejoint/>'
                      f'<geom type="capsule" fromto="0 0 0 0 {f["length"]:.9g} 0" size="{f["radius"]:.9g}" '
                      f'mass="{FINGER_MASS}" friction="0 0.005 0.0001" condim="4" solref="0.002 1" '
                      f'contype="2" conaffinity="1"/></body>')
        welds.append(f'    <weld body1="target{i}" body2="finger{i}" solref="{timeconst:.9g} {dampratio:.9g}"/>')
    return "\n".join([
        '<mujoco model="two_hands">',
        f'  <option timestep="{dt:.9g}" gravity="0 0 -9.81" cone="elliptic" impratio="10" '
        'integrator="implicitfast" solver="Newton"/>',
        '  <worldbody>', *bodies, '  </worldbody>',
        '  <equality>', *welds, '  </equality>',
        '</mujoco>'])


def run(duration: float, dt: float) -> dict:
    spec = hands_spec.spec()
    model = mujoco.MjModel.from_xml_string(model_xml(spec, dt))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    z0 = [float(data.body(f"box{i}").xpos[2]) for i in range(3)]
    n = int(round(duration / dt))
    per = np.empty(n)
    for k in range(n):
        pos, rot = hands_spec.poses((k + 1) * dt)
        data.mocap_pos[:] = pos
        data.mocap_quat[:] = [_quat(r) for r in rot]
        t0 = time.perf_counter()
        mujoco.mj_step(model, data)
        per[k] = time.perf_counter() - t0
    return {"step": {"median_us": float(np.median(per) * 1e6), "mean_us": float(per.mean() * 1e6)},
            "lift_m": [float(data.body(f"box{i}").xpos[2]) - z0[i] for i in range(3)],
            "ncon_end": int(data.ncon), "version": mujoco.__version__}


def handle(req: dict) -> dict:
    if req.get("cmd") == "run":
        return run(float(req["duration"]), float(req["dt"]))
    raise ValueError(f"unknown command {req.get('cmd')!r}")


def serve() -> None:
    for line in sys.stdin:
        if not line.strip():
            continue
        try:
            reply = {"ok": True, **handle(json.loads(line))}
        except Exception as exc:  # report, keep serving
            reply = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
        sys.stdout.write(json.dumps(reply) + "\n")
        sys.stdout.flush()


if __name__ == "__main__":
    serve()
