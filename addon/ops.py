"""Scene-setup operators: roles, fingers, validation, reset, display cleanup."""
from __future__ import annotations

import bpy
from bpy.props import EnumProperty

from . import convert, display, rest_poses
from .engine import placement
from .engine.scene import SceneError, prepare
from .prefs import get_prefs
from .props import ROLE_ITEMS


class GRASPLAB_OT_set_role(bpy.types.Operator):
    """Set the grasp role of the selected objects"""
    bl_idname = "grasp_lab.set_role"
    bl_label = "Set Grasp Role"
    bl_options = {"REGISTER", "UNDO"}

    role: EnumProperty(name="Role", items=ROLE_ITEMS, default="DYNAMIC")

    @classmethod
    def poll(cls, context):
        return bool(context.selected_objects)

    def execute(self, context):
        prefs = get_prefs(context)
        for obj in context.selected_objects:
            gl = obj.grasp_lab
            gl.role = self.role
            if self.role in {"DYNAMIC", "STATIC"}:
                gl.mu_s, gl.mu_d = prefs.mu_s, prefs.mu_d
            elif self.role == "FINGER":
                gl.radius, gl.stiffness = prefs.finger_radius, prefs.finger_stiffness
        self.report({"INFO"}, f"{len(context.selected_objects)} object(s) set to {self.role.title()}")
        return {"FINISHED"}


# The sides of a selected object a new fingertip goes to, in turn: -x, +x, -y, +y, top.
FINGER_SIDES = ((0, -1.0), (0, 1.0), (1, -1.0), (1, 1.0), (2, 1.0))
FINGER_SIZE_FRACTION = 0.05     # a fingertip at least this fraction of the object's size: seen


def finger_placement(corners, n_existing, radius):
    """(location, radius) of a new fingertip beside an object whose world bounding box has
    ``corners``: touching the middle of one side (the n-th of FINGER_SIDES), not inside it,
    and at least FINGER_SIZE_FRACTION of the object's size so that it is seen."""
    lo = [min(c[i] for c in corners) for i in range(3)]
    hi = [max(c[i] for c in corners) for i in range(3)]
    radius = max(radius, FINGER_SIZE_FRACTION * max(h - l for h, l in zip(hi, lo)))
    axis, sign = FINGER_SIDES[n_existing % len(FINGER_SIDES)]
    loc = [(h + l) / 2 for h, l in zip(hi, lo)]
    loc[axis] = (hi if sign > 0 else lo)[axis] + sign * radius
    return loc, radius


def _finger_target(context):
    """The body a new fingertip goes beside: the selected mesh (not a finger); with a fingertip
    selected, the body the last one went beside (Add Finger selects the fingertip it adds, so
    that the next click still goes to the same body, on its opposite side); else None (nothing
    selected: the 3D cursor)."""
    s = context.scene.grasp_lab
    target = context.active_object
    if target is None or not target.select_get():
        return None                 # nothing chosen: the 3D cursor
    if target.type == "MESH" and target.grasp_lab.role != "FINGER":
        return target
    remembered = s.finger_target
    if target.grasp_lab.role == "FINGER" and remembered is not None \
            and remembered.name in context.view_layer.objects and remembered.type == "MESH":
        return remembered
    return None


class GRASPLAB_OT_add_finger(bpy.types.Operator):
    """Add a fingertip (a sphere empty with the Finger role) beside the selected object, touching
    it (again beside that object when the last fingertip added is selected: opposite sides in
    turn), or at the 3D cursor when no object was chosen"""
    bl_idname = "grasp_lab.add_finger"
    bl_label = "Add Finger"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        prefs = get_prefs(context)
        fingers = [o for o in context.view_layer.objects if o.grasp_lab.role == "FINGER"]
        target = _finger_target(context)
        context.scene.grasp_lab.finger_target = target
        radius = prefs.finger_radius
        if target is not None:
            from mathutils import Vector
            corners = [target.matrix_world @ Vector(c) for c in target.bound_box]
            location, radius = finger_placement(corners, len(fingers), radius)
        else:
            location = context.scene.cursor.location
        obj = bpy.data.objects.new(f"Finger {len(fingers)}", None)
        obj.empty_display_type = "SPHERE"
        obj.empty_display_size = radius
        obj.location = location
        context.collection.objects.link(obj)
        gl = obj.grasp_lab
        gl.role = "FINGER"
        gl.radius = radius
        gl.stiffness = prefs.finger_stiffness
        gl.channel = max([o.grasp_lab.channel + 1 for o in fingers], default=0)
        for o in context.selected_objects:
            o.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
        return {"FINISHED"}


def support_offer(context):
    """The dynamic bodies that would fall at Start Session (nothing static in the scene to
    rest on, engine.placement.needs_support), else []."""
    objs = [o for o in context.view_layer.objects if o.type == "MESH" or o.grasp_lab.role == "FINGER"]
    if not placement.needs_support([o.grasp_lab.role for o in objs], context.scene.grasp_lab.gravity):
        return []
    return [o for o in objs if o.grasp_lab.role == "DYNAMIC"]


class GRASPLAB_OT_add_table(bpy.types.Operator):
    """Add a static box (a table) under the dynamic bodies, its top touching their bottom, so that
    they rest on it instead of falling when the session starts"""
    bl_idname = "grasp_lab.add_table"
    bl_label = "Add Table"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from mathutils import Vector
        bodies = [o for o in context.view_layer.objects if o.grasp_lab.role == "DYNAMIC"]
        if not bodies:
            self.report({"ERROR"}, "Grasp Lab: no dynamic body to put a table under")
            return {"CANCELLED"}
        corners = [tuple(o.matrix_world @ Vector(c)) for o in bodies for c in o.bound_box]
        centre, dims = placement.table_under(corners)
        mesh = bpy.data.meshes.new("Table")
        hx, hy, hz = (d / 2 for d in dims)
        verts = [(sx * hx, sy * hy, sz * hz) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
        faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
        mesh.from_pydata(verts, [], faces)
        mesh.update()
        table = bpy.data.objects.new("Table", mesh)
        table.location = centre
        context.collection.objects.link(table)
        table.grasp_lab.role = "STATIC"
        prefs = get_prefs(context)
        table.grasp_lab.mu_s, table.grasp_lab.mu_d = prefs.mu_s, prefs.mu_d
        self.report({"INFO"}, f"Grasp Lab: a table under {', '.join(o.name for o in bodies)}")
        return {"FINISHED"}


# What the last Check found, shown under the Check button (a report popup would cover it):
# scene name -> (ok, text).
last_check = {}


class GRASPLAB_OT_validate(bpy.types.Operator):
    """Check the grasp scene: meshes closed and outward, sane scale; report masses"""
    bl_idname = "grasp_lab.validate_scene"
    bl_label = "Check Grasp Scene"

    def invoke(self, context, event):
        return self._check(context, from_button=True)

    def execute(self, context):
        return self._check(context, from_button=False)

    def _check(self, context, from_button):
        try:
            desc, _, _ = convert.scene_description(context)
            prepare(desc)
        except SceneError as ex:
            last_check[context.scene.name] = (False, str(ex))
            # From the button: the panel shows it under the button, and the status bar; an
            # error report would open a popup over the button. From a script: an error.
            self.report({"WARNING"} if from_button else {"ERROR"}, f"Grasp Lab: {ex}")
            return {"CANCELLED"}
        n_dyn = sum(not b.static for b in desc.bodies)
        parts = ", ".join(f"{b.name} {b.mass_properties.mass * 1000:.1f} g"
                          for b in desc.bodies if not b.static)
        text = (f"Grasp scene OK: {n_dyn} dynamic, {len(desc.bodies) - n_dyn} static, "
                f"{len(desc.fingers)} fingers" + (f" ({parts})" if parts else ""))
        last_check[context.scene.name] = (True, text)
        self.report({"INFO"}, text)
        return {"FINISHED"}


class GRASPLAB_OT_reset(bpy.types.Operator):
    """Put dynamic bodies back where the last session started them"""
    bl_idname = "grasp_lab.reset"
    bl_label = "Reset Bodies"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        n = rest_poses.restore_rest_poses(context)
        self.report({"INFO"}, f"{n} body(ies) reset")
        return {"FINISHED"}


class GRASPLAB_OT_clear_display(bpy.types.Operator):
    """Delete the 'Grasp Lab' collection of god-objects and force/torque arrows"""
    bl_idname = "grasp_lab.clear_display"
    bl_label = "Clear Display Objects"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        display.clear_display_objects()
        return {"FINISHED"}


CLASSES = (GRASPLAB_OT_set_role, GRASPLAB_OT_add_finger, GRASPLAB_OT_add_table, GRASPLAB_OT_validate,
           GRASPLAB_OT_reset, GRASPLAB_OT_clear_display)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
