"""``grasp-lab export``: a recording as CSV tables or one .npz (columns: docs/cli.md)."""
from __future__ import annotations

import csv
import os

import numpy as np

from .recording import STATE_NAMES, Recording

BODY_COLUMNS = ["time", "body", "x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "wx", "wy", "wz",
                "fx", "fy", "fz", "tx", "ty", "tz"]
FINGER_COLUMNS = ["time", "finger", "hip_x", "hip_y", "hip_z", "go_x", "go_y", "go_z",
                  "force_x", "force_y", "force_z", "device_fx", "device_fy", "device_fz", "state", "contact"]
EVENT_COLUMNS = ["time", "kind", "subject", "detail"]


def _rows(ticks, every):
    return ticks[::every] if every > 1 else ticks


def _events_by_time(rec: Recording) -> list:
    """Events in time order (the file holds them as written: tick-derived events by the
    recorder thread, device events as the session polled them)."""
    return sorted(rec.events, key=lambda e: float(e.get("time", 0.0)))


def _fmt(a):
    return [repr(float(v)) for v in a]


def export_csv(rec: Recording, folder: str, every: int = 1) -> dict:
    """bodies.csv, fingers.csv, events.csv in ``folder``; one row per tick (every ``every``-th)
    per body or finger. Returns {name: rows written}."""
    os.makedirs(folder, exist_ok=True)
    ticks = _rows(rec.ticks, every)
    counts = {}
    with open(os.path.join(folder, "bodies.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(BODY_COLUMNS)
        values = np.concatenate([ticks["pose"], ticks["velocity"], ticks["wrench"]], axis=2)  # (n, nb, 19)
        for k, t in enumerate(ticks["time"]):
            ts = repr(float(t))
            for b, name in enumerate(rec.body_names):
                w.writerow([ts, name, *_fmt(values[k, b])])
        counts["bodies.csv"] = len(ticks) * len(rec.body_names)
    with open(os.path.join(folder, "fingers.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(FINGER_COLUMNS)
        values = np.concatenate([ticks["hip"], ticks["god_object"], ticks["force"], ticks["device_force"]],
                                axis=2)
        for k, t in enumerate(ticks["time"]):
            ts = repr(float(t))
            for f, name in enumerate(rec.finger_names):
                s = int(ticks["state"][k, f])
                c = int(ticks["contact"][k, f])
                w.writerow([ts, name, *_fmt(values[k, f]), STATE_NAMES[s] if 0 <= s < 3 else str(s),
                            rec.body_names[c] if 0 <= c < len(rec.body_names) else ""])
        counts["fingers.csv"] = len(ticks) * len(rec.finger_names)
    with open(os.path.join(folder, "events.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(EVENT_COLUMNS)
        for e in _events_by_time(rec):
            w.writerow([repr(float(e.get("time", 0.0))), e.get("kind", ""), e.get("subject", ""),
                        e.get("detail", "")])
        counts["events.csv"] = len(rec.events)
    return counts


def export_npz(rec: Recording, path: str, every: int = 1) -> int:
    """Every tick field as an array (time first), names and events. Returns the ticks written."""
    ticks = _rows(rec.ticks, every)
    arrays = {name: np.ascontiguousarray(ticks[name]) for name in ticks.dtype.names}
    events = _events_by_time(rec)
    np.savez_compressed(
        path, body_names=np.array(rec.body_names), finger_names=np.array(rec.finger_names),
        haptic_rate=rec.haptic_rate,
        event_time=np.array([e.get("time", 0.0) for e in events], dtype=np.float64),
        event_kind=np.array([e.get("kind", "") for e in events]),
        event_subject=np.array([e.get("subject", "") for e in events]),
        event_detail=np.array([e.get("detail", "") for e in events]), **arrays)
    return len(ticks)
