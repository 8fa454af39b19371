"""What the live view says about the grasp, bpy-free: the analysis of each display update
(``analysis.analyse`` on the session's snapshot), the HUD and sidebar text, the colour of a
god-object by its friction use and the geometry of the weakest-wrench arrow and ring.

The analysis runs here, on the main thread, once per display update; the haptic loop never
waits for it (it only publishes the snapshot)."""
from __future__ import annotations

import collections
import math
import re
import time

import numpy as np

from . import analysis, defaults
from .recording import STATE_NAMES

FREE_COLOR = (0.10, 0.45, 1.00, 1.0)     # a god-object touching nothing: the god-object blue
# Friction use |Ft| / (mu |Fn|): 0 green (far from slip), 0.5 yellow, 1 red (at slip).
_GREEN, _YELLOW, _RED = (0.10, 0.85, 0.25), (1.00, 0.85, 0.10), (1.00, 0.10, 0.10)
WEAKEST_COLOR = (1.00, 0.20, 0.90, 1.0)  # magenta: no other overlay uses it


def friction_color(use: float) -> tuple:
    """RGBA for a friction use: green at 0, yellow at 0.5, red at 1 and beyond (and when
    the use is not a number: a contact with no normal force cannot hold anything)."""
    u = 1.0 if not math.isfinite(use) else min(max(use, 0.0), 1.0)
    a, b, k = (_GREEN, _YELLOW, u / 0.5) if u < 0.5 else (_YELLOW, _RED, (u - 0.5) / 0.5)
    return tuple(a[i] + k * (b[i] - a[i]) for i in range(3)) + (1.0,)


def friction_colors(use) -> np.ndarray:
    """friction_color of every element of ``use`` (any shape): RGBA in a last axis."""
    use = np.asarray(use, dtype=np.float64)
    u = np.where(np.isfinite(use), np.clip(use, 0.0, 1.0), 1.0)
    low = (u < 0.5)[..., None]
    a = np.where(low, _GREEN, _YELLOW)
    b = np.where(low, _YELLOW, _RED)
    k = np.where(low[..., 0], u / 0.5, (u - 0.5) / 0.5)[..., None]
    return np.concatenate([a + k * (b - a), np.ones(u.shape + (1,))], axis=-1)


def finger_color_series(table, rows, n_fingers: int) -> np.ndarray:
    """finger_colors at each record of ``rows`` (in order, each once) of the recording that
    ``table`` (analysis.analyse_recording) was made of: (len(rows), n_fingers, 4)."""
    rows = np.asarray(rows, dtype=np.int64)
    out = np.tile(np.asarray(FREE_COLOR, dtype=np.float64), (len(rows), n_fingers, 1))
    count = np.asarray(table.count, dtype=np.int64)
    if count.sum() == 0:
        return out
    set_of = np.repeat(np.arange(len(count)), count)        # each contact row's set
    contact = (np.asarray(table.first, dtype=np.int64)[set_of]
               + np.arange(len(set_of)) - np.repeat(np.cumsum(count) - count, count))
    at = np.searchsorted(rows, np.asarray(table.snapshot, dtype=np.int64)[set_of])
    # in order, so that a finger in two sets takes the last, as finger_colors does
    for r, f, c in zip(at, np.asarray(table.finger)[contact], friction_colors(np.asarray(table.friction_use)[contact])):
        out[r, f] = c
    return out


def finger_colors(grasps, n_fingers: int) -> list:
    """One RGBA per finger: by friction use in contact with a held body, else FREE_COLOR."""
    colors = [FREE_COLOR] * n_fingers
    for g in grasps:
        for c in g.contacts:
            colors[c.finger] = friction_color(c.friction_use)
    return colors


COSTS_KEPT = 100_000           # about 55 min of display updates at 30 Hz


class GraspMonitor:
    """The analysis of a session's snapshots, one display update at a time.

    The load's inertial part needs each body's centre-of-mass acceleration: it is the change
    of the centre-of-mass velocity between two display updates over the time between them
    (the haptic loop's simulated time), zero on the first update."""

    def __init__(self, models, finger_radii, gravity=None, edges: int = 8, torsions=None):
        self.models = list(models)
        self.finger_radii = np.asarray(finger_radii, dtype=np.float64).reshape(-1)
        self.torsions = None if torsions is None else np.asarray(torsions, dtype=np.float64)  # soft fingertips' rho
        self.gravity = tuple(float(g) for g in (defaults.world("gravity") if gravity is None else gravity))
        self.edges = int(edges)
        self.grasps = []            # the last update's BodyGrasp list
        self.cost_s = 0.0           # wall time of the last update (analysis included)
        # The last COSTS_KEPT updates' times, seconds: bounded, so an hour-long session keeps a
        # few MB at most (a list grew by 7 MB an hour).
        self.costs = collections.deque(maxlen=COSTS_KEPT)
        self.error = ""             # why the last update has no analysis (a refused contact set)
        self._prev = None           # (time, centre-of-mass velocities)
        self._acc = None
        self._memo = {}             # the last update's core answers per contact set (analysis.analyse_arrays)

    def accelerations(self, snap) -> np.ndarray:
        if not self.models:                 # fingers only: nothing to hold
            return np.zeros((0, 3))
        v = analysis.com_velocities(self.models, snap.poses, np.asarray(snap.velocities, dtype=np.float64))
        if self._prev is not None and snap.time > self._prev[0]:
            self._acc = (v - self._prev[1]) / (snap.time - self._prev[0])
        elif self._acc is None or self._acc.shape != v.shape:
            self._acc = np.zeros_like(v)
        if self._prev is None or snap.time != self._prev[0]:
            self._prev = (snap.time, v)
        return self._acc

    def update(self, snap) -> list:
        t0 = time.perf_counter()
        acc = self.accelerations(snap)
        self.grasps, self.error = [], ""
        if np.any(snap.contacts >= 0):
            try:
                self.grasps = analysis.analyse(self.models, snap.poses, snap.god_objects, snap.spring_forces,
                                               snap.normals, snap.finger_states, snap.contacts,
                                               self.finger_radii, accelerations=acc, gravity=self.gravity,
                                               edges=self.edges, volume=False,  # the HUD shows no volume
                                               memo=self._memo, reuse=True,
                                               patches=getattr(snap, "patches", None), torsions=self.torsions)
            except ValueError as ex:    # one display update without numbers; the session goes on
                self.error = str(ex)
        self.cost_s = time.perf_counter() - t0
        self.costs.append(self.cost_s)
        return self.grasps


def _ratio(x: float) -> str:
    return "∞" if not math.isfinite(x) else f"{x:.1f}×"


NBSP = "\u00a0"     # joins what wrapping must not split: a number and its unit, a finger's entry


def _keep(text: str) -> str:
    return text.replace(" ", NBSP)


FIRM_USE = 0.5      # every contact using under half its friction: held firmly
BARELY_USE = 0.8    # a contact using this much of its friction is close to slipping
NEAR_NOTHING_USE = 0.01     # under this share of its friction, no finger is worth naming


def verdict(grasp, body_name: str, finger_names) -> str:
    """One line in words for a body the fingers touch: whether it is held, how firmly, and
    what would make it slip first. Held means no contact sliding and the grip at least the
    load; firmly, in force closure with every contact under FIRM_USE of its friction;
    barely, a contact at BARELY_USE or more. The first to slip is the contact using the
    largest share of its friction (a contact without normal force counts as fully used); none
    is named while every contact uses under NEAR_NOTHING_USE."""
    uses = [(c.friction_use if math.isfinite(c.friction_use) else math.inf, c) for c in grasp.contacts]
    worst_use, worst = max(uses, key=lambda u: u[0]) if uses else (0.0, None)
    if any(c.state == 2 for c in grasp.contacts):
        word = "slipping"
    elif not grasp.grip_ratio >= 1.0:
        word = "not held (grip below load)"
    elif grasp.force_closure and worst_use < FIRM_USE:
        word = "held firmly"
    elif worst_use < BARELY_USE:
        word = "held" if grasp.force_closure else "held, but free to turn (not in force closure)"
    else:
        word = "held, barely"
    if worst is None:
        return f"{body_name}: {word}"
    if worst_use < NEAR_NOTHING_USE:
        return f"{body_name}: {word}; no finger near slipping"      # resting on a table, squeezed
    who = finger_names[worst.finger]
    return (f"{body_name}: {word}; {_keep(who)} slips first "
            f"({_keep(f'{_percent(worst.friction_use)} of its friction')})")


def verdict_lines(grasps, body_names, finger_names) -> list:
    """verdict for each touched body; one line saying so when no finger touches a body."""
    if not grasps:
        return ["No finger on a body"]
    return [verdict(g, body_names[g.body], finger_names) for g in grasps]


class _Baked:
    """What verdict reads of a grasp, from a baked frame's properties."""

    def __init__(self, **kw):
        self.__dict__.update(kw)


def baked_verdict_lines(bodies, fingers) -> list:
    """verdict_lines at a baked frame, from the bake's animated properties there: ``bodies``
    [(name, gl_held, gl_closure, gl_grip_load)], ``fingers`` [(name, gl_state, gl_friction_use)].
    The bake keeps no finger-to-body link, so each held body is judged with every finger in
    contact (exact for one body; a scene with several reads the fingers of all of them)."""
    names = [f[0] for f in fingers]
    touching = [_Baked(finger=k, state=int(round(state)), friction_use=use if use >= 0 else math.nan)
                for k, (_, state, use) in enumerate(fingers) if int(round(state)) > 0]
    grasps = [_Baked(body=i, contacts=touching, force_closure=closure > 0.5,
                     grip_ratio=ratio if ratio >= 0 else math.inf)
              for i, (_, held, closure, ratio) in enumerate(bodies) if held > 0.5]
    return verdict_lines(grasps, [b[0] for b in bodies], names)


def grasp_lines(grasps, body_names, finger_names) -> list:
    """The grasp, per held body: the verdict in words first, then the numbers: closure and
    epsilon, the force it resists in its weakest direction, grip against load, the finger
    closest to slipping; then each finger's state and friction use. ``wrap`` never splits a
    value from its unit or a finger's entry (they are joined by no-break spaces)."""
    if not grasps:
        return ["No finger on a body"]
    lines = verdict_lines(grasps, body_names, finger_names)
    for g in grasps:
        closure = "closure yes" if g.force_closure else "closure no"
        lines.append(f"{body_names[g.body]}: {closure}  {_keep(f'ε {g.epsilon:.3f}')}  "
                     f"resists {_keep(f'{g.resisted_force:.2f} N')}")
        lines.append(f"  grip {_keep(f'{g.grip_force:.2f} N')} / load {_keep(f'{g.load_force:.2f} N')} "
                     f"= {_ratio(g.grip_ratio)}")
        if g.min_slip_finger >= 0:
            lines.append(f"  slip margin {_keep(f'{g.min_slip_margin:.2f} N')} at "
                         f"{_keep(finger_names[g.min_slip_finger])}")
        fingers = [_keep(f"{finger_names[c.finger]} {STATE_NAMES[c.state] if 0 <= c.state < 3 else c.state} "
                         f"{_percent(c.friction_use)}") for c in g.contacts]
        lines.append("  " + "   ".join(fingers))
    return lines


def _percent(use: float) -> str:
    return "—" if not math.isfinite(use) else f"{100 * use:.0f}%"


def force_output(runtime_enabled: bool, devices_enabled=None) -> str:
    """One statement of whether forces reach the hand: the haptic loop's safety layer
    (watchdog, stale input) and, with devices, whether any device has its forces enabled."""
    if not runtime_enabled:
        return "forces held at zero (safety: late loop or stale input)"
    if devices_enabled is not None and len(devices_enabled) and not any(devices_enabled):
        return "forces off (no device enabled)"
    return "forces on"


def wrap(lines, width, measure=len) -> list:
    """Lines wrapped at spaces so that ``measure(line) <= width`` (characters by default; a
    panel passes its width in pixels and the interface font's measure). A continuation is
    indented two more spaces than its line; a word wider than the width gets a line of its
    own, whole."""
    out = []
    for line in lines:
        body = line.lstrip(" ")
        indent = line[:len(line) - len(body)]
        pieces = re.split(r"( +)", body)
        current, gap = indent + pieces[0], ""
        for k in range(1, len(pieces), 2):
            sep, word = pieces[k], pieces[k + 1]
            if measure(current + sep + word) <= width:
                current += sep + word
            else:
                out.append(current)
                current = indent + "  " + word
        out.append(current)
    return out


def wrap_path(path: str, width, measure=len) -> list:
    """A file path in lines of at most ``width`` (as ``wrap``), broken after a separator so
    that every piece can be read and the whole path is there; a name longer than the width
    gets a line of its own."""
    parts = [p + "/" for p in path.split("/")[:-1]] + [path.split("/")[-1]]
    out, current = [], ""
    for part in (p for p in parts if p):
        if current and measure(current + part) > width:
            out.append(current)
            current = ""
        current += part
    return out + ([current] if current else [])


def weakest_geometry(grasp, length: float | None = None, segments: int = 48, scale: float = 1.0,
                     outside: bool = False):
    """Where to draw the weakest wrench of a grasp in force closure, world coordinates:
    ``arrow`` (start, end): from the centre of mass along its force part, ``length`` times
    the part's norm (default twice the torque radius); ``ring`` (segments + 1, 3): a closed
    circle about its torque part's axis, radius the radius times the part's norm, and
    ``ring_tip`` (point, tangent): where and which way the ring turns (right hand about the
    axis). ``scale`` multiplies both sizes. ``outside``: drawn around the body instead of over
    it (the viewport's way, so that it never hides the object): the arrow starts on the body's
    bounding sphere and the ring's radius is the sphere's plus the scaled one. None when the
    grasp is not in closure (no weakest direction)."""
    w = np.asarray(grasp.weakest, dtype=np.float64)
    if not grasp.force_closure or not np.all(np.isfinite(w)) or not np.any(w):
        return None
    center = np.asarray(grasp.center, dtype=np.float64)
    radius = float(grasp.radius)
    length = scale * (2.0 * radius if length is None else float(length))
    force, torque = w[:3], w[3:]
    f = float(np.linalg.norm(force))
    start = center + radius * force / f if outside and f > 1e-12 else center
    out = {"arrow": (start, start + length * force), "ring": None, "ring_tip": None}
    t = float(np.linalg.norm(torque))
    if t > 1e-9:
        axis = torque / t
        u = np.cross(axis, (1.0, 0.0, 0.0) if abs(axis[0]) < 0.9 else (0.0, 1.0, 0.0))
        u /= np.linalg.norm(u)
        v = np.cross(axis, u)
        r = scale * radius * t + (radius if outside else 0.0)
        a = np.linspace(0.0, 2.0 * math.pi, segments + 1)
        out["ring"] = center + r * (np.cos(a)[:, None] * u + np.sin(a)[:, None] * v)
        out["ring_tip"] = (center + r * u, v)      # d/da at a = 0: +v, counter-clockwise about axis
    return out


WEAKEST_LEGEND = "magenta: the push (arrow) and twist (ring) the grasp resists least"
