"""Fast keyframe baking that works on Blender 4.2 (Action.fcurves) and on 4.4+ / 5.0
(layered actions: slots and channelbags; Action.fcurves is gone in 5.0)."""
from __future__ import annotations

import bpy
import numpy as np

LINEAR = 1  # index of 'LINEAR' in FCurve keyframe interpolation enum


def _fcurves(obj):
    ad = obj.animation_data
    action = ad.action if ad else None
    if action is None:
        return None
    if bpy.app.version >= (4, 4, 0):
        from bpy_extras import anim_utils
        cb = anim_utils.action_get_channelbag_for_slot(action, ad.action_slot)
        return cb.fcurves if cb is not None else None
    return action.fcurves


def transform_channels(obj):
    """(data path, component count) of the object's transform in its rotation mode."""
    mode = obj.rotation_mode
    rot = ("rotation_quaternion", 4) if mode == "QUATERNION" else \
          ("rotation_axis_angle", 4) if mode == "AXIS_ANGLE" else ("rotation_euler", 3)
    return [("location", 3), rot, ("scale", 3)]


def read_transform(obj) -> np.ndarray:
    """Current local transform values, concatenated in transform_channels order."""
    vals = []
    for path, n in transform_channels(obj):
        vals.extend(getattr(obj, path)[:n])
    return np.array(vals, dtype=np.float64)


def bake(obj, frames, values) -> None:
    """Replace the object's transform keys with ``values`` (n_frames, n_channels)."""
    values = np.asarray(values, dtype=np.float64)
    channels, col = [], 0
    for path, n in transform_channels(obj):
        for i in range(n):
            channels.append((path, i, values[:, col]))
            col += 1
    bake_channels(obj, frames, channels)


def bake_channels(obj, frames, channels, reduce: bool = False) -> int:
    """Replace the keys of each (data path, index, values[, run]) channel of ``obj`` with one
    linear key a frame (key_arrays, then write_keys). Returns the keys written."""
    frames = np.asarray(frames, dtype=np.float64)
    if len(frames) == 0 or not channels:
        return 0
    return write_keys(obj, float(frames[0]), key_arrays(frames, channels, reduce))


def key_arrays(frames, channels, reduce: bool = False) -> list:
    """The keys of each (data path, index, values[, run]) channel as (path, index, co): co the
    interleaved frame/value pairs, float32, as ``keyframe_points.foreach_set`` takes them. No
    bpy: safe off the main thread. ``run`` (optional, an index per frame): ``values`` holds one
    value per run of frames, frame i taking ``values[run[i]]`` (an object at rest is one run: no
    work per frame). ``reduce``: leave out the keys inside runs of equal values (as stored,
    float32), which linear interpolation gives back exactly."""
    frames32 = np.asarray(frames, dtype=np.float32)
    run_starts = {}
    out = []
    for path, index, values, *run in channels:
        run = run[0] if run else None
        if run is not None and id(run) not in run_starts:
            run_starts[id(run)] = np.flatnonzero(run[1:] != run[:-1]) + 1
        f, v = _keys(np.asarray(values, dtype=np.float32), frames32, run, run_starts.get(id(run)), reduce)
        co = np.empty(2 * len(v), dtype=np.float32)
        co[0::2] = f
        co[1::2] = v
        out.append((path, index, co))
    return out


def write_keys(obj, first_frame: float, arrays) -> int:
    """Replace the keys of ``obj``'s channels with ``arrays`` (key_arrays). Custom properties
    (``'["name"]'``) must exist. Baking again replaces the keys; it never adds a second
    F-curve. Returns the keys written."""
    if not arrays:
        return 0
    obj.animation_data_create()
    fcurves = _fcurves(obj)
    for path in dict.fromkeys(path for path, _, _ in arrays):
        # keyframe_insert creates the action, its slot and the path's F-curves where they are
        # missing (the same call on an F-curve of 36 000 keys costs 7 ms: not when baking again).
        if fcurves is None or fcurves.find(path, index=0) is None:
            obj.keyframe_insert(path, frame=first_frame)
            fcurves = _fcurves(obj)
    written = 0
    for path, index, co in arrays:
        fc = fcurves.find(path, index=index)
        if fc is None:
            fc = fcurves.new(path, index=index)
        n = len(co) // 2
        kp = fc.keyframe_points
        kp.clear()
        kp.add(n)
        kp.foreach_set("co", co)
        # Linear keys need no handles: no fc.update() (a quarter of a microsecond a key).
        kp.foreach_set("interpolation", np.full(n, LINEAR, dtype=np.int32))
        # New keys come selected: thousands of selected keys make the first G or X in the
        # Graph Editor move or delete the whole bake.
        unselected = np.zeros(n, dtype=bool)
        for prop in ("select_control_point", "select_left_handle", "select_right_handle"):
            kp.foreach_set(prop, unselected)
        written += n
    return written


def _keys(v, frames, run, starts, reduce: bool):
    """(frames, values) of the keys of one channel: ``v`` per frame, or per run of frames
    (``run``; ``starts``: the first frame of each run after the first)."""
    if run is None:
        if reduce and len(v) > 2:
            keep = np.ones(len(v), dtype=bool)
            keep[1:-1] = (v[1:-1] != v[:-2]) | (v[1:-1] != v[2:])
            return frames[keep], v[keep]
        return frames, v
    if not reduce:
        return frames, v[run]
    # Keys where the value changes, on both sides of the change, and at both ends: what the
    # per-frame reduction keeps of the expanded channel.
    change = starts[v[1:] != v[:-1]]
    keep = np.zeros(len(run), dtype=bool)
    keep[[0, -1]] = True
    keep[change - 1] = True
    keep[change] = True
    return frames[keep], v[run[keep]]
