"""Events of a recording, derived from consecutive tick records (docs/recording-format.md):
the writer's recorder and the live view detect them alike."""
from __future__ import annotations

import numpy as np

from .format import FLAG_FORCES_ENABLED, STATE_NAMES


class EventDetector:
    """Events from consecutive tick records: contact begin/end, stick/slip changes,
    device forces switched off/on by the safety layer, force clamping."""

    def __init__(self, header: dict):
        self.bodies = header["body_names"]
        self.fingers = header["finger_names"]
        rt = header.get("runtime") or {}
        self.max_force = rt.get("max_force")
        self.watchdog_us = 1e6 * rt["watchdog_timeout"] if rt.get("watchdog_timeout") else None
        self._last = None       # (state, contact, enabled, clamped) of the previous tick

    def _body(self, i):
        return self.bodies[i] if 0 <= i < len(self.bodies) else f"body {i}"

    def __call__(self, records: np.ndarray):
        """Yields (tick, time, kind, subject, detail)."""
        if len(records) == 0:
            return
        state, contact = records["state"], records["contact"]
        enabled = (records["flags"] & FLAG_FORCES_ENABLED) != 0
        if self.max_force is not None and len(self.fingers):
            clamped = np.linalg.norm(records["device_force"], axis=2) >= self.max_force * (1 - 1e-9)
        else:
            clamped = np.zeros(state.shape, dtype=bool)
        if self._last is None:
            prev = (np.zeros_like(state[0]), np.full_like(contact[0], -1), np.ones((), bool),
                    np.zeros_like(clamped[0]))
        else:
            prev = self._last
        cat = lambda p, a: np.concatenate([np.asarray(p)[None], a])  # noqa: E731
        s2, c2, e2, k2 = cat(prev[0], state), cat(prev[1], contact), cat(prev[2], enabled), cat(prev[3], clamped)
        ticks, times = records["tick"], records["time"]
        for k in np.flatnonzero(e2[1:] != e2[:-1]):
            t = int(ticks[k]), float(times[k])
            if e2[k + 1]:
                yield (*t, "forces_on", "", "device forces enabled (ramping in)")
            else:
                period = float(records["period_us"][k])
                why = (f"watchdog: haptic period {period:.0f} us" if self.watchdog_us and period > self.watchdog_us
                       else "input stale or not yet received")
                yield (*t, "forces_off", "", why)
        for k, f in zip(*np.nonzero(c2[1:] != c2[:-1])):
            t = int(ticks[k]), float(times[k])
            finger = self.fingers[f]
            was, now = int(c2[k, f]), int(c2[k + 1, f])
            if was >= 0:
                yield (*t, "contact_end", finger, self._body(was))
            if now >= 0:
                yield (*t, "contact_begin", finger, self._body(now))
        for k, f in zip(*np.nonzero(s2[1:] != s2[:-1])):
            now = int(s2[k + 1, f])
            if now in (1, 2):
                name = STATE_NAMES[now]
                yield (int(ticks[k]), float(times[k]), name, self.fingers[f],
                       f"{STATE_NAMES[int(s2[k, f])] if 0 <= s2[k, f] < 3 else s2[k, f]} -> {name}")
        for k, f in zip(*np.nonzero(k2[1:] != k2[:-1])):
            kind = "clamp_begin" if k2[k + 1, f] else "clamp_end"
            yield (int(ticks[k]), float(times[k]), kind, self.fingers[f], f"max_force {self.max_force} N")
        self._last = (state[-1].copy(), contact[-1].copy(), enabled[-1].copy(), clamped[-1].copy())
