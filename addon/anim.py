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


def bake_channels(obj, frames, channels) -> None:
    """Replace the keys of each (data path, index, values) channel of ``obj`` with one key a
    frame (linear). Custom properties (``'["name"]'``) must exist. Baking again replaces the
    keys; it never adds a second F-curve."""
    frames = np.asarray(frames, dtype=np.float64)
    if len(frames) == 0 or not channels:
        return
    obj.animation_data_create()
    for path in dict.fromkeys(path for path, _, _ in channels):
        obj.keyframe_insert(path, frame=float(frames[0]))   # creates action/slot/fcurves
    fcurves = _fcurves(obj)
    interpolation = np.full(len(frames), LINEAR, dtype=np.int32)
    co = np.empty(2 * len(frames), dtype=np.float32)
    co[0::2] = frames
    for path, index, values in channels:
        fc = fcurves.find(path, index=index)
        if fc is None:
            fc = fcurves.new(path, index=index)
        kp = fc.keyframe_points
        kp.clear()
        kp.add(len(frames))
        co[1::2] = values
        kp.foreach_set("co", co)
        kp.foreach_set("interpolation", interpolation)
        fc.update()
