"""Force continuity of a recording (bpy-free): per finger, the per-tick change of the force
rendered to the device, its distribution, and every change above a threshold with its cause.

The hand feels a force discontinuity (the source chapter, §2.6), so a jump must have a
physical reason. The causes are read from the tick records around the jump (the tick and
the ``WINDOW`` ticks before it): a contact starting or ending, a stick/slip transition, a
change in the set of convex parts the finger touches (the ``parts`` field; recordings made
before it was added cannot name this cause), the touched body's contacts with other bodies
jumping (it landed on or left the table: its residual force less gravity and the fingers'
reactions), a body handed over between the haptic and the
object thread (``adopted``), the safety layer (forces gated on or off, ramped or clamped:
the jump is in ``device_force − force``), or the hand itself: the HIP's own terms of the
coupling, ``−k ΔHIP − c Δv_HIP`` (its spring and its damper: a HIP that starts moving at
10 cm/s in one tick changes a 2 N s/m damper's force by 0.2 N; a convex finger's patch has
one spring and damper per god-object, m of them, so ``m`` times that), when the change without
them is below the threshold: the god-object did not jump, the hand moved. A *steady change*
is one that, less the hand's terms, differs from the tick before's by less than the threshold,
after a tick that was no jump or an explained one: the force ramps (a body accelerating, a
carried body's god-object moving along with the HIP), it does not step. *Free motion*: the
finger touched nothing at that tick or the one before (the cursor renderer's light mass is
felt in free space). A jump with none of these is *unexplained*.
"""
from __future__ import annotations

import numpy as np

from .recording import FLAG_FORCES_ENABLED

DEFAULT_THRESHOLD = 0.25          # N per tick
WINDOW = 2                        # ticks before a jump whose transitions can explain it
CAUSES = ("contact onset", "contact end", "stick/slip", "change of convex part", "body contact",
          "hand-over between threads", "safety gate", "HIP motion", "steady change", "free motion")
UNEXPLAINED = "unexplained"
CONVEX_FINGER_SPRINGS = 16        # a convex finger's contacts at most (the core's GC_MAX_FINGER_CONTACTS)


def _transitions(a: np.ndarray) -> np.ndarray:
    """(n,) bool: the value at tick t differs from tick t - 1 (False at t = 0)."""
    out = np.zeros(len(a), dtype=bool)
    if len(a) > 1:
        out[1:] = a[1:] != a[:-1]
    return out


def _within(changed: np.ndarray, t: int) -> bool:
    return bool(changed[max(0, t - WINDOW):t + 1].any())


def _less_hand(change: np.ndarray, hand: np.ndarray, springs: int) -> np.ndarray:
    """``change + m hand`` per row: the change the hand's terms (one spring's and damper's,
    ``hand``) did not make. A sphere finger has one spring (m = 1); a convex finger's patch one
    per god-object, m of them (1..``springs``, not recorded): the m that explains most."""
    if springs <= 1:
        return change + hand
    hh = np.einsum("ij,ij->i", hand, hand)
    m = np.where(hh > 0.0, -np.einsum("ij,ij->i", change, hand) / np.where(hh > 0.0, hh, 1.0), 1.0)
    return change + hand * np.clip(m, 1.0, float(springs))[:, None]


def body_contact_forces(ticks: np.ndarray, masses, gravity) -> np.ndarray:
    """(n, B, 3): per body the force its contacts with other bodies put on it, from the
    record: the residual force (its rate of change of momentum) less gravity and less the
    fingers' reactions (a finger exerting ``force`` on the device puts ``−force`` on the
    body). Static bodies: zero."""
    n, nb = len(ticks), ticks["wrench"].shape[1]
    out = np.zeros((n, nb, 3))
    g = np.asarray(gravity, dtype=np.float64)
    for b in range(nb):
        if masses[b] is None:
            continue
        on_body = ticks["contact"] == b                                   # (n, F)
        fingers = np.einsum("nf,nfk->nk", on_body.astype(np.float64), ticks["force"])
        out[:, b] = ticks["wrench"][:, b, :3] - masses[b] * g + fingers
    return out


def finger_continuity(ticks: np.ndarray, i: int, stiffness: float, damping: float = 0.0,
                      threshold: float = DEFAULT_THRESHOLD, field: str = "device_force",
                      body_contacts: np.ndarray | None = None, springs: int = 1) -> dict:
    """Finger ``i`` of the tick records: the distribution of |F(t) − F(t−1)| over the ticks
    where it touches something at t or t − 1 (free ticks would only dilute it), and the
    ticks above ``threshold`` with their causes. ``body_contacts`` (``body_contact_forces``)
    lets a jump of the touched body's contacts with other bodies be named. ``springs``: how
    many god-object springs the finger may have at once (1 for a sphere finger, whose seam
    springs share one; ``CONVEX_FINGER_SPRINGS`` for a convex finger's patch)."""
    if not threshold > 0.0:
        raise ValueError(f"threshold: expected a positive force in N, got {threshold!r}")
    force = np.ascontiguousarray(ticks[field][:, i])
    delta = np.zeros(len(force))
    if len(force) > 1:
        delta[1:] = np.linalg.norm(np.diff(force, axis=0), axis=1)
    contact = ticks["contact"][:, i]
    touching = contact >= 0
    in_contact = touching.copy()
    in_contact[1:] |= touching[:-1]
    in_contact[0] = False
    sample = delta[in_contact]
    onset = np.zeros(len(contact), dtype=bool)
    end = np.zeros(len(contact), dtype=bool)
    onset[1:] = touching[1:] & ~touching[:-1]
    end[1:] = ~touching[1:] & touching[:-1]
    state = ticks["state"][:, i]
    stick_slip = _transitions(state) & (state > 0)
    stick_slip[1:] &= state[:-1] > 0
    parts = _transitions(ticks["parts"][:, i]) & touching if "parts" in ticks.dtype.names else None
    if parts is not None:
        parts[1:] &= touching[:-1]
    handover = _transitions(ticks["adopted"])
    gate = _transitions(ticks["flags"] & FLAG_FORCES_ENABLED)
    safety_delta = np.zeros(len(force))
    if field != "force" and len(force) > 1:
        safety_delta[1:] = np.linalg.norm(np.diff(force - ticks["force"][:, i], axis=0), axis=1)
    impact = np.zeros(len(force), dtype=bool)     # the touched body's other contacts jumped
    if body_contacts is not None and len(force) > 1:
        body = np.where(touching, contact, np.concatenate(([-1], contact[:-1])))
        rows = np.nonzero(body[1:] >= 0)[0] + 1
        step = np.linalg.norm(body_contacts[rows, body[rows]] - body_contacts[rows - 1, body[rows]], axis=1)
        impact[rows] = step > threshold
    without_hand = delta.copy()          # |dF + k dHIP + c dv_HIP|: the change the hand did not make
    off_trend = delta.copy()             # the same, against the tick before's
    if len(force) > 1:
        step = np.zeros((len(force), 3))
        step[1:] = np.diff(ticks["hip"][:, i], axis=0)
        dt = np.ones(len(force))
        dt[1:] = np.diff(ticks["time"])
        velocity = step / np.where(dt > 0.0, dt, np.inf)[:, None]
        dv = np.zeros_like(velocity)
        dv[2:] = np.diff(velocity[1:], axis=0)
        change = np.zeros((len(force), 3))
        change[1:] = np.diff(force, axis=0)
        hand = stiffness * step + damping * dv
        without_hand = np.linalg.norm(_less_hand(change, hand, springs), axis=1)
        off_trend[2:] = np.linalg.norm(_less_hand(np.diff(change[1:], axis=0), np.diff(hand[1:], axis=0), springs),
                                       axis=1)
    jumps = []
    explained = set()                    # jump ticks with a cause: a trend after one still counts
    for t in np.nonzero(delta > threshold)[0].tolist():
        causes = []
        if not in_contact[t]:
            causes.append("free motion")
        if _within(onset, t):
            causes.append("contact onset")
        if _within(end, t):
            causes.append("contact end")
        if _within(stick_slip, t):
            causes.append("stick/slip")
        if parts is not None and _within(parts, t):
            causes.append("change of convex part")
        if _within(impact, t):
            causes.append("body contact")
        if _within(handover, t):
            causes.append("hand-over between threads")
        if _within(gate, t) or safety_delta[t] > 0.5 * delta[t]:
            causes.append("safety gate")
        if without_hand[t] <= threshold:
            causes.append("HIP motion")
        elif off_trend[t] <= threshold and (t < 1 or delta[t - 1] <= threshold or t - 1 in explained):
            causes.append("steady change")
        if causes:
            explained.add(t)
        jumps.append({"tick": int(ticks["tick"][t]), "time": float(ticks["time"][t]), "delta": float(delta[t]),
                      "causes": causes or [UNEXPLAINED]})
    worst = int(np.argmax(delta)) if len(delta) else 0
    pct = (lambda q: float(np.percentile(sample, q))) if len(sample) else (lambda q: 0.0)
    return {"contact_ticks": int(len(sample)), "p50": pct(50), "p99": pct(99), "p999": pct(99.9),
            "max": float(delta[worst]) if len(delta) else 0.0,
            "max_tick": int(ticks["tick"][worst]) if len(delta) else 0,
            "max_time": float(ticks["time"][worst]) if len(delta) else 0.0,
            "jumps": jumps, "delta": delta}


def force_continuity(rec, threshold: float = DEFAULT_THRESHOLD, field: str = "device_force") -> dict:
    """All fingers of a recording (``recording.Recording``): ``{"threshold", "field",
    "parts_recorded", "fingers": [{"name", ...finger_continuity}]}``."""
    scene = rec.header["scene"]
    scene_fingers = scene["fingers"]
    masses = [None if b["static"] else float(b["mass"]) for b in scene["bodies"]]
    body_contacts = body_contact_forces(rec.ticks, masses, scene["gravity"])
    fingers = []
    for i, name in enumerate(rec.finger_names):
        convex = scene_fingers[i].get("points") is not None
        r = finger_continuity(rec.ticks, i, float(scene_fingers[i]["stiffness"]),
                              float(scene_fingers[i]["damping"]), threshold, field, body_contacts,
                              springs=CONVEX_FINGER_SPRINGS if convex else 1)
        r["name"] = name
        fingers.append(r)
    return {"threshold": threshold, "field": field, "parts_recorded": "parts" in rec.ticks.dtype.names,
            "fingers": fingers}


def cause_counts(finger: dict) -> dict:
    """How many of a finger's jumps each cause explains (a jump may have several)."""
    counts = {}
    for j in finger["jumps"]:
        for c in j["causes"]:
            counts[c] = counts.get(c, 0) + 1
    return counts


def unexplained(result: dict) -> list:
    """(finger name, jump) for every jump with no cause."""
    return [(f["name"], j) for f in result["fingers"] for j in f["jumps"] if j["causes"] == [UNEXPLAINED]]


def summary_line(result: dict) -> str:
    """One line for ``grasp-lab info``: the largest change per finger and the jumps counted."""
    parts = []
    for f in result["fingers"]:
        n = len(f["jumps"])
        parts.append(f"{f['name']} max {f['max']:.3f} N at {f['max_time']:.3f} s, p99.9 {f['p999']:.3f} N, "
                     f"{n} above" + (f" ({sum(1 for j in f['jumps'] if j['causes'] == [UNEXPLAINED])} unexplained)"
                                     if n else ""))
    return f"per-tick |dF| (> {result['threshold']:g} N): " + "; ".join(parts)


def report(result: dict, max_jumps: int = 20) -> str:
    """The full text of ``grasp-lab continuity``: distribution and jumps per finger."""
    lines = [f"force continuity: per-tick change of {result['field']} per finger, over its contact ticks; "
             f"threshold {result['threshold']:g} N"]
    if not result["parts_recorded"]:
        lines.append("  (recorded before the parts field: a change of convex part cannot be named)")
    for f in result["fingers"]:
        lines.append(f"{f['name']}: {f['contact_ticks']} contact ticks, p50 {f['p50']:.4f} N, p99 {f['p99']:.4f} N, "
                     f"p99.9 {f['p999']:.4f} N, max {f['max']:.4f} N (tick {f['max_tick']}, {f['max_time']:.3f} s); "
                     f"{len(f['jumps'])} above the threshold")
        counts = cause_counts(f)
        if counts:
            lines.append("  causes: " + ", ".join(f"{c} {n}" for c, n in sorted(counts.items())))
        for j in f["jumps"][:max_jumps]:
            lines.append(f"  tick {j['tick']:>8} {j['time']:9.3f} s  {j['delta']:.4f} N  {', '.join(j['causes'])}")
        if len(f["jumps"]) > max_jumps:
            lines.append(f"  ... {len(f['jumps']) - max_jumps} more")
    return "\n".join(lines)
