"""Several serial devices on one running world (docs/devices.md): the bpy-free half of the
sidebar's device list and of ``grasp-lab run --device``.

Each device drives its own block of fingers through its own workspace frame. While they
are attached the core's serial threads push the HIPs, so the session's input source must
not push as well (``DeviceInput``: not interactive, no script). A device that hangs up is
reopened on its port every ``retry`` seconds; its fingers let go meanwhile (in the core).
Safety events of every device are collected for the recording.
"""
from __future__ import annotations

import time

import numpy as np

from ..inputs import InputSource
from .cli_commands import parse_device_spec
from .serial_device import SerialDevice


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
    fingertips go in through ``push_device_hips`` at every poll, merged with the serial
    devices' fingers; a source with ``send_forces`` (a glove) gets its fingers' device
    forces back, zero until enabled."""

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

    def disconnect(self) -> None:
        if self.connected:
            self.source.close()
        self.connected = False

    def reconnect(self, port=None) -> None:
        self.disconnect()
        self.connect()

    def enable(self, on: bool = True) -> None:
        self.enabled = bool(on)

    def poll(self, forces) -> None:
        if not self.connected:
            return
        hips = np.ascontiguousarray(self.source.hips_at(time.monotonic() - self._t0), dtype=np.float64)
        if not self.world.push_device_hips(self.finger_offset, hips):
            self.rejected += 1
        self.polls += 1
        if hasattr(self.source, "send_forces") and forces is not None:
            self.source.send_forces(forces[self.finger_offset:self.finger_offset + self.num_fingers], self.enabled)

    def stats(self) -> dict:
        state = getattr(self.source, "state", None)
        return {"state": "streaming" if self.connected else "disconnected", "enabled": self.enabled,
                "pose_rate": 0.0, "poses": getattr(state, "lines", getattr(state, "reports", self.polls)),
                "dropped": getattr(state, "rejected", 0) + self.rejected, "latency_p99_us": 0.0,
                "name": self.source.name}

    def events(self) -> list:
        return []


class DeviceSet:
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
        """``--device`` specs (serial:PORT[@FIRST]) in order; a spec without @FIRST takes the
        fingers after the previous device's. ``frames``: optional 4x4 per spec."""
        n_world = self.world.finger_count
        next_first = 0
        for i, spec in enumerate(specs):
            d = parse_device_spec(spec)
            if d["kind"] != "serial":
                raise ValueError(f"--device {spec!r}: only serial devices drive a runtime session from the "
                                 f"command line (SpaceMouse and OpenGloves are input sources)")
            first = d["finger_offset"] if "@" in spec else next_first
            count = fingers_per_device[i] if fingers_per_device else max(1, n_world - first)
            if first + count > n_world:
                raise ValueError(f"--device {spec!r}: fingers {first}..{first + count - 1}, the scene has {n_world}")
            self.add(d["port"], first, count, frames[i] if frames else None, **limits)
            next_first = first + count

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
        sources = [d for d in self.devices if isinstance(d, SourceDevice)]
        if sources:
            forces = self.world.snapshot()["forces"] if any(hasattr(d.source, "send_forces") for d in sources) \
                else None
            for d in sources:
                d.poll(forces)
        for d in self.devices:
            for t, name, value in d.events():
                new.append((t, d.label, name, value))
            state = d.stats().get("state")
            if state in ("hangup", "disconnected") and now - self._last_try.get(id(d), 0.0) >= self.retry:
                self._last_try[id(d)] = now
                try:
                    d.reconnect()
                    new.append((now, d.label, "reconnected", 0))
                except (ConnectionError, ValueError):
                    pass        # still unplugged: its fingers stay let go; try again later
        self.events += new
        return new

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
