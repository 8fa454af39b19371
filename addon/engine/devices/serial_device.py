"""A Grasp Lab serial device attached to a running world (docs/devices.md).

pyserial opens and configures the port (raw, 8N1, the baud rate; a pseudo-terminal
ignores the rate); the C core's device thread then owns its I/O at the haptic rate. This
class only holds the port open and talks to the core's API: it never reads the port.
``UdpDevice`` is the same over UDP (docs/protocol.md section 7): a socket instead of a port.
"""
from __future__ import annotations

import numpy as np

DEFAULT_BAUD = 1_000_000
# Counters carried over a reconnection (the core's device thread starts its own from zero).
COUNTERS = ("poses", "forces_sent", "heartbeats", "dropped", "sequence_gaps", "disconnects", "estops", "stall_zeroes",
            "write_errors", "push_rejected", "late_poses", "duplicate_poses", "foreign_datagrams")


def workspace_matrix(transform) -> list:
    """A workspace frame (4x4, device metres -> world) as 16 row-major numbers, checked."""
    m = np.eye(4) if transform is None else np.asarray(transform, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError(f"transform: need a finite 4x4 matrix, got shape {m.shape}")
    if not np.allclose(m[3], (0, 0, 0, 1)):
        raise ValueError("transform: the last row must be (0, 0, 0, 1)")
    if abs(np.linalg.det(m[:3, :3])) < 1e-12:
        raise ValueError("transform: singular (a workspace frame must keep three dimensions)")
    return [float(v) for v in m.reshape(-1)]


class SerialDevice:
    """One device on one port, driving world fingers ``finger_offset ..``."""

    def __init__(self, world, port: str, finger_offset: int = 0, num_fingers: int = 1, transform=None,
                 baud: int = DEFAULT_BAUD, label: str | None = None, **limits):
        self.world = world
        self.label = label or port
        self.port = port
        self.finger_offset = int(finger_offset)
        self.num_fingers = int(num_fingers)
        self.transform = workspace_matrix(transform)
        self.baud = int(baud)
        self.limits = limits        # force_ttl, lost_timeout, max_force, ramp_time, max_position, stall_timeout
        self.serial = None
        self.device_id = None
        self.enabled = False
        self._past = {}             # counters of the connections before this one

    def connect(self) -> None:
        import serial
        try:
            self.serial = serial.Serial(self.port, self.baud, timeout=0, write_timeout=0, exclusive=True)
        except (serial.SerialException, OSError) as e:
            raise ConnectionError(f"{self.port}: cannot open the port ({e})") from e
        try:
            # Bytes from before this conversation (poses a device streamed after a Find Devices
            # probe, to nobody) are not this session's: its first pose is a fresh one.
            self.serial.reset_input_buffer()
            self.device_id = self.world.attach_serial(
                self.serial.fileno(), finger_offset=self.finger_offset, num_fingers=self.num_fingers,
                transform=self.transform, **self.limits)
        except Exception:
            self.serial.close()
            self.serial = None
            raise
        if self.enabled:
            self.world.serial_enable(self.device_id, True)

    def _detach(self) -> None:
        if self.device_id is not None:
            self._past = self.stats()           # the totals so far, before the thread's go
            self.world.detach_serial(self.device_id)
            self.device_id = None

    def disconnect(self) -> None:
        self._detach()
        if self.serial is not None:
            self.serial.close()
            self.serial = None

    def reconnect(self, port: str | None = None) -> None:
        """After an unplug (state 'hangup'): reopen the port (or a new one), same fingers. While
        the port is not there (ConnectionError) the device stays attached: its thread keeps
        its fingers let go (their HIPs on their god-objects), which a detached device would not."""
        if port:
            self.port = port
        if self.device_id is not None and self._port_gone():
            raise ConnectionError(f"{self.port}: not there (unplugged)")
        self.disconnect()
        self.connect()

    def _port_gone(self) -> bool:
        import os
        return not os.path.exists(self.port)

    @property
    def connected(self) -> bool:
        return self.device_id is not None

    def enable(self, on: bool = True) -> None:
        """Forces to the device on or off (they ramp in from zero when turned on)."""
        self.enabled = bool(on)
        if self.device_id is not None:
            self.world.serial_enable(self.device_id, self.enabled)

    def estop(self) -> None:
        self.enabled = False
        if self.device_id is not None:
            self.world.serial_estop(self.device_id)

    def stats(self) -> dict:
        """The core's serial_stats, its counters totalled over every connection of this device."""
        if self.device_id is None:
            return dict(self._past, state="disconnected", enabled=False)
        st = self.world.serial_stats(self.device_id)
        for k in COUNTERS:
            st[k] = st.get(k, 0) + self._past.get(k, 0)
        if "frame_errors" in self._past:
            st["frame_errors"] = {k: v + self._past["frame_errors"].get(k, 0) for k, v in st["frame_errors"].items()}
        return st

    def events(self) -> list:
        return [] if self.device_id is None else self.world.serial_events(self.device_id)

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, *exc):
        self.disconnect()


class UdpDevice(SerialDevice):
    """The same frames over UDP, one a datagram: a bridge program over a vendor SDK, or a device
    on another machine, at ``host:port``. The socket is bound to the loopback interface for a
    device on this machine, else to ``bind`` (default: every interface); the core pins the
    session to the address that answers the hello and counts datagrams from any other."""

    def __init__(self, world, host: str, port: int, finger_offset: int = 0, num_fingers: int = 1, transform=None,
                 label: str | None = None, bind: str | None = None, **limits):
        import ipaddress
        import socket
        try:
            self.address = ipaddress.ip_address(socket.gethostbyname(host) if not _is_ip(host) else host)
        except (OSError, ValueError) as e:
            raise ConnectionError(f"udp:{host}:{port}: cannot resolve the host ({e})") from e
        if not 1 <= int(port) <= 65535:
            raise ValueError(f"udp:{host}:{port}: the port must be 1..65535")
        super().__init__(world, f"udp:{host}:{port}", finger_offset, num_fingers, transform,
                         label=label or f"udp:{host}:{port}", **limits)
        self.udp_port = int(port)
        self.bind = bind if bind is not None else ("127.0.0.1" if self.address.is_loopback else "0.0.0.0")
        self.sock = None

    def connect(self) -> None:
        import socket
        self.sock = socket.socket(socket.AF_INET if self.address.version == 4 else socket.AF_INET6, socket.SOCK_DGRAM)
        try:
            self.sock.bind((self.bind if self.address.version == 4 else "::1" if self.address.is_loopback else "::", 0))
            self.sock.setblocking(False)
            self.device_id = self.world.attach_serial(
                self.sock.fileno(), finger_offset=self.finger_offset, num_fingers=self.num_fingers,
                transform=self.transform, udp_host=str(self.address), udp_port=self.udp_port, **self.limits)
        except Exception:
            self.sock.close()
            self.sock = None
            raise
        if self.enabled:
            self.world.serial_enable(self.device_id, True)

    def _port_gone(self) -> bool:
        return False        # a socket of ours: always there

    def disconnect(self) -> None:
        self._detach()
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    @property
    def local_port(self) -> int:
        return self.sock.getsockname()[1] if self.sock is not None else 0


def _is_ip(host: str) -> bool:
    import ipaddress
    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        return False
