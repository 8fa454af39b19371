"""Scene-setup operators: roles, fingers, validation, reset, display cleanup."""
from __future__ import annotations

import bpy
from bpy.props import EnumProperty

from . import convert, display
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


class GRASPLAB_OT_add_finger(bpy.types.Operator):
    """Add a fingertip (a sphere empty with the Finger role) at the 3D cursor"""
    bl_idname = "grasp_lab.add_finger"
    bl_label = "Add Finger"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        prefs = get_prefs(context)
        fingers = [o for o in context.view_layer.objects if o.grasp_lab.role == "FINGER"]
        obj = bpy.data.objects.new(f"Finger {len(fingers)}", None)
        obj.empty_display_type = "SPHERE"
        obj.empty_display_size = prefs.finger_radius
        obj.location = context.scene.cursor.location
        context.collection.objects.link(obj)
        gl = obj.grasp_lab
        gl.role = "FINGER"
        gl.radius = prefs.finger_radius
        gl.stiffness = prefs.finger_stiffness
        gl.channel = max([o.grasp_lab.channel + 1 for o in fingers], default=0)
        for o in context.selected_objects:
            o.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
        return {"FINISHED"}


class GRASPLAB_OT_validate(bpy.types.Operator):
    """Check the grasp scene: meshes closed and outward, sane scale; report masses"""
    bl_idname = "grasp_lab.validate_scene"
    bl_label = "Check Grasp Scene"

    def execute(self, context):
        try:
            desc, _, _ = convert.scene_description(context)
            prepare(desc)
        except SceneError as ex:
            self.report({"ERROR"}, f"Grasp Lab: {ex}")
            return {"CANCELLED"}
        n_dyn = sum(not b.static for b in desc.bodies)
        parts = ", ".join(f"{b.name} {b.mass_properties.mass * 1000:.1f} g"
                          for b in desc.bodies if not b.static)
        self.report({"INFO"}, f"Grasp scene OK: {n_dyn} dynamic, {len(desc.bodies) - n_dyn} static, "
                              f"{len(desc.fingers)} fingers" + (f" ({parts})" if parts else ""))
        return {"FINISHED"}


class GRASPLAB_OT_reset(bpy.types.Operator):
    """Put dynamic bodies back where the last session started them"""
    bl_idname = "grasp_lab.reset"
    bl_label = "Reset Bodies"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from .session import restore_rest_poses
        n = restore_rest_poses(context)
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


CLASSES = (GRASPLAB_OT_set_role, GRASPLAB_OT_add_finger, GRASPLAB_OT_validate,
           GRASPLAB_OT_reset, GRASPLAB_OT_clear_display)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
