"""File > Import > Grasp Lab Recording, and the same in the Grasp tab's Recording panel:
bake a recording (.mcap) into the scene (bake.py); and Open in Rerun there (engine/rerun_view.py,
what ``grasp-lab view`` does)."""
from __future__ import annotations

import os

import bpy
from bpy.props import BoolProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from . import bake, record, ui
from .engine.recording import RecordingError, open_recording


class GRASPLAB_OT_import_recording(bpy.types.Operator, ImportHelper):
    """Bake a Grasp Lab recording into the scene: bodies, fingertips, god-objects and force/torque
    arrows as keyframes; grip force, friction use and finger states as animated properties"""
    bl_idname = "grasp_lab.import_recording"
    bl_label = "Import Grasp Lab Recording"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".mcap"
    filter_glob: StringProperty(default="*.mcap", options={"HIDDEN"})
    every_tick: BoolProperty(name="Every Tick", default=False,
                             description="A key at every haptic tick (subframes) instead of every frame")

    def invoke(self, context, event):
        return _browse_recordings(self, context)

    def execute(self, context):
        try:
            render = context.scene.render
            rec = open_recording(self.filepath, fps=None if self.every_tick else render.fps / render.fps_base,
                                 previous=True)
            for warning in rec.warnings():
                self.report({"WARNING"}, warning)
            report = bake.bake_recording(context, rec, every_tick=self.every_tick)
        except (RecordingError, ValueError, OSError) as ex:
            self.report({"ERROR"}, f"Grasp Lab: {ex}")
            return {"CANCELLED"}
        context.scene.grasp_lab.last_recording = self.filepath
        self.report({"WARNING"} if report.missing else {"INFO"}, f"Grasp Lab: {report.message()}")
        return {"FINISHED"}


def _browse_recordings(op, context):
    """The file browser on the recording just made (or the newest in the recording folder),
    not on the .blend's folder and name."""
    s = context.scene.grasp_lab
    latest = record.latest_recording(s)
    if latest:
        op.filepath = latest
    else:
        folder = record.folder_of(s)
        if os.path.isdir(folder):
            op.filepath = os.path.join(folder, "")
    context.window_manager.fileselect_add(op)
    return {"RUNNING_MODAL"}


class GRASPLAB_OT_open_in_rerun(bpy.types.Operator, ImportHelper):
    """Open a recording in the Rerun viewer: the 3-D grasp, its plots and events (a separate
    program; Blender goes on). Converted once and kept beside the recording; needs rerun-sdk
    in Blender's Python (docs/viewers.md)"""
    bl_idname = "grasp_lab.open_in_rerun"
    bl_label = "Open in Rerun"

    filename_ext = ".mcap"
    filter_glob: StringProperty(default="*.mcap", options={"HIDDEN"})

    def invoke(self, context, event):
        return _browse_recordings(self, context)

    def execute(self, context):
        from .engine.rerun_view import view_recording
        try:
            done = view_recording(self.filepath, warn=lambda line: self.report({"WARNING"}, line))
        except (ImportError, RecordingError, ValueError, OSError) as ex:
            self.report({"ERROR"}, f"Grasp Lab: {ex}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Grasp Lab: {bpy.path.basename(done['rrd'])} "
                              f"({'converted' if done['converted'] else 'cached'}) in the Rerun viewer")
        return {"FINISHED"}


def baked_objects(context) -> list:
    """The objects a bake keyed measures on: god-objects and force arrows (``gl_*`` properties)."""
    return [o for o in context.view_layer.objects
            if o.animation_data is not None and o.animation_data.action is not None
            and any(k.startswith("gl_") for k in o.keys())]


class GRASPLAB_OT_show_curves(bpy.types.Operator):
    """Show the baked measures (grip, load, closure, epsilon, friction use, states: the gl_
    properties) in a Graph Editor: selects the objects that carry them, turns the timeline into
    a Graph Editor if none is open, and frames the curves"""
    bl_idname = "grasp_lab.show_curves"
    bl_label = "Show Curves"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return bool(baked_objects(context))

    def execute(self, context):
        objs = baked_objects(context)
        for o in context.selected_objects:
            o.select_set(False)
        for o in objs:
            # Display objects are made unselectable by a session (a click on a fingertip goes to
            # the finger, not its god-object); the Graph Editor lists selected objects only.
            o.hide_select = False
            o.select_set(True)
        context.view_layer.objects.active = objs[0]
        area = _graph_editor(context)
        if area is not None:
            space = area.spaces.active
            space.dopesheet.show_only_selected = True
            # Each curve scaled to -1..1: grip/load (tens) would flatten epsilon (hundredths)
            # and closure (0 or 1) to a line at zero on one axis.
            space.use_normalization = True
            space.dopesheet.filter_text = "gl_"          # the measures, not the transforms
            region = next(r for r in area.regions if r.type == "WINDOW")
            with context.temp_override(area=area, region=region):
                bpy.ops.graph.view_all()
        self.report({"INFO"}, f"Grasp Lab: the measures of {len(objs)} objects" +
                    (" in the Graph Editor" if area is not None else " selected (open a Graph Editor)"))
        return {"FINISHED"}


def _graph_editor(context):
    """A Graph Editor of the window: one that is open, else the bottom 40 % of the largest 3D
    viewport split off as one (the timeline is too short to read curves in)."""
    window = context.window
    screen = window.screen if window is not None else None
    if screen is None:
        return None
    area = next((a for a in screen.areas if a.type == "GRAPH_EDITOR"), None)
    if area is not None:
        return area
    views = [a for a in screen.areas if a.type == "VIEW_3D"]
    if not views:
        return None
    view = max(views, key=lambda a: a.width * a.height)
    before = set(screen.areas[:])
    with context.temp_override(window=window, screen=screen, area=view):
        bpy.ops.screen.area_split(direction="HORIZONTAL", factor=0.4)
    new = [a for a in screen.areas if a not in before]
    if not new:
        return None
    # The split's new area is the lower one when the factor is below a half.
    area = min([view] + new, key=lambda a: a.y)
    area.type = "GRAPH_EDITOR"
    area.ui_type = "FCURVES"
    area.spaces.active.show_region_ui = False       # the curves the whole width
    return area


class GRASPLAB_OT_open_recording_folder(bpy.types.Operator):
    """Open the folder this scene's sessions record to in the system's file manager (made if
    it does not exist yet)"""
    bl_idname = "grasp_lab.open_recording_folder"
    bl_label = "Open Folder"

    def execute(self, context):
        folder = record.folder_of(context.scene.grasp_lab)
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as ex:
            self.report({"ERROR"}, f"Grasp Lab: cannot make the recording folder {folder}: {ex}")
            return {"CANCELLED"}
        bpy.ops.wm.path_open(filepath=folder)
        return {"FINISHED"}


def _menu(self, context):
    self.layout.operator(GRASPLAB_OT_import_recording.bl_idname, text="Grasp Lab Recording (.mcap)")


def _panel(self, context):
    row = self.layout.row(align=True)
    row.operator(GRASPLAB_OT_import_recording.bl_idname, text="Bake Recording", icon="IMPORT")
    row.operator(GRASPLAB_OT_show_curves.bl_idname, icon="GRAPH")
    self.layout.operator(GRASPLAB_OT_open_in_rerun.bl_idname, icon="VIEW3D")


def register():
    bpy.utils.register_class(GRASPLAB_OT_import_recording)
    bpy.utils.register_class(GRASPLAB_OT_show_curves)
    bpy.utils.register_class(GRASPLAB_OT_open_in_rerun)
    bpy.utils.register_class(GRASPLAB_OT_open_recording_folder)
    bpy.types.TOPBAR_MT_file_import.append(_menu)
    ui.GRASPLAB_PT_recording.append(_panel)


def unregister():
    ui.GRASPLAB_PT_recording.remove(_panel)
    bpy.types.TOPBAR_MT_file_import.remove(_menu)
    bpy.utils.unregister_class(GRASPLAB_OT_open_recording_folder)
    bpy.utils.unregister_class(GRASPLAB_OT_open_in_rerun)
    bpy.utils.unregister_class(GRASPLAB_OT_show_curves)
    bpy.utils.unregister_class(GRASPLAB_OT_import_recording)
