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
        for e in rec.events:
            w.writerow([repr(float(e.get("time", 0.0))), e.get("kind", ""), e.get("subject", ""),
                        e.get("detail", "")])
        counts["events.csv"] = len(rec.events)
    return counts


def export_npz(rec: Recording, path: str, every: int = 1) -> int:
    """Every tick field as an array (time first), names and events. Returns the ticks written."""
    ticks = _rows(rec.ticks, every)
    arrays = {name: np.ascontiguousarray(ticks[name]) for name in ticks.dtype.names}
    np.savez_compressed(
        path, body_names=np.array(rec.body_names), finger_names=np.array(rec.finger_names),
        haptic_rate=rec.haptic_rate,
        event_time=np.array([e.get("time", 0.0) for e in rec.events], dtype=np.float64),
        event_kind=np.array([e.get("kind", "") for e in rec.events]),
        event_subject=np.array([e.get("subject", "") for e in rec.events]),
        event_detail=np.array([e.get("detail", "") for e in rec.events]), **arrays)
    return len(ticks)


# ------------------------------------------------------------------------ grasp-lab analyze

GRASP_COLUMNS = ["time", "body", "contacts", "force_closure", "torque_closure", "force_only_closure", "epsilon",
                 "volume", "weakest_fx", "weakest_fy", "weakest_fz", "weakest_tx", "weakest_ty", "weakest_tz",
                 "mu_min", "friction_needed", "min_slip_margin", "min_slip_finger", "grip_force", "load_force",
                 "center_x", "center_y", "center_z", "radius"]
CONTACT_COLUMNS = ["time", "body", "finger", "px", "py", "pz", "nx", "ny", "nz", "mu", "fn", "ft", "friction_use",
                   "slip_margin"]


def _text(values) -> list:
    """Numbers as the shortest repr that reads back exactly (inf as 'inf')."""
    return list(map(repr, np.asarray(values, dtype=np.float64).tolist()))


def _write_table(path: str, header: list, columns: list) -> int:
    with open(path, "w", newline="") as fh:
        fh.write(",".join(header) + "\n")
        rows = 0
        for row in zip(*columns):
            fh.write(",".join(row) + "\n")
            rows += 1
    return rows


def export_analysis_csv(rec: Recording, table, folder: str) -> dict:
    """grasp.csv (one row per analysed tick per body in contact) and contacts.csv (the contacts
    it used) of an ``analysis.GraspTable`` of ``rec`` in ``folder`` (columns: docs/cli.md).
    Returns {name: rows written}."""
    os.makedirs(folder, exist_ok=True)
    names = np.array(rec.body_names + [""], dtype=object)
    fingers = np.array(rec.finger_names + [""], dtype=object)
    time = rec.ticks["time"][table.snapshot]
    q = table.quality
    flag = lambda a: np.where(a, "1", "0").tolist()  # noqa: E731
    columns = [_text(time), names[table.body].tolist(), list(map(str, table.count.tolist())),
               flag(q["force_closure"]), flag(q["torque_closure"]), flag(q["force_only_closure"]),
               _text(q["epsilon"]), _text(q["volume"])]
    columns += [_text(q["weakest"][:, k]) for k in range(6)]
    columns += [_text(table.mu_min), _text(table.friction_needed), _text(table.min_slip_margin),
                fingers[table.min_slip_finger].tolist(), _text(table.grip_force), _text(table.load_force)]
    columns += [_text(table.center[:, k]) for k in range(3)] + [_text(table.radius)]
    counts = {"grasp.csv": _write_table(os.path.join(folder, "grasp.csv"), GRASP_COLUMNS, columns)}
    set_of = np.repeat(np.arange(len(table.body)), table.count)
    columns = [_text(time[set_of]), names[table.body[set_of]].tolist(), fingers[table.finger].tolist()]
    columns += [_text(table.point[:, k]) for k in range(3)] + [_text(table.normal[:, k]) for k in range(3)]
    columns += [_text(table.mu), _text(table.fn), _text(table.ft), _text(table.friction_use),
                _text(table.slip_margin)]
    counts["contacts.csv"] = _write_table(os.path.join(folder, "contacts.csv"), CONTACT_COLUMNS, columns)
    return counts
