"""3Dconnexion SpaceMouse as a hand: 6-DoF rate control of a hand frame that carries the
fingertips (and turns a convex finger, a palm or a pad, with it), a button that closes the grip
(docs/devices.md).

HID reports (vendors 0x046D Logitech-era and 0x256F 3Dconnexion; usage page 1, usage 8
"multi-axis controller"):
- split models: report 1 = translation (int16 x, y, z), report 2 = rotation (int16 rx,
  ry, rz), report 3 = buttons (a little-endian bit mask);
- single-report models: report 1 carries translation and rotation (12 bytes after the id).
Values run about +-350. The device's axes: x right, y towards the user, z down (pushing
the cap down is +z); the hand frame here is x right, y forward, z up, so y and z (and
their rotations) change sign.

Reading uses hidapi; on Linux its ``hidraw`` module (the default ``hid`` module would
detach the kernel driver). Input only: the SpaceMouse renders no force.
"""
from __future__ import annotations

import math
import struct
import sys
import time

import numpy as np

from ..inputs import InputSource

VENDORS = (0x046D, 0x256F)
USAGE_PAGE, USAGE = 0x01, 0x08
FULL_SCALE = 350.0
_AXES = struct.Struct("<hhh")
# Device axes -> hand frame (x right, y forward, z up).
_SIGNS = np.array([1.0, -1.0, -1.0])


class SpaceMouseState:
    """The latest axes (normalised to about -1..1) and buttons, from raw reports."""

    def __init__(self):
        self.translation = np.zeros(3)
        self.rotation = np.zeros(3)
        self.buttons = 0
        self.reports = 0
        self.rejected = 0

    def feed(self, report: bytes) -> bool:
        """One HID input report (report id first). False (and counted) when not understood."""
        report = bytes(report)
        if not report:
            self.rejected += 1
            return False
        rid, body = report[0], report[1:]
        if rid == 1 and len(body) >= 12:
            self.translation = _SIGNS * np.array(_AXES.unpack_from(body, 0)) / FULL_SCALE
            self.rotation = _SIGNS * np.array(_AXES.unpack_from(body, 6)) / FULL_SCALE
        elif rid == 1 and len(body) >= 6:
            self.translation = _SIGNS * np.array(_AXES.unpack_from(body, 0)) / FULL_SCALE
        elif rid == 2 and len(body) >= 6:
            self.rotation = _SIGNS * np.array(_AXES.unpack_from(body, 0)) / FULL_SCALE
        elif rid == 3 and len(body) >= 1:
            self.buttons = int.from_bytes(body[:4], "little")
        else:
            self.rejected += 1
            return False
        self.reports += 1
        return True


def _deadzone(v: np.ndarray, dz: float) -> np.ndarray:
    mag = np.abs(v)
    return np.where(mag <= dz, 0.0, np.sign(v) * (np.minimum(mag, 1.0) - dz) / (1.0 - dz))


def _quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of a rotation matrix (Shepperd: from its largest of
    w^2, x^2, y^2, z^2, so never dividing by a small number)."""
    t = np.trace(R)
    d = np.diag(R)
    k = int(np.argmax([t, *d]))
    if k == 0:
        w = math.sqrt(1.0 + t) / 2.0
        q = [w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)]
    else:
        i = k - 1
        j, m = (i + 1) % 3, (i + 2) % 3
        v = math.sqrt(1.0 + 2.0 * d[i] - t) / 2.0
        q = [0.0] * 4
        q[0] = (R[m, j] - R[j, m]) / (4 * v)
        q[1 + i], q[1 + j], q[1 + m] = v, (R[j, i] + R[i, j]) / (4 * v), (R[m, i] + R[i, m]) / (4 * v)
    q = np.array(q)
    return q / np.linalg.norm(q)


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a b for quaternions (w, x, y, z), rows broadcast."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def _rotation(axis_angle: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(axis_angle))
    if angle < 1e-12:
        return np.eye(3)
    k = axis_angle / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


class SpaceMouseHand:
    """Rate control: full deflection moves the hand at ``speed`` m/s and turns it at
    ``turn_rate`` rad/s (in its own axes). The fingertips sit at ``open_tips`` (hand frame,
    (n, 3)) and move towards ``closed_tips`` while the grip button is held (``grip_time``
    s for the full stroke), back when released. ``finger_orientations`` ((n, 4) w, x, y, z,
    hand frame; None: positions only) turn with the hand: a palm or a pad (a convex finger)
    tilts as the hand does (``orientations()``)."""

    def __init__(self, open_tips, closed_tips, origin=(0, 0, 0), speed=0.2, turn_rate=1.5,
                 deadzone=0.05, grip_button=0, grip_time=0.5, finger_orientations=None):
        self.open_tips = np.asarray(open_tips, dtype=np.float64).reshape(-1, 3)
        self.closed_tips = np.asarray(closed_tips, dtype=np.float64).reshape(self.open_tips.shape)
        self.finger_orientations = None
        if finger_orientations is not None:
            q = np.asarray(finger_orientations, dtype=np.float64).reshape(len(self.open_tips), 4)
            norm = np.linalg.norm(q, axis=1)
            if not np.all(np.isfinite(q)) or np.any(norm < 1e-10):
                raise ValueError("finger_orientations: a zero or non-finite quaternion")
            self.finger_orientations = q / norm[:, None]
        self.position = np.asarray(origin, dtype=np.float64).copy()
        self.orientation = np.eye(3)
        self.speed, self.turn_rate, self.deadzone = float(speed), float(turn_rate), float(deadzone)
        self.grip_button, self.grip_time = int(grip_button), float(grip_time)
        self.grip = 0.0

    def update(self, state: SpaceMouseState, dt: float) -> None:
        v = self.speed * _deadzone(state.translation, self.deadzone)
        w = self.turn_rate * _deadzone(state.rotation, self.deadzone)
        self.position = self.position + self.orientation @ v * dt
        self.orientation = self.orientation @ _rotation(w * dt)
        u, _, vt = np.linalg.svd(self.orientation)   # keep it a rotation
        self.orientation = u @ vt
        target = 1.0 if state.buttons >> self.grip_button & 1 else 0.0
        step = dt / self.grip_time if self.grip_time > 0 else 1.0
        self.grip = min(target, self.grip + step) if target > self.grip else max(target, self.grip - step)

    def tips(self) -> np.ndarray:
        local = (1 - self.grip) * self.open_tips + self.grip * self.closed_tips
        return self.position + local @ self.orientation.T

    def orientations(self):
        """The fingers' orientations in the world ((n, 4) w, x, y, z: the hand's rotation times
        each finger's own in the hand), or None for a hand given none."""
        if self.finger_orientations is None:
            return None
        return _quat_mul(_quat_from_matrix(self.orientation), self.finger_orientations)


def hand_from_fingertips(tips, frame=None, closing=0.7, orientations=None) -> SpaceMouseHand:
    """A hand carrying fingertips where they are now (world, (n, 3)); ``frame`` (4x4, the
    workspace frame) is the hand's start pose, its origin by default at their centroid. The
    grip moves each fingertip ``closing`` of the way towards the hand's origin.
    ``orientations`` ((n, 4) w, x, y, z, world: the fingers' now) turn with the hand from
    here: each finger's orientation is the hand's rotation since now times this one."""
    tips = np.asarray(tips, dtype=np.float64).reshape(-1, 3)
    m = np.eye(4) if frame is None else np.asarray(frame, dtype=np.float64)
    if frame is None:
        m[:3, 3] = tips.mean(axis=0)
    R = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
    local = (tips - m[:3, 3]) @ R
    in_hand = None
    if orientations is not None:     # the fingers' own, in the hand's frame: R^-1 q
        conj = _quat_from_matrix(R) * np.array([1.0, -1.0, -1.0, -1.0])
        in_hand = _quat_mul(conj, np.asarray(orientations, dtype=np.float64).reshape(len(tips), 4))
    hand = SpaceMouseHand(local, (1.0 - closing) * local, origin=m[:3, 3], finger_orientations=in_hand)
    hand.orientation = R
    return hand


def hid_module():
    """hidapi's module for this platform: ``hidraw`` on Linux, ``hid`` elsewhere."""
    if sys.platform.startswith("linux"):
        import hidraw
        return hidraw
    import hid
    return hid


def enumerate_spacemice() -> list:
    """SpaceMice hidapi sees: dicts with path, vendor_id, product_id, product_string."""
    try:
        hid = hid_module()
    except ImportError:
        return []
    found = []
    for d in hid.enumerate():
        if d.get("vendor_id") in VENDORS and (d.get("usage_page"), d.get("usage")) == (USAGE_PAGE, USAGE):
            found.append(d)
    return found


class SpaceMouseSource(InputSource):
    """HIPs from a SpaceMouse hand (live: ``hips_at`` reads what the device sent)."""
    name = "spacemouse"

    def __init__(self, hand: SpaceMouseHand, path: bytes | None = None, device=None):
        """``device``: an opened hidapi-like object (``read(n)``, ``close()``), e.g. a
        replay of recorded reports; by default the first SpaceMouse (or ``path``)."""
        super().__init__(len(hand.open_tips))
        self.hand = hand
        self.path = path
        self.state = SpaceMouseState()
        self._given = device
        self._dev = None
        self._last_t = None

    def open(self) -> None:
        if self._given is not None:
            self._dev = self._given
            return
        hid = hid_module()
        paths = [self.path] if self.path else [d["path"] for d in enumerate_spacemice()]
        if not paths:
            raise ConnectionError("no SpaceMouse found (vendors 046d/256f, usage page 1 usage 8)")
        self._dev = hid.device()
        self._dev.open_path(paths[0])
        self._dev.set_nonblocking(True)

    def poll(self) -> None:
        while self._dev is not None:
            report = self._dev.read(64)
            if not report:
                break
            self.state.feed(bytes(report))

    def hips_at(self, t: float) -> np.ndarray:
        self.poll()
        now = time.monotonic()
        if self._last_t is not None:
            self.hand.update(self.state, min(now - self._last_t, 0.1))
        self._last_t = now
        return self.hand.tips()

    def live_orientations(self):
        """The fingers' orientations as the hand turned them (at the last ``hips_at``), or
        None for a hand given none."""
        return self.hand.orientations()

    def close(self) -> None:
        if self._dev is not None:
            self._dev.close()
            self._dev = None
