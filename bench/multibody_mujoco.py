"""MuJoCo side of the multi-body benchmark (runs in .venv-bench, never imports graspcore).

Imported by bench/scenes_mujoco.py, whose JSON-line worker serves the `mb_*` commands.
A scene is the plain dict of bench/bench_scenes.py:scene_spec(name) (boxes with half
extents, mass, pose and friction; fingers with a HIP, radius, stiffness and damping).

Model conventions (the same as the held-box grasp model in scenes_mujoco.py):
  * a static body (the table) is a box geom of the worldbody; every other body is a body
    with a free joint and one box geom (`mass` given, so MuJoCo computes the same
    uniform-density inertia as graspcore), its pose from the spec (quaternion w x y z);
  * a fingertip is a body with a sphere geom (radius from the spec, 10 g, gravcomp="1")
    on three world-aligned slide joints, driven by three `position` actuators with
    kp = the finger's stiffness and kv = its damping (1000 N/m and 2 N s/m; the tray's
    pinch fingers 4000 N/m and 5 N s/m), control = the HIP. The fingertip starts at the
    surface point it touches (the HIP moved out of the held box along the face normal),
    as in the grasp model;
  * fingers collide with bodies, not with each other (contype 2 / conaffinity 1; bodies
    contype 1 / conaffinity 1);
  * option: cone="elliptic", impratio="10", integrator="implicitfast", Newton solver with
    MuJoCo's default iterations and tolerance, timestep = the spec's dt (1 ms);
  * every geom: condim="4" (sliding + torsional friction, also box-box), friction
    "mu_s 0.005 0.0001", solref="0.002 1", default solimp. MuJoCo combines two geoms'
    friction with the maximum; the fingertip geoms get friction 0 so that a finger takes
    the friction of the body it touches (as a graspcore finger does). In these scenes
    every pair of bodies that touch has equal friction, so max = graspcore's geometric
    mean;
  * variant "recommended+noslip" adds noslip_iterations="10" (MuJoCo's post-processing
    against slip, as in the grasp benchmark);
  * variant "condim3" uses condim="3" (no torsional friction) for box-box and box-table
    contacts, fingertips keep condim 4.
"""
from __future__ import annotations

import time

import mujoco
import numpy as np

from multibody_spec import finger_touch

FINGER_MASS = 0.01      # kg, as in the grasp model
VARIANTS = ("recommended", "recommended+noslip", "condim3")


def _f(xs) -> str:
    return " ".join(f"{float(x):.9g}" for x in xs)


def model_xml(spec: dict, variant: str = "recommended") -> str:
    if variant not in VARIANTS:
        raise ValueError(f"variant: one of {VARIANTS}")
    body_condim = 3 if variant == "condim3" else 4
    noslip = 10 if variant == "recommended+noslip" else 0
    statics, bodies, fingers, actuators = [], [], [], []
    for i, b in enumerate(spec["bodies"]):
        geom = (f'type="box" size="{_f(b["half"])}" friction="{b["mu_s"]:.9g} 0.005 0.0001" '
                f'condim="{body_condim}" contype="1" conaffinity="1"')
        if b["static"]:
            statics.append(f'    <geom name="static{i}" {geom} pos="{_f(b["position"])}" '
                           f'quat="{_f(b["orientation"])}"/>')
        else:
            bodies.append(f'    <body name="b{i}" pos="{_f(b["position"])}" quat="{_f(b["orientation"])}">\n'
                          f'      <freejoint/>\n'
                          f'      <geom name="g{i}" {geom} mass="{b["mass"]:.9g}"/>\n'
                          f'    </body>')
    for i, f in enumerate(spec["fingers"]):
        fingers.append(f'    <body name="finger{i}" gravcomp="1">\n'
                       f'      <joint name="f{i}x" type="slide" axis="1 0 0"/>\n'
                       f'      <joint name="f{i}y" type="slide" axis="0 1 0"/>\n'
                       f'      <joint name="f{i}z" type="slide" axis="0 0 1"/>\n'
                       f'      <geom name="tip{i}" type="sphere" size="{f["radius"]:.9g}" mass="{FINGER_MASS}" '
                       f'friction="0 0 0" condim="4" contype="2" conaffinity="1"/>\n'
                       f'    </body>')
        for ax in "xyz":
            actuators.append(f'    <position joint="f{i}{ax}" kp="{f["stiffness"]:.9g}" kv="{f["damping"]:.9g}"/>')
    act = ("  <actuator>\n" + "\n".join(actuators) + "\n  </actuator>\n") if actuators else ""
    return (f'<mujoco model="{spec["name"]}">\n'
            f'  <option timestep="{spec["dt"]:.9g}" gravity="{_f(spec["gravity"])}" cone="elliptic" '
            f'impratio="10" integrator="implicitfast" noslip_iterations="{noslip}"/>\n'
            f'  <size memory="256M"/>\n'
            f'  <default>\n    <geom solref="0.002 1"/>\n  </default>\n'
            f'  <worldbody>\n' + "\n".join(statics + bodies + fingers) + "\n  </worldbody>\n"
            + act + "</mujoco>\n")


class MultiBodyScene:
    def __init__(self, spec: dict, variant: str = "recommended"):
        self.m = mujoco.MjModel.from_xml_string(model_xml(spec, variant))
        self.d = mujoco.MjData(self.m)
        self.dt = spec["dt"]
        self.dynamic = [i for i, b in enumerate(spec["bodies"]) if not b["static"]]
        self.body_ids = [mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_BODY, f"b{i}") for i in self.dynamic]
        self.qadr = [int(self.m.jnt_qposadr[self.m.body_jntadr[b]]) for b in self.body_ids]
        for i, (_, touch) in enumerate(finger_touch(spec)):
            hip = spec["fingers"][i]["hip"]
            for k, ax in enumerate("xyz"):
                j = mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_JOINT, f"f{i}{ax}")
                self.d.qpos[self.m.jnt_qposadr[j]] = touch[k]
                self.d.ctrl[3 * i + k] = hip[k]
        mujoco.mj_forward(self.m, self.d)

    def positions(self) -> list[list[float]]:
        """Positions of the dynamic bodies, in spec order (static bodies left out)."""
        return [self.d.qpos[a:a + 3].tolist() for a in self.qadr]

    def step(self, n: int) -> None:
        mujoco.mj_step(self.m, self.d, nstep=n)

    def time(self, steps: int) -> dict:
        t0 = time.perf_counter()
        mujoco.mj_step(self.m, self.d, nstep=steps)
        t = (time.perf_counter() - t0) / steps
        return {"per_step": t, "ncon": int(self.d.ncon), "nefc": int(self.d.nefc)}

    def warnings(self) -> dict:
        out = {}
        for i, w in enumerate(self.d.warning):
            if w.number:
                try:
                    out[mujoco.mjtWarning(i).name] = int(w.number)
                except Exception:
                    out[str(i)] = int(w.number)
        return out
