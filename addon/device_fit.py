"""Can this device do this task? in Blender (docs/devices.md): the Devices panel's *Device Fit*: device
profiles chosen for the scene, their workspaces drawn in the viewport at their frames (translucent,
red where the fingertip animation leaves them), the HUD line of who leaves when, and *Fit Devices* on
the last recording. The evaluation is ``engine.fit`` (no bpy), shared with ``grasp-lab fit``."""
from __future__ import annotations

import bpy
import numpy as np
from bpy.props import BoolProperty, CollectionProperty, EnumProperty, PointerProperty, StringProperty

from . import record
from .ui import wrapped_labels
from .convert import sample_fingers, scene_objects
from .engine import fit
from .engine.devices import device_profiles
from .engine.recording import RecordingError, open_recording

# Translucent colours of the end-effectors' volumes, and of a volume the animation leaves.
EFFECTOR_COLORS = ((0.25, 0.55, 1.0, 0.12), (0.2, 0.85, 0.45, 0.12), (0.95, 0.75, 0.2, 0.12),
                   (0.75, 0.4, 0.95, 0.12), (0.3, 0.9, 0.9, 0.12))
LEFT_COLOR = (1.0, 0.1, 0.1, 0.28)
OUTSIDE_POINT = (1.0, 0.1, 0.1, 1.0)
INSIDE_POINT = (1.0, 1.0, 1.0, 0.5)
SUBPANEL_MARGIN = 70        # px: a sub-panel's margins, where its labels wrap (measured on screen)

# The scene's fingertip animation, sampled at every frame by *Check Animation* (sampling moves the
# timeline, which a draw callback must never do): {"scene": name, "task": fit.Task}.
_path: dict = {}
_handlers: list = []
_shader: dict = {}
# Profiles read once (the viewport asks at every redraw); *Check Animation* reads them again. The enum's
# items are kept here too: Blender needs the strings of a dynamic enum kept alive.
_profiles: dict = {}
_items: list = []


def profile(name: str):
    if name not in _profiles:
        _profiles[name] = device_profiles.find(name)
    return _profiles[name]


def _profile_items(self, context):
    if not _items:
        for p in device_profiles.load_all():
            _items.append((p.name, p.name, p.title))
    return _items or [("NONE", "none", "no device profile found")]


def _is_empty(self, obj):
    return obj.type == "EMPTY"


def _redraw(self=None, context=None):
    wm = bpy.context.window_manager
    for win in wm.windows:
        for area in win.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


class GRASPLAB_PG_fit_device(bpy.types.PropertyGroup):
    profile: StringProperty(name="Profile", description="A device profile (grasp-lab fit --list)")
    fingers: StringProperty(name="Fingers", update=_redraw,
                            description="The scene's fingers it takes, comma-separated, one an end-effector in "
                                        "order (empty: the first ones)")
    frame: PointerProperty(name="Workspace Frame", type=bpy.types.Object, poll=_is_empty, update=_redraw,
                           description="An Empty placing the device frame (its location and turn about z); "
                                       "none: the scene origin")
    show: BoolProperty(name="Show", default=True, update=_redraw, description="Draw its workspaces in the viewport")


def entry_fingers(entry) -> list | None:
    return [f.strip() for f in entry.fingers.split(",") if f.strip()] or None


def entry_spec(entry) -> str:
    fingers = entry_fingers(entry)
    return entry.profile + (":" + ",".join(fingers) if fingers else "")


def entry_placement(entry) -> fit.Placement:
    return fit.placement_from_matrix(None if entry.frame is None else [list(r) for r in entry.frame.matrix_world])


def sample_animation(context) -> fit.Task:
    """The fingertips' animated path at every frame of the scene's range, as a task."""
    scene = context.scene
    _, fingers = scene_objects(context)
    if not fingers:
        raise ValueError("the scene has no fingertips (objects with the Finger role)")
    times, pos, _ = sample_fingers(context, fingers, scene.frame_start, scene.frame_end)
    task = fit.task_from_path([f.name for f in fingers], times, pos)
    _path.update(scene=scene.name, task=task)
    return task


def frame_exits(scene) -> list:
    """Per shown entry its exits at its frame (from the sampled animation); entries that cannot be
    evaluated give their error as a line instead."""
    task = _path.get("task") if _path.get("scene") == scene.name else None
    out = []
    if task is None:
        return out
    for entry in scene.grasp_lab_fit_devices:
        if not entry.show:
            continue
        try:
            out.append(fit.exits_at_frame(task, profile(entry.profile), entry_fingers(entry),
                                          entry_placement(entry)))
        except (fit.FitError, device_profiles.ProfileError) as ex:
            out.append(str(ex))
    return out


def hud_lines(scene) -> list:
    task = _path.get("task")
    lines = []
    for ex in frame_exits(scene):
        lines += [ex] if isinstance(ex, str) else fit.exit_lines(ex, task.time)
    return lines


class GRASPLAB_OT_fit_device_add(bpy.types.Operator):
    bl_idname = "grasp_lab.fit_device_add"
    bl_label = "Add Device Profile"
    bl_description = ("Evaluate the scene against this device: its workspaces drawn at a workspace frame (an Empty "
                      "at the 3D cursor), red where the fingertip animation leaves them")
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        scene = context.scene
        name = scene.grasp_lab_fit_choice
        try:
            profile(name)
        except device_profiles.ProfileError as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        entry = scene.grasp_lab_fit_devices.add()
        entry.profile = name
        frame = bpy.data.objects.new(f"Workspace {name}", None)
        frame.empty_display_type = "ARROWS"
        frame.empty_display_size = 0.05
        frame.location = scene.cursor.location
        scene.collection.objects.link(frame)
        entry.frame = frame
        try:
            sample_animation(context)
        except ValueError as ex:
            self.report({"WARNING"}, str(ex))
        _redraw()
        return {"FINISHED"}


class GRASPLAB_OT_fit_device_remove(bpy.types.Operator):
    bl_idname = "grasp_lab.fit_device_remove"
    bl_label = "Remove Device Profile"
    bl_options = {"REGISTER", "UNDO"}
    index: bpy.props.IntProperty()

    def execute(self, context):
        entries = context.scene.grasp_lab_fit_devices
        if not 0 <= self.index < len(entries):
            return {"CANCELLED"}
        entries.remove(self.index)
        _redraw()
        return {"FINISHED"}


class GRASPLAB_OT_fit_check_animation(bpy.types.Operator):
    bl_idname = "grasp_lab.fit_check_animation"
    bl_label = "Check Animation"
    bl_description = "Sample the fingertip animation again (after changing it) for the workspaces drawn"

    def execute(self, context):
        _profiles.clear()
        _items.clear()
        try:
            sample_animation(context)
        except ValueError as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        for line in hud_lines(context.scene):
            self.report({"INFO"}, line)
        _redraw()
        return {"FINISHED"}


def fit_devices(context) -> list:
    """*Fit Devices*: every profile of the scene's list against the last recording; the lines written
    under the button (as ``grasp-lab fit`` prints them)."""
    scene = context.scene
    entries = list(scene.grasp_lab_fit_devices)
    if not entries:
        raise ValueError("no device profile: add one (Add Device Profile)")
    path = record.latest_recording(scene.grasp_lab)
    if not path:
        raise ValueError("no recording yet: run the scene with Record on first")
    rec = open_recording(path)
    if len(rec.ticks) == 0:
        raise ValueError(f"{path}: no tick was recorded")
    _, results = fit.fit_recording(rec, [entry_spec(e) for e in entries], [entry_placement(e) for e in entries])
    return [f"{bpy.path.basename(path)}:"] + fit.report_lines(results)


class GRASPLAB_OT_fit_devices(bpy.types.Operator):
    bl_idname = "grasp_lab.fit_devices"
    bl_label = "Fit Devices"
    bl_description = ("Can these devices render the last recording? Each finger's verdict per device: fits, fits "
                      "once the device frame is placed, or where and why it fails")

    def execute(self, context):
        try:
            lines = fit_devices(context)
        except (ValueError, OSError, RecordingError, device_profiles.ProfileError) as ex:
            self.report({"ERROR"}, f"Fit Devices: {ex}")
            context.scene.grasp_lab_fit_report = f"Fit Devices: {ex}"
            return {"CANCELLED"}
        context.scene.grasp_lab_fit_report = "\n".join(lines)
        self.report({"INFO"}, lines[1] if len(lines) > 1 else lines[0])
        return {"FINISHED"}


class GRASPLAB_PT_device_fit(bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Grasp"
    bl_label = "Device Fit"
    bl_parent_id = "GRASPLAB_PT_devices"

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        row = layout.row(align=True)
        row.prop(scene, "grasp_lab_fit_choice", text="Device")
        row.operator("grasp_lab.fit_device_add", text="", icon="ADD")
        for i, entry in enumerate(scene.grasp_lab_fit_devices):
            box = layout.box()
            row = box.row()
            row.prop(entry, "show", text="")
            row.label(text=entry.profile)
            row.operator("grasp_lab.fit_device_remove", text="", icon="X").index = i
            box.prop(entry, "fingers")
            box.prop(entry, "frame", text="Frame")
        if len(scene.grasp_lab_fit_devices):
            layout.operator("grasp_lab.fit_check_animation", icon="FILE_REFRESH")
            wrapped_labels(layout, context, hud_lines(scene), margin=SUBPANEL_MARGIN)
            layout.operator("grasp_lab.fit_devices", icon="CHECKMARK")
            if scene.grasp_lab_fit_report:
                wrapped_labels(layout, context, scene.grasp_lab_fit_report.split("\n"), margin=SUBPANEL_MARGIN)


# --------------------------------------------------------------------------- the viewport

def _draw_view():
    scene = bpy.context.scene
    exits = [e for e in frame_exits(scene) if not isinstance(e, str)]
    if not exits:
        return
    import gpu
    from gpu_extras.batch import batch_for_shader
    sh = _shader.get("uniform")
    if sh is None:
        sh = _shader["uniform"] = gpu.shader.from_builtin("UNIFORM_COLOR")
    task = _path["task"]
    gpu.state.blend_set("ALPHA")
    gpu.state.depth_mask_set(False)
    for ex in exits:
        for e, ws in enumerate(ex.profile.workspaces[:len(ex.fingers)]):
            tris = fit.workspace_triangles(ws, ex.placement).reshape(-1, 3).astype(np.float32)
            left = ex.first_exit[e] is not None
            sh.uniform_float("color", LEFT_COLOR if left else EFFECTOR_COLORS[e % len(EFFECTOR_COLORS)])
            batch_for_shader(sh, "TRIS", {"pos": tris}).draw(sh)
            path = task.hip[:, task.index(ex.fingers[e])].astype(np.float32)
            outside = ex.outside[:, e]
            gpu.state.point_size_set(6.0)
            for mask, color in ((~outside, INSIDE_POINT), (outside, OUTSIDE_POINT)):
                if mask.any():
                    sh.uniform_float("color", color)
                    batch_for_shader(sh, "POINTS", {"pos": path[mask]}).draw(sh)
    gpu.state.point_size_set(1.0)
    gpu.state.depth_mask_set(True)
    gpu.state.blend_set("NONE")


def _draw_hud():
    lines = hud_lines(bpy.context.scene)
    if not lines:
        return
    import blf
    region = bpy.context.region
    # right of the toolbar, below the viewport's own text (its name, the collection)
    tools = next((r for r in bpy.context.area.regions if r.type == "TOOLS"), None)
    x = (tools.width if tools is not None and tools.width > 1 else 0) + 20
    font = 0
    blf.size(font, 14)
    y = region.height - 140
    for line in lines:
        blf.color(font, 1.0, 0.35, 0.3, 1.0) if "leaves" in line else blf.color(font, 0.8, 1.0, 0.8, 1.0)
        blf.position(font, x, y, 0)
        blf.draw(font, line)
        y -= 20


@bpy.app.handlers.persistent
def _forget_path(*_):
    """Another file: its animation is not the one sampled."""
    _path.clear()


CLASSES = (GRASPLAB_PG_fit_device, GRASPLAB_OT_fit_device_add, GRASPLAB_OT_fit_device_remove,
           GRASPLAB_OT_fit_check_animation, GRASPLAB_OT_fit_devices, GRASPLAB_PT_device_fit)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Scene.grasp_lab_fit_devices = CollectionProperty(type=GRASPLAB_PG_fit_device)
    bpy.types.Scene.grasp_lab_fit_choice = EnumProperty(name="Device", items=_profile_items,
                                                        description="A device profile to evaluate the scene against")
    bpy.types.Scene.grasp_lab_fit_report = StringProperty(name="Fit Devices", default="")
    bpy.app.handlers.load_post.append(_forget_path)
    if not bpy.app.background:          # no gpu headless
        st = bpy.types.SpaceView3D
        _handlers.append(st.draw_handler_add(_draw_view, (), "WINDOW", "POST_VIEW"))
        _handlers.append(st.draw_handler_add(_draw_hud, (), "WINDOW", "POST_PIXEL"))


def unregister():
    if _forget_path in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_forget_path)
    st = bpy.types.SpaceView3D
    while _handlers:
        st.draw_handler_remove(_handlers.pop(), "WINDOW")
    _shader.clear()
    _path.clear()
    _profiles.clear()
    _items.clear()
    del bpy.types.Scene.grasp_lab_fit_report
    del bpy.types.Scene.grasp_lab_fit_choice
    del bpy.types.Scene.grasp_lab_fit_devices
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
