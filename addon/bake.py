"""Baking a recording into the scene as keyframes (docs/recording-format.md, docs/blender.md).

Bodies (by name), fingertip objects (their HIPs), god-objects and residual force/torque
arrows (the "Grasp Lab" collection) get keys at the scene's frame rate, or at every
haptic tick as subframes. Measures for the Graph Editor are animated custom properties:
on "GL God-object <finger>": ``gl_state`` (0 free, 1 stick, 2 slip), ``gl_force`` |F|,
``gl_normal_force`` |Fn|, ``gl_tangential_force`` |Ft|, ``gl_friction_use``
|Ft|/(mu |Fn|) (mu of the contact's current cone), and its material's colour as the live view
shows it (by friction use on a held body, else the free blue), so that a render at any frame has
that frame's colour; on "GL Force <body>": ``gl_grip`` (sum
of |Fn| of the fingers on it), ``gl_force`` |residual force|, ``gl_torque`` |residual torque|,
and the grasp analysis (engine/analysis.py, docs/analysis.md): ``gl_held``, ``gl_closure``,
``gl_epsilon``, ``gl_mu_min``, ``gl_slip_margin``, ``gl_grip_load``.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from functools import partial

import bpy
import numpy as np
from mathutils import Matrix, Quaternion

from . import anim, display, hands
from .engine import analysis, grasp_display, sound
from .engine.measures import DESCRIPTIONS, body_grip, finger_measures
from .engine.recording import Recording, scene_from_dict
from .engine.runner import quat_rotate


@dataclass
class BakeReport:
    frames: int = 0
    baked: list = field(default_factory=list)       # object names keyed
    missing: list = field(default_factory=list)     # "body Box", "finger F0": not in the scene
    keys: int = 0
    frame_end_was: int | None = None        # the scene's end frame before the bake moved it
    frame_end: int | None = None
    sound: str = ""                         # the WAV written and put in the sequencer
    sound_error: str = ""                   # why there is none

    def message(self) -> str:
        text = f"baked {len(self.baked)} objects over {self.frames} frames ({self.keys} keys)"
        if self.frame_end_was is not None:
            text += (f"; the scene's end frame is now {self.frame_end} (was {self.frame_end_was}): "
                     "the recording is longer than the animation")
        if self.missing:
            text += ("; not in the scene (renamed or deleted), not baked: " + ", ".join(self.missing))
        if self.sound:
            text += f"; its sound: {self.sound} (a sound strip in the sequencer)"
        if self.sound_error:
            text += f"; no sound: {self.sound_error}"
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
    flips = np.einsum("ij,ij->i", q[1:], q[:-1]) < 0
    if not flips.any():
        return q
    sign = np.ones(len(q))
    sign[1:] = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
    return q * sign[:, None]


def _norms(v: np.ndarray) -> np.ndarray:
    """Euclidean norms of the rows of v (n, k) (einsum: a third of np.linalg.norm's time)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _changes(rows: np.ndarray) -> np.ndarray:
    """Mask of the rows (n, k) that differ from the row before (the first always): rows
    compared as bytes (one comparison a row; rows may be strided, each row contiguous)."""
    change = np.ones(len(rows), dtype=bool)
    if len(rows) > 1:
        packed = np.ascontiguousarray(rows) if rows.strides[-1] != rows.itemsize else rows
        whole = packed.view(np.dtype((np.void, packed.shape[-1] * packed.itemsize)))[:, 0]
        change[1:] = whole[1:] != whole[:-1]
    return change


def _distinct(rows: np.ndarray, change: np.ndarray | None = None):
    """(first rows of each run of equal consecutive rows, index of each row's run): work done once
    per run and spread back with ``result[index]`` (a body at rest is one row). ``change``:
    where runs start, if not the rows' own changes."""
    if change is None:
        change = _changes(rows)
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


def _rigid_channels(poses, frame_to_world, parent):
    """Channels (location, quaternion) of an object following body frame poses (n, 7), keeping
    its offset ``frame_to_world`` from the body frame and its parent (``parent``: world -> the
    object's basis), and the object's scale. No bpy (runs off the main thread)."""
    poses, run = _distinct(poses)
    pos, quat = poses[:, :3], poses[:, 3:]
    fr, ft = frame_to_world[:3, :3], frame_to_world[:3, 3]
    scale = np.linalg.norm(fr, axis=0)                   # column norms: the object's scale
    if np.array_equal(parent, np.eye(4)) and np.allclose(fr / scale, np.eye(3), rtol=0, atol=1e-12):
        # No parent and the object's axes along the body frame's (the usual case): the keys
        # are the body poses themselves (the general path's matrices give them back to 1e-16).
        loc = pos + quat_rotate(quat, ft) if np.any(ft) else pos
        rot = continuous(quat / _norms(quat)[:, None])
    else:
        rw = _quat_matrices(quat)
        # parent @ [rw | pos] @ frame_to_world, as (m*3, 3) products (one BLAS call each).
        basis_r = (rw.reshape(-1, 3) @ fr).reshape(-1, 3, 3)
        basis_t = (rw.reshape(-1, 3) @ ft).reshape(-1, 3) + pos
        pr, pt = parent[:3, :3], parent[:3, 3]
        basis_r = np.swapaxes((np.swapaxes(basis_r, 1, 2).reshape(-1, 3) @ pr.T).reshape(-1, 3, 3), 1, 2)
        loc = basis_t @ pr.T + pt
        scale = np.linalg.norm(basis_r[0], axis=0)
        rot = quats_from_matrices(basis_r / np.linalg.norm(basis_r, axis=1)[:, None, :])
    return ([("location", i, loc[:, i], run) for i in range(3)]
            + [("rotation_quaternion", i, rot[:, i], run) for i in range(4)]), scale


def _point_channels(points, parent):
    """Location channels of an object whose origin follows world points (n, 3). No bpy."""
    points, run = _distinct(points)
    loc = points if np.array_equal(parent, np.eye(4)) else points @ parent[:3, :3].T + parent[:3, 3]
    return [("location", i, loc[:, i], run) for i in range(3)]


def _arrow_channels(origin, vec, scale, run):
    """loc / quaternion / scale channels of display arrows (unit arrow along +Z) from origin
    along vec, given per run of frames (``run``)."""
    length = _norms(vec)
    u = vec / np.where(length > 1e-12, length, 1.0)[:, None]
    # The rotation taking +Z to u: (1 + uz, -uy, ux, 0) normalised; -Z: a half turn about X.
    q = np.zeros((len(u), 4))
    q[:, 0], q[:, 1], q[:, 2] = 1.0 + u[:, 2], -u[:, 1], u[:, 0]
    size = _norms(q)
    flat = size < 1e-9
    q[flat], size[flat] = (0.0, 1.0, 0.0, 0.0), 1.0
    q = continuous(q / size[:, None])
    visible = length * scale >= 1e-9
    sx = np.where(visible, display.ARROW_WIDTH, 0.0)
    sz = np.where(visible, length * scale, 0.0)
    return ([("location", i, origin[:, i], run) for i in range(3)]
            + [("rotation_quaternion", i, q[:, i], run) for i in range(4)]
            + [("scale", 0, sx, run), ("scale", 1, sx, run), ("scale", 2, sz, run)])


def _describe(obj, name):
    """The property's tooltip: what it is and its unit (engine.measures.DESCRIPTIONS)."""
    if name in DESCRIPTIONS:
        obj.id_properties_ui(name).update(description=DESCRIPTIONS[name])


def _custom(obj, props: dict, run=None) -> list:
    """Channels of animated custom properties (made here), values per frame or per ``run``."""
    for name in props:
        obj[name] = 0.0
        _describe(obj, name)
    return [(f'["{name}"]', 0, values) + ((run,) if run is not None else ()) for name, values in props.items()]


SOUND_STRIP = "Grasp Lab Sound"


def sound_path(rec_path: str, blend_path: str = "") -> str:
    """Where a bake writes the recording's sound: ``<recording name>.wav`` beside the .blend
    (``blend_path``; beside the recording while the .blend is not saved)."""
    folder = os.path.dirname(os.path.abspath(blend_path or rec_path))
    return os.path.join(folder, os.path.splitext(os.path.basename(rec_path))[0] + ".wav")


def bake_sound(scene, rec_path: str, wav_path: str, frame_start: int) -> str:
    """The recording's sound (every tick: engine/sound.py) as a WAV at ``wav_path`` and as the
    scene's sound strip "Grasp Lab Sound" from ``frame_start`` (the frame of session time 0),
    replacing the strip of an earlier bake: a render to video (FFmpeg with audio) carries it.
    The mapping: the scene's (its Session panel's pitch settings). The strip names the WAV
    relative to the open .blend when it is saved (Blender moves such paths along when the scene
    is saved elsewhere: ``//name.wav`` beside the .blend it is saved as)."""
    from .engine.recording import open_recording
    from .sound_live import mapping_of
    full = open_recording(rec_path)             # the bake's own copy may hold only the frames' ticks
    done = sound.write_wav(wav_path, full.header["scene"], full.ticks, mapping_of(scene.grasp_lab))
    if scene.sequence_editor is None:
        scene.sequence_editor_create()
    editor = scene.sequence_editor
    strips = editor.strips if hasattr(editor, "strips") else editor.sequences     # renamed in 4.4
    old = strips.get(SOUND_STRIP)
    if old is not None:
        strips.remove(old)
    strip = strips.new_sound(SOUND_STRIP, done["path"], channel=1, frame_start=int(frame_start))
    strip.name = SOUND_STRIP
    if bpy.data.filepath:
        strip.sound.filepath = bpy.path.relpath(done["path"])
    return done["path"]


def bake_recording(context, rec: Recording, every_tick: bool = False, force_scale: float | None = None,
                   torque_scale: float | None = None, sound_to: str | None = None,
                   blend_path: str | None = None) -> BakeReport:
    """Bake ``rec`` into the context's scene. Returns what was baked and what was missing.
    ``sound_to``: the WAV of its sound (default: sound_path beside the .blend; "" none);
    ``blend_path``: the .blend the scene will be saved as (default: the open file's, if saved)."""
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
    if np.array_equal(idx, np.arange(len(rec.ticks))):
        ticks = rec.ticks               # read at the frame rate already: every tick is a frame's
    else:                               # rows of bytes: numpy's structured take is far slower
        width = rec.ticks.dtype.itemsize
        ticks = rec.ticks.view(np.uint8).reshape(-1, width)[idx].view(rec.ticks.dtype)[:, 0]
    # Each object's samples contiguous, in one pass over the records (kilobytes apart: reading
    # them object by object misses the cache and the TLB on every row): (objects, frames, k).
    per = {name: np.ascontiguousarray(np.moveaxis(ticks[name], 1, 0))
           for name in ("pose", "hip", "god_object", "wrench", "contact")}
    desc = scene_from_dict(rec.header["scene"])
    report = BakeReport(frames=len(frames))
    # First the objects and what bpy says of them; then each job's keys (numpy only), written.
    jobs = []           # () -> [(object, channels, scale to set or None)]
    for i, b in enumerate(desc.bodies):
        obj = bpy.data.objects.get(b.name)
        if obj is None:
            report.missing.append(f"body {b.name}")
        elif not b.static:
            f0 = Quaternion(b.orientation).to_matrix().to_4x4()
            f0.translation = b.position
            obj.rotation_mode = "QUATERNION"
            jobs.append(partial(_rigid_job, obj, per["pose"][i], _np(f0.inverted() @ _rest_matrix(obj)),
                                _parent_inverse(obj)))
    for j, f in enumerate(desc.fingers):
        obj = bpy.data.objects.get(f.name)
        if obj is None and hands.bone_finger_named(f.name) is None:
            report.missing.append(f"finger {f.name}")
        elif obj is None:
            pass            # a Finger bone: its hand's rendered armature is keyed below
        else:
            jobs.append(partial(_point_job, obj, per["hip"][j], _parent_inverse(obj), []))
    # The display objects: made if missing, so a scene whose bodies are gone still shows forces.
    shown = display.DisplayObjects(scene, desc)
    measures = {k: np.ascontiguousarray(v.T) for k, v in finger_measures(rec, ticks).items()}
    for j, obj in enumerate(shown.god_objects):
        size = shown.radii[j]
        obj.scale = (size, size, size)
        props = _custom(obj, {k: v[j] for k, v in measures.items()})
        jobs.append(partial(_point_job, obj, per["god_object"][j], _parent_inverse(obj), props))
    grip = body_grip(per["contact"].T, measures["gl_normal_force"].T, len(desc.bodies))
    # The grasp measures of each held body (docs/analysis.md), at the baked ticks.
    rows = np.unique(idx)
    table = analysis.analyse_recording(rec, rows=rows)
    grasp = analysis.body_series(table, rows, len(desc.bodies))
    at = np.searchsorted(rows, idx)
    colors = grasp_display.finger_color_series(table, rows, len(desc.fingers))[at]    # (frames, fingers, 4)
    for j, obj in enumerate(shown.god_objects):
        jobs.append(partial(_color_job, obj.material_slots[0].material, np.ascontiguousarray(colors[:, j])))
    for k, i in enumerate(shown.dynamic):
        force_arrow, torque_arrow = shown.force_arrows[k], shown.torque_arrows[k]
        for arrow in (force_arrow, torque_arrow):
            arrow.rotation_mode = "QUATERNION"
        for name in ("gl_grip", "gl_force", "gl_torque"):
            force_arrow[name] = 0.0
            _describe(force_arrow, name)
        props = _custom(force_arrow, {name: np.ascontiguousarray(v[:, i]) for name, v in grasp.items()}, at)
        jobs.append(partial(_arrows_job, force_arrow, torque_arrow, per["pose"][i], per["wrench"][i],
                            desc.bodies[i].mass_properties.center_of_mass, grip[:, i], force_scale, torque_scale,
                            props))

    # Hands: the rendered armatures, keyed from the records (docs/hands.md).
    for rendered, keys in hands.bake_recorded_hands(scene, desc, ticks, frames):
        report.baked.append(rendered.name)
        report.keys += keys

    wm = context.window_manager
    wm.progress_begin(0, len(jobs))
    try:
        for n, job in enumerate(jobs):
            for obj, channels, scale in job():
                if scale is not None:
                    obj.scale = scale       # rigid motion under a fixed parent: the scale is constant
                if isinstance(obj, bpy.types.Object):      # not a god-object's material
                    report.baked.append(obj.name)
                report.keys += anim.write_keys(obj, float(frames[0]), anim.key_arrays(frames, channels, reduce=True))
            wm.progress_update(n + 1)
    finally:
        wm.progress_end()
    last = int(np.ceil(frames[-1]))
    if scene.frame_end < last:
        report.frame_end_was, report.frame_end = scene.frame_end, last
        scene.frame_end = last
    blend_path = bpy.data.filepath if blend_path is None else blend_path
    if sound_to is None:
        sound_to = sound_path(rec.path, blend_path)
    if sound_to:
        # Last: the keys are in whatever becomes of the sound (a read-only folder says so).
        try:
            report.sound = bake_sound(scene, rec.path, sound_to, frame_start)
        except (OSError, ValueError, RuntimeError) as ex:
            report.sound_error = str(ex)
    return report


def _rigid_job(obj, poses, frame_to_world, parent):
    channels, scale = _rigid_channels(poses, frame_to_world, parent)
    return [(obj, channels, scale)]


def _point_job(obj, points, parent, extra):
    return [(obj, _point_channels(points, parent) + extra, None)]


def _color_job(material, colors):
    """A god-object's material coloured per frame (colors (n, 4) RGBA): the viewport's and
    Workbench's colour, and the shader's base and emission colour (what display._set_color
    sets live)."""
    colors, run = _distinct(colors)
    rgba = [(i, np.ascontiguousarray(colors[:, i])) for i in range(4)]
    out = [(material, [("diffuse_color", i, v, run) for i, v in rgba], None)]
    bsdf = material.node_tree.nodes.get("Principled BSDF") if material.node_tree is not None else None
    if bsdf is not None:
        paths = [f'nodes["{bsdf.name}"].inputs["Base Color"].default_value']
        paths += [f'nodes["{bsdf.name}"].inputs["{key}"].default_value'
                  for key in ("Emission Color", "Emission") if key in bsdf.inputs][:1]
        out.append((material.node_tree, [(path, i, v, run) for path in paths for i, v in rgba], None))
    return out


def _arrows_job(force_arrow, torque_arrow, pose, wrench, com_local, grip, force_scale, torque_scale, extra):
    """A body's force and torque arrows, once per run of equal poses and wrenches (a body at
    rest: once), and the arrow's measures (grip, |force|, |torque|, and ``extra``'s channels)."""
    change = _changes(pose) | _changes(wrench)
    pose, run = _distinct(pose, change)
    wrench = wrench[change]
    com = pose[:, :3] + quat_rotate(pose[:, 3:], com_local)
    force, torque = wrench[:, :3], wrench[:, 3:]
    props = [('["gl_grip"]', 0, grip), ('["gl_force"]', 0, _norms(force), run),
             ('["gl_torque"]', 0, _norms(torque), run)]
    return [(force_arrow, _arrow_channels(com, force, force_scale, run) + props + extra, None),
            (torque_arrow, _arrow_channels(com, torque, torque_scale, run), None)]
