"""The scene's device list in a session (docs/devices.md): connected to the running world as
an engine DeviceSet when a live session starts, ``--device`` specs added for one session, a
line of status per device (the sidebar and the HUD). The sidebar itself is devices_ui.py."""
from __future__ import annotations

from .engine.devices.live import DeviceSet, assign_specs


def workspace_matrix(entry):
    """The entry's workspace frame as a 4x4 list (identity without an Empty)."""
    if entry.frame is None:
        return None
    return [list(row) for row in entry.frame.matrix_world]


def _add_entry(devices, world, entry):
    frame = workspace_matrix(entry)
    if entry.kind == "SERIAL":
        devices.add(entry.port, entry.finger_offset, entry.num_fingers, frame, label=entry.port)
        return
    if entry.kind == "UDP":
        host, _, port = entry.port.rpartition(":")
        if not port.isdigit():
            raise ValueError(f"{entry.port}: a UDP device needs HOST:PORT")
        devices.add_udp(host.strip("[]"), int(port), entry.finger_offset, entry.num_fingers, frame,
                        label=entry.port)
        return
    first, n = entry.finger_offset, entry.num_fingers
    if first + n > world.finger_count:
        raise ValueError(f"fingers {first}..{first + n - 1}: the scene has {world.finger_count}")
    if entry.kind == "SPACEMOUSE":
        from .engine.devices.spacemouse import SpaceMouseSource, hand_from_fingertips
        hand = hand_from_fingertips(world.snapshot()["hips"][first:first + n], frame)
        source = SpaceMouseSource(hand, path=entry.port.encode() if entry.port else None)
    else:
        from .engine.devices.opengloves import OpenGlovesSource
        if n != 5:
            raise ValueError("a glove drives 5 fingers (thumb to pinky)")
        source = OpenGlovesSource(entry.port, hand_frame=frame, left=entry.left_hand)
    devices.add_source(source, first, entry.port or entry.kind.lower())


def connect_scene_devices(scene, world) -> DeviceSet:
    """Attach every device of the scene's list to a running world; entries that fail to
    open are left out (their error is in ``failed``)."""
    devices = DeviceSet(world)
    devices.failed = {}
    for entry in scene.grasp_lab_devices:
        try:
            _add_entry(devices, world, entry)
        except (ConnectionError, OSError, ImportError, ValueError) as ex:
            devices.failed[entry.port or entry.kind.lower()] = str(ex)
    return devices


def status_lines(devices) -> list:
    """One line a device, for the sidebar and the HUD."""
    lines = []
    for s in devices.status():
        first, n = s["fingers"]
        lines.append(f"{s['label']}: {s['state']}, fingers {first}..{first + n - 1}, {s['rate_hz']:.0f} Hz, "
                     f"dropped {s['dropped']}, p99 {s['latency_p99_us']:.0f} µs, "
                     f"forces {'enabled' if s['enabled'] else 'not enabled'}")
    for port, err in getattr(devices, "failed", {}).items():
        lines.append(f"{port}: not connected ({err})")
    return lines


def add_device_specs(context, specs) -> list:
    """``--device`` specs (``serial:PORT[@FIRST]``, ``spacemouse[:PATH]``, ``opengloves:PORT``)
    appended to the scene's device list; a spec without ``@FIRST`` takes the fingers after
    the list's last device. Returns the entries' indices (``remove_entries`` takes them out)."""
    entries = context.scene.grasp_lab_devices
    n_fingers = sum(1 for o in context.view_layer.objects if o.grasp_lab.role == "FINGER")
    first = max((e.finger_offset + e.num_fingers for e in entries), default=0)
    added = []
    for d in assign_specs(specs, n_fingers, first):      # all read before any is added
        entry = entries.add()
        entry.kind = d["kind"].upper()
        entry.port = d.get("port") or d.get("path") or ""
        entry.finger_offset, entry.num_fingers = d["finger_offset"], d["num_fingers"]
        added.append(len(entries) - 1)
    return added


def remove_entries(context, indices) -> None:
    for i in sorted(indices, reverse=True):
        context.scene.grasp_lab_devices.remove(i)
