"""Devices in Blender (docs/devices.md): discovery, the scene's device list (port, fingers,
workspace frame), connect/disconnect and forces on/off during a live session, and live
status per device. The logic is ``engine.devices`` (bpy-free); this is its sidebar."""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, CollectionProperty, EnumProperty, IntProperty, PointerProperty, StringProperty

from . import convert, session, ui
from .engine import placement
from .engine.devices.cli_commands import hid_devices
from .engine.devices.discovery import find_devices, hello_fingers
from .engine.devices.live import free_fingers
from .scene_devices import scene_finger_count, status_lines, taken_fingers, waiting_entry

# What Find Devices found: Grasp Lab devices (their hello and port), SpaceMice, and how many
# ports it asked (None: not run yet).
_discovered: dict = {"devices": [], "spacemice": [], "asked": None}


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
    bl_description = ("Say hello on USB serial ports and on raw pseudo-terminals (a device emulator's) and "
                      "list the Grasp Lab devices that answer, and SpaceMice")

    def execute(self, context):
        devices, probed = find_devices()
        _discovered["devices"] = devices
        _discovered["spacemice"] = hid_devices()
        _discovered["asked"] = len(probed)
        self.report({"INFO"}, f"{len(devices)} Grasp Lab device{'s' * (len(devices) != 1)} "
                              f"({len(probed)} port{'s' * (len(probed) != 1)} asked), "
                              f"{len(_discovered['spacemice'])} SpaceMice")
        return {"FINISHED"}


class GRASPLAB_OT_device_add(bpy.types.Operator):
    bl_idname = "grasp_lab.device_add"
    bl_label = "Add Device"
    bl_description = ("Add a device on the fingers no other device drives, with a workspace frame (an Empty) "
                      "at the centre of those fingers (at the 3D cursor when the scene has none yet)")
    bl_options = {"REGISTER", "UNDO"}
    port: StringProperty(name="Port")
    kind: EnumProperty(name="Kind", items=KIND_ITEMS, default="SERIAL")
    fingers: IntProperty(name="Fingers", default=0, min=0, max=32,
                         description="The device's finger count (0: ask a serial device for its hello)")

    def execute(self, context):
        scene = context.scene
        entries = scene.grasp_lab_devices
        wanted = self.fingers or (5 if self.kind == "OPENGLOVES" else None)
        if wanted is None and self.kind == "SERIAL" and self.port:
            wanted = hello_fingers([self.port]).get(self.port)
        declared = waiting_entry(entries, self.kind) if self.port else None
        if declared is not None:
            # The scene declares this device (its fingers, its workspace frame): it gets the port.
            entry = entries[declared]
            entry.port = self.port
            entry.num_fingers = min(entry.num_fingers, wanted or entry.num_fingers)
            scene.grasp_lab_device_index = declared
            self.report({"INFO"}, f"{self.port}: device {declared + 1} of the scene, fingers "
                                  f"{entry.finger_offset}..{entry.finger_offset + entry.num_fingers - 1}")
            return {"FINISHED"}
        n_fingers = scene_finger_count(context)
        try:
            # Without a hello (typed in later, a SpaceMouse): every free finger from the first free one.
            first, count = free_fingers(taken_fingers(entries), n_fingers, wanted or max(1, n_fingers))
        except ValueError as ex:
            # Added all the same (fingers may come later), after the driven ones; a session
            # started before the scene has them says which device has none.
            first = max((a + n for a, n in taken_fingers(entries)), default=0)
            count = wanted or 1
            self.report({"WARNING"}, f"Add Device: {ex}; it drives fingers {first}..{first + count - 1} "
                                     f"once the scene has them")
        entry = entries.add()
        entry.kind = self.kind
        entry.port = self.port
        entry.finger_offset, entry.num_fingers = first, count
        if wanted and count < wanted:
            self.report({"WARNING"}, f"{self.port or self.kind.lower()} has {wanted} fingers; only {count} of the "
                                     f"scene's are free: it drives fingers {first}..{first + count - 1}")
        frame = bpy.data.objects.new(f"Device Frame {len(entries)}", None)
        frame.empty_display_type = "ARROWS"
        frame.empty_display_size = 0.05
        # Among the fingers it drives, not at the 3D cursor: the device's rest pose lies on the
        # scene's fingers (engine.placement.workspace_frame); a SpaceMouse or a glove carries
        # the fingertips from where they are, at scale 1.
        fingers = convert.scene_objects(context)[1][first:first + count]
        origin, scale = placement.workspace_frame([tuple(f.matrix_world.translation) for f in fingers],
                                                  tuple(scene.cursor.location))
        frame.location = origin
        if self.kind in {"SERIAL", "UDP"}:
            frame.scale = (scale, scale, scale)
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
        context.scene.grasp_lab_device_forces = self.on      # its update turns the devices' forces on/off
        return {"FINISHED"}


def _forces_changed(scene, context):
    """Forces On/Off: the setting a session starts with, and during one, the devices' forces now."""
    devices = _active_devices()
    if devices is not None:
        devices.enable(scene.grasp_lab_device_forces)


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
        for d in _discovered["devices"]:
            col = layout.column(align=True)      # two short lines: the sidebar never cuts them
            row = col.row()
            row.label(text=d["name"] or "Grasp Lab device", icon="LINKED")
            op = row.operator("grasp_lab.device_add", text="", icon="ADD")
            op.port, op.kind, op.fingers = d["port"], "SERIAL", d["n_fingers"]
            col.label(text=f"{d['n_fingers']} finger{'s' * (d['n_fingers'] != 1)}, {d['port']}", icon="BLANK1")
        for d in _discovered["spacemice"]:
            row = layout.row()
            row.label(text=f"SpaceMouse: {d.get('description') or d['path']}", icon="ORIENTATION_GIMBAL")
            op = row.operator("grasp_lab.device_add", text="", icon="ADD")
            op.port, op.kind = d["path"], "SPACEMOUSE"
        if _discovered["asked"] is not None and not _discovered["devices"] and not _discovered["spacemice"]:
            layout.label(text=f"No device answered ({_discovered['asked']} ports asked)", icon="INFO")
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
            if not entry.port and entry.kind != "SPACEMOUSE":
                box.label(text="Waiting for a port (Find Devices)", icon="INFO")
        devices = _active_devices()
        if devices is not None or len(context.scene.grasp_lab_devices):
            # Before a session: the forces it starts with; during one: the forces now.
            layout.prop(context.scene, "grasp_lab_device_forces", toggle=True,
                        text="Forces On" if context.scene.grasp_lab_device_forces else "Forces Off",
                        icon="FORCE_FORCE" if context.scene.grasp_lab_device_forces else "PAUSE")
        if devices is not None:
            ui.wrapped_labels(layout, context, status_lines(devices))
            layout.operator("grasp_lab.device_reconnect", icon="LINKED")
        elif len(context.scene.grasp_lab_devices):
            # Two short lines: the sidebar at its default width never cuts them.
            col = layout.column(align=True)
            col.label(text="Devices connect when", icon="INFO")
            col.label(text="a live session starts", icon="BLANK1")


CLASSES = (GRASPLAB_PG_device, GRASPLAB_OT_devices_refresh, GRASPLAB_OT_device_add, GRASPLAB_OT_device_remove,
           GRASPLAB_OT_device_forces, GRASPLAB_OT_device_reconnect, GRASPLAB_PT_devices)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Scene.grasp_lab_devices = CollectionProperty(type=GRASPLAB_PG_device)
    bpy.types.Scene.grasp_lab_device_index = IntProperty(default=0)
    bpy.types.Scene.grasp_lab_device_forces = BoolProperty(
        name="Device Forces", default=False, update=_forces_changed,
        description="Send forces back to the devices (they ramp in): the setting a live session starts "
                    "with; during a session, on or off now")


def unregister():
    del bpy.types.Scene.grasp_lab_device_forces
    del bpy.types.Scene.grasp_lab_device_index
    del bpy.types.Scene.grasp_lab_devices
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
