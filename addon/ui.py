"""The "Grasp" tab in the 3D viewport sidebar."""
from __future__ import annotations

import os

import bpy

from . import ops, record, rest_poses, session
from .engine import grasp_display
from .engine import hands


def _measure(context, icon_first="NONE", margin=56):
    """(width, measure) of a label line in this region: pixels and the interface font where
    there is a window, else characters at about 6.5 px each. ``margin``: the panel's and boxes'
    margins, px (a sub-panel's are wider)."""
    scale = context.preferences.system.ui_scale
    # the panel's and a box's margins and the label's own padding: a 240 px path was cut in a
    # box of a 291 px sidebar (Blender 4.3, measured on screen)
    width = (context.region.width if context.region else 300) - margin * scale
    if icon_first != "NONE":
        width -= 50 * scale             # the icon before the text and its padding (measured on screen)
    measure = None
    if not bpy.app.background:
        import blf
        blf.size(0, context.preferences.ui_styles[0].widget.points * scale)
        measure = lambda text: blf.dimensions(0, text)[0]  # noqa: E731
    if measure is None:
        width, measure = int(width / (6.5 * scale)), len
    return width, measure


def wrapped_labels(layout, context, lines, icon_first="NONE", path=False, margin=56):
    """Labels that wrap at the region's width instead of being cut off mid-word (``path``: one
    file path, broken after its separators; ``margin`` as _measure's)."""
    width, measure = _measure(context, icon_first, margin)
    wrapped = grasp_display.wrap_path(lines[0], width, measure) if path else grasp_display.wrap(lines, width, measure)
    col = layout.column(align=True)
    for k, line in enumerate(wrapped):
        col.label(text=line, icon=icon_first if k == 0 else "NONE")
    return col


def baked_frame_lines(context) -> list:
    """The verdict at the current frame of a bake (engine.grasp_display.baked_verdict_lines),
    [] when the scene has no baked measures."""
    objs = context.view_layer.objects
    bodies = [(o.name[len("GL Force "):], o.get("gl_held", 0.0), o.get("gl_closure", 0.0),
               o.get("gl_grip_load", 0.0)) for o in objs if o.name.startswith("GL Force ") and "gl_held" in o]
    if not bodies:
        return []
    fingers = [(o.name[len("GL God-object "):], o.get("gl_state", 0.0), o.get("gl_friction_use", 0.0))
               for o in sorted(objs, key=lambda o: o.name)
               if o.name.startswith("GL God-object ") and "gl_state" in o]
    return grasp_display.baked_verdict_lines(bodies, fingers)


class _GraspPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Grasp"


class GRASPLAB_PT_main(_GraspPanel, bpy.types.Panel):
    bl_label = "Grasp Lab"

    def draw(self, context):
        layout = self.layout
        row = layout.row(align=True)
        row.operator("grasp_lab.add_finger", icon="EMPTY_AXIS")
        row.operator("grasp_lab.add_hand", icon="VIEW_PAN")
        row.operator("grasp_lab.validate_scene", text="Check", icon="CHECKMARK")
        obj = context.active_object
        if obj is not None and obj.type == "ARMATURE":
            layout.operator("grasp_lab.set_hand_roles", icon="BONE_DATA")
        check = ops.last_check.get(context.scene.name)
        if check is not None:
            ok, text = check
            wrapped_labels(layout.box(), context, [text], icon_first="CHECKMARK" if ok else "ERROR")


class GRASPLAB_PT_object(_GraspPanel, bpy.types.Panel):
    bl_label = "Object"
    bl_parent_id = "GRASPLAB_PT_main"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        obj = context.active_object
        if obj is None:
            layout.label(text="No active object")
            return
        gl = obj.grasp_lab
        layout.prop(gl, "role")
        if gl.role in {"DYNAMIC", "STATIC"}:
            layout.prop(gl, "shape", text="Shape")
            if gl.role == "DYNAMIC":
                layout.prop(gl, "mass_mode")
                layout.prop(gl, "mass" if gl.mass_mode == "MASS" else "density")
            col = layout.column(align=True)
            col.prop(gl, "mu_s", text="Friction Static")
            col.prop(gl, "mu_d", text="Dynamic")
            layout.prop(gl, "viscosity")
        elif gl.role == "FINGER":
            layout.prop(gl, "radius")
            layout.prop(gl, "stiffness")
            layout.prop(gl, "damping")
            layout.prop(gl, "renderer")
            if gl.renderer == "CURSOR":
                layout.prop(gl, "cursor_mass")
            if obj.type != "MESH" or gl.torsion:     # a mesh finger's patch has its own torsion
                row = layout.row()
                row.active = obj.type != "MESH" and gl.renderer == "XFCA"
                row.prop(gl, "torsion")
            layout.prop(gl, "channel", text="Channel")


class GRASPLAB_PT_bone(_GraspPanel, bpy.types.Panel):
    """The active bone of the active armature as a finger (docs/hands.md)."""
    bl_label = "Bone"
    bl_parent_id = "GRASPLAB_PT_main"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "ARMATURE"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        obj = context.active_object
        bone = obj.data.bones.active
        if obj.get(hands.RENDERED_OF_PROPERTY):
            layout.label(text=f"Rendered hand of {obj[hands.RENDERED_OF_PROPERTY]} (output)", icon="INFO")
            return
        if bone is None:
            layout.label(text="No active bone")
            return
        gl = obj.pose.bones[bone.name].grasp_lab
        layout.label(text=bone.name, icon="BONE_DATA")
        layout.prop(gl, "role")
        if gl.role == "FINGER":
            layout.prop(gl, "radius")
            layout.prop(gl, "stiffness")
            layout.prop(gl, "damping")
            layout.prop(gl, "channel", text="Channel")


class GRASPLAB_PT_scene(_GraspPanel, bpy.types.Panel):
    bl_label = "Scene"
    bl_parent_id = "GRASPLAB_PT_main"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        s = context.scene.grasp_lab
        layout.prop(s, "gravity")
        layout.prop(s, "gyroscopic", text="Gyroscopic")
        layout.prop(s, "haptic_rate")
        layout.prop(s, "display_rate")
        layout.prop(s, "input_source")


class GRASPLAB_PT_session(_GraspPanel, bpy.types.Panel):
    bl_label = "Session"
    bl_parent_id = "GRASPLAB_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.grasp_lab
        active = session.active_session()
        falling = ops.support_offer(context) if active is None else []
        if falling:
            # Nothing static to rest on: say so before the session, with the one-click fix.
            box = layout.box()
            names = ", ".join(o.name for o in falling[:3]) + (" ..." if len(falling) > 3 else "")
            wrapped_labels(box, context, [f"Nothing holds {names} up: it falls when the session starts"],
                           icon_first="ERROR")
            box.operator("grasp_lab.add_table", icon="MESH_PLANE")
        # The panel's one primary action, drawn highlighted (depress) and large.
        row = layout.row()
        row.scale_y = 1.5
        if active is None:
            row.operator("grasp_lab.session", text="Start Session", icon="PLAY", depress=True)
        else:
            row.operator("grasp_lab.stop_session", text="Stop Session", icon="PAUSE", depress=True)
            wrapped_labels(layout.box(), context, active.grasp_lines())
        col = layout.column()
        col.use_property_split = True
        col.use_property_decorate = False
        col.prop(s, "duration")
        if s.duration == 0:
            scene = context.scene
            fps = scene.render.fps / scene.render.fps_base
            col.label(text=f"0 s: the animation, frames {scene.frame_start}–{scene.frame_end} "
                           f"({(scene.frame_end - scene.frame_start) / fps:.1f} s)")
        col.prop(s, "loop")
        col.prop(s, "bake")
        col.prop(s, "display_objects")
        sub = col.column(align=True)
        sub.active = s.display_objects
        sub.prop(s, "force_scale", text="Force m/N")
        sub.prop(s, "torque_scale", text="Torque m/N·m")
        # Sound and its volume on one row: the volume greyed while the sound is off.
        row = col.row(heading="Sound", align=True)
        row.prop(s, "sound", text="")
        sub = row.row(align=True)
        sub.active = s.sound
        sub.prop(s, "sound_volume", text="Volume", slider=True)
        if s.sound:
            sub = col.column(align=True)
            sub.prop(s, "sound_pitch_low", text="Pitch Hz at 0 N")
            sub.prop(s, "sound_pitch_high", text="at Full Force")
            sub.prop(s, "sound_force_full", text="Full Force N")
            sub.prop(s, "sound_curve")
        col.prop(s, "weakest_scale", text="Wrench Size")
        col.prop(s, "live_view")
        if s.live_view:                     # its address only when it is on: a shorter panel
            sub = col.column(align=True)
            sub.prop(s, "live_view_viewer")
            if s.live_view_viewer == "RERUN":
                sub.prop(s, "live_view_rerun_port")
            else:
                sub.prop(s, "live_view_port")
                sub.prop(s, "live_view_bind")
        moved = rest_poses.moved_from_rest(context) if active is None else []
        if moved:
            # After a session the bodies hang where it left them: say so, and offer the way back.
            box = layout.box()
            text = (f"{moved[0].name} is where the session left it" if len(moved) == 1 else
                    f"{len(moved)} bodies are where the session left them")
            wrapped_labels(box, context, [text], icon_first="INFO")
            box.operator("grasp_lab.reset", icon="LOOP_BACK", depress=True)
        row = layout.row(align=True)
        if not moved:
            row.operator("grasp_lab.reset", icon="LOOP_BACK")
        row.operator("grasp_lab.clear_display", text="Clear Display", icon="TRASH")
        baked = baked_frame_lines(context) if active is None else []
        if baked:
            # Scrubbing a bake: the grasp in words at this frame.
            wrapped_labels(layout.box(), context, [f"Frame {context.scene.frame_current} (baked):"] + baked,
                           icon_first="KEYFRAME")
        res = session.last_result
        if active is None and res is not None and res.stats and res.scene_name == context.scene.name:
            # The session's summary: the grasp in words when it ended, then its length.
            box = layout.box()
            wrapped_labels(box, context, [f"Last session, {res.stats.get('time', 0):.2f} s:"] + res.verdict,
                           icon_first="INFO")


class GRASPLAB_PT_loop(_GraspPanel, bpy.types.Panel):
    """The loop's telemetry, one level down from the grasp (closed until asked for)."""
    bl_label = "Loop"
    bl_parent_id = "GRASPLAB_PT_session"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return session.active_session() is not None

    def draw(self, context):
        wrapped_labels(self.layout, context, session.active_session().loop_lines(detail=True))


class GRASPLAB_PT_recording(_GraspPanel, bpy.types.Panel):
    bl_label = "Recording"
    bl_parent_id = "GRASPLAB_PT_main"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        s = context.scene.grasp_lab
        layout.prop(s, "record")
        layout.prop(s, "recording_folder", text="Folder")
        # The folder in full, where the files really go (an unsaved file: the per-user one).
        box = layout.box()
        if not bpy.data.filepath and record.folder_of(s) == os.path.normpath(record.user_folder()):
            wrapped_labels(box, context, ["Not saved yet: recording to your Grasp Lab folder"], icon_first="INFO")
        wrapped_labels(box, context, [record.folder_of(s) + os.sep], path=True)
        box.operator("grasp_lab.open_recording_folder", icon="FILE_FOLDER")
        if s.last_recording:
            wrapped_labels(layout, context, [bpy.path.basename(s.last_recording)], icon_first="FILE", path=True)


CLASSES = (GRASPLAB_PT_main, GRASPLAB_PT_object, GRASPLAB_PT_bone, GRASPLAB_PT_scene, GRASPLAB_PT_session,
           GRASPLAB_PT_loop, GRASPLAB_PT_recording)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
