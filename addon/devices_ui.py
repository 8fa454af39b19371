"""Devices in Blender (docs/devices.md): discovery, the scene's device list (port, fingers,
workspace frame), connect/disconnect and forces on/off during a live session, and live
status per device. The logic is ``engine.devices`` (bpy-free); this is its sidebar."""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, CollectionProperty, EnumProperty, IntProperty, PointerProperty, StringProperty

from . import session
from .engine.devices.cli_commands import discover
from .scene_devices import status_lines

_discovered: list = []


def _is_empty(self, obj):
    return obj.type == "EMPTY"


KIND_ITEMS = (
    ("SERIAL", "Grasp Lab Serial", "A device speaking the Grasp Lab serial protocol (1 kHz, forces)"),
    ("UDP", "Grasp Lab UDP", "The same protocol over UDP at HOST:PORT: a bridge program or a device on another machine"),
    ("SPACEMOUSE", "SpaceMouse", "6-DoF rate control of a hand carrying the fingertips; button 1 closes the grip"),
    ("OPENGLOVES", "OpenGloves", "An OpenGloves / LucidGloves glove: five curls in, a brake per finger out"),
)


class GRASPLAB_PG_device(bpy.types.PropertyGroup):
    kind: EnumProperty(name="Kind", items=KIND_ITEMS, default="SERIAL")
    port: StringProperty(name="Port", description="Serial port (a SpaceMouse: its HID path, empty = the first)")
    left_hand: BoolProperty(name="Left Hand", default=False, description="A glove on the left hand (mirrors x)")
    finger_offset: IntProperty(name="First Finger", default=0, min=0, max=63,
                               description="The device drives fingers from this one on (by channel order)")
    num_fingers: IntProperty(name="Fingers", default=2, min=1, max=32,
                             description="How many fingers the device drives")
    frame: PointerProperty(name="Workspace Frame", type=bpy.types.Object, poll=_is_empty,
                           description="An Empty whose transform maps device coordinates (m) into the scene")


def _active_devices():
    active = session.active_session()
    return getattr(active, "devices", None) if active is not None else None


class GRASPLAB_OT_devices_refresh(bpy.types.Operator):
    bl_idname = "grasp_lab.devices_refresh"
    bl_label = "Find Devices"
    bl_description = "List serial ports and SpaceMice"

    def execute(self, context):
        _discovered[:] = discover()
        self.report({"INFO"}, f"{len(_discovered)} ports and HID devices")
        return {"FINISHED"}


class GRASPLAB_OT_device_add(bpy.types.Operator):
    bl_idname = "grasp_lab.device_add"
    bl_label = "Add Device"
    bl_description = "Add a serial device with a workspace frame (an Empty at the 3D cursor)"
    bl_options = {"REGISTER", "UNDO"}
    port: StringProperty(name="Port")
    kind: EnumProperty(name="Kind", items=KIND_ITEMS, default="SERIAL")

    def execute(self, context):
        scene = context.scene
        entries = scene.grasp_lab_devices
        entry = entries.add()
        entry.kind = self.kind
        entry.port = self.port
        entry.finger_offset = sum(e.num_fingers for e in list(entries)[:-1])
        # A glove has five; another device drives the scene's fingers no device has yet.
        n_fingers = sum(1 for o in context.view_layer.objects if o.grasp_lab.role == "FINGER")
        entry.num_fingers = 5 if self.kind == "OPENGLOVES" else min(32, max(1, n_fingers - entry.finger_offset))
        frame = bpy.data.objects.new(f"Device Frame {len(entries)}", None)
        frame.empty_display_type = "ARROWS"
        frame.empty_display_size = 0.05
        frame.location = scene.cursor.location
        scene.collection.objects.link(frame)
        entry.frame = frame
        scene.grasp_lab_device_index = len(entries) - 1
        return {"FINISHED"}


class GRASPLAB_OT_device_remove(bpy.types.Operator):
    bl_idname = "grasp_lab.device_remove"
    bl_label = "Remove Device"
    bl_options = {"REGISTER", "UNDO"}
    index: IntProperty()

    def execute(self, context):
        entries = context.scene.grasp_lab_devices
        if not 0 <= self.index < len(entries):
            self.report({"ERROR"}, f"no device {self.index}")
            return {"CANCELLED"}
        entries.remove(self.index)
        return {"FINISHED"}


class GRASPLAB_OT_device_forces(bpy.types.Operator):
    bl_idname = "grasp_lab.device_forces"
    bl_label = "Device Forces"
    bl_description = "Turn the connected devices' forces on (they ramp in) or off"
    on: BoolProperty(name="On", default=True)

    @classmethod
    def poll(cls, context):
        return _active_devices() is not None

    def execute(self, context):
        _active_devices().enable(self.on)
        return {"FINISHED"}


class GRASPLAB_OT_device_reconnect(bpy.types.Operator):
    bl_idname = "grasp_lab.device_reconnect"
    bl_label = "Reconnect"
    bl_description = "Reopen the ports of devices that hung up"

    @classmethod
    def poll(cls, context):
        return _active_devices() is not None

    def execute(self, context):
        devices = _active_devices()
        for d in devices.devices:
            if d.stats().get("state") in ("hangup", "disconnected"):
                try:
                    d.reconnect()
                except (ConnectionError, ValueError) as ex:
                    self.report({"WARNING"}, str(ex))
        return {"FINISHED"}


class GRASPLAB_PT_devices(bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Grasp"
    bl_label = "Devices"
    bl_parent_id = "GRASPLAB_PT_main"

    def draw(self, context):
        layout = self.layout
        row = layout.row(align=True)
        row.operator("grasp_lab.devices_refresh", icon="FILE_REFRESH")
        # A device by its port (an emulator's pseudo-terminal, a UDP address): typed in its entry.
        row.operator("grasp_lab.device_add", text="Add Device", icon="ADD").port = ""
        for d in _discovered:
            row = layout.row()
            where = d.get("port") or d.get("path")
            row.label(text=f"{d['kind']}: {where} {d.get('description') or ''}")
            if d["kind"] in ("serial", "spacemouse"):
                op = row.operator("grasp_lab.device_add", text="", icon="ADD")
                op.port = where
                op.kind = "SERIAL" if d["kind"] == "serial" else "SPACEMOUSE"
        for i, entry in enumerate(context.scene.grasp_lab_devices):
            box = layout.box()
            row = box.row()
            row.prop(entry, "kind", text="")
            row.prop(entry, "port", text="")
            row.operator("grasp_lab.device_remove", text="", icon="X").index = i
            if entry.kind == "OPENGLOVES":
                box.prop(entry, "left_hand")
            row = box.row(align=True)
            row.prop(entry, "finger_offset")
            row.prop(entry, "num_fingers")
            box.prop(entry, "frame")
        devices = _active_devices()
        if devices is not None:
            col = layout.column()
            for line in status_lines(devices):
                col.label(text=line)
            row = layout.row(align=True)        # two to a row: "Forces On" / "Off" never cut
            row.operator("grasp_lab.device_forces", text="Forces On", icon="PLAY").on = True
            row.operator("grasp_lab.device_forces", text="Forces Off", icon="PAUSE").on = False
            layout.operator("grasp_lab.device_reconnect", icon="LINKED")
        elif len(context.scene.grasp_lab_devices):
            layout.label(text="Devices connect when a live session starts", icon="INFO")


CLASSES = (GRASPLAB_PG_device, GRASPLAB_OT_devices_refresh, GRASPLAB_OT_device_add, GRASPLAB_OT_device_remove,
           GRASPLAB_OT_device_forces, GRASPLAB_OT_device_reconnect, GRASPLAB_PT_devices)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Scene.grasp_lab_devices = CollectionProperty(type=GRASPLAB_PG_device)
    bpy.types.Scene.grasp_lab_device_index = IntProperty(default=0)


def unregister():
    del bpy.types.Scene.grasp_lab_device_index
    del bpy.types.Scene.grasp_lab_devices
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
