"""PyBullet side of the multi-body benchmark (runs in .venv-bench, never imports graspcore).

Run by bench/run_bench.py as a subprocess reading one JSON request per line on stdin
and writing one JSON reply per line on stdout (like bench/scenes_mujoco.py), so that its
timing repeats are interleaved with graspcore's and MuJoCo's. A scene is the plain dict
of bench/bench_scenes.py:scene_spec(name).

The model (PyBullet `DIRECT`, one physics client per scene):
  * every body is a `GEOM_BOX` collision shape with the spec's half extents, created with
    `createMultiBody(baseMass=mass, ..., useMaximalCoordinates=True)` (a plain Bullet
    rigid body; Bullet computes the uniform-density box inertia from the shape); the
    table has mass 0 (static). Quaternions are converted from (w, x, y, z) to Bullet's
    (x, y, z, w);
  * friction: Bullet combines two bodies' lateral friction by multiplying them, so each
    body gets lateralFriction = sqrt(mu_s); a pair then has sqrt(mu_a mu_b), exactly
    graspcore's geometric mean. Rolling and spinning friction 0, restitution 0 (Bullet's
    defaults);
  * a fingertip is a 10 g sphere (the spec's radius; a Bullet multibody base, because
    PyBullet's createConstraint to the world fails on a maximal-coordinate body) tied to
    its HIP by a `JOINT_FIXED` user constraint (finger centre -> HIP in the world,
    orientation held) with maxForce = stiffness x squeeze: Bullet has no spring
    constraint in its Python API, so the finger is a force-limited position constraint.
    Not JOINT_POINT2POINT: it leaves the sphere free to spin, a box pinched between
    spinning spheres rolls down them (measured: it falls), whereas graspcore's
    god-object and MuJoCo's slide-joint fingertip do not rotate. While the HIP is inside the held
    body the constraint saturates and pushes the fingertip toward the HIP with at most
    maxForce per axis, the force a graspcore finger spring exerts at the same squeeze
    (1000 N/m x 3 mm = 3 N for the 5-finger grasps, 4000 N/m x 4 mm = 16 N for the tray
    pinch); the other axes hold the fingertip's position. Fingertips start touching the
    face (as in the MuJoCo model), collide with bodies but not with each other, and get
    lateralFriction = sqrt(mu_s of the body they hold), so a finger-body contact has the
    body's friction, as in graspcore;
  * engine: timestep = the spec's dt (1 ms), one `stepSimulation()` per step; every
    other setting is PyBullet's default (read back with getPhysicsEngineParameters and
    reported: 50 solver iterations), default collision margins.
"""
from __future__ import annotations

import json
import math
import os
import sys
import time

import numpy as np

if __name__ == "__main__":
    # PyBullet prints a build banner on stdout (from C, at import): keep the real stdout
    # for the protocol and send everything else to stderr.
    _PROTOCOL = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
import pybullet as pb  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from multibody_spec import finger_touch  # noqa: E402

FINGER_MASS = 0.01
BODY_GROUP, BODY_MASK, FINGER_GROUP, FINGER_MASK = 1, 3, 2, 1


def xyzw(q):
    w, x, y, z = q
    return [x, y, z, w]


class Scene:
    def __init__(self, spec: dict):
        self.c = pb.connect(pb.DIRECT)
        c = self.c
        pb.setGravity(*spec["gravity"], physicsClientId=c)
        pb.setPhysicsEngineParameter(fixedTimeStep=spec["dt"], numSubSteps=0, physicsClientId=c)
        self.dt = spec["dt"]
        self.ids, self.dynamic = [], []
        for i, b in enumerate(spec["bodies"]):
            shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=b["half"], physicsClientId=c)
            bid = pb.createMultiBody(baseMass=0.0 if b["static"] else b["mass"],
                                     baseCollisionShapeIndex=shape, basePosition=b["position"],
                                     baseOrientation=xyzw(b["orientation"]), useMaximalCoordinates=True,
                                     physicsClientId=c)
            pb.changeDynamics(bid, -1, lateralFriction=math.sqrt(b["mu_s"]), physicsClientId=c)
            pb.setCollisionFilterGroupMask(bid, -1, BODY_GROUP, BODY_MASK, physicsClientId=c)
            self.ids.append(bid)
            if not b["static"]:
                self.dynamic.append(bid)
        self.fingers = []
        for f, (held, touch) in zip(spec["fingers"], finger_touch(spec)):
            shape = pb.createCollisionShape(pb.GEOM_SPHERE, radius=f["radius"], physicsClientId=c)
            fid = pb.createMultiBody(baseMass=FINGER_MASS, baseCollisionShapeIndex=shape,
                                     basePosition=list(touch), physicsClientId=c)
            mu = spec["bodies"][held]["mu_s"] if held >= 0 else 1.0
            pb.changeDynamics(fid, -1, lateralFriction=math.sqrt(mu), physicsClientId=c)
            pb.setCollisionFilterGroupMask(fid, -1, FINGER_GROUP, FINGER_MASK, physicsClientId=c)
            squeeze = float(np.linalg.norm(np.asarray(f["hip"]) - touch))
            cid = pb.createConstraint(fid, -1, -1, -1, pb.JOINT_FIXED, [0, 0, 0], [0, 0, 0],
                                      f["hip"], physicsClientId=c)
            pb.changeConstraint(cid, maxForce=f["stiffness"] * squeeze, physicsClientId=c)
            self.fingers.append({"body": fid, "constraint": cid, "max_force": f["stiffness"] * squeeze})

    def positions(self) -> list[list[float]]:
        return [list(pb.getBasePositionAndOrientation(b, physicsClientId=self.c)[0]) for b in self.dynamic]

    def step(self, n: int) -> None:
        for _ in range(n):
            pb.stepSimulation(physicsClientId=self.c)

    def time(self, steps: int) -> dict:
        c, step = self.c, pb.stepSimulation
        t0 = time.perf_counter()
        for _ in range(steps):
            step(physicsClientId=c)
        t = (time.perf_counter() - t0) / steps
        return {"per_step": t, "ncon": len(pb.getContactPoints(physicsClientId=c))}

    def close(self) -> None:
        pb.disconnect(physicsClientId=self.c)


def empty_step_cost(steps: int = 20000) -> float:
    """Seconds per stepSimulation() call on an empty world: the Python-call overhead that
    PyBullet's per-step figure includes (graspcore and MuJoCo step N times inside C)."""
    c = pb.connect(pb.DIRECT)
    pb.setPhysicsEngineParameter(fixedTimeStep=1e-3, numSubSteps=0, physicsClientId=c)
    best = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(steps):
            pb.stepSimulation(physicsClientId=c)
        best = min(best, (time.perf_counter() - t0) / steps)
    pb.disconnect(physicsClientId=c)
    return best


_scenes: dict = {}


def handle(req: dict) -> dict:
    cmd = req["cmd"]
    if cmd == "info":
        from importlib.metadata import version
        c = pb.connect(pb.DIRECT)
        pb.setPhysicsEngineParameter(fixedTimeStep=1e-3, numSubSteps=0, physicsClientId=c)
        params = pb.getPhysicsEngineParameters(physicsClientId=c)
        pb.disconnect(physicsClientId=c)
        return {"pybullet": version("pybullet"), "api_version": pb.getAPIVersion(),
                "numpy": np.__version__, "python": sys.version.split()[0], "params": params,
                "empty_step_s": empty_step_cost()}
    if cmd == "setup":           # build a scene and run its warm-up
        s = Scene(req["spec"])
        s.step(int(round(req["spec"].get("warmup_s", 0.0) / s.dt)))
        _scenes[req["key"]] = s
        return {"positions": s.positions(),
                "max_force": [f["max_force"] for f in s.fingers]}
    if cmd == "time":            # one timed repeat, continuing the simulation
        return _scenes[req["key"]].time(req["steps"])
    if cmd == "positions":
        return {"positions": _scenes[req["key"]].positions()}
    if cmd == "drop":
        s = _scenes.pop(req["key"], None)
        if s:
            s.close()
        return {}
    raise ValueError(f"unknown command {cmd!r}")


def serve() -> None:
    out = _PROTOCOL
    for line in sys.stdin:
        if not line.strip():
            continue
        try:
            reply = {"ok": True, **handle(json.loads(line))}
        except Exception as exc:  # report, keep serving
            reply = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
        out.write(json.dumps(reply) + "\n")
        out.flush()


if __name__ == "__main__":
    serve()
