"""The scene's device list in a session (docs/devices.md): connected to the running world as
an engine DeviceSet when a live session starts, ``--device`` specs added for one session, a
line of status per device (the sidebar and the HUD). The sidebar itself is devices_ui.py."""
from __future__ import annotations

from .engine.devices.discovery import hello_fingers
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
        turns = [world.finger_pose(i)[1] for i in range(first, first + n)]   # a palm turns with the hand
        hand = hand_from_fingertips(world.snapshot()["hips"][first:first + n], frame, orientations=turns)
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
    for entry in entries_in_use(scene):
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


def scene_finger_count(context) -> int:
    return sum(1 for o in context.view_layer.objects if o.grasp_lab.role == "FINGER")


def taken_fingers(entries) -> list:
    """(first, count) of the fingers each entry of the device list drives."""
    return [(e.finger_offset, 5 if e.kind == "OPENGLOVES" else e.num_fingers) for e in entries]


def entries_in_use(scene) -> list:
    """The device list's entries a live session connects: those with a port (a SpaceMouse's
    may be empty: the first one). An entry a scene declares without a port (the library's
    two_people_box: a port is the machine's, not the file's) waits for one; its fingers follow
    their animation meanwhile."""
    return [e for e in scene.grasp_lab_devices if e.port or e.kind == "SPACEMOUSE"]


def waiting_entry(entries, kind: str, first=None, claimed=()):
    """The first entry of ``kind`` waiting for a port (at finger ``first`` when given; not one of
    ``claimed``), or None (a SpaceMouse without a path takes the first one: it never waits)."""
    for i, e in enumerate(entries):
        if e.kind == kind != "SPACEMOUSE" and not e.port and i not in claimed and \
                (first is None or e.finger_offset == first):
            return i
    return None


def add_device_specs(context, specs) -> list:
    """``--device`` specs (``serial:PORT[@FIRST]``, ``udp:HOST:PORT[@FIRST]``, ``spacemouse[:PATH]``,
    ``opengloves:PORT``) into the scene's device list for one session: a spec gives its port to
    the first entry of its kind the scene declares without one (at FIRST, with ``@FIRST``); the
    others are appended on the fingers ``assign_specs`` gives them (a serial device as many as
    its hello says, asked here). A filled entry keeps the scene's fingers (fewer when the hello
    says fewer). Returns what ``remove_entries`` takes to put the list back as it was."""
    from .engine.devices.cli_commands import parse_device_spec
    entries = context.scene.grasp_lab_devices
    parsed = [(spec, parse_device_spec(spec)) for spec in specs]     # all checked before any is added
    hellos = hello_fingers([d["port"] for _, d in parsed if d["kind"] == "serial"])
    declared, appended = {}, []
    for spec, d in parsed:
        port = d.get("port") or d.get("path") or ""
        i = waiting_entry(entries, d["kind"].upper(), d["finger_offset"] if "@" in spec else None,
                          claimed=declared) if port else None
        if i is None:
            appended.append(spec)
        else:
            declared[i] = port
    # Every spec placed before the list changes: a spec with no finger to drive leaves it as it was.
    placed = assign_specs(appended, scene_finger_count(context), taken_fingers(entries), hellos=hellos)
    changed = []
    for i, port in declared.items():
        entry = entries[i]
        changed.append((i, entry.num_fingers))
        entry.port = port
        entry.num_fingers = min(entry.num_fingers, hellos.get(port) or entry.num_fingers)
    for d in placed:
        entry = entries.add()
        entry.kind = d["kind"].upper()
        entry.port = d.get("port") or d.get("path") or ""
        entry.finger_offset, entry.num_fingers = d["finger_offset"], d["num_fingers"]
        changed.append((len(entries) - 1, None))
    return changed


def remove_entries(context, changed) -> None:
    """Undo ``add_device_specs``: appended entries removed, declared entries without a port again
    (with the scene's finger count)."""
    entries = context.scene.grasp_lab_devices
    for i, declared_fingers in sorted(changed, key=lambda c: c[0], reverse=True):
        if declared_fingers is None:
            entries.remove(i)
        else:
            entries[i].port, entries[i].num_fingers = "", declared_fingers
