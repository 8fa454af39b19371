"""``grasp-lab export``: a recording as CSV tables or one .npz (columns: docs/cli.md)."""
from __future__ import annotations

import csv
import io
import os
import zipfile

import numpy as np

from .outputs import AtomicFile, OutputError, write_together
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
    per body or finger. The three are written beside their targets and renamed into place
    together when all are written. Returns {name: rows written}."""
    ticks = _rows(rec.ticks, every)
    return write_together(folder, {
        "bodies.csv": lambda fh: _write_bodies(rec, ticks, csv.writer(fh)),
        "fingers.csv": lambda fh: _write_fingers(rec, ticks, csv.writer(fh)),
        "events.csv": lambda fh: _write_events(rec, csv.writer(fh))})


def _write_bodies(rec, ticks, bodies) -> int:
    bodies.writerow(BODY_COLUMNS)
    values = np.concatenate([ticks["pose"], ticks["velocity"], ticks["wrench"]], axis=2)  # (n, nb, 19)
    for k, t in enumerate(ticks["time"]):
        ts = repr(float(t))
        for b, name in enumerate(rec.body_names):
            bodies.writerow([ts, name, *_fmt(values[k, b])])
    return len(ticks) * len(rec.body_names)


def _write_fingers(rec, ticks, fingers) -> int:
    fingers.writerow(FINGER_COLUMNS)
    values = np.concatenate([ticks["hip"], ticks["god_object"], ticks["force"], ticks["device_force"]], axis=2)
    for k, t in enumerate(ticks["time"]):
        ts = repr(float(t))
        for f, name in enumerate(rec.finger_names):
            s = int(ticks["state"][k, f])
            c = int(ticks["contact"][k, f])
            fingers.writerow([ts, name, *_fmt(values[k, f]), STATE_NAMES[s] if 0 <= s < 3 else str(s),
                              rec.body_names[c] if 0 <= c < len(rec.body_names) else ""])
    return len(ticks) * len(rec.finger_names)


def _write_events(rec, events) -> int:
    events.writerow(EVENT_COLUMNS)
    for e in _events_by_time(rec):
        events.writerow([repr(float(e.get("time", 0.0))), e.get("kind", ""), e.get("subject", ""),
                         e.get("detail", "")])
    return len(rec.events)


def export_npz(rec: Recording, path: str, every: int = 1) -> int:
    """Every tick field as an array (time first), names and events, in one .npz written
    beside ``path`` (the exact name given) and renamed into place. Returns the ticks written."""
    ticks = _rows(rec.ticks, every)
    events = _events_by_time(rec)
    arrays = {"body_names": np.array(rec.body_names), "finger_names": np.array(rec.finger_names),
              "haptic_rate": np.array(rec.haptic_rate),
              "event_time": np.array([e.get("time", 0.0) for e in events], dtype=np.float64),
              "event_kind": np.array([e.get("kind", "") for e in events]),
              "event_subject": np.array([e.get("subject", "") for e in events]),
              "event_detail": np.array([e.get("detail", "") for e in events])}
    arrays.update({name: np.ascontiguousarray(ticks[name]) for name in ticks.dtype.names})
    out = AtomicFile(path)
    try:
        # np.savez_compressed's layout, with the archive closed on any error (a full disk)
        # before the file is discarded.
        with zipfile.ZipFile(out.file, "w", zipfile.ZIP_DEFLATED, allowZip64=True) as archive:
            for name, array in arrays.items():
                with archive.open(f"{name}.npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, array, allow_pickle=False)
    except OSError as ex:
        out.discard()
        raise OutputError(f"{out.path}: could not be written ({ex.strerror or ex}); it is as it was") from None
    except BaseException:
        out.discard()
        raise
    out.commit()
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


def _write_table(fh, header: list, columns: list) -> int:
    fh.write(",".join(header) + "\n")
    rows = 0
    for row in zip(*columns):
        fh.write(",".join(row) + "\n")
        rows += 1
    return rows


def export_analysis_csv(rec: Recording, table, folder: str) -> dict:
    """grasp.csv (one row per analysed tick per body in contact) and contacts.csv (the contacts
    it used) of an ``analysis.GraspTable`` of ``rec`` in ``folder`` (columns: docs/cli.md).
    Both are written whole and go in together (outputs.write_together). Returns {name: rows written}."""
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
    grasp_columns = columns
    set_of = np.repeat(np.arange(len(table.body)), table.count)
    columns = [_text(time[set_of]), names[table.body[set_of]].tolist(), fingers[table.finger].tolist()]
    columns += [_text(table.point[:, k]) for k in range(3)] + [_text(table.normal[:, k]) for k in range(3)]
    columns += [_text(table.mu), _text(table.fn), _text(table.ft), _text(table.friction_use),
                _text(table.slip_margin)]
    return write_together(folder, {"grasp.csv": lambda fh: _write_table(fh, GRASP_COLUMNS, grasp_columns),
                                   "contacts.csv": lambda fh: _write_table(fh, CONTACT_COLUMNS, columns)})
