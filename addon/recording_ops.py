"""File > Import > Grasp Lab Recording, and the same in the Grasp tab's Recording panel:
bake a recording (.mcap) into the scene (bake.py)."""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from . import bake, ui
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


def _menu(self, context):
    self.layout.operator(GRASPLAB_OT_import_recording.bl_idname, text="Grasp Lab Recording (.mcap)")


def _panel(self, context):
    self.layout.operator(GRASPLAB_OT_import_recording.bl_idname, text="Bake Recording", icon="IMPORT")


def register():
    bpy.utils.register_class(GRASPLAB_OT_import_recording)
    bpy.types.TOPBAR_MT_file_import.append(_menu)
    ui.GRASPLAB_PT_recording.append(_panel)


def unregister():
    ui.GRASPLAB_PT_recording.remove(_panel)
    bpy.types.TOPBAR_MT_file_import.remove(_menu)
    bpy.utils.unregister_class(GRASPLAB_OT_import_recording)
