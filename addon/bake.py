"""Baking a recording into the scene as keyframes (docs/recording-format.md, docs/blender.md).

Bodies (by name), fingertip objects (their HIPs), god-objects and residual force/torque
arrows (the "Grasp Lab" collection) get keys at the scene's frame rate, or at every
haptic tick as subframes. Measures for the Graph Editor are animated custom properties:
on "GL God-object <finger>": ``gl_state`` (0 free, 1 stick, 2 slip), ``gl_force`` |F|,
``gl_normal_force`` |Fn|, ``gl_tangential_force`` |Ft|, ``gl_friction_use``
|Ft|/(mu_s |Fn|); on "GL Force <body>": ``gl_grip`` (sum of |Fn| of the fingers on it),
``gl_force`` |residual force|, ``gl_torque`` |residual torque|.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import bpy
import numpy as np
from mathutils import Matrix, Quaternion

from . import anim, display
from .engine.recording import Recording, scene_from_dict
from .engine.runner import quat_rotate


@dataclass
class BakeReport:
    frames: int = 0
    baked: list = field(default_factory=list)       # object names keyed
    missing: list = field(default_factory=list)     # "body Box", "finger F0": not in the scene
    keys: int = 0

    def message(self) -> str:
        text = f"baked {len(self.baked)} objects over {self.frames} frames ({self.keys} keys)"
        if self.missing:
            text += ("; not in the scene (renamed or deleted), not baked: " + ", ".join(self.missing))
        return text


def _np(m: Matrix) -> np.ndarray:
    return np.array(m, dtype=np.float64)


def quats_from_matrices(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z) of rotation matrices (n, 3, 3), with sign continuity
    (each key on the same side as the one before, so interpolation never takes the long way)."""
    n = len(r)
    q = np.empty((n, 4))
    tr = r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2]
    # Shepperd: the largest of w, x, y, z first, for accuracy.
    cand = np.stack([tr, r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]], axis=1)
    k = np.argmax(cand, axis=1)
    for case in range(4):
        m = k == case
        if not m.any():
            continue
        a = r[m]
        if case == 0:
            s = 2.0 * np.sqrt(1.0 + tr[m])
            q[m] = np.stack([0.25 * s, (a[:, 2, 1] - a[:, 1, 2]) / s, (a[:, 0, 2] - a[:, 2, 0]) / s,
                             (a[:, 1, 0] - a[:, 0, 1]) / s], axis=1)
        elif case == 1:
            s = 2.0 * np.sqrt(1.0 + a[:, 0, 0] - a[:, 1, 1] - a[:, 2, 2])
            q[m] = np.stack([(a[:, 2, 1] - a[:, 1, 2]) / s, 0.25 * s, (a[:, 0, 1] + a[:, 1, 0]) / s,
                             (a[:, 0, 2] + a[:, 2, 0]) / s], axis=1)
        elif case == 2:
            s = 2.0 * np.sqrt(1.0 + a[:, 1, 1] - a[:, 0, 0] - a[:, 2, 2])
            q[m] = np.stack([(a[:, 0, 2] - a[:, 2, 0]) / s, (a[:, 0, 1] + a[:, 1, 0]) / s, 0.25 * s,
                             (a[:, 1, 2] + a[:, 2, 1]) / s], axis=1)
        else:
            s = 2.0 * np.sqrt(1.0 + a[:, 2, 2] - a[:, 0, 0] - a[:, 1, 1])
            q[m] = np.stack([(a[:, 1, 0] - a[:, 0, 1]) / s, (a[:, 0, 2] + a[:, 2, 0]) / s,
                             (a[:, 1, 2] + a[:, 2, 1]) / s, 0.25 * s], axis=1)
    return continuous(q / np.linalg.norm(q, axis=1, keepdims=True))


def continuous(q: np.ndarray) -> np.ndarray:
    """Flip quaternions so that each is on the same side (dot >= 0) as the one before."""
    if len(q) < 2:
        return q
    flips = np.sum(q[1:] * q[:-1], axis=1) < 0
    sign = np.concatenate([[1.0], np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)])
    return q * sign[:, None]


def _distinct(rows: np.ndarray):
    """(first rows of each run of equal consecutive rows, index of each row's run): work done once
    per run and spread back with ``result[index]`` (a body at rest is one row)."""
    flat = rows.reshape(len(rows), -1)
    change = np.ones(len(rows), dtype=bool)
    change[1:] = np.any(flat[1:] != flat[:-1], axis=1)
    return rows[change], np.cumsum(change) - 1


def _quat_matrices(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1)], axis=1)


def _parent_inverse(obj) -> np.ndarray:
    """World -> the object's basis: (parent world @ parent inverse)^-1 (the parent as it is now)."""
    if obj.parent is None:
        return np.eye(4)
    return _np((obj.parent.matrix_world @ obj.matrix_parent_inverse).inverted())


def _rest_matrix(obj) -> Matrix:
    gl = obj.grasp_lab
    if gl.has_rest:
        v = list(gl.rest_matrix)
        return Matrix([v[0:4], v[4:8], v[8:12], v[12:16]])
    return obj.matrix_world.copy()


def _bake_rigid(obj, frames, poses, start_pos, start_quat) -> int:
    """Keys for ``obj`` following body frame poses (n, 7): the object keeps its offset from the
    body frame at the start of the recording (its rest matrix), its scale and its parent."""
    f0 = Quaternion(start_quat).to_matrix().to_4x4()
    f0.translation = start_pos
    frame_to_world = _np(f0.inverted() @ _rest_matrix(obj))
    poses, run = _distinct(poses)
    n = len(poses)
    world = np.zeros((n, 4, 4))
    world[:, :3, :3] = _quat_matrices(poses[:, 3:])
    world[:, :3, 3] = poses[:, :3]
    world[:, 3, 3] = 1.0
    basis = _parent_inverse(obj) @ world @ frame_to_world
    loc = basis[:, :3, 3]
    scale = np.linalg.norm(basis[:, :3, :3], axis=1)           # column norms
    rot = quats_from_matrices(basis[:, :3, :3] / scale[:, None, :])
    obj.rotation_mode = "QUATERNION"
    obj.scale = scale[0]        # rigid motion under a fixed parent: the scale does not change
    loc, rot = loc[run], rot[run]
    return anim.bake_channels(obj, frames, [("location", i, loc[:, i]) for i in range(3)]
                              + [("rotation_quaternion", i, rot[:, i]) for i in range(4)], reduce=True)


def _bake_points(obj, frames, points, size=None, extra=()) -> int:
    """Keys for an object whose origin follows world points (n, 3), and ``extra`` channels."""
    inv = _parent_inverse(obj)
    loc = points @ inv[:3, :3].T + inv[:3, 3]
    if size is not None:
        obj.scale = (size, size, size)
    return anim.bake_channels(obj, frames, [("location", i, loc[:, i]) for i in range(3)] + list(extra),
                              reduce=True)


def _arrow_channels(origin, vec, scale):
    """loc / quaternion / scale of display arrows (unit arrow along +Z) from origin along vec."""
    rows, run = _distinct(np.concatenate([origin, vec], axis=1))
    origin, vec = rows[:, :3], rows[:, 3:]
    length = np.linalg.norm(vec, axis=1)
    u = vec / np.where(length > 1e-12, length, 1.0)[:, None]
    # The rotation taking +Z to u: (1 + uz, -uy, ux, 0) normalised; -Z: a half turn about X.
    q = np.stack([1.0 + u[:, 2], -u[:, 1], u[:, 0], np.zeros(len(u))], axis=1)
    flat = np.linalg.norm(q, axis=1) < 1e-9
    q[flat] = (0.0, 1.0, 0.0, 0.0)
    q = continuous(q / np.linalg.norm(q, axis=1, keepdims=True))
    visible = length * scale >= 1e-9
    sx = np.where(visible, display.ARROW_WIDTH, 0.0)[run]
    sz = np.where(visible, length * scale, 0.0)[run]
    origin, q = origin[run], q[run]
    return ([("location", i, origin[:, i]) for i in range(3)]
            + [("rotation_quaternion", i, q[:, i]) for i in range(4)]
            + [("scale", 0, sx), ("scale", 1, sx), ("scale", 2, sz)])


def _custom(obj, frames, props: dict) -> list:
    for name in props:
        obj[name] = 0.0
    return [(f'["{name}"]', 0, values) for name, values in props.items()]


def finger_measures(rec: Recording, ticks) -> dict:
    """Per finger (n, nf): |F|, |Fn|, |Ft|, friction use |Ft| / (mu_s |Fn|), state."""
    f, n = ticks["force"], ticks["normal"]
    fn = np.sum(f * n, axis=2)
    ft = np.linalg.norm(f - fn[:, :, None] * n, axis=2)
    mu = np.array([b["mu_s"] for b in rec.header["scene"]["bodies"]] + [np.nan])
    mu_c = mu[np.where(ticks["contact"] >= 0, ticks["contact"], len(mu) - 1)]
    with np.errstate(divide="ignore", invalid="ignore"):
        use = np.where((ticks["contact"] >= 0) & (np.abs(fn) > 1e-12), ft / (mu_c * np.abs(fn)), 0.0)
    return {"gl_state": ticks["state"].astype(np.float64), "gl_force": np.linalg.norm(f, axis=2),
            "gl_normal_force": np.abs(fn), "gl_tangential_force": ft, "gl_friction_use": use}


def bake_recording(context, rec: Recording, every_tick: bool = False, force_scale: float | None = None,
                   torque_scale: float | None = None) -> BakeReport:
    """Bake ``rec`` into the context's scene. Returns what was baked and what was missing."""
    scene = context.scene
    s = scene.grasp_lab
    force_scale = s.force_scale if force_scale is None else force_scale
    torque_scale = s.torque_scale if torque_scale is None else torque_scale
    fps = scene.render.fps / scene.render.fps_base
    frame_start = rec.header.get("frame_start", scene.frame_start)
    t = rec.ticks["time"]
    if every_tick:
        idx = np.arange(len(t))
        times = t
    else:
        first = int(np.ceil(t[0] * fps - 1e-9))
        last = int(np.floor(t[-1] * fps + 1e-9))
        times = np.arange(first, last + 1) / fps
        idx = rec.sample(times)
    if len(idx) == 0:
        raise ValueError(f"{rec.path}: the recording is shorter than one frame")
    frames = frame_start + times * fps
    ticks = rec.ticks[idx]
    # Each object's samples contiguous (records are kilobytes apart): (objects, frames, k).
    per = {name: np.ascontiguousarray(np.moveaxis(ticks[name], 1, 0))
           for name in ("pose", "hip", "god_object", "wrench", "contact")}
    desc = scene_from_dict(rec.header["scene"])
    report = BakeReport(frames=len(frames))
    wm = context.window_manager
    steps = len(desc.bodies) + len(desc.fingers) + 2
    wm.progress_begin(0, steps)
    done = 0

    def progress():
        nonlocal done
        done += 1
        wm.progress_update(done)

    def keyed(obj, keys):
        report.baked.append(obj.name)
        report.keys += keys

    try:
        for i, b in enumerate(desc.bodies):
            progress()
            obj = bpy.data.objects.get(b.name)
            if obj is None:
                report.missing.append(f"body {b.name}")
                continue
            if b.static:
                continue
            keyed(obj, _bake_rigid(obj, frames, per["pose"][i], b.position, b.orientation))
        for j, f in enumerate(desc.fingers):
            progress()
            obj = bpy.data.objects.get(f.name)
            if obj is None:
                report.missing.append(f"finger {f.name}")
                continue
            keyed(obj, _bake_points(obj, frames, per["hip"][j]))
        # The display objects: made if missing, so a scene whose bodies are gone still shows forces.
        shown = display.DisplayObjects(scene, desc)
        measures = {k: np.ascontiguousarray(v.T) for k, v in finger_measures(rec, ticks).items()}
        for j, obj in enumerate(shown.god_objects):
            keyed(obj, _bake_points(obj, frames, per["god_object"][j], size=shown.radii[j],
                                    extra=_custom(obj, frames, {k: v[j] for k, v in measures.items()})))
        progress()
        grip = np.zeros((len(idx), len(desc.bodies)))
        fn = measures["gl_normal_force"]
        for j in range(len(desc.fingers)):
            c = per["contact"][j]
            on = c >= 0
            np.add.at(grip, (np.flatnonzero(on), c[on]), fn[j, on])
        for k, i in enumerate(shown.dynamic):
            b = desc.bodies[i]
            pose = per["pose"][i]
            com = pose[:, :3] + quat_rotate(pose[:, 3:], b.mass_properties.center_of_mass)
            force, torque = per["wrench"][i, :, :3], per["wrench"][i, :, 3:]
            arrow = shown.force_arrows[k]
            arrow.rotation_mode = "QUATERNION"
            props = _custom(arrow, frames, {"gl_grip": grip[:, i], "gl_force": np.linalg.norm(force, axis=1),
                                            "gl_torque": np.linalg.norm(torque, axis=1)})
            keyed(arrow, anim.bake_channels(arrow, frames, _arrow_channels(com, force, force_scale) + props,
                                            reduce=True))
            arrow = shown.torque_arrows[k]
            arrow.rotation_mode = "QUATERNION"
            keyed(arrow, anim.bake_channels(arrow, frames, _arrow_channels(com, torque, torque_scale),
                                            reduce=True))
        progress()
    finally:
        wm.progress_end()
    last = int(np.ceil(frames[-1]))
    if scene.frame_end < last:
        scene.frame_end = last
    return report
