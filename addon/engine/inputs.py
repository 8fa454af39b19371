"""Input sources: where HIPs (device fingertip positions) come from.

Every source answers ``hips_at(t)``: an (n_fingers, 3) array of world positions at
session time ``t`` (seconds). Scripted sources are pure functions of ``t``, which makes
headless sessions deterministic. Two more questions let the threaded runtime take the input
at its own tick times, whatever the display rate (docs/blender.md "Live sessions"):

* ``script()``: the scripted part as a whole track ``(times, positions, scripted mask,
  orientations or None)``, handed to the core once (``World.set_hip_track``) and sampled by the
  haptic loop at every tick; None if nothing is scripted;
* ``orientations_at(t)``: the scripted fingers' orientations at ``t`` (a turning palm), or
  None when the input carries none; ``live_orientations()``: the live fingers' latest ones, or
  None;
* ``interactive``: True when some fingers follow live samples (pushed with a time stamp at
  every display tick, walked by the haptic loop at a bounded speed).
"""
from __future__ import annotations

import numpy as np


class InputSource:
    """Base class. ``duration`` is None for open-ended (live) sources."""
    name = "input"
    duration = None

    def __init__(self, n_fingers: int):
        self.n_fingers = int(n_fingers)

    interactive = True      # by default every finger follows pushed samples

    def open(self) -> None:
        pass

    def script(self):
        return None

    def orientations_at(self, t: float):
        return None

    def live_orientations(self):
        return None

    def hips_at(self, t: float) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def close(self) -> None:
        pass


class StaticInput(InputSource):
    """Fingertips that do not move."""
    name = "static"

    def __init__(self, positions):
        p = np.array(positions, dtype=np.float64).reshape(-1, 3)
        super().__init__(len(p))
        self._p = p

    def hips_at(self, t):
        return self._p


def turning_fingers(orientations, tol=1e-9) -> np.ndarray:
    """(n_fingers,) bools: the fingers whose sampled orientations (n, n_fingers, 4) change
    (q and -q are one rotation)."""
    q = np.asarray(orientations, dtype=np.float64)
    if len(q) < 2:
        return np.zeros(q.shape[1], dtype=bool)
    return (1.0 - np.abs(np.einsum("ijk,jk->ij", q, q[0]))).max(axis=0) > tol


def _norm2(q):
    """|q|^2 as the core sums it (w w + x x + y y + z z, in that order, no fused multiply-add)."""
    return ((q[..., 0] * q[..., 0] + q[..., 1] * q[..., 1]) + q[..., 2] * q[..., 2]) + q[..., 3] * q[..., 3]


_ULP_STEPS = sorted(((a, b) for a in range(-3, 4) for b in range(-3, 4)), key=lambda d: abs(d[0]) + abs(d[1]))


def core_unit_quaternions(q) -> np.ndarray:
    """Unit quaternions (n, 4) near ``q`` that the core's normalisation leaves as they are, bit
    for bit (|q| computes to exactly 1): the orientation a tick records is then the one given,
    and a re-simulation that sets the recorded one steps the same state. Each is ``q`` normalised
    with its two largest components moved by at most 3 ulps (always enough in tests of 10^5
    random rotations)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.sqrt(_norm2(q))[..., None]
    out = q.copy()
    todo = np.sqrt(_norm2(q)) != 1.0
    if not todo.any():
        return out
    rows = np.flatnonzero(todo)
    big = np.argsort(-np.abs(q[rows]), axis=1)[:, :2]
    for steps in _ULP_STEPS:
        c = q[rows].copy()
        for col, d in zip(big.T, steps):
            v = c[np.arange(len(rows)), col]
            for _ in range(abs(d)):
                v = np.nextafter(v, np.copysign(np.inf, d))
            c[np.arange(len(rows)), col] = v
        ok = np.sqrt(_norm2(c)) == 1.0
        out[rows[ok]] = c[ok]
        rows, big = rows[~ok], big[~ok]
        if not len(rows):
            break
    return out


class SampledTrajectory(InputSource):
    """HIPs sampled at increasing times (e.g. every animation frame), linearly
    interpolated in between and held after the last sample: a scripted device. With
    ``orientations`` (n, n_fingers, 4: w x y z) the fingers turn too (a palm), by the core's
    normalised lerp along the shorter arc."""
    name = "timeline"

    def __init__(self, times, positions, orientations=None):
        times = np.asarray(times, dtype=np.float64)
        positions = np.asarray(positions, dtype=np.float64)
        if times.ndim != 1 or len(times) < 1:
            raise ValueError("times: need a 1-D array with at least one sample")
        if positions.ndim != 3 or positions.shape[0] != len(times) or positions.shape[2] != 3:
            raise ValueError(f"positions: expected ({len(times)}, n_fingers, 3), got {positions.shape}")
        if len(times) > 1 and np.any(np.diff(times) <= 0):
            raise ValueError("times: must be strictly increasing")
        if not np.all(np.isfinite(positions)):
            raise ValueError("positions: non-finite fingertip position")
        if orientations is not None:
            orientations = np.asarray(orientations, dtype=np.float64)
            if orientations.shape != positions.shape[:2] + (4,):
                raise ValueError(f"orientations: expected {positions.shape[:2] + (4,)}, got {orientations.shape}")
            if not (np.all(np.isfinite(orientations)) and np.all(np.linalg.norm(orientations, axis=2) > 1e-10)):
                raise ValueError("orientations: a zero or non-finite quaternion")
        super().__init__(positions.shape[1])
        self.times = times
        self.positions = positions
        self.orientations = orientations
        self.duration = float(times[-1] - times[0])
        self._t0 = float(times[0])

    interactive = False

    def script(self):
        return self.times, self.positions, None, self.orientations

    def orientations_at(self, t):
        """As the core's track computes them, operation for operation (its set_finger_pose
        normalises): set_finger_pose with these before every step is the runtime, bit for bit."""
        q = self.orientations
        if q is None:
            return None
        ts = self.times
        tt = self._t0 + float(t)
        if tt <= ts[0] or len(ts) == 1:
            return q[0]
        if tt >= ts[-1]:
            return q[-1]
        i = int(np.searchsorted(ts, tt, side="right")) - 1
        a = (tt - ts[i]) / (ts[i + 1] - ts[i])
        s = np.where(np.einsum("jk,jk->j", q[i], q[i + 1]) < 0.0, -a, a)[:, None]
        return (1.0 - a) * q[i] + s * q[i + 1]

    def hips_at(self, t):
        ts = self.times
        tt = self._t0 + float(t)
        if tt <= ts[0] or len(ts) == 1:
            return self.positions[0]
        if tt >= ts[-1]:
            return self.positions[-1]
        i = int(np.searchsorted(ts, tt, side="right")) - 1
        a = (tt - ts[i]) / (ts[i + 1] - ts[i])
        return (1.0 - a) * self.positions[i] + a * self.positions[i + 1]


class TimelineInput(InputSource):
    """Fingertip objects of a Blender scene: the animated ones replay their sampled track,
    the others are wherever the user puts them (``set_live`` at every display tick: grab a
    fingertip empty with G and the god-object follows). With nothing animated the session
    is open-ended."""
    name = "timeline"

    def __init__(self, track: SampledTrajectory, scripted):
        super().__init__(track.n_fingers)
        self.track = track
        self.scripted = np.asarray(scripted, dtype=bool).reshape(self.n_fingers)
        self.live = np.array(track.positions[0], dtype=np.float64)
        self.live_q = None          # (n, 4) once set_live is given orientations (mesh fingers)
        self.interactive = bool(not self.scripted.all())
        self.duration = track.duration if self.scripted.any() else None

    def set_live(self, positions, orientations=None):
        """Where the user put the live fingers; ``orientations`` (n, 4) turn them too (a palm
        rotated in the viewport)."""
        p = np.asarray(positions, dtype=np.float64).reshape(self.n_fingers, 3)
        if not np.all(np.isfinite(p)):
            raise ValueError("fingertip positions: non-finite value")
        self.live[~self.scripted] = p[~self.scripted]
        if orientations is not None:
            q = np.asarray(orientations, dtype=np.float64).reshape(self.n_fingers, 4)
            if not (np.all(np.isfinite(q)) and np.all(np.linalg.norm(q, axis=1) > 1e-10)):
                raise ValueError("fingertip orientations: a zero or non-finite quaternion")
            self.live_q = q.copy()

    def live_orientations(self):
        return self.live_q

    def hips_at(self, t):
        if not self.interactive:
            return self.track.hips_at(t)
        out = self.live.copy()
        out[self.scripted] = self.track.hips_at(t)[self.scripted]
        return out

    def script(self):
        if not self.scripted.any():
            return None
        return self.track.times, self.track.positions, self.scripted, self.track.orientations

    def orientations_at(self, t):
        return self.track.orientations_at(t)


class CallableInput(InputSource):
    """HIPs from a Python function ``f(t) -> (n, 3)`` (scripts, tests)."""
    name = "callable"

    def __init__(self, n_fingers, fn, duration=None):
        super().__init__(n_fingers)
        self._fn = fn
        self.duration = duration

    def hips_at(self, t):
        return np.asarray(self._fn(t), dtype=np.float64).reshape(self.n_fingers, 3)
