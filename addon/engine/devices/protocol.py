"""The Grasp Lab serial protocol, version 1 (docs/protocol.md).

A frame on the wire is ``COBS(body) 0x00``; ``body`` is a 4-byte header (version, type,
sequence number), a payload whose layout the type fixes, and the CRC-16/CCITT-FALSE of
header and payload. All fields are little-endian. The C core has an identical codec
(native/src/device_codec.c); both are checked against tests/devices/protocol_vectors.txt.
"""
from __future__ import annotations

import binascii
import math
import struct
from typing import NamedTuple

VERSION = 1
HEADER = struct.Struct("<BBH")           # version, type, seq
CRC_SIZE = 2
MAX_FINGERS = 32
POSE_FINGER, ORIENTED_FINGER = 12, 28   # a pose's bytes a finger: x, y, z; then w, x, y, z (CAP_ORIENTATION)
MAX_BODY = HEADER.size + 6 + ORIENTED_FINGER * MAX_FINGERS + CRC_SIZE   # the largest: a pose of 32 with orientations
MAX_WIRE = MAX_BODY + MAX_BODY // 254 + 1                  # its COBS encoding, delimiter excluded
DEVICE_MAX_BODY = HEADER.size + 6 + 12 * MAX_FINGERS + CRC_SIZE     # the largest a device receives: a force of 32
DEVICE_MAX_WIRE = DEVICE_MAX_BODY + DEVICE_MAX_BODY // 254 + 1
QUAT_UNIT_TOL = 1e-3     # | |q|^2 - 1 | of a pose's orientation (the core's GC_DEVICE_QUAT_UNIT_TOL)
NAME_MAX = 32

# Frame types.
HELLO_HOST = 0x01     # host -> device: start streaming
HELLO_DEVICE = 0x02   # device -> host: capabilities
POSE = 0x03           # device -> host: fingertip positions
FORCE = 0x04          # host -> device: fingertip forces with a time to live
ENABLE = 0x05         # host -> device: forces on (1) or off (0)
ESTOP = 0x06          # either way: forces off, latched until ENABLE(1)
HEARTBEAT = 0x07      # either way: liveness when nothing else is sent
TYPE_NAMES = {HELLO_HOST: "hello_host", HELLO_DEVICE: "hello_device", POSE: "pose", FORCE: "force",
              ENABLE: "enable", ESTOP: "estop", HEARTBEAT: "heartbeat"}

# Capability flags (HELLO_DEVICE), units, pose status bits, e-stop reasons.
CAP_FORCES = 0x01
CAP_ORIENTATION = 0x02          # the device can send each finger's orientation after the positions
FORCE_TAKES_ORIENTATION = 0x01  # FORCE byte 5: the host takes them (the device may send them from now on)
UNITS_METRE, UNITS_MILLIMETRE = 0, 1
UNIT_SCALE = {UNITS_METRE: 1.0, UNITS_MILLIMETRE: 1e-3}
STATUS_FORCES_ON, STATUS_ESTOPPED, STATUS_GRIP = 0x01, 0x02, 0x04
ESTOP_HOST, ESTOP_BUTTON, ESTOP_FAULT = 0, 1, 2

_HELLO_HOST = struct.Struct("<H")             # requested pose rate, Hz (0: the device's own)
_HELLO_DEVICE = struct.Struct("<BBBBHfH")     # fingers, flags, units, reserved, rate, force max, ttl max ms
_POSE = struct.Struct("<IBB")                 # device time us, fingers, status
_FORCE = struct.Struct("<HHBB")               # ack seq, ttl us, fingers, reserved
_U8 = struct.Struct("<B")
_U32 = struct.Struct("<I")
# Fixed payload sizes; pose and force add 12 bytes a finger, hello_device up to NAME_MAX name bytes.
_FIXED = {HELLO_HOST: _HELLO_HOST.size, HELLO_DEVICE: _HELLO_DEVICE.size, POSE: _POSE.size,
          FORCE: _FORCE.size, ENABLE: 1, ESTOP: 1, HEARTBEAT: 4}


class ProtocolError(ValueError):
    """A frame that is not valid; ``kind`` is the counter it goes to
    (cobs, short, crc, version, type, length, range)."""

    def __init__(self, kind: str, message: str):
        super().__init__(f"{kind}: {message}")
        self.kind = kind


class Frame(NamedTuple):
    type: int
    seq: int
    payload: bytes


class HelloDevice(NamedTuple):
    n_fingers: int
    renders_forces: bool
    units: int
    rate_hz: int
    force_max: float     # N, per finger (norm), enforced by the device
    ttl_max_ms: int      # longest time to live the device accepts
    name: str
    orientations: bool = False   # it can send the fingers' orientations (CAP_ORIENTATION)


class Pose(NamedTuple):
    time_us: int
    status: int
    positions: tuple     # n (x, y, z) in device units
    orientations: tuple | None = None    # n (w, x, y, z) unit quaternions, device axes; None: positions only


class Force(NamedTuple):
    ack_seq: int
    ttl_us: int
    forces: tuple        # n (fx, fy, fz), N, device axes
    takes_orientations: bool = False     # the host takes the device's orientations


# ---- CRC-16/CCITT-FALSE and COBS ------------------------------------------------------

def crc16(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE: polynomial 0x1021, initial 0xFFFF, no reflection, no final xor
    (binascii's CRC-CCITT started at 0xFFFF)."""
    return binascii.crc_hqx(data, crc)


def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: the result has no zero byte. A block of 254
    non-zero bytes implies no zero after it, so data ending with one needs no final block."""
    out = bytearray()
    pieces = bytes(data).split(b"\0")
    for i, piece in enumerate(pieces):
        full = False
        while len(piece) >= 254:
            out.append(255)
            out += piece[:254]
            piece = piece[254:]
            full = True
        if full and not piece and i == len(pieces) - 1:
            break
        out.append(len(piece) + 1)
        out += piece
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        code = data[i]
        if code == 0:
            raise ProtocolError("cobs", f"zero byte at {i} inside a frame")
        end = i + code
        if end > n:
            raise ProtocolError("cobs", f"block at {i} of length {code - 1} runs past the end ({n} bytes)")
        block = data[i + 1:end]
        if 0 in block:
            raise ProtocolError("cobs", f"zero byte inside the block at {i}")
        out += block
        i = end
        if code != 255 and i < n:
            out.append(0)
    return bytes(out)


# ---- frames ---------------------------------------------------------------------------

def encode(type_: int, seq: int, payload: bytes = b"") -> bytes:
    """One frame on the wire, delimiter included."""
    body = HEADER.pack(VERSION, type_, seq & 0xFFFF) + payload
    body += struct.pack("<H", crc16(body))
    if len(body) > MAX_BODY:
        raise ProtocolError("length", f"frame of {len(body)} bytes exceeds {MAX_BODY}")
    return cobs_encode(body) + b"\x00"


def _check_length(type_: int, payload: bytes) -> None:
    n = len(payload)
    fixed = _FIXED[type_]
    if type_ == POSE:
        if n < fixed or n - fixed not in (payload[4] * POSE_FINGER, payload[4] * ORIENTED_FINGER):
            raise ProtocolError("length", f"pose payload of {n} bytes does not match its finger count")
    elif type_ == FORCE:
        if n < fixed or (n - fixed) % 12 or payload[4] * 12 != n - fixed:
            raise ProtocolError("length", f"{TYPE_NAMES[type_]} payload of {n} bytes does not match its finger count")
    elif type_ == HELLO_DEVICE:
        if not fixed <= n <= fixed + NAME_MAX:
            raise ProtocolError("length", f"hello_device payload of {n} bytes (expected {fixed}..{fixed + NAME_MAX})")
    elif n != fixed:
        raise ProtocolError("length", f"{TYPE_NAMES[type_]} payload of {n} bytes (expected {fixed})")


def decode(wire: bytes) -> Frame:
    """One frame from its COBS encoding (delimiter excluded); ProtocolError when invalid."""
    if len(wire) > MAX_WIRE:
        raise ProtocolError("length", f"{len(wire)} encoded bytes exceed {MAX_WIRE}")
    body = cobs_decode(wire)
    if len(body) < HEADER.size + CRC_SIZE:
        raise ProtocolError("short", f"{len(body)} bytes, a frame has at least {HEADER.size + CRC_SIZE}")
    (want,) = struct.unpack_from("<H", body, len(body) - CRC_SIZE)
    got = crc16(body[:-CRC_SIZE])
    if got != want:
        raise ProtocolError("crc", f"CRC 0x{got:04X}, frame says 0x{want:04X}")
    version, type_, seq = HEADER.unpack_from(body)
    if version != VERSION:
        raise ProtocolError("version", f"protocol version {version}, this host speaks {VERSION}")
    if type_ not in TYPE_NAMES:
        raise ProtocolError("type", f"unknown frame type 0x{type_:02X}")
    payload = body[HEADER.size:-CRC_SIZE]
    _check_length(type_, payload)
    return Frame(type_, seq, payload)


class StreamDecoder:
    """Frames from a byte stream. Invalid frames are dropped and counted by kind; after
    any error the decoder resynchronises on the next zero byte. Empty frames (a lone
    delimiter) are ignored: a sender may emit 0x00 to flush a half-received frame."""

    KINDS = ("cobs", "short", "crc", "version", "type", "length", "overflow")

    def __init__(self):
        self._buf = bytearray()
        self._overflow = False
        self.frames = 0
        self.errors = dict.fromkeys(self.KINDS, 0)

    @property
    def dropped(self) -> int:
        return sum(self.errors.values())

    def feed(self, data: bytes) -> list:
        out = []
        pieces = bytes(data).split(b"\0")
        for k, piece in enumerate(pieces):
            complete = k < len(pieces) - 1   # a delimiter follows this piece
            if self._overflow:
                self._overflow = not complete
                continue
            self._buf += piece
            if len(self._buf) > MAX_WIRE:
                self.errors["overflow"] += 1
                self._buf.clear()
                self._overflow = not complete
                continue
            if not complete or not self._buf:
                continue
            try:
                out.append(decode(bytes(self._buf)))
                self.frames += 1
            except ProtocolError as e:
                self.errors[e.kind] += 1
            self._buf.clear()
        return out


# ---- payloads -------------------------------------------------------------------------

def _vectors(values, what: str, limit: float) -> bytes:
    out = bytearray()
    for v in values:
        if len(v) != 3:
            raise ProtocolError("length", f"{what}: need (x, y, z) triples, got {v!r}")
        for c in v:
            if not math.isfinite(c) or abs(c) > limit:
                raise ProtocolError("range", f"{what}: {c!r} is not a finite number within +-{limit:g}")
        out += struct.pack("<fff", *v)
    return bytes(out)


def _unpack_vectors(payload: bytes, offset: int, n: int, what: str) -> tuple:
    values = struct.unpack_from(f"<{3 * n}f", payload, offset)
    if not all(math.isfinite(c) for c in values):
        raise ProtocolError("range", f"{what}: NaN or infinite component")
    return tuple(values[3 * i:3 * i + 3] for i in range(n))


def hello_host(rate_hz: int = 0) -> bytes:
    return _HELLO_HOST.pack(rate_hz)


def parse_hello_host(payload: bytes) -> int:
    return _HELLO_HOST.unpack(payload)[0]


def hello_device(n_fingers: int, renders_forces: bool, units: int, rate_hz: int, force_max: float,
                 ttl_max_ms: int, name: str = "", orientations: bool = False) -> bytes:
    if not 1 <= n_fingers <= MAX_FINGERS:
        raise ProtocolError("range", f"n_fingers: {n_fingers} outside 1..{MAX_FINGERS}")
    raw = name.encode("utf-8")
    if len(raw) > NAME_MAX:
        raise ProtocolError("length", f"name: {len(raw)} bytes, at most {NAME_MAX}")
    flags = (CAP_FORCES if renders_forces else 0) | (CAP_ORIENTATION if orientations else 0)
    return _HELLO_DEVICE.pack(n_fingers, flags, units, 0, rate_hz, force_max, ttl_max_ms) + raw


def parse_hello_device(payload: bytes) -> HelloDevice:
    n, flags, units, _, rate, fmax, ttl = _HELLO_DEVICE.unpack_from(payload)
    if not 1 <= n <= MAX_FINGERS:
        raise ProtocolError("range", f"hello_device: {n} fingers outside 1..{MAX_FINGERS}")
    if units not in UNIT_SCALE:
        raise ProtocolError("range", f"hello_device: unknown units code {units}")
    if not (math.isfinite(fmax) and fmax >= 0):
        raise ProtocolError("range", f"hello_device: force limit {fmax!r} is not a finite number >= 0")
    name = payload[_HELLO_DEVICE.size:].decode("utf-8", "replace")
    return HelloDevice(n, bool(flags & CAP_FORCES), units, rate, fmax, ttl, name, bool(flags & CAP_ORIENTATION))


def _quaternions(values, n: int) -> bytes:
    values = [tuple(q) for q in values]
    if len(values) != n:
        raise ProtocolError("length", f"pose: {len(values)} orientations for {n} fingers")
    out = bytearray()
    for q in values:
        if len(q) != 4 or not all(math.isfinite(c) for c in q) or \
                abs(sum(c * c for c in q) - 1.0) > QUAT_UNIT_TOL:
            raise ProtocolError("range", f"pose: orientation {q!r} is not a finite unit quaternion (w, x, y, z)")
        out += struct.pack("<ffff", *q)
    return bytes(out)


def pose(time_us: int, positions, status: int = 0, orientations=None) -> bytes:
    """A POSE payload; ``orientations`` (n unit quaternions w, x, y, z) follow the positions,
    for a device whose hello said CAP_ORIENTATION once the host's FORCE frames take them."""
    positions = [tuple(p) for p in positions]
    if not 1 <= len(positions) <= MAX_FINGERS:
        raise ProtocolError("range", f"pose: {len(positions)} fingers outside 1..{MAX_FINGERS}")
    out = _POSE.pack(time_us & 0xFFFFFFFF, len(positions), status) + _vectors(positions, "pose", 3.4e38)
    return out if orientations is None else out + _quaternions(orientations, len(positions))


def parse_pose(payload: bytes) -> Pose:
    time_us, n, status = _POSE.unpack_from(payload)
    positions = _unpack_vectors(payload, _POSE.size, n, "pose")
    if len(payload) != _POSE.size + ORIENTED_FINGER * n or n == 0:
        return Pose(time_us, status, positions)
    values = struct.unpack_from(f"<{4 * n}f", payload, _POSE.size + POSE_FINGER * n)
    turns = tuple(values[4 * i:4 * i + 4] for i in range(n))
    if not all(math.isfinite(c) for c in values) or \
            any(abs(sum(c * c for c in q) - 1.0) > QUAT_UNIT_TOL for q in turns):
        raise ProtocolError("range", "pose: an orientation is not a finite unit quaternion")
    return Pose(time_us, status, positions, turns)


def force(ack_seq: int, ttl_us: int, forces, takes_orientations: bool = False) -> bytes:
    forces = [tuple(f) for f in forces]
    if not 1 <= len(forces) <= MAX_FINGERS:
        raise ProtocolError("range", f"force: {len(forces)} fingers outside 1..{MAX_FINGERS}")
    flags = FORCE_TAKES_ORIENTATION if takes_orientations else 0
    return _FORCE.pack(ack_seq & 0xFFFF, ttl_us, len(forces), flags) + _vectors(forces, "force", 3.4e38)


def parse_force(payload: bytes) -> Force:
    ack, ttl, n, flags = _FORCE.unpack_from(payload)
    return Force(ack, ttl, _unpack_vectors(payload, _FORCE.size, n, "force"), bool(flags & FORCE_TAKES_ORIENTATION))


def enable(on: bool) -> bytes:
    return _U8.pack(1 if on else 0)


def estop(reason: int = ESTOP_HOST) -> bytes:
    return _U8.pack(reason)


def heartbeat(time_us: int) -> bytes:
    return _U32.pack(time_us & 0xFFFFFFFF)


def parse_u8(payload: bytes) -> int:
    return payload[0]


def parse_heartbeat(payload: bytes) -> int:
    return _U32.unpack(payload)[0]
