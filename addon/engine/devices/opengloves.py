"""OpenGloves / LucidGloves: ASCII lines at 115200 baud in, per-finger force feedback out
(docs/devices.md).

Input, one line per sample, in either encoding:
- *alpha*: a key letter and its value, e.g. ``A512B1024C0D4095E2000F2048G2048I\\n``:
  ``A``..``E`` the curls of thumb, index, middle, ring, pinky (0..``analog_max``, 4095
  by default), ``F``/``G`` joystick x/y, ``P`` trigger value; a letter without a number is
  a button that is pressed (``H`` joystick click, ``I`` trigger, ``J`` A, ``K`` B,
  ``L`` grab, ``M`` pinch, ``N`` menu, ``O`` calibrate); keys in parentheses such as
  ``(AB)`` (splay, per-joint values) are kept but not used by the finger model;
- *legacy*: comma-separated integers, the five curls first, then joystick x, y and the
  buttons as 0/1: ``512,1024,0,4095,2000,2048,2048,0,1,0,0,0,0\\n``.
A line with a curl outside 0..analog_max, or that is not one of these, is dropped and
counted.

Output: ``A<0-1000>B<0-1000>C<0-1000>D<0-1000>E<0-1000>\\n``, a brake level per finger
(thumb to pinky); 1000 is full resistance. It is the finger's force along its own
fingertip force, ``|f|`` over ``full_scale`` newtons.

Finger model: each finger is a planar chain of three links (proximal, middle, distal)
from its base (the MCP joint; for the thumb, the CMC joint) in the hand frame, extending
along ``u`` and flexing towards ``w`` (into the palm). A curl c in 0..1 bends the three
joints together by c times their ranges; the fingertip is the end of the chain.
The hand frame (right hand, palm down): x towards the thumb side, y along the fingers,
z out of the back of the hand; a left hand mirrors x.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ..inputs import InputSource

FINGERS = ("thumb", "index", "middle", "ring", "pinky")
CURL_KEYS = "ABCDE"
BUTTON_KEYS = {"H": "joystick", "I": "trigger", "J": "a", "K": "b", "L": "grab", "M": "pinch", "N": "menu",
               "O": "calibrate"}
LEGACY_BUTTONS = ("joystick", "trigger", "a", "b", "grab", "pinch")
BAUD = 115200
_TOKEN = re.compile(r"(\([A-Z]+\)|[A-Z])(-?\d*)")


@dataclass(frozen=True)
class FingerGeometry:
    base: tuple          # m, hand frame
    extend: tuple        # u: unit, the finger straight
    flex: tuple          # w: unit, perpendicular to u, into the palm
    links: tuple         # m, proximal, middle, distal
    ranges: tuple        # degrees each joint bends at full curl


# An adult hand (about 19 cm long), right hand; the thumb points forward-outward and
# flexes across the palm.
_S = math.sqrt(0.5)
HAND_MODEL = (
    FingerGeometry((0.030, 0.025, -0.010), (_S, _S, 0.0), (-_S * _S, _S * _S, -_S), (0.040, 0.032, 0.027), (40, 50, 70)),
    FingerGeometry((0.022, 0.090, 0.0), (0, 1, 0), (0, 0, -1), (0.045, 0.025, 0.020), (90, 100, 70)),
    FingerGeometry((0.002, 0.095, 0.0), (0, 1, 0), (0, 0, -1), (0.050, 0.030, 0.022), (90, 100, 70)),
    FingerGeometry((-0.018, 0.090, 0.0), (0, 1, 0), (0, 0, -1), (0.047, 0.028, 0.021), (90, 100, 70)),
    FingerGeometry((-0.036, 0.080, 0.0), (0, 1, 0), (0, 0, -1), (0.037, 0.021, 0.019), (90, 100, 70)),
)


def fingertip(geometry: FingerGeometry, curl: float) -> np.ndarray:
    """Hand-frame fingertip of one finger at curl 0 (straight) .. 1 (closed)."""
    c = min(1.0, max(0.0, float(curl)))
    u, w = np.array(geometry.extend, dtype=float), np.array(geometry.flex, dtype=float)
    w = w - u * (w @ u)
    w /= np.linalg.norm(w)
    p = np.array(geometry.base, dtype=float)
    angle = 0.0
    for length, rng in zip(geometry.links, geometry.ranges):
        angle += math.radians(rng) * c
        p = p + length * (math.cos(angle) * u + math.sin(angle) * w)
    return p


def fingertips(curls, hand_frame=None, left=False, model=HAND_MODEL) -> np.ndarray:
    """(5, 3) fingertips for five curls (0..1); hand_frame (4x4) maps the hand frame into
    the scene (identity: hand frame = scene)."""
    tips = np.array([fingertip(g, c) for g, c in zip(model, curls)])
    if left:
        tips[:, 0] = -tips[:, 0]
    if hand_frame is None:
        return tips
    m = np.asarray(hand_frame, dtype=np.float64)
    return tips @ m[:3, :3].T + m[:3, 3]


class GloveState:
    """The latest sample of a glove: curls 0..1 (thumb..pinky), joystick, buttons."""

    def __init__(self, analog_max: int = 4095):
        self.analog_max = int(analog_max)
        self.curls = np.zeros(5)
        self.joystick = (0.0, 0.0)
        self.trigger = 0.0
        self.buttons: dict = {}
        self.extended: dict = {}
        self.lines = 0
        self.rejected = 0
        self.encoding = None

    def _scale(self, raw: int) -> float:
        return raw / self.analog_max

    def feed_line(self, line: str | bytes) -> bool:
        """One input line; False (and counted) when it is dropped."""
        if isinstance(line, bytes):
            line = line.decode("ascii", "replace")
        line = line.strip()
        try:
            ok = self._legacy(line) if line[:1].isdigit() else self._alpha(line)
        except (ValueError, IndexError):
            ok = False
        if ok:
            self.lines += 1
        else:
            self.rejected += 1
        return ok

    def _check_curls(self, raw) -> bool:
        return len(raw) == 5 and all(0 <= v <= self.analog_max for v in raw)

    def _alpha(self, line: str) -> bool:
        pos, values = 0, {}
        for m in _TOKEN.finditer(line):
            if m.start() != pos:
                return False
            pos = m.end()
            values[m.group(1)] = int(m.group(2)) if m.group(2) else None
        if pos != len(line) or not line:
            return False
        raw = [values.get(k) for k in CURL_KEYS]
        if any(v is None for v in raw) or not self._check_curls(raw):
            return False
        self.curls = np.array([self._scale(v) for v in raw])
        half = self.analog_max / 2
        self.joystick = tuple((values[k] - half) / half if values.get(k) is not None else 0.0 for k in "FG")
        self.trigger = self._scale(values["P"]) if values.get("P") is not None else 0.0
        self.buttons = {name: key in values for key, name in BUTTON_KEYS.items()}
        self.extended = {k: v for k, v in values.items() if k.startswith("(")}
        self.encoding = "alpha"
        return True

    def _legacy(self, line: str) -> bool:
        fields = [int(f) for f in line.split(",")]
        if len(fields) < 5 or not self._check_curls(fields[:5]):
            return False
        self.curls = np.array([self._scale(v) for v in fields[:5]])
        half = self.analog_max / 2
        self.joystick = tuple((fields[i] - half) / half if len(fields) > i else 0.0 for i in (5, 6))
        self.buttons = {name: len(fields) > 7 + i and fields[7 + i] != 0 for i, name in enumerate(LEGACY_BUTTONS)}
        self.encoding = "legacy"
        return True


def brake_levels(forces, full_scale: float = 4.0, enabled: bool = True) -> np.ndarray:
    """The five brake levels 0..1000 for five finger forces ((5, 3) N, or five magnitudes)."""
    f = np.asarray(forces, dtype=np.float64)
    mags = np.linalg.norm(f.reshape(5, 3), axis=1) if f.size == 15 else f.reshape(5)
    if not enabled or not (full_scale > 0):
        mags = np.zeros(5)
    mags = np.where(np.isfinite(mags), mags, 0.0)     # a NaN never reaches the glove
    return np.clip(np.rint(1000.0 * mags / (full_scale if full_scale > 0 else 1.0)), 0, 1000).astype(int)


def force_feedback_line(forces, full_scale: float = 4.0, enabled: bool = True) -> bytes:
    """The haptic line for five finger forces ((5, 3) N, or five magnitudes)."""
    levels = brake_levels(forces, full_scale, enabled)
    return ("".join(f"{k}{v}" for k, v in zip(CURL_KEYS, levels)) + "\n").encode("ascii")


def sent_forces(forces, full_scale: float = 4.0, enabled: bool = True) -> np.ndarray:
    """(5, 3): the forces the brake levels sent for ``forces`` (5, 3) stand for: each finger's
    force direction at the level's magnitude (zero where its level is, or its force is not finite)."""
    f = np.asarray(forces, dtype=np.float64).reshape(5, 3)
    norm = np.linalg.norm(f, axis=1)
    level = brake_levels(f, full_scale, enabled)
    ok = (level > 0) & np.isfinite(norm) & (norm > 0)
    scale = np.where(ok, level * (full_scale / 1000.0) / np.where(ok, norm, 1.0), 0.0)
    return np.where(ok[:, None], f * scale[:, None], 0.0)


class OpenGlovesSource(InputSource):
    """HIPs of five fingers from a glove on a serial port (live), force feedback back."""
    name = "opengloves"

    def __init__(self, port: str, hand_frame=None, left=False, analog_max=4095, full_scale=4.0, baud=BAUD):
        super().__init__(5)
        self.port, self.baud = port, baud
        self.hand_frame = np.eye(4) if hand_frame is None else np.asarray(hand_frame, dtype=np.float64)
        self.left = left
        self.full_scale = full_scale
        self.state = GloveState(analog_max)
        self._serial = None
        self._pending = b""

    def open(self) -> None:
        import serial
        self._serial = serial.Serial(self.port, self.baud, timeout=0)

    def poll(self) -> None:
        if self._serial is None:
            return
        data = self._serial.read(4096)
        if not data:
            return
        lines = (self._pending + data).split(b"\n")
        self._pending = lines.pop()
        if len(self._pending) > 512:       # no newline for too long: not a glove line
            self._pending = b""
            self.state.rejected += 1
        for line in lines:
            if line.strip():
                self.state.feed_line(line)

    def hips_at(self, t: float) -> np.ndarray:
        self.poll()
        return fingertips(self.state.curls, self.hand_frame, self.left)

    def send_forces(self, forces, enabled: bool):
        """Writes the haptic line; returns the forces it stands for ((5, 3), ``sent_forces``; None
        when given magnitudes only)."""
        if self._serial is None:
            return np.zeros((5, 3))
        self._serial.write(force_feedback_line(forces, self.full_scale, enabled))
        return sent_forces(forces, self.full_scale, enabled) if np.size(forces) == 15 else None

    def close(self) -> None:
        if self._serial is not None:
            self._serial.close()
            self._serial = None
