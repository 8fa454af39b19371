"""Showing a session: real objects in a "Grasp Lab" collection (they render and can be
keyframed) and, in live sessions, a gpu overlay + HUD in the 3D viewport.

The overlay's shaders are created lazily inside the draw callback (there is no GPU
context headless); draw handlers are only added for live (INVOKE) sessions and are
always removed on stop / unregister.
"""
from __future__ import annotations

import bmesh
import bpy
import numpy as np
from mathutils import Matrix, Vector

from .engine import grasp_display

COLLECTION = "Grasp Lab"
GO_MESH = "GL Sphere"
ARROW_MESH = "GL Arrow"
COLORS = {
    "GL God-object": (0.10, 0.45, 1.00, 1.0),
    "GL Force": (1.00, 0.15, 0.10, 1.0),
    "GL Torque": (0.10, 0.85, 0.25, 1.0),
}
ARROW_WIDTH = 0.004     # m, shaft radius of a drawn arrow
MIN_GO_RADIUS = 0.002   # god-objects of point fingers are still visible
_Z = Vector((0.0, 0.0, 1.0))


# --------------------------------------------------------------------------- data-blocks

def _material(name, color=None):
    mat = bpy.data.materials.get(name)
    if mat is None:
        mat = bpy.data.materials.new(name)
        if bpy.app.version < (5, 0, 0):
            mat.use_nodes = True        # always on (and deprecated) from 5.0
        _set_color(mat, COLORS[name] if color is None else color)
        bsdf = mat.node_tree.nodes.get("Principled BSDF")
        if bsdf is not None and "Emission Strength" in bsdf.inputs:
            bsdf.inputs["Emission Strength"].default_value = 0.5
    return mat


def _set_color(mat, color):
    """The viewport's (solid) colour and the shader's, base and emission."""
    color = tuple(color)
    if tuple(mat.diffuse_color) == color:
        return
    mat.diffuse_color = color
    bsdf = mat.node_tree.nodes.get("Principled BSDF") if mat.node_tree is not None else None
    if bsdf is not None:
        bsdf.inputs["Base Color"].default_value = color
        for key in ("Emission Color", "Emission"):
            if key in bsdf.inputs:
                bsdf.inputs[key].default_value = color
                break


def _sphere_mesh():
    me = bpy.data.meshes.get(GO_MESH)
    if me is None:
        me = bpy.data.meshes.new(GO_MESH)
        bm = bmesh.new()
        bmesh.ops.create_uvsphere(bm, u_segments=16, v_segments=8, radius=1.0)
        bm.to_mesh(me)
        bm.free()
        for p in me.polygons:
            p.use_smooth = True
    return me


def _arrow_mesh():
    """Unit arrow along +Z: shaft radius 1, head radius 2.5, head 20 % of the length."""
    me = bpy.data.meshes.get(ARROW_MESH)
    if me is None:
        me = bpy.data.meshes.new(ARROW_MESH)
        bm = bmesh.new()
        bmesh.ops.create_cone(bm, cap_ends=True, segments=12, radius1=1.0, radius2=1.0, depth=0.8,
                              matrix=Matrix.Translation((0, 0, 0.4)))
        bmesh.ops.create_cone(bm, cap_ends=True, segments=12, radius1=2.5, radius2=0.0, depth=0.2,
                              matrix=Matrix.Translation((0, 0, 0.9)))
        bm.to_mesh(me)
        bm.free()
    return me


def ensure_collection(scene):
    coll = bpy.data.collections.get(COLLECTION)
    if coll is None:
        coll = bpy.data.collections.new(COLLECTION)
    if scene.collection.children.get(coll.name) is None:
        scene.collection.children.link(coll)
    return coll


def _object(coll, name, mesh):
    obj = bpy.data.objects.get(name)
    if obj is None or obj.type != "MESH":
        obj = bpy.data.objects.new(name, mesh)
    if coll.objects.get(obj.name) is None:
        coll.objects.link(obj)
    obj.hide_select = True
    return obj


class DisplayObjects:
    """God-objects (one sphere per finger) and residual force/torque arrows (per dynamic body)."""

    def __init__(self, scene, desc):
        self.scene = scene
        coll = ensure_collection(scene)
        sphere, arrow = _sphere_mesh(), _arrow_mesh()
        for name in COLORS:
            m = _material(name)
            for me in ((sphere,) if name == "GL God-object" else (arrow,)):
                if not me.materials:
                    me.materials.append(m)
        # A convex finger's (a palm's, a bone's capsule) god-object is its pressure centroid: a small
        # dot, the finger itself being the mesh or the rendered bone (docs/hands.md).
        self.radii = [MIN_GO_RADIUS if f.points is not None else max(f.radius, MIN_GO_RADIUS) for f in desc.fingers]
        self.god_objects = [_object(coll, f"GL God-object {f.name}", sphere)
                            for f in desc.fingers]
        # Each god-object its own material, coloured by its finger's friction use.
        for obj in self.god_objects:
            obj.material_slots[0].link = "OBJECT"
            obj.material_slots[0].material = _material(obj.name, COLORS["GL God-object"])
        self.dynamic = [i for i, b in enumerate(desc.bodies) if not b.static]
        self.force_arrows = [_object(coll, f"GL Force {desc.bodies[i].name}", arrow)
                             for i in self.dynamic]
        self.torque_arrows = [_object(coll, f"GL Torque {desc.bodies[i].name}", arrow)
                              for i in self.dynamic]
        for a in self.torque_arrows:
            a.material_slots[0].link = "OBJECT"
            a.material_slots[0].material = _material("GL Torque")

    @property
    def objects(self):
        return self.god_objects + self.force_arrows + self.torque_arrows

    @staticmethod
    def _arrow_matrix(origin, vec, scale):
        v = Vector(vec)
        length = v.length * scale
        if length < 1e-9:
            m = Matrix.Diagonal((0.0, 0.0, 0.0, 1.0))
            m.translation = origin
            return m
        rot = _Z.rotation_difference(v).to_matrix().to_4x4()
        rot.translation = origin
        return rot @ Matrix.Diagonal((ARROW_WIDTH, ARROW_WIDTH, length, 1.0))

    def update(self, snap, force_scale, torque_scale, colors=None):
        """Place god-objects and arrows; ``colors`` (RGBA per finger) colour the god-objects."""
        for obj, r, go in zip(self.god_objects, self.radii, snap.god_objects):
            m = Matrix.Diagonal((r, r, r, 1.0))
            m.translation = go
            obj.matrix_world = m
        for obj, color in zip(self.god_objects, colors or ()):
            _set_color(obj.material_slots[0].material, color)
        for k, i in enumerate(self.dynamic):
            com = Vector(snap.com[i])
            self.force_arrows[k].matrix_world = self._arrow_matrix(com, snap.force[i], force_scale)
            self.torque_arrows[k].matrix_world = self._arrow_matrix(com, snap.torque[i], torque_scale)


def clear_display_objects():
    """Remove the Grasp Lab collection, its objects and the shared meshes/materials."""
    coll = bpy.data.collections.get(COLLECTION)
    if coll is not None:
        for obj in list(coll.objects):
            bpy.data.objects.remove(obj)
        bpy.data.collections.remove(coll)
    for name in (GO_MESH, ARROW_MESH):
        me = bpy.data.meshes.get(name)
        if me is not None and me.users == 0:
            bpy.data.meshes.remove(me)
    for mat in list(bpy.data.materials):
        if mat.users == 0 and mat.name.startswith(tuple(COLORS)):
            bpy.data.materials.remove(mat)


# --------------------------------------------------------------------------- overlay

_handlers = []          # (space type, handle)
_overlay = {"snap": None, "hud": "", "grasps": (), "show_overlay": True, "show_hud": True, "weakest_scale": 0.5}
_shader = {}


def _draw_view():
    snap = _overlay["snap"]
    if snap is None or not _overlay["show_overlay"] or len(snap.hips) == 0:
        return
    import gpu
    from gpu_extras.batch import batch_for_shader
    sh = _shader.get("uniform")
    if sh is None:
        sh = _shader["uniform"] = gpu.shader.from_builtin("UNIFORM_COLOR")
    fl = _shader.get("flat")
    if fl is None:
        fl = _shader["flat"] = gpu.shader.from_builtin("FLAT_COLOR")
    gpu.state.line_width_set(2.0)
    gpu.state.blend_set("ALPHA")
    # HIP to god-object, and a dot on the god-object, in its friction-use colour.
    grasps = _overlay["grasps"]
    colors = np.array(grasp_display.finger_colors(grasps, len(snap.hips)), dtype=np.float32)
    pts = np.empty((2 * len(snap.hips), 3), dtype=np.float32)
    pts[0::2] = snap.hips
    pts[1::2] = snap.god_objects
    batch_for_shader(fl, "LINES", {"pos": pts, "color": np.repeat(colors, 2, axis=0)}).draw(fl)
    gpu.state.point_size_set(10.0)
    batch_for_shader(fl, "POINTS", {"pos": snap.god_objects.astype(np.float32), "color": colors}).draw(fl)
    _draw_weakest(sh, batch_for_shader, grasps)
    # Forces rendered to the device, from the god-objects (1 N = 2 cm).
    pts = np.empty((2 * len(snap.hips), 3), dtype=np.float32)
    pts[0::2] = snap.god_objects
    pts[1::2] = snap.god_objects + 0.02 * snap.finger_forces
    sh.uniform_float("color", (1.0, 0.2, 0.2, 1.0))
    batch_for_shader(sh, "LINES", {"pos": pts}).draw(sh)
    batch = batch_for_shader(sh, "POINTS", {"pos": snap.hips.astype(np.float32)})
    gpu.state.point_size_set(6.0)
    sh.uniform_float("color", (1.0, 1.0, 1.0, 1.0))
    batch.draw(sh)
    gpu.state.line_width_set(1.0)
    gpu.state.point_size_set(1.0)
    gpu.state.blend_set("NONE")


def weakest_shown(grasp):
    """The weakest wrench as the viewport draws it: around the body (never over it), at the
    session's Weakest Wrench scale (grasp_display.weakest_geometry)."""
    return grasp_display.weakest_geometry(grasp, scale=_overlay["weakest_scale"], outside=True)


def _draw_weakest(sh, batch_for_shader, grasps):
    """Per body in closure: the weakest wrench's force part as an arrow from the centre of
    mass, its torque part as a ring about its axis with a head showing the sense."""
    import gpu
    gpu.state.line_width_set(3.0)
    sh.uniform_float("color", grasp_display.WEAKEST_COLOR)
    for g in grasps:
        geo = weakest_shown(g)
        if geo is None:
            continue
        start, end = geo["arrow"]
        lines = [start, end] + _head(start, end)
        if geo["ring"] is not None:
            ring = geo["ring"]
            lines += [p for a, b in zip(ring[:-1], ring[1:]) for p in (a, b)]
            tip, tangent = geo["ring_tip"]
            lines += _head(tip - 0.3 * np.linalg.norm(ring[0] - geo["arrow"][0]) * tangent, tip)
        batch_for_shader(sh, "LINES", {"pos": np.array(lines, dtype=np.float32)}).draw(sh)
    gpu.state.line_width_set(2.0)


def _head(start, end, size=0.25):
    """Four strokes of an arrowhead at ``end`` (seen from any side)."""
    d = np.asarray(end) - np.asarray(start)
    n = float(np.linalg.norm(d))
    if n < 1e-9:
        return []
    d /= n
    u = np.cross(d, (1.0, 0.0, 0.0) if abs(d[0]) < 0.9 else (0.0, 1.0, 0.0))
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    back = np.asarray(end) - size * n * d
    out = []
    for side in (u, -u, v, -v):
        out += [np.asarray(end), back + 0.4 * size * n * side]
    return out


def _draw_hud():
    text = _overlay["hud"]
    if not text or not _overlay["show_hud"]:
        return
    import blf
    font = 0
    blf.size(font, 14)
    blf.color(font, 1.0, 1.0, 1.0, 0.9)
    y = 60
    for line in reversed(text.split("\n")):
        blf.position(font, 20, y, 0)
        blf.draw(font, line)
        y += 20


def add_overlay(show_overlay=True, show_hud=True, weakest_scale=0.5):
    """Add the viewport draw handlers (live sessions only; never headless)."""
    if bpy.app.background or _handlers:
        return
    _overlay.update(snap=None, hud="", grasps=(), show_overlay=show_overlay, show_hud=show_hud,
                    weakest_scale=weakest_scale)
    st = bpy.types.SpaceView3D
    _handlers.append(st.draw_handler_add(_draw_view, (), "WINDOW", "POST_VIEW"))
    _handlers.append(st.draw_handler_add(_draw_hud, (), "WINDOW", "POST_PIXEL"))


def set_overlay(snap, hud, grasps=()):
    _overlay["snap"] = snap
    _overlay["hud"] = hud
    _overlay["grasps"] = grasps


def remove_overlay():
    st = bpy.types.SpaceView3D
    while _handlers:
        st.draw_handler_remove(_handlers.pop(), "WINDOW")
    _overlay["snap"] = None
    _overlay["hud"] = ""
    _overlay["grasps"] = ()
    _shader.clear()


def overlay_active() -> bool:
    return bool(_handlers)


def tag_redraw(context=None):
    wm = bpy.context.window_manager if context is None else context.window_manager
    for win in wm.windows:
        for area in win.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()
