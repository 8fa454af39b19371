"""Several serial devices on one running world (docs/devices.md): the bpy-free half of the
sidebar's device list and of ``grasp-lab run --device``.

Each device drives its own block of fingers through its own workspace frame. While they
are attached the core's serial threads push the HIPs, so the session's input source must
not push as well (``DeviceInput``: not interactive; its script covers only the fingers no
device drives). A device that hangs up is reopened on its port every ``retry`` seconds; its
fingers let go meanwhile (in the core). Safety events of every device are collected for the
recording, stamped on the session clock.
"""
from __future__ import annotations

import time

import numpy as np

from ..inputs import InputSource
from .cli_commands import parse_device_spec
from .serial_device import SerialDevice, UdpDevice


GLOVE_FINGERS = 5       # a glove drives thumb to pinky


def assign_specs(specs, n_fingers: int, taken=(), counts=None, hellos=None) -> list:
    """``--device`` specs, all read (``parse_device_spec``) before any is used, each with the
    fingers it drives: ``finger_offset`` and ``num_fingers``. A device wants ``counts[i]``
    fingers when given, a glove five, a serial device as many as its hello says (``hellos``:
    port -> finger count), else every finger from where it goes on; it goes at its ``@FIRST``,
    else on the first fingers no device drives (``free_fingers``; ``taken``: (first, count) of
    the devices there are). The one place specs become fingers: the scene's device list
    (scene_devices.add_device_specs) and ``DeviceSet.add_specs``. ValueError names the spec
    that has no finger to drive, or fewer than ``counts`` asks for."""
    parsed = [(spec, parse_device_spec(spec)) for spec in specs]
    taken, hellos, out = list(taken), hellos or {}, []
    for i, (spec, d) in enumerate(parsed):
        d = dict(d, spec=spec)
        wanted = int(counts[i]) if counts else GLOVE_FINGERS if d["kind"] == "opengloves" else \
            hellos.get(d.get("port"))
        try:
            first, count = free_fingers(taken, n_fingers, wanted or max(1, n_fingers),
                                        d.get("finger_offset", 0) if "@" in spec else None)
        except ValueError as e:
            raise ValueError(f"--device {spec!r}: {e}") from None
        if (counts or "@" in spec) and wanted and count < wanted:
            # Asked for (counts) or placed by hand (@N): a device that would lose fingers there is
            # refused, not cut to the fingers that are left.
            raise ValueError(f"--device {spec!r}: the device has {wanted} fingers ({first}..{first + wanted - 1}), "
                             f"the scene has {n_fingers} and {count} of them free there")
        d["finger_offset"], d["num_fingers"] = first, count
        taken.append((first, count))
        out.append(d)
    return out


def device_fingers(devices, n_fingers: int, finger_names=None) -> np.ndarray:
    """Which device drives each finger: an (n_fingers,) array of indices into ``devices``
    (-1: none). ``devices``: (label, first finger, finger count) per device. A device with a
    finger the scene does not have, or two devices on one finger, is an error naming them."""
    owner = np.full(int(n_fingers), -1, dtype=np.int64)
    for k, (label, first, count) in enumerate(devices):
        first, count = int(first), int(count)
        if count < 1 or first < 0 or first + count > n_fingers:
            have = f"fingers 0..{n_fingers - 1}" if n_fingers else "no fingers"
            raise ValueError(f"device {label}: drives fingers {first}..{first + count - 1}, but the scene has "
                             f"{have}" + (f" ({', '.join(finger_names)})" if finger_names else ""))
        taken = owner[first:first + count]
        if np.any(taken >= 0):
            other = devices[int(taken[taken >= 0][0])][0]
            raise ValueError(f"device {label}: fingers {first}..{first + count - 1} overlap those of device {other}")
        owner[first:first + count] = k
    return owner


def free_fingers(taken, n_fingers: int, wanted: int, first: int | None = None) -> tuple:
    """Where a new device goes: (first finger, count). ``taken``: (first, count) of the devices
    there are; ``wanted``: the fingers the device has (its hello). The first run of ``wanted``
    free fingers (from ``first`` when given), else the first free finger with as many free
    fingers as follow it (the device drives its first ones). ValueError when none is free."""
    free = np.ones(int(n_fingers), dtype=bool)
    for a, n in taken:
        free[max(0, int(a)):max(0, int(a) + int(n))] = False
    starts = [int(first)] if first is not None else range(int(n_fingers))
    best = None
    for a in starts:
        run = 0
        while a + run < n_fingers and free[a + run] and run < wanted:
            run += 1
        if run == wanted:
            return a, run
        if run and best is None:
            best = (a, run)
    if best is None:
        if first is not None and not 0 <= first < n_fingers:
            raise ValueError(f"finger {first}: the scene has " +
                             (f"fingers 0..{n_fingers - 1}" if n_fingers else "no fingers"))
        raise ValueError(f"finger {first}: another device drives it already" if first is not None else
                         "no free finger: another device drives every finger of the scene" if n_fingers else
                         "the scene has no fingers (give objects the role Finger)")
    return best


def without_fingers(script, driven):
    """A scripted track ``(times, positions, mask[, orientations])`` minus the fingers ``driven``
    (a bool mask): a device drives its fingers whatever their animation says. None when nothing
    is left."""
    if script is None:
        return None
    times, positions, mask, *orientations = script
    n = positions.shape[1]
    keep = (np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool).copy()) & ~np.asarray(driven)
    return (times, positions, keep, *orientations) if keep.any() else None


class DeviceInput(InputSource):
    """The input source of a session whose fingers the serial devices drive: nothing is
    pushed from Python; a scripted track (``script``, as ``TimelineInput.script()``) still
    drives the fingers it covers."""
    name = "devices"
    interactive = False

    def __init__(self, n_fingers, script=None):
        super().__init__(n_fingers)
        self._script = script

    def script(self):
        return self._script

    def hips_at(self, t):
        return np.zeros((self.n_fingers, 3))


class SourceDevice:
    """A device read in Python (SpaceMouse, OpenGloves: tens of Hz) in a DeviceSet. Its
    fingertips go at every poll into its fingers' slots in the core (``push_device_hips``, with
    the fingers' orientations when the source has them: ``live_orientations``), the channel the
    serial device threads write; a source with ``send_forces`` (a glove) gets its
    fingers' forces from the latest haptic tick through the same gate as a serial device's
    (``device_forces``: zero until enabled, ramped in, zero while the haptic loop stalls). What
    it was sent (nothing, for an input-only device) is what the recording holds as its
    fingers' device force (``device_forces_sent``)."""

    def __init__(self, world, source, finger_offset: int, label: str):
        self.world, self.source, self.label, self.port = world, source, label, label
        self.finger_offset, self.num_fingers = int(finger_offset), int(source.n_fingers)
        self.enabled = False
        self.connected = False
        self.polls = 0
        self.rejected = 0
        self._t0 = time.monotonic()

    def connect(self) -> None:
        self.source.open()
        self.connected = True
        self._sent(np.zeros((self.num_fingers, 3)))     # nothing yet (an input-only device: ever)

    def disconnect(self) -> None:
        if self.connected:
            self.source.close()
            self._sent(np.zeros((self.num_fingers, 3)))
        self.connected = False

    def _sent(self, forces) -> None:
        self.world.device_forces_sent(self.finger_offset, np.ascontiguousarray(forces, dtype=np.float64))

    def reconnect(self, port=None) -> None:
        self.disconnect()
        self.connect()

    def enable(self, on: bool = True) -> None:
        self.enabled = bool(on)

    def poll(self) -> None:
        if not self.connected:
            return
        hips = np.ascontiguousarray(self.source.hips_at(time.monotonic() - self._t0), dtype=np.float64)
        turning = getattr(self.source, "live_orientations", None)     # a SpaceMouse hand turning a palm
        turns = turning() if turning else None
        pushed = (self.world.push_device_hips(self.finger_offset, hips) if turns is None else
                  self.world.push_device_hips(self.finger_offset, hips, np.ascontiguousarray(turns, dtype=np.float64)))
        if not pushed:
            self.rejected += 1
        self.polls += 1
        if hasattr(self.source, "send_forces"):
            forces = np.zeros((self.num_fingers, 3))
            self.world.device_forces(self.finger_offset, forces, self.enabled)
            self._sent(self.source.send_forces(forces, self.enabled))

    def stats(self) -> dict:
        state = getattr(self.source, "state", None)
        return {"state": "streaming" if self.connected else "disconnected", "enabled": self.enabled,
                "pose_rate": 0.0, "poses": getattr(state, "lines", getattr(state, "reports", self.polls)),
                "dropped": getattr(state, "rejected", 0) + self.rejected, "latency_p99_us": 0.0,
                "name": self.source.name}

    def events(self) -> list:
        return []


class DeviceSet:
    """``events``: (session time s, device label, event, value), as they were observed."""

    def __init__(self, world, retry: float = 0.5):
        self.world = world
        self.devices: list = []
        self.retry = float(retry)
        self._last_try: dict = {}
        self.events: list = []          # (time, device label, event, value)

    def add(self, port: str, finger_offset: int, num_fingers: int, transform=None, label: str | None = None,
            **limits) -> SerialDevice:
        dev = SerialDevice(self.world, port, finger_offset, num_fingers, transform, label=label, **limits)
        dev.connect()
        self.devices.append(dev)
        return dev

    def add_specs(self, specs, fingers_per_device=None, frames=None, **limits) -> None:
        """``--device`` specs (serial:PORT[@FIRST]) in order. A device drives
        ``fingers_per_device[i]`` fingers, else as many as its hello says (asked here), else
        (no answer) every free finger from there on; from FIRST, else from the first finger no
        device drives (``free_fingers``). ``frames``: optional 4x4 per spec."""
        from .discovery import hello_fingers
        n_world = self.world.finger_count
        for spec in specs:      # all read, and only serial ones, before any port is asked
            if parse_device_spec(spec)["kind"] != "serial":
                raise ValueError(f"--device {spec!r}: only serial devices drive a runtime session from the "
                                 f"command line (SpaceMouse and OpenGloves are input sources)")
        hellos = {} if fingers_per_device else hello_fingers([parse_device_spec(s)["port"] for s in specs])
        taken = [(dev.finger_offset, dev.num_fingers) for dev in self.devices]
        for i, d in enumerate(assign_specs(specs, n_world, taken, counts=fingers_per_device, hellos=hellos)):
            first, count = d["finger_offset"], d["num_fingers"]
            self.add(d["port"], first, count, frames[i] if frames else None, **limits)

    def add_udp(self, host: str, port: int, finger_offset: int, num_fingers: int, transform=None,
                label: str | None = None, **limits) -> UdpDevice:
        """A device (or a bridge program) speaking the protocol over UDP at host:port."""
        dev = UdpDevice(self.world, host, port, finger_offset, num_fingers, transform, label=label, **limits)
        dev.connect()
        self.devices.append(dev)
        return dev

    def add_source(self, source, finger_offset: int, label: str | None = None) -> SourceDevice:
        """A SpaceMouse or glove input source driving fingers finger_offset.. (opened here)."""
        dev = SourceDevice(self.world, source, finger_offset, label or source.name)
        dev.connect()
        self.devices.append(dev)
        return dev

    def enable(self, on: bool = True) -> None:
        for d in self.devices:
            d.enable(on)

    def poll(self) -> list:
        """Feed the Python-read devices; collect safety events; reopen hung-up devices.
        Returns the new events."""
        new = []
        now = time.monotonic()
        for d in self.devices:
            if isinstance(d, SourceDevice):
                d.poll()
        for d in self.devices:
            for _mono, name, value, session_time in d.events():
                new.append((max(0.0, session_time), d.label, name, value))
                if name == "estop":
                    d.enabled = False   # latched until the user turns forces on again (not by a reconnect)
            state = d.stats().get("state")
            if state in ("hangup", "disconnected") and now - self._last_try.get(id(d), 0.0) >= self.retry:
                self._last_try[id(d)] = now
                try:
                    d.reconnect()
                    new.append((self.session_time(), d.label, "reconnected", 0))
                except (ConnectionError, ValueError):
                    pass        # still unplugged: its fingers stay let go; try again later
        self.events += new
        return new

    def session_time(self) -> float:
        """Now on the session clock: the haptic loop's latest tick (a millisecond old at most)."""
        return float(self.world.snapshot()["time"]) if self.world.running else 0.0

    def status(self) -> list:
        """Per device: what the sidebar and HUD show."""
        out = []
        for d in self.devices:
            s = d.stats()
            out.append({"label": d.label, "port": d.port, "fingers": (d.finger_offset, d.num_fingers),
                        "state": s.get("state"), "enabled": s.get("enabled", False),
                        "rate_hz": s.get("pose_rate", 0.0), "dropped": s.get("dropped", 0),
                        "latency_p99_us": s.get("latency_p99_us", 0.0), "name": s.get("name", "")})
        return out

    def close(self) -> None:
        for d in self.devices:
            d.disconnect()
        self.devices = []


ESTOP_REASONS = {0: "the host", 1: "the device's stop button", 2: "a device fault",
                 256: "seen in the device's pose status (its ESTOP frame was lost)"}


def device_event_detail(event: str, value: int) -> str:
    """What a device event's value means (docs/recording-format.md), for the recording."""
    value = int(value)
    if event == "connected":
        return f"capabilities received: the device has {value} fingers"
    if event == "lost":
        return "hang-up (the port closed or failed)" if value == 1 else "silence (no valid pose for lost_timeout)"
    if event == "recovered":
        return "valid poses again"
    if event == "reconnected":
        return "port reopened"
    if event == "enabled":
        return "forces on (ENABLE(1) sent)" if value else "forces off (ENABLE(0) sent)"
    if event == "estop":
        return f"e-stop by {ESTOP_REASONS.get(value, f'the device (reason {value})')}: forces zero until enabled"
    if event == "stall":
        return "forces zeroed: the haptic loop stalled" if value else "haptic loop running again"
    if event == "dropped":
        return f"{value} frames dropped"
    if event == "foreign":
        return f"{value} datagrams from another address ignored"
    return f"value {value}"


def losses(events) -> list:
    """Each time a device was lost, from its events ((time, device, event, value), as in
    ``DeviceSet.events``): (device, time lost, how, time back or None)."""
    out, open_loss = [], {}
    for t, label, name, value in sorted(events, key=lambda e: e[0]):
        if name == "lost" and label not in open_loss:
            open_loss[label] = len(out)
            out.append([label, t, "hang-up" if int(value) == 1 else "silence", None])
        elif name in ("recovered", "connected") and label in open_loss:
            out[open_loss.pop(label)][3] = t
    return [tuple(x) for x in out]


def summary_line(label: str, st: dict) -> str:
    """A device's counters at the end of a session, in one line (``grasp-lab run``)."""
    if "poses" not in st:
        return f"{label}: never connected"
    kinds = ", ".join(f"{k} {v}" for k, v in st.get("frame_errors", {}).items() if v)
    out = (f"{label}: {st.get('poses', 0)} poses, {st.get('forces_sent', 0)} force frames, "
           f"{st.get('dropped', 0)} frames dropped" + (f" ({kinds})" if kinds else "") +
           f", {st.get('sequence_gaps', 0)} missing, {st.get('estops', 0)} e-stops, "
           f"{st.get('disconnects', 0)} losses, {st.get('stall_zeroes', 0)} stalls")
    if st.get("late_poses") or st.get("duplicate_poses") or st.get("foreign_datagrams"):
        out += (f", UDP: {st.get('late_poses', 0)} late, {st.get('duplicate_poses', 0)} duplicated, "
                f"{st.get('foreign_datagrams', 0)} from others")
    return out


def recorded_device_events(events) -> list:
    """A recording's device events (dicts, docs/recording-format.md) as ``losses`` takes them."""
    return [(float(e.get("time", 0.0)), e.get("subject", ""), e["kind"][len("device_"):], int(e.get("value", 0)))
            for e in events if str(e.get("kind", "")).startswith("device_")]


def loss_lines(events) -> list:
    """``losses`` as sentences, for the terminal and ``grasp-lab info``."""
    return [f"{label} lost at {t:.3f} s ({how}), " + (f"back at {back:.3f} s" if back is not None
                                                             else "not back by the end")
            for label, t, how, back in losses(events)]
