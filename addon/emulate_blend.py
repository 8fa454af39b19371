"""``grasp-lab emulate --from SCENE.blend`` (docs/devices.md): the device emulator
(engine/devices/emulator.py) playing the fingertip animation of a .blend. Reading the .blend
needs bpy, so this half is on the bpy side: the Blender command ``emulate``, and
``python -m addon.emulate_blend --pty --from SCENE.blend`` in a Python with the bpy module."""
from __future__ import annotations

import os
import sys

import bpy

from .engine.devices import emulator
from .engine.inputs import SampledTrajectory


def motion_from_blend(path, first=0, count=None):
    """The fingertip animation of a Grasp Lab .blend, looped, as (motion, finger count): its
    fingertips in channel order from the ``first`` on, ``count`` of them (default: the rest;
    one person's hand of a scene several devices drive). Positions are the fingertips' world
    coordinates: with an identity workspace frame the device replays the scene's own
    animation."""
    if not os.path.exists(path):
        raise SystemExit(f"--from {path}: no such file")
    # Blender prints to the C stdout while reading; the first line of ours must be "PORT ...".
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(path))
        times, positions = _sample_fingertips(bpy.context.scene)
    finally:
        os.dup2(saved, 1)
        os.close(saved)
    have = len(positions[0])
    count = have - first if count is None else count
    if not (0 <= first < have and 1 <= count <= have - first):
        raise SystemExit(f"--from {path}: fingertips {first}..{first + count - 1} asked for, the scene has "
                         f"{have} (channels in order: 0..{have - 1})")
    positions = [p[first:first + count] for p in positions]
    track = SampledTrajectory(times, positions)
    period = max(track.duration, 1e-9)
    return (lambda t, n: [tuple(p) for p in track.hips_at(t % period)]), track.n_fingers


def _finger_channel(obj):
    """The device channel of a fingertip object, None for other objects. Reads the add-on's
    properties, or their stored values when the add-on is not registered (role FINGER = 3)."""
    gl = getattr(obj, "grasp_lab", None)
    if gl is not None and hasattr(gl, "role"):
        return gl.channel if gl.role == "FINGER" else None
    raw = obj.get("grasp_lab")
    if raw is None and hasattr(obj, "bl_system_properties_get"):
        # Blender 5.0 keeps registered properties apart from the object's custom properties.
        system = obj.bl_system_properties_get()
        raw = system.get("grasp_lab") if system is not None else None
    if raw is None or raw.get("role", 0) != 3:
        return None
    return raw.get("channel", 0)


def _sample_fingertips(scene):
    tips = sorted((o for o in scene.objects if _finger_channel(o) is not None),
                  key=lambda o: (_finger_channel(o), o.name))
    if not tips:
        raise SystemExit("--from: the .blend has no fingertip objects (role Finger)")
    fps = scene.render.fps / scene.render.fps_base
    times, positions = [], []
    for frame in range(scene.frame_start, max(scene.frame_end, scene.frame_start + 1) + 1):
        scene.frame_set(frame)
        times.append((frame - scene.frame_start) / fps)
        positions.append([tuple(o.matrix_world.translation) for o in tips])
    return times, positions


def emulate(args, out=None, err=None) -> int:
    """The Blender command: ``grasp-lab emulate`` with ``--from``."""
    return emulator.main(args=args, motion=motion_from_blend(args.from_blend, args.first, args.fingers))


if __name__ == "__main__":
    _args = emulator.build_parser().parse_args()
    sys.exit(emulate(_args) if _args.from_blend else emulator.main(args=_args))
