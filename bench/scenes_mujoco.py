"""MuJoCo side of the grasp benchmark (runs in .venv-bench, never imports graspcore).

Run by bench/run_bench.py as a subprocess that reads one JSON request per line on
stdin and writes one JSON reply per line on stdout, so that the runner can interleave
MuJoCo's timing repeats with graspcore's (same machine load for both).
The scene numbers (box, fingertips, HIPs) come from the request, built by
bench/bench_core_scenes.py:scene_spec(), so both engines run the same scene.

The finger model (the MuJoCo equivalent of a graspcore finger):
  each fingertip is its own body holding a sphere geom (r = 8 mm, 10 g), moved by three
  world-aligned slide joints; a `position` actuator on each slide joint with kp = 1000
  N/m and kv = 2 N s/m has the HIP coordinate as its control, so the fingertip is pulled
  to the HIP by the same 1000 N/m spring and 2 N s/m damper as a graspcore finger, and
  the force on the device is kp (tip - HIP). `gravcomp="1"` on the finger bodies (our
  HIPs carry no weight). Fingers collide with the box only (contype/conaffinity).

Settings ("recommended"), MuJoCo's documented recommendations for grasping:
  cone="elliptic", impratio="10", condim="4" (tangential + torsional friction),
  friction "0.8 0.005 0.0001" (sliding mu = graspcore's mu_s), integrator="implicitfast"
  (the actuator damping is integrated implicitly), Newton solver with default
  iterations/tolerance, default solimp, contact solref="0.002 1" (time constant 2 dt,
  the stiffest the documentation advises; with the default 0.02 a 10 g fingertip sinks
  into the box and a 3 mm squeeze cannot hold it). "recommended+noslip" adds
  noslip_iterations="10", MuJoCo's post-processing against slip. A request may pass its
  own config dict (noslip_iterations, solref, finger_mass) for sensitivity runs.

The multi-body scenes (bench/bench_scenes.py) are built by bench/multibody_mujoco.py and
served here by the `mb_*` commands (mb_setup, mb_time, mb_positions, mb_drop, mb_xml).
"""
from __future__ import annotations

import json
import sys
import time

import os

import mujoco
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import multibody_mujoco  # noqa: E402

# The configurations measured. "recommended" is the one the ratio and the creep target
# are quoted against; the others show how much the numbers depend on the choices.
DEFAULT_SOLREF = "0.002 1"   # contact time constant 2 dt (the stiffest MuJoCo advises), critically damped
DEFAULT_FINGER_MASS = 0.01   # kg
CONFIGS = {
    "recommended": {"noslip_iterations": 0},
    "recommended+noslip": {"noslip_iterations": 10},
    # Fingertips as mocap spheres at the HIPs (kinematic, no DOF, no actuator): the box is
    # the only body MuJoCo integrates, as in graspcore; the grip comes from MuJoCo's own
    # soft contact on the 3 mm overlap instead of the finger springs.
    "mocap": {"noslip_iterations": 0, "mocap": True},
}


def config(name_or_dict) -> dict:
    c = dict(CONFIGS[name_or_dict]) if isinstance(name_or_dict, str) else dict(name_or_dict)
    c.setdefault("noslip_iterations", 0)
    c.setdefault("solref", DEFAULT_SOLREF)
    c.setdefault("finger_mass", DEFAULT_FINGER_MASS)
    c.setdefault("mocap", False)
    return c


def contact_points(spec: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    """(fingertip centre at first touch, HIP) for each finger: the HIP lies SQUEEZE
    inside the touch position along the face normal."""
    out = []
    half, tip, squeeze = spec["half"], spec["tip"], spec["squeeze"]
    for hip in spec["hips"]:
        hip = np.asarray(hip, float)
        axis = int(np.argmax(np.abs(hip)))          # the face the finger is on
        n = np.zeros(3)
        n[axis] = np.sign(hip[axis])
        touch = hip.copy()
        touch[axis] = n[axis] * (half + tip)
        out.append((touch, hip))
    return out


def model_xml(spec: dict, variant) -> str:
    v = config(variant)
    h = spec["half"]
    g = " ".join(f"{x:.9g}" for x in spec["gravity"])
    fingers, actuators = [], []
    for i, hip in enumerate(spec["hips"]):
        if v["mocap"]:
            pos = " ".join(f"{x:.9g}" for x in hip)
            fingers.append(f"""
    <body name="finger{i}" mocap="true" pos="{pos}">
      <geom name="tip{i}" type="sphere" size="{spec['tip']}" contype="2" conaffinity="1"/>
    </body>""")
            continue
        fingers.append(f"""
    <body name="finger{i}" gravcomp="1">
      <joint name="f{i}x" type="slide" axis="1 0 0"/>
      <joint name="f{i}y" type="slide" axis="0 1 0"/>
      <joint name="f{i}z" type="slide" axis="0 0 1"/>
      <geom name="tip{i}" type="sphere" size="{spec['tip']}" mass="{v['finger_mass']}"
            contype="2" conaffinity="1"/>
    </body>""")
        for ax in "xyz":
            actuators.append(f'<position joint="f{i}{ax}" kp="{spec["stiffness"]}" '
                             f'kv="{spec["damping"]}"/>')
    return f"""<mujoco model="grasp_{len(spec['hips'])}_fingers">
  <option timestep="{spec['dt']}" gravity="{g}" cone="elliptic" impratio="10"
          integrator="implicitfast" noslip_iterations="{v['noslip_iterations']}"/>
  <default>
    <geom condim="4" friction="{spec['mu_s']} 0.005 0.0001" solref="{v['solref']}"/>
  </default>
  <worldbody>
    <body name="box">
      <freejoint/>
      <geom name="box" type="box" size="{h} {h} {h}" mass="{spec['mass']}"
            contype="1" conaffinity="1"/>
    </body>{''.join(fingers)}
  </worldbody>
  {"<actuator>" + chr(10) + "    " + (chr(10) + "    ").join(actuators) + chr(10) + "  </actuator>" if actuators else ""}
</mujoco>
"""


class Scene:
    def __init__(self, spec: dict, variant: str):
        self.m = mujoco.MjModel.from_xml_string(model_xml(spec, variant))
        self.d = mujoco.MjData(self.m)
        self.dt = spec["dt"]
        pts = contact_points(spec)
        box_qadr = self.m.jnt_qposadr[0]
        self.box_q = slice(box_qadr, box_qadr + 3)
        if config(variant)["mocap"]:
            pts = []                                        # the tips sit at the HIPs (model_xml)
        for i, (touch, hip) in enumerate(pts):
            for k in range(3):
                j = 1 + 3 * i + k                           # joint 0 is the box's freejoint
                self.d.qpos[self.m.jnt_qposadr[j]] = touch[k]
                self.d.ctrl[3 * i + k] = hip[k]
        mujoco.mj_forward(self.m, self.d)

    def box(self) -> np.ndarray:
        return self.d.qpos[self.box_q].copy()

    def step(self, n: int) -> None:
        mujoco.mj_step(self.m, self.d, nstep=n)

    def snapshot(self) -> None:
        self.saved = mujoco.MjData(self.m)
        mujoco.mj_copyData(self.saved, self.m, self.d)

    def time(self, steps: int) -> tuple[float, int, float]:
        """One timed repeat from the settled snapshot (a slipping grasp would otherwise
        lose the box over many repeats). Returns (s per step, contacts at the end,
        box displacement during the repeat in m)."""
        mujoco.mj_copyData(self.d, self.m, self.saved)
        p0 = self.box()
        t0 = time.perf_counter()
        mujoco.mj_step(self.m, self.d, nstep=steps)
        t = (time.perf_counter() - t0) / steps
        return t, int(self.d.ncon), float(np.linalg.norm(self.box() - p0))


_scenes: dict = {}


def handle(req: dict) -> dict:
    cmd = req["cmd"]
    if cmd == "info":
        return {"mujoco": mujoco.__version__, "numpy": np.__version__,
                "python": sys.version.split()[0]}
    if cmd == "xml":
        return {"xml": model_xml(req["spec"], req["variant"])}
    if cmd == "setup":           # build a scene and let it settle (warm-up)
        s = Scene(req["spec"], req["variant"])
        s.step(int(round(req["warmup_s"] / s.dt)))
        s.snapshot()
        _scenes[req["key"]] = s
        return {"box_after_warmup": s.box().tolist(), "ncon": int(s.d.ncon)}
    if cmd == "time":            # one timed repeat on a prepared scene
        t, ncon, moved = _scenes[req["key"]].time(req["steps"])
        return {"per_step": t, "ncon": ncon, "moved_m": moved}
    if cmd == "drop":
        _scenes.pop(req["key"], None)
        return {}
    if cmd == "creep":
        s = Scene(req["spec"], req["variant"])
        s.step(int(round(req["settle_s"] / s.dt)))
        p0 = s.box()
        n, chunk, max_dev = int(round(req["hold_s"] / s.dt)), 100, 0.0
        for _ in range(n // chunk):
            s.step(chunk)
            max_dev = max(max_dev, float(np.linalg.norm(s.box() - p0)))
        d = s.box() - p0
        return {"displacement_m": float(np.linalg.norm(d)), "dz_m": float(d[2]),
                "max_deviation_m": max_dev, "sag_at_settle_m": float(-p0[2]),
                "ncon": int(s.d.ncon)}
    if cmd == "mb_xml":
        return {"xml": multibody_mujoco.model_xml(req["spec"], req["variant"])}
    if cmd == "mb_setup":        # a multi-body scene, after its warm-up
        s = multibody_mujoco.MultiBodyScene(req["spec"], req["variant"])
        s.step(int(round(req["spec"].get("warmup_s", 0.0) / s.dt)))
        _scenes[req["key"]] = s
        return {"positions": s.positions(), "ncon": int(s.d.ncon)}
    if cmd == "mb_time":         # one timed repeat, continuing the simulation
        return _scenes[req["key"]].time(req["steps"])
    if cmd == "mb_positions":
        s = _scenes[req["key"]]
        return {"positions": s.positions(), "warnings": s.warnings()}
    if cmd == "mb_drop":
        _scenes.pop(req["key"], None)
        return {}
    raise ValueError(f"unknown command {cmd!r}")


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
