"""Build the pinch-and-lift sample scene (and optionally run it and render it).

A 5 cm, 100 g box rests on a static table (a 40 x 30 x 2 cm slab, top at z = 0).
Two fingertips (8 mm spheres, 1000 N/m, 2 N s/m) start 15 mm clear of its sides,
close until their HIPs are 3 mm inside the faces (about 3 N of squeeze each, well
above the 0.98 N weight with mu_s = 0.8), lift it 10 cm, hold it, carry it 10 cm
sideways, put it back down on the table and let go. The fingertips are empties
animated on the timeline (the scripted device), 24 fps, linear interpolation:

    frames   1- 13  rest: the box settles on the table, fingers open   (0.5 s)
    frames  13- 25  close                                              (0.5 s)
    frames  25- 31  squeeze                                            (0.25 s)
    frames  31- 55  lift 10 cm                                         (1 s)
    frames  55- 61  hold                                               (0.25 s)
    frames  61- 85  carry 10 cm along +y                               (1 s)
    frames  85- 91  hold                                               (0.25 s)
    frames  91-115  put down                                           (1 s)
    frames 115-121  hold on the table                                  (0.25 s)
    frames 121-133  release                                            (0.5 s)
    frames 133-145  rest                                               (0.5 s)

Usage (with the extension enabled, e.g. from the tests or Blender's Python console):

    python sample_scenes/build_pinch_and_lift.py [--save build/pinch_and_lift.blend]
        [--run] [--render docs/images/pinch_and_lift.png [--frame 43]]

``build(bpy)`` is importable: the tests call it to set up the scene, and
``hip_positions(t)`` gives the same fingertip path analytically.
"""
from __future__ import annotations

import argparse
import sys

BOX_SIZE = 0.05
BOX_MASS = 0.1
BOX_MU = (0.8, 0.6)             # mu_s, mu_d of the box
TABLE_SIZE = (0.40, 0.30, 0.02)
TABLE_CENTER = (0.0, 0.05, -0.01)   # top face at z = 0
TABLE_MU = (0.6, 0.5)           # box on table: sqrt(0.8 * 0.6) = 0.69 static
BOX_Z = BOX_SIZE / 2            # box centre when it rests on the table
FINGER_RADIUS = 0.008
STIFFNESS = 1000.0
DAMPING = 2.0
SQUEEZE = 0.003                 # HIP depth inside the box side when closed
CLEARANCE = 0.015               # gap between the open fingertips and the box
CLOSED_X = BOX_SIZE / 2 + FINGER_RADIUS - SQUEEZE
OPEN_X = BOX_SIZE / 2 + FINGER_RADIUS + CLEARANCE
FPS = 24
LIFT = 0.10
CARRY = 0.10                    # sideways, along +y
# (frame, phase that starts there, half distance between the HIPs, y, z); linear in between.
KEYS = (
    (1, "rest", OPEN_X, 0.0, BOX_Z),
    (13, "close", OPEN_X, 0.0, BOX_Z),
    (25, "squeeze", CLOSED_X, 0.0, BOX_Z),
    (31, "lift", CLOSED_X, 0.0, BOX_Z),
    (55, "hold", CLOSED_X, 0.0, BOX_Z + LIFT),
    (61, "carry", CLOSED_X, 0.0, BOX_Z + LIFT),
    (85, "hold", CLOSED_X, CARRY, BOX_Z + LIFT),
    (91, "put down", CLOSED_X, CARRY, BOX_Z + LIFT),
    (115, "hold", CLOSED_X, CARRY, BOX_Z),
    (121, "release", CLOSED_X, CARRY, BOX_Z),
    (133, "rest", OPEN_X, CARRY, BOX_Z),
    (145, "end", OPEN_X, CARRY, BOX_Z),
)
MID_LIFT_FRAME = 43             # halfway through the lift


def hip_positions(t):
    """Analytic HIPs at time t (s) from frame 1: (2, 3) array. Used by the tests."""
    import numpy as np
    frame = 1 + t * FPS
    fr = [k[0] for k in KEYS]
    x, y, z = (float(np.interp(frame, fr, [k[i] for k in KEYS])) for i in (2, 3, 4))
    return np.array([[-x, y, z], [x, y, z]])


def phase_at(frame):
    """Name of the phase the animation is in at ``frame``."""
    name = KEYS[0][1]
    for f, n, *_ in KEYS:
        if frame >= f:
            name = n
    return name


def build(bpy):
    """Create the scene in the current file (expects an empty or default scene): the library's
    ``pinch_and_lift`` (sample_scenes/library.py builds it from the numbers above).
    Returns the box object."""
    _library().build(bpy, "pinch_and_lift")
    return bpy.data.objects["Box"]


def _library():
    import importlib.util
    import os
    name = "grasp_lab_scene_library"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(
            name, os.path.join(os.path.dirname(os.path.abspath(__file__)), "library.py"))
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod            # before running it: its dataclasses look it up
        spec.loader.exec_module(mod)
    return sys.modules[name]


# --------------------------------------------------------------------------- rendering

def _material(bpy, name, color):
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    mat.diffuse_color = color
    return mat


def add_render_setup(bpy):
    """The docs' camera position (on the library's camera, its target and sun), materials
    (Workbench shows the material colour) and visible fingertip spheres (role None, parented
    to the finger empties: the HIPs)."""
    import bmesh
    scene = bpy.context.scene
    bpy.data.objects["Camera"].location = (0.17, -0.42, 0.16)
    bpy.data.objects["Camera Target"].location = (0.0, 0.035, 0.055)
    bpy.data.objects["Table"].data.materials.append(_material(bpy, "Table", (0.78, 0.66, 0.50, 1.0)))
    bpy.data.objects["Box"].data.materials.append(_material(bpy, "Box", (0.93, 0.90, 0.80, 1.0)))
    tip_mat = _material(bpy, "Fingertip", (0.30, 0.30, 0.33, 1.0))
    for i in range(2):
        me = bpy.data.meshes.new(f"Fingertip {i}")
        bm = bmesh.new()
        bmesh.ops.create_uvsphere(bm, u_segments=24, v_segments=12, radius=FINGER_RADIUS)
        bm.to_mesh(me)
        bm.free()
        for p in me.polygons:
            p.use_smooth = True
        me.materials.append(tip_mat)
        tip = bpy.data.objects.new(f"Fingertip {i}", me)
        tip.parent = bpy.data.objects[f"Finger {i}"]
        scene.collection.objects.link(tip)
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "STUDIO"
    scene.display.shading.studio_light = "studio.sl"        # the default leaves the table dark
    scene.display.shading.color_type = "MATERIAL"
    scene.display.shading.show_shadows = True
    scene.view_settings.view_transform = "Standard"
    if scene.world is None:
        scene.world = bpy.data.worlds.new("World")
    scene.world.color = (0.80, 0.84, 0.90)
    scene.render.resolution_x, scene.render.resolution_y = 960, 600
    scene.render.resolution_percentage = 100


def add_finger_force_arrows(bpy, frames, god_objects, forces, scale, bake=True):
    """Orange arrows from each god-object along the force rendered to the device
    (`finger_forces`: squeeze outward, the weight downward), as the live overlay draws them.
    ``god_objects``/``forces``: (n_frames, n_fingers, 3). Keyframed per frame when ``bake``,
    otherwise set to the last frame. Uses the extension's arrow mesh (after a session)."""
    import numpy as np
    from mathutils import Matrix, Vector
    arrow = bpy.data.meshes.get("GL Arrow")
    if arrow is None:
        raise RuntimeError("no 'GL Arrow' mesh: run a session with Display Objects on first")
    mat = _material(bpy, "Finger Force", (1.0, 0.55, 0.0, 1.0))
    width, z = 0.003, Vector((0.0, 0.0, 1.0))
    scene = bpy.context.scene
    anim = _extension_module("anim") if bake else None
    objs = []
    for j in range(np.shape(forces)[1]):
        obj = bpy.data.objects.new(f"Finger Force {j}", arrow)
        scene.collection.objects.link(obj)
        obj.material_slots[0].link = "OBJECT"
        obj.material_slots[0].material = mat
        objs.append(obj)
        rows = []
        for go, f in zip(np.asarray(god_objects)[:, j], np.asarray(forces)[:, j]):
            v = Vector(f)
            length = v.length * scale
            if length < 1e-9:
                m = Matrix.Diagonal((0.0, 0.0, 0.0, 1.0))
            else:
                m = z.rotation_difference(v).to_matrix().to_4x4() @ Matrix.Diagonal(
                    (width, width, length, 1.0))
            m.translation = go
            obj.matrix_world = m
            if bake:
                rows.append(anim.read_transform(obj))
        if bake:
            anim.bake(obj, frames, np.array(rows))
    return objs


def _extension_module(name):
    import importlib
    import bpy
    for mod in bpy.context.preferences.addons.keys():
        if mod.endswith(".grasp_lab"):
            return importlib.import_module(f"{mod}.{name}")
    raise RuntimeError("the grasp_lab extension is not enabled")


def render(bpy, filepath):
    import os
    scene = bpy.context.scene
    scene.render.filepath = os.path.abspath(filepath)
    bpy.ops.render.render(write_still=True)
    return scene.render.filepath


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--save", help="write the .blend here")
    ap.add_argument("--run", action="store_true", help="run a headless session after building")
    ap.add_argument("--render", help="run to --frame, then render it (Workbench) to this PNG")
    ap.add_argument("--frame", type=int, default=MID_LIFT_FRAME,
                    help=f"last frame of the session for --render (default {MID_LIFT_FRAME}: mid-lift)")
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
        add_render_setup(bpy)
    if args.save:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.save))
    scene = bpy.context.scene
    scene.grasp_lab.force_scale = args.force_scale
    if args.render:
        scene.grasp_lab.record = True
        scene.grasp_lab.recording_folder = grasp_env.isolate()
        bpy.ops.grasp_lab.session(duration=(args.frame - scene.frame_start) / FPS)
        rec = _extension_module("engine.recording").open_recording(scene.grasp_lab.last_recording)
        last = rec.ticks[-1:]
        add_finger_force_arrows(bpy, None, last["god_object"], last["device_force"],
                                args.force_scale, bake=False)
        print(render(bpy, args.render))
    elif args.run:
        bpy.ops.grasp_lab.session()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
