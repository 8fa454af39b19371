"""Build the pinch-and-lift sample scene (and optionally run it and render it).

A 5 cm, 100 g box is pinched by two fingertips (8 mm spheres, 1000 N/m) that start
3 mm inside its sides, i.e. already in contact and squeezing with about 3 N each:
there is no table in the core yet, so the grip must hold the box from the first
step. The fingertips are empties animated on the timeline (the scripted device):

    frames  1-13  hold (0.5 s at 24 fps)
    frames 13-37  lift 10 cm (1 s)
    frames 37-61  hold (1 s)

Usage (with the extension enabled, e.g. from the tests or Blender's Python console):

    python sample_scenes/build_pinch_and_lift.py [--save sample_scenes/pinch_and_lift.blend]
        [--run] [--render docs/images/pinch_and_lift.png]

``build(bpy)`` is importable: the tests call it to set up the scene.
"""
from __future__ import annotations

import argparse
import sys

BOX_SIZE = 0.05
BOX_MASS = 0.1
FINGER_RADIUS = 0.008
SQUEEZE = 0.003                 # HIP depth inside the box side at rest
FINGER_X = BOX_SIZE / 2 + FINGER_RADIUS - SQUEEZE
STIFFNESS = 1000.0
FPS = 24
LIFT = 0.10
# (frame, z offset) of the fingertip keyframes, linear interpolation.
KEYS = ((1, 0.0), (13, 0.0), (37, LIFT), (61, LIFT))


def hip_positions(t):
    """Analytic HIPs at time t (s) from frame 1: (2, 3) array. Used by the tests."""
    import numpy as np
    frame = 1 + t * FPS
    fr = np.array([k[0] for k in KEYS], dtype=float)
    zs = np.array([k[1] for k in KEYS], dtype=float)
    z = float(np.interp(frame, fr, zs))
    return np.array([[-FINGER_X, 0.0, z], [FINGER_X, 0.0, z]])


def build(bpy):
    """Create the scene in the current file (expects an empty or default scene)."""
    scene = bpy.context.scene
    scene.render.fps = FPS
    scene.render.fps_base = 1.0
    scene.frame_start = KEYS[0][0]
    scene.frame_end = KEYS[-1][0]
    scene.frame_set(scene.frame_start)
    scene.unit_settings.system = "METRIC"
    s = scene.grasp_lab
    s.gravity = (0.0, 0.0, -9.81)
    s.haptic_rate = 1000.0
    s.duration = 0.0

    me = bpy.data.meshes.new("Box")
    h = BOX_SIZE / 2
    verts = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    me.from_pydata(verts, [], faces)
    me.update()
    box = bpy.data.objects.new("Box", me)
    scene.collection.objects.link(box)
    gl = box.grasp_lab
    gl.role = "DYNAMIC"
    gl.mass_mode = "MASS"
    gl.mass = BOX_MASS
    gl.mu_s, gl.mu_d = 0.8, 0.6

    for i, sign in enumerate((-1.0, 1.0)):
        f = bpy.data.objects.new(f"Finger {i}", None)
        f.empty_display_type = "SPHERE"
        f.empty_display_size = FINGER_RADIUS
        scene.collection.objects.link(f)
        fg = f.grasp_lab
        fg.role = "FINGER"
        fg.radius = FINGER_RADIUS
        fg.stiffness = STIFFNESS
        fg.channel = i
        for frame, z in KEYS:
            f.location = (sign * FINGER_X, 0.0, z)
            f.keyframe_insert("location", frame=frame)
        _set_linear(bpy, f)
    scene.frame_set(scene.frame_start)
    return box


def _set_linear(bpy, obj):
    ad = obj.animation_data
    action = ad.action
    if bpy.app.version >= (4, 4, 0):
        from bpy_extras import anim_utils
        fcurves = anim_utils.action_get_channelbag_for_slot(action, ad.action_slot).fcurves
    else:
        fcurves = action.fcurves
    for fc in fcurves:
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"
        fc.update()


def add_camera_and_light(bpy):
    import math
    scene = bpy.context.scene
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.lens = 50
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = (0.30, -0.42, 0.26)
    target = bpy.data.objects.new("Camera Target", None)
    target.location = (0.0, 0.0, 0.075)
    scene.collection.objects.link(target)
    track = cam.constraints.new("TRACK_TO")
    track.target = target
    scene.camera = cam
    # A ground plane for context only (role None: the core has no body-body contacts yet).
    ground = bpy.data.meshes.new("Ground")
    g = 0.15
    ground.from_pydata([(-g, -g, -0.08), (g, -g, -0.08), (g, g, -0.08), (-g, g, -0.08)], [],
                       [(0, 1, 2, 3)])
    scene.collection.objects.link(bpy.data.objects.new("Ground", ground))
    light = bpy.data.objects.new("Light", bpy.data.lights.new("Light", "SUN"))
    light.rotation_euler = (math.radians(40), math.radians(10), math.radians(30))
    scene.collection.objects.link(light)
    # Make the fingertips visible in renders: small spheres parented to the empties.
    for i in range(2):
        f = bpy.data.objects[f"Finger {i}"]
        me = bpy.data.meshes.new(f"Fingertip {i}")
        import bmesh
        bm = bmesh.new()
        bmesh.ops.create_uvsphere(bm, u_segments=24, v_segments=12, radius=FINGER_RADIUS)
        bm.to_mesh(me)
        bm.free()
        tip = bpy.data.objects.new(f"Fingertip {i}", me)
        tip.parent = f
        scene.collection.objects.link(tip)


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--save", help="write the .blend here")
    ap.add_argument("--run", action="store_true", help="run a headless session after building")
    ap.add_argument("--render", help="run, then render the final frame (Workbench) to this PNG")
    ap.add_argument("--duration", type=float, default=0.0,
                    help="session length for --run/--render, s (0: the whole animation)")
    ap.add_argument("--force-scale", type=float, default=0.02, help="force arrow length, m/N")
    ap.add_argument("--zip", help="install the extension from this built zip (default: "
                                  "$GRASP_LAB_ZIP, else a development repository of addon/)")
    args = ap.parse_args(argv)
    import os
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                    "tests", "blender"))
    import grasp_env                 # isolates Blender's user resources, then loads the add-on
    grasp_env.isolate()
    import bpy
    grasp_env.enable(args.zip)
    bpy.ops.wm.read_homefile(use_empty=True)
    build(bpy)
    if args.render:
        add_camera_and_light(bpy)
    if args.save:
        import os
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.save))
    if args.run or args.render:
        bpy.context.scene.grasp_lab.force_scale = args.force_scale
        bpy.ops.grasp_lab.session(duration=args.duration)
    if args.render:
        import os
        scene = bpy.context.scene
        scene.render.engine = "BLENDER_WORKBENCH"
        scene.display.shading.light = "STUDIO"
        scene.display.shading.color_type = "MATERIAL"
        scene.render.resolution_x, scene.render.resolution_y = 960, 600
        scene.render.resolution_percentage = 100
        scene.render.filepath = os.path.abspath(args.render)
        bpy.ops.render.render(write_still=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
