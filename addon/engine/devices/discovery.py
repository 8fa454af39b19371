"""Finding Grasp Lab devices: which ports are worth a hello, and the hello itself
(docs/devices.md, Discovery). bpy-free; the sidebar's *Find Devices* and ``grasp-lab
devices`` call ``find_devices``.

A probe says HELLO_HOST on every candidate port at once and waits a bounded time for
HELLO_DEVICE (docs/protocol.md section 3). It never blocks (every descriptor is
non-blocking, the wait is one ``select`` with a deadline), never leaves a port open, and a
port that does not answer sees nothing but the hellos: its terminal settings are put back
as they were, a port another program holds locked (a running session's device) is not
written to at all.

Candidates (``candidate_ports``):

* serial ports with a USB identity (pyserial's list: USB CDC-ACM and USB-serial adapters);
  platform UARTs without one (``/dev/ttyS0 n/a``) are listed but only probed when named;
* on Linux, pseudo-terminals (``/dev/pts/N``) of this user that are **in raw mode** (no
  echo, no line editing) and **nobody's controlling terminal**: what a device emulator or a
  bridge program (``grasp-lab emulate --pty``, ``socat``) opens, never a terminal where a
  shell, an editor or a pager runs (they are a process's controlling terminal, and a shell
  keeps its terminal in line mode).
"""
from __future__ import annotations

import errno
import fcntl
import os
import select
import sys
import termios
import time

from . import protocol as P

PROBE_TIMEOUT = 0.5         # s: a device answers a hello within milliseconds
HELLO_REPEAT = 0.1          # s: the host's rhythm (protocol.md section 3)
BAUD = 1_000_000            # a UART's rate (protocol.md section 4); a pty or USB CDC ignores it


# ---- candidates -----------------------------------------------------------------------------

def _controlling_terminals() -> set:
    """Device numbers of every terminal some process has as its controlling terminal (Linux /proc)."""
    out = set()
    try:
        pids = [p for p in os.listdir("/proc") if p.isdigit()]
    except OSError:
        return out
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat", "rb") as fh:
                stat = fh.read()
        except OSError:         # gone meanwhile, or not ours to read
            continue
        fields = stat[stat.rfind(b")") + 2:].split()     # after "pid (comm) ": state ppid pgrp session tty_nr
        if len(fields) > 4 and int(fields[4]):
            out.add(int(fields[4]))
    return out


def _tty_nr(rdev: int) -> int:
    """A device number as /proc/PID/stat's tty_nr encodes it (minor bits 31..20 and 7..0, major 15..8)."""
    major, minor = os.major(rdev), os.minor(rdev)
    return (minor & 0xFF) | (major << 8) | ((minor & ~0xFF) << 12)


def _is_raw(attrs) -> bool:
    lflag = attrs[3]
    return not lflag & (termios.ICANON | termios.ECHO)


def pty_candidates() -> list:
    """Pseudo-terminals that may be a device: this user's, raw, nobody's controlling terminal."""
    if not sys.platform.startswith("linux") or not os.path.isdir("/dev/pts"):
        return []
    controlling = _controlling_terminals()
    out = []
    for name in sorted((n for n in os.listdir("/dev/pts") if n.isdigit()), key=int):
        path = f"/dev/pts/{name}"
        try:
            st = os.stat(path)
        except OSError:
            continue
        if st.st_uid != os.getuid() or _tty_nr(st.st_rdev) in controlling:
            continue
        try:
            fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:
            continue
        try:
            raw = _is_raw(termios.tcgetattr(fd))
        except termios.error:
            raw = False
        finally:
            os.close(fd)
        if raw:
            out.append(path)
    return out


def serial_ports() -> list:
    """Serial ports pyserial sees: dicts with port, description, hwid, vid, pid."""
    try:
        from serial.tools import list_ports
    except ImportError:
        return []
    return [{"kind": "serial", "port": p.device, "description": p.description, "hwid": p.hwid,
             "vid": p.vid, "pid": p.pid} for p in sorted(list_ports.comports(), key=lambda p: p.device)]


def candidate_ports(listed=None) -> list:
    """Ports worth a hello, in order: USB serial ports of ``listed`` (default ``serial_ports()``),
    then raw pseudo-terminals."""
    listed = serial_ports() if listed is None else listed
    usb = [d["port"] for d in listed if d.get("vid") is not None]
    return usb + [p for p in pty_candidates() if p not in usb]


# ---- the probe ------------------------------------------------------------------------------

class _Probe:
    def __init__(self, port: str, terminals):
        self.port = port
        self.terminals = terminals      # lazily: device numbers of controlling terminals
        self.fd = None
        self.saved = None           # terminal settings to put back (a UART we set to 1 Mbaud raw)
        self.decoder = P.StreamDecoder()
        self.received = 0
        self.result = None
        self.seq = 0

    def open(self) -> None:
        try:
            fd = os.open(self.port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError as e:
            self.result = {"status": "error", "detail": f"cannot open ({e.strerror})"}
            return
        self.fd = fd
        if not os.isatty(fd):
            self.result = {"status": "error", "detail": "not a serial port"}
            return
        if _tty_nr(os.fstat(fd).st_rdev) in self.terminals():
            # A shell's or an editor's terminal (or a serial console), even when named by hand.
            self.result = {"status": "terminal", "detail": "a process's controlling terminal: not probed"}
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as e:
            if e.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
                self.result = {"status": "busy", "detail": "in use by another program (or a running session)"}
                return
            raise
        attrs = termios.tcgetattr(fd)
        if not (os.path.dirname(self.port) == "/dev/pts" and _is_raw(attrs)):
            # A UART (or a pty named by hand): raw 8N1 at 1 Mbaud for the probe, as it was after.
            self.saved = attrs
            raw = list(attrs)
            raw[0] = 0                                          # iflag: no XON/XOFF, no CR mapping
            raw[1] = 0                                          # oflag
            raw[2] = termios.CS8 | termios.CREAD | termios.CLOCAL
            raw[3] = 0                                          # lflag: no echo, no line editing
            speed = getattr(termios, "B1000000", termios.B115200)
            raw[4] = raw[5] = speed
            raw[6] = list(attrs[6])
            raw[6][termios.VMIN], raw[6][termios.VTIME] = 0, 0
            try:
                termios.tcsetattr(fd, termios.TCSANOW, raw)
            except termios.error:
                self.saved = None

    def hello(self) -> None:
        frame = (b"\x00" if self.seq == 0 else b"") + P.encode(P.HELLO_HOST, self.seq, P.hello_host(0))
        self.seq += 1
        try:
            os.write(self.fd, frame)
        except OSError:         # a full output queue (flow control held): that hello is lost
            pass

    def read(self) -> None:
        try:
            data = os.read(self.fd, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as e:    # hung up
            self.result = {"status": "error", "detail": f"read failed ({e.strerror})"}
            return
        self.received += len(data)
        for frame in self.decoder.feed(data):
            if frame.type != P.HELLO_DEVICE:
                continue
            try:
                hello = P.parse_hello_device(frame.payload)
            except P.ProtocolError as e:
                self.result = {"status": "invalid", "detail": f"a hello that breaks the protocol ({e})"}
                return
            self.result = {"status": "grasp_lab", "hello": hello._asdict(),
                           "detail": f"Grasp Lab device '{hello.name}': {hello.n_fingers} fingers"}
            return

    def close(self) -> None:
        if self.fd is None:
            return
        try:
            if os.isatty(self.fd):
                termios.tcflush(self.fd, termios.TCIFLUSH)     # what it sent was for this probe only
                if self.saved is not None:
                    termios.tcsetattr(self.fd, termios.TCSANOW, self.saved)
        except termios.error:
            pass
        finally:
            os.close(self.fd)       # the lock goes with it
            self.fd = None

    def outcome(self, timeout: float) -> dict:
        if self.result is None:
            if self.decoder.frames or self.decoder.dropped or self.received:
                self.result = {"status": "not_grasp_lab",
                               "detail": f"no Grasp Lab hello within {timeout:g} s: {self.received} bytes, "
                                         f"{self.decoder.frames} frames, {self.decoder.dropped} not in the protocol"}
            else:
                self.result = {"status": "silent", "detail": f"no Grasp Lab hello within {timeout:g} s: silent"}
        return dict(self.result, port=self.port)


def probe_ports(ports, timeout: float = PROBE_TIMEOUT) -> list:
    """Say hello on every port at once; per port (in order) a dict: ``port``, ``status``
    (``grasp_lab``, ``silent``, ``not_grasp_lab``, ``invalid``, ``busy``, ``terminal``: some
    process's controlling terminal, never written to; ``error``), ``detail``
    and, for a device, ``hello`` (its capabilities, protocol.HelloDevice as a dict). Returns
    within ``timeout`` (plus the time to open and close the ports)."""
    if not timeout > 0:
        raise ValueError(f"timeout: must be > 0 s, got {timeout}")
    terminals = []

    def controlling():
        if not terminals:
            terminals.append(_controlling_terminals() if sys.platform.startswith("linux") else set())
        return terminals[0]
    probes = [_Probe(p, controlling) for p in dict.fromkeys(ports)]
    try:
        for p in probes:
            p.open()
        waiting = [p for p in probes if p.result is None]
        start = time.monotonic()
        next_hello = start
        while waiting:
            now = time.monotonic()
            if now >= start + timeout:
                break
            if now >= next_hello:
                for p in waiting:
                    p.hello()
                next_hello += HELLO_REPEAT
            wait = max(0.0, min(next_hello, start + timeout) - time.monotonic())
            ready, _, _ = select.select([p.fd for p in waiting], [], [], wait)
            for p in waiting:
                if p.fd in ready:
                    p.read()
            waiting = [p for p in waiting if p.result is None]
    finally:
        for p in probes:
            p.close()
    return [p.outcome(timeout) for p in probes]


def hello_fingers(ports, timeout: float = PROBE_TIMEOUT) -> dict:
    """Finger count per port from the devices' hello (ports that do not answer are left out):
    how many fingers a device added by its port drives."""
    ports = [p for p in ports if p]
    return {r["port"]: r["hello"]["n_fingers"] for r in probe_ports(ports, timeout) if r["status"] == "grasp_lab"} \
        if ports else {}


def find_devices(timeout: float = PROBE_TIMEOUT, extra_ports=()) -> list:
    """Grasp Lab devices on the candidate ports (and ``extra_ports``): dicts with ``port``,
    ``name``, ``n_fingers`` and the rest of the hello, in port order; and every probe's result
    (``probed``) for saying why a port is not listed. Returns (devices, probed)."""
    ports = candidate_ports() + [p for p in extra_ports if p]
    probed = probe_ports(ports, timeout) if ports else []
    devices = [dict(r["hello"], port=r["port"], kind="grasp_lab") for r in probed if r["status"] == "grasp_lab"]
    return devices, probed
