"""Can this device do this task? A recorded grasp evaluated against device profiles (docs/devices.md,
"Can this device do this task?"). No bpy; ``grasp-lab fit`` and Blender's *Fit Devices* both call
``fit_recording``.

For each finger given to an end-effector and each tick: is its HIP inside the end-effector's workspace
(after the best rigid placement of the device frame), is the force it renders within the peak limit and,
through a first-order thermal model, the continuous limit, is the coupling stiffness within the device's
stable bound (scaled to the recording's haptic rate), do two end-effectors come closer than their size
allows, and do neighbouring fingers cross where the kinematics cannot.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from .devices.device_profiles import Profile

VERDICTS = ("fits", "placed", "fails")
REFERENCE_RATE = 1000.0         # Hz: the rate the profiles' stable stiffness is given at
YAW_STEP_DEG = 2.0              # the turns about the vertical tried when a translation alone does not fit
# Two numbers equal within this (m, N) are equal: a path that touches a wall exactly is inside.
TOLERANCE = 1e-9
CHECKS = ("workspace", "peak", "duty", "stiffness", "interference", "crossing")


class FitError(ValueError):
    """Bad input to the evaluation: one line saying what."""


# ----------------------------------------------------------------------------- the task

@dataclass
class Task:
    """What the device would have to render: per tick and finger the HIP, the force, whether the finger
    touches something and its coupling stiffness."""
    finger_names: list
    time: np.ndarray            # (T,) s
    hip: np.ndarray             # (T, F, 3) m, world
    force: np.ndarray           # (T, F, 3) N
    contact: np.ndarray         # (T, F) bool
    stiffness: np.ndarray       # (T, F) N/m
    haptic_rate: float          # Hz

    def index(self, name: str) -> int:
        if name not in self.finger_names:
            raise FitError(f"no finger {name!r} in the recording (its fingers: {', '.join(self.finger_names)})")
        return self.finger_names.index(name)


def task_from_recording(rec) -> Task:
    """A recording's task: its HIPs, coupling forces (what the finger exerts, as a device renders it),
    contacts, and each finger's stiffness over time (the header's, changed by ``parameter`` events)."""
    ticks = rec.ticks
    names = list(rec.finger_names)
    by_name = {f["name"]: f for f in rec.header["scene"]["fingers"]}
    k = np.empty((len(ticks), len(names)))
    for i, n in enumerate(names):
        k[:, i] = float(by_name[n]["stiffness"]) if n in by_name else 0.0
    time = np.asarray(ticks["time"], dtype=np.float64)
    for e in sorted((e for e in rec.events if e.get("kind") == "parameter" and e.get("name") == "stiffness"
                     and e.get("subject") in names), key=lambda e: float(e.get("time", 0.0))):
        first = int(np.searchsorted(time, float(e["time"]) - TOLERANCE))
        k[first:, names.index(e["subject"])] = float(e["value"])
    return Task(finger_names=names, time=time, hip=np.asarray(ticks["hip"], dtype=np.float64),
                force=np.asarray(ticks["force"], dtype=np.float64),
                contact=np.asarray(ticks["contact"]) >= 0, stiffness=k, haptic_rate=rec.haptic_rate)


# ----------------------------------------------------------------------------- placement

@dataclass
class Placement:
    """Where the device frame is in the scene: turned ``yaw_deg`` about the vertical, its origin at
    ``translation`` (world = R(yaw) q + translation, q in the device frame)."""
    yaw_deg: float = 0.0
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def rotation(self) -> np.ndarray:
        a = math.radians(self.yaw_deg)
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def to_device(self, p: np.ndarray) -> np.ndarray:
        """World points (..., 3) in the device frame."""
        return (p - self.translation) @ self.rotation

    def text(self) -> str:
        t = self.translation
        return (f"device frame at ({t[0]:.4f}, {t[1]:.4f}, {t[2]:.4f}) m"
                + (f", turned {self.yaw_deg:g} deg about z" if self.yaw_deg else ""))

    def as_dict(self) -> dict:
        return {"translation": [float(v) for v in self.translation], "yaw_deg": float(self.yaw_deg)}


def _circumball(points: np.ndarray):
    """The smallest ball with every point on its surface (its centre in their affine hull), or None."""
    p0 = points[0]
    if len(points) == 1:
        return p0.copy(), 0.0
    a = points[1:] - p0
    g = a @ a.T
    try:
        lam = np.linalg.solve(g, 0.5 * np.diag(g))
    except np.linalg.LinAlgError:
        return None
    c = p0 + lam @ a
    return c, float(np.max(np.sum((points - c) ** 2, axis=1)))


def _ball_of_few(points: np.ndarray):
    """The exact smallest enclosing ball of a handful of points: the smallest circumball, over their
    subsets of at most d + 1 points, that holds them all."""
    best = None
    d = points.shape[1]
    for k in range(1, min(len(points), d + 1) + 1):
        for sub in itertools.combinations(range(len(points)), k):
            ball = _circumball(points[list(sub)])
            if ball is None:
                continue
            c, r2 = ball
            if best is not None and r2 >= best[1]:
                continue
            if np.all(np.sum((points - c) ** 2, axis=1) <= r2 * (1 + 1e-12) + 1e-24):
                best = (c, r2)
    return best


def min_ball(points: np.ndarray):
    """The smallest ball (circle in 2-D) holding every point, exact: grow a support set with the point
    farthest outside the ball of the set, each time solved exactly, until none is outside. The radius
    grows strictly at each step, so it ends. Returns (centre, radius)."""
    pts = np.unique(np.asarray(points, dtype=np.float64), axis=0)
    support = pts[:1]
    c, r2 = pts[0].copy(), 0.0
    while True:
        d2 = np.sum((pts - c) ** 2, axis=1)
        k = int(np.argmax(d2))
        if d2[k] <= r2 * (1 + 1e-12) + 1e-24:
            return c, math.sqrt(r2)
        cand = np.vstack([support, pts[k]])
        c, r2 = _ball_of_few(cand)
        on = np.sum((cand - c) ** 2, axis=1) >= r2 * (1 - 1e-9) - 1e-24
        support = cand[on]


def _best_translation(profile: Profile, u: list):
    """The device-frame offset c (points q = u - c) that maximises the smallest workspace margin over
    every tick and end-effector, exact for each shape, and that margin. ``u``: per end-effector its
    points (T, 3) in the turned device frame."""
    ws = profile.workspaces
    x = np.concatenate([ui - w.center for ui, w in zip(u, ws)])     # every point relative to its centre
    shape = ws[0].shape
    if shape == "box":
        h = ws[0].size / 2
        hi, lo = x.max(axis=0), x.min(axis=0)
        c = (hi + lo) / 2
        return c, float(np.min(h - (hi - lo) / 2))
    if shape == "cylinder":
        centre, rho = min_ball(x[:, :2])
        zhi, zlo = x[:, 2].max(), x[:, 2].min()
        c = np.array([centre[0], centre[1], (zhi + zlo) / 2])
        return c, float(min(ws[0].radius - rho, ws[0].height / 2 - (zhi - zlo) / 2))
    centre, rho = min_ball(x)
    return centre, float(ws[0].radius - rho)


def _workspace_margins(profile: Profile, placement: Placement, paths: list) -> np.ndarray:
    """(T, E) signed margin of each end-effector's path in its workspace under ``placement``."""
    return np.stack([w.margin(placement.to_device(p)) for w, p in zip(profile.workspaces, paths)], axis=1)


def _yaws(profile: Profile, frame: Placement) -> list:
    """The turns about the vertical to try: the frame's own first; none other for a round workspace
    centred on one axis (turning it changes nothing)."""
    ws = profile.workspaces
    if ws[0].shape != "box" and all(np.allclose(w.center[:2], ws[0].center[:2]) for w in ws):
        return [frame.yaw_deg]
    return [frame.yaw_deg] + [(frame.yaw_deg + k * YAW_STEP_DEG) % 360.0
                              for k in range(1, int(round(360 / YAW_STEP_DEG)))]


def _placed(profile: Profile, paths: list, yaw: float, upto: int | None = None):
    """The best translation at turn ``yaw`` for the ticks before ``upto`` (all: None): (placement, margin)."""
    turn = Placement(yaw, np.zeros(3))
    u = [turn.to_device(p[:upto]) for p in paths]
    c, m = _best_translation(profile, u)
    return Placement(yaw, turn.rotation @ c), m


def best_placement(profile: Profile, paths: list, frame: Placement):
    """The placement of the device frame that maximises the smallest workspace margin over the task:
    the frame's own turn with the best translation (exact), else the best over turns about the
    vertical in ``YAW_STEP_DEG`` steps. Returns (placement, margin)."""
    best = None
    for yaw in _yaws(profile, frame):
        cand = _placed(profile, paths, yaw)
        if best is None or cand[1] > best[1] + TOLERANCE:
            best = cand
        if best[1] >= -TOLERANCE:
            break
    return best


def _prefix_fits(profile: Profile, u: list) -> int:
    """How many ticks from the first some translation keeps inside the workspaces (exact): the prefix
    ranges only grow, so a box is read off running extremes and a round shape is bisected."""
    ws = profile.workspaces
    x = np.stack([ui - w.center for ui, w in zip(u, ws)], axis=1)       # (T, E, 3)
    T = len(x)
    if ws[0].shape == "box":
        hi = np.maximum.accumulate(x.max(axis=1), axis=0)
        lo = np.minimum.accumulate(x.min(axis=1), axis=0)
        ok = np.all(hi - lo <= ws[0].size + 2 * TOLERANCE, axis=1)
        bad = np.nonzero(~ok)[0]
        return int(bad[0]) if len(bad) else T

    def fits(n):
        return _best_translation(profile, [ui[:n] for ui in u])[1] >= -TOLERANCE
    if fits(T):
        return T
    lo_n, hi_n = 0, T           # fits(lo_n) (0 ticks: trivially), not fits(hi_n)
    while hi_n - lo_n > 1:
        mid = (lo_n + hi_n) // 2
        lo_n, hi_n = (mid, hi_n) if fits(mid) else (lo_n, mid)
    return lo_n


def longest_placement(profile: Profile, paths: list, frame: Placement):
    """When no placement holds the whole task: the one that holds it longest from its start (the
    first tick it cannot hold is where the device's verdict fails), at the frame's turn or the best
    turn about the vertical. Returns (placement, margin over the ticks it holds)."""
    best = None
    for yaw in _yaws(profile, frame):
        turn = Placement(yaw, np.zeros(3))
        n = _prefix_fits(profile, [turn.to_device(p) for p in paths])
        if best is None or n > best[0]:
            best = (n, yaw)
    n, yaw = best
    return _placed(profile, paths, yaw, max(n, 1))


# ----------------------------------------------------------------------------- the checks

def duty(force_norm: np.ndarray, time: np.ndarray, tau: float, first_dt: float) -> np.ndarray:
    """The force's thermal RMS over time, (T, E): H' = (|F|^2 - H) / tau, from H = 0 before the first
    tick, each tick's force held over its interval (the exact solution for a held force); returns sqrt(H)."""
    dt = np.diff(time, prepend=time[0] - first_dt)
    alpha = 1.0 - np.exp(-np.maximum(dt, 0.0) / tau)
    f2 = force_norm ** 2
    h = np.empty_like(f2)
    acc = np.zeros(f2.shape[1])
    for n in range(len(f2)):
        acc = acc + alpha[n] * (f2[n] - acc)
        h[n] = acc
    return np.sqrt(h)


@dataclass
class FingerVerdict:
    finger: str
    verdict: str                    # fits | placed | fails
    first_fail_time: float | None = None
    first_fail_tick: int | None = None
    cause: str = ""
    check: str = ""                 # which check failed first (CHECKS), "" when it fits
    margin: float | None = None     # the failing check's margin at that tick (negative), or the smallest
    # workspace margin over the task when it fits (m)
    effector: int | None = None     # its end-effector (None: it has none)

    def as_dict(self) -> dict:
        return {"finger": self.finger, "verdict": self.verdict, "first_fail_time": self.first_fail_time,
                "cause": self.cause}


@dataclass
class ProfileResult:
    profile: Profile
    verdict: str
    placement: Placement
    placement_margin: float         # the smallest workspace margin under the placement (m)
    fingers: list                   # FingerVerdict per finger of the task evaluated
    timeline: dict = field(default_factory=dict)    # check -> (T, E) margins; "time" -> (T,)
    assigned: list = field(default_factory=list)    # task finger index per end-effector used

    def as_dict(self) -> dict:
        return {"profile": self.profile.name, "verdict": self.verdict, "placement": self.placement.as_dict(),
                "fingers": [f.as_dict() for f in self.fingers]}

    def rank_key(self):
        fails = [f for f in self.fingers if f.verdict == "fails"]
        first = min((f.first_fail_time for f in fails if f.first_fail_time is not None), default=math.inf)
        return (VERDICTS.index(self.verdict), len(fails), -first, -self.placement_margin)


def _causes(profile: Profile, names: list, values: dict, rate_bound: float):
    """A function giving the text of a check's failure for end-effector e at tick n."""
    def text(check, n, e):
        if check == "interference":
            other, d = values[check][0][n, e], values[check][1][n, e]
            return (f"{d * 1000:.1f} mm from {names[int(other)]}, closer than the end-effectors allow "
                    f"({2000 * profile.effector_radius:g} mm)")
        v = values[check][n, e]
        if check == "workspace":
            return f"leaves the workspace by {-v * 1000:.1f} mm"
        if check == "peak":
            return f"force {v:.3f} N above the {profile.peak_force:g} N peak"
        if check == "duty":
            return (f"duty {v:.3f} N rms above the {profile.continuous_force:g} N continuous limit "
                    f"(thermal time {profile.duty_time:g} s)")
        if check == "stiffness":
            return f"coupling stiffness {v:g} N/m above the {rate_bound:g} N/m stable bound"
        return f"crosses {names[int(v)]} (the kinematics cannot)"
    return text


def evaluate(task: Task, profile: Profile, fingers: list | None = None, frame: Placement | None = None) -> ProfileResult:
    """One profile against the task. ``fingers``: task finger names, one an end-effector in order
    (default: the task's first fingers, as many as the device has end-effectors; the others fail
    with no end-effector). ``frame``: the device frame's placement as set (default: the scene origin)."""
    frame = frame or Placement()
    n_eff = profile.end_effectors
    if fingers:
        if len(fingers) > n_eff:
            raise FitError(f"{profile.name}: {len(fingers)} fingers given ({', '.join(fingers)}), the device has "
                           f"{n_eff} end-effector{'s' if n_eff > 1 else ''}")
        if len(set(fingers)) != len(fingers):
            raise FitError(f"{profile.name}: a finger is given twice ({', '.join(fingers)})")
        assigned = [task.index(f) for f in fingers]
        unassigned = []
    else:
        assigned = list(range(min(n_eff, len(task.finger_names))))
        unassigned = list(range(len(assigned), len(task.finger_names)))
    names = [task.finger_names[i] for i in assigned]
    ws_eff = profile.workspaces[:len(assigned)]
    sub = Profile(**{**profile.__dict__, "workspaces": ws_eff, "end_effectors": len(assigned)})
    paths = [task.hip[:, i] for i in assigned]
    T, E = len(task.time), len(assigned)

    at_frame = _workspace_margins(sub, frame, paths)
    if np.min(at_frame) >= -TOLERANCE:
        placement, pmargin, moved = frame, float(np.min(at_frame)), False
    else:
        placement, pmargin = best_placement(sub, paths, frame)
        if pmargin < -TOLERANCE:
            placement, pmargin = longest_placement(sub, paths, frame)
        moved = True
    margins, values = {}, {}
    margins["workspace"] = _workspace_margins(sub, placement, paths)
    values["workspace"] = margins["workspace"]
    fnorm = np.linalg.norm(task.force[:, assigned], axis=-1)
    margins["peak"] = profile.peak_force - fnorm
    values["peak"] = fnorm
    rms = duty(fnorm, task.time, profile.duty_time, 1.0 / task.haptic_rate)
    margins["duty"] = profile.continuous_force - rms
    values["duty"] = rms
    bound = profile.stable_stiffness * task.haptic_rate / REFERENCE_RATE
    k = task.stiffness[:, assigned]
    margins["stiffness"] = np.where(task.contact[:, assigned], bound - k, np.inf)
    values["stiffness"] = k
    inter = np.full((T, E), np.inf)
    inter_other = np.zeros((T, E), dtype=np.int64)
    inter_dist = np.zeros((T, E))
    for a, b in itertools.combinations(range(E), 2):
        d = np.linalg.norm(paths[a] - paths[b], axis=-1)
        m = d - 2 * profile.effector_radius
        for me, other in ((a, b), (b, a)):
            closer = m < inter[:, me]
            inter[closer, me] = m[closer]
            inter_other[closer, me] = other
            inter_dist[closer, me] = d[closer]
    margins["interference"] = inter
    values["interference"] = (inter_other, inter_dist)
    cross = np.full((T, E), np.inf)
    cross_v = np.zeros((T, E), dtype=np.int64)
    if not profile.can_cross and E > 1:
        order = sorted(range(E), key=lambda e: (ws_eff[e].center[0], e))
        q = [placement.to_device(p) for p in paths]
        for left, right in zip(order, order[1:]):
            s = q[right][:, 0] - q[left][:, 0]
            # the order the fingers start in is the order of their arms (set up so): it must stay
            nonzero = np.nonzero(np.abs(s) > TOLERANCE)[0]
            if len(nonzero) and s[nonzero[0]] < 0:
                s = -s
            for me, other in ((left, right), (right, left)):
                lower = s < cross[:, me]
                cross[lower, me] = s[lower]
                cross_v[lower, me] = other
    margins["crossing"] = cross
    values["crossing"] = cross_v
    text = _causes(profile, names, values, bound)

    verdicts = []
    for e, fi in enumerate(assigned):
        first = None
        for check in CHECKS:
            bad = np.nonzero(margins[check][:, e] < -TOLERANCE)[0]
            if len(bad) and (first is None or bad[0] < first[0]):
                first = (int(bad[0]), check)
        if first is None:
            verdict = "placed" if moved else "fits"
            verdicts.append(FingerVerdict(task.finger_names[fi], verdict, margin=float(np.min(margins["workspace"][:, e])),
                                          effector=e))
        else:
            n, check = first
            m = margins[check][n, e]
            verdicts.append(FingerVerdict(task.finger_names[fi], "fails", float(task.time[n]), n, text(check, n, e),
                                          check, float(m), effector=e))
    for fi in unassigned:
        verdicts.append(FingerVerdict(task.finger_names[fi], "fails", float(task.time[0]), 0,
                                      f"no end-effector (the device has {n_eff})", "end_effectors", None))
    verdict = max((v.verdict for v in verdicts), key=VERDICTS.index) if verdicts else "fits"
    timeline = {"time": task.time, **{c: margins[c] for c in CHECKS}}
    return ProfileResult(profile, verdict, placement, pmargin, verdicts, timeline, assigned)


def rank(results: list) -> list:
    """The devices best first: fits, then placed, then fails (fewer failing fingers, later first failure)."""
    return sorted(results, key=lambda r: r.rank_key())


def report_lines(results: list) -> list:
    """The verdicts as the terminal shows them, best device first."""
    lines = []
    for r in rank(results):
        lines.append(f"{r.profile.name}: {r.verdict}" + (f" ({r.placement.text()})" if r.verdict == "placed" else ""))
        if r.verdict == "fails" and any(f.check == "workspace" for f in r.fingers):
            lines.append(f"  best placement: {r.placement.text()} (smallest workspace margin "
                         f"{r.placement_margin * 1000:.1f} mm)")
        for f in r.fingers:
            if f.verdict == "fails":
                at = "" if f.first_fail_tick is None else f" at {f.first_fail_time:.3f} s (tick {f.first_fail_tick})"
                lines.append(f"  {f.finger}: fails{at}: {f.cause}")
            else:
                lines.append(f"  {f.finger}: {f.verdict}, workspace margin {f.margin * 1000:.1f} mm")
    return lines


def result_json(results: list) -> dict:
    return {"profiles": [r.as_dict() for r in rank(results)]}


MARGIN_COLUMNS = ["profile", "time", "finger"] + [f"{c}_margin" for c in CHECKS]


def margin_rows(result: ProfileResult, task: Task, every: int = 1):
    """The timeline of margins, a row per tick (every ``every``-th) per finger: workspace (m), peak and
    duty (N), stiffness (N/m), interference and crossing (m); empty where the check does not apply."""
    tl = result.timeline
    for n in range(0, len(tl["time"]), every):
        for e, fi in enumerate(result.assigned):
            row = [result.profile.name, repr(float(tl["time"][n])), task.finger_names[fi]]
            for c in CHECKS:
                v = tl[c][n, e]
                row.append("" if not np.isfinite(v) else repr(float(v)))
            yield row


# ----------------------------------------------------------------------------- one implementation for
# the command line and Blender's Fit Devices

def parse_spec(spec: str):
    """``PROFILE[:FINGERS]`` (FINGERS comma-separated, one an end-effector in order) -> (Profile, names or None)."""
    from .devices.device_profiles import find
    name, _, fingers = spec.partition(":")
    if not name:
        raise FitError(f"--device {spec!r}: no profile named (PROFILE[:FINGERS])")
    names = [f.strip() for f in fingers.split(",")] if fingers else None
    if names is not None and not all(names):
        raise FitError(f"--device {spec!r}: an empty finger name in {fingers!r}")
    return find(name), names


def parse_frame(text: str) -> Placement:
    """``X,Y,Z[,YAW_DEG]``: where the device frame is in the scene."""
    try:
        v = [float(s) for s in text.split(",")]
    except ValueError:
        v = []
    if len(v) not in (3, 4) or not all(math.isfinite(x) for x in v):
        raise FitError(f"--frame {text!r}: expected X,Y,Z or X,Y,Z,YAW_DEG (metres, degrees)")
    return Placement(v[3] if len(v) == 4 else 0.0, np.array(v[:3]))


def fit_recording(rec, specs: list, frame=None):
    """Every ``PROFILE[:FINGERS]`` spec against a recording: (task, results ranked best first).
    ``frame``: the device frame's placement for all of them, or a list of one a spec (Blender's
    entries each have their own workspace frame)."""
    if not specs:
        raise FitError("no device given (--device PROFILE[:FINGERS]; grasp-lab fit --list names them)")
    parsed = [parse_spec(s) for s in specs]         # every spec checked before any work
    frames = frame if isinstance(frame, list) else [frame] * len(specs)
    task = task_from_recording(rec)
    for profile, names in parsed:
        for n in names or ():
            task.index(n)
    return task, rank([evaluate(task, p, names, f) for (p, names), f in zip(parsed, frames)])


def write_json(results: list, path: str) -> str:
    import json
    from .outputs import AtomicFile
    with AtomicFile(path) as out:
        out.file.write((json.dumps(result_json(results), indent=2) + "\n").encode())
    return path


def write_csv(results: list, task: Task, folder: str, every: int = 1) -> tuple:
    """DIR/margins.csv: the timeline of margins of every profile. Returns (path, rows)."""
    import csv
    import io
    import os
    from .outputs import AtomicFile
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, "margins.csv")
    rows = 0
    with AtomicFile(path) as out:
        text = io.TextIOWrapper(out.file, newline="", encoding="utf-8")
        w = csv.writer(text)
        w.writerow(MARGIN_COLUMNS)
        for r in results:
            for row in margin_rows(r, task, every):
                w.writerow(row)
                rows += 1
        text.flush()
        text.detach()
    return path, rows


# ----------------------------------------------------------------------------- the viewport's view of it
# (addon/device_fit.py draws what these compute; no bpy here)

def placement_from_matrix(matrix) -> Placement:
    """A workspace frame's 4x4 world matrix (an Empty's) as a placement: its location and its turn
    about z (the evaluation turns devices about the vertical only; a tilt is ignored)."""
    if matrix is None:
        return Placement()
    m = np.asarray(matrix, dtype=np.float64)
    return Placement(math.degrees(math.atan2(m[1, 0], m[0, 0])) % 360.0, m[:3, 3].copy())


def task_from_path(names: list, times, positions) -> Task:
    """A task from fingertip positions alone (a scene's animation, sampled): no force, no contact;
    only the workspace, interference and crossing checks have something to say about it."""
    pos = np.asarray(positions, dtype=np.float64)
    t = np.asarray(times, dtype=np.float64)
    rate = 1.0 / float(np.min(np.diff(t))) if len(t) > 1 and np.min(np.diff(t)) > 0 else REFERENCE_RATE
    T, F = pos.shape[:2]
    return Task(list(names), t, pos, np.zeros((T, F, 3)), np.zeros((T, F), bool), np.zeros((T, F)), rate)


@dataclass
class FrameExits:
    """Where a path leaves a device's workspaces with the device frame where it stands."""
    profile: Profile
    placement: Placement
    fingers: list                   # finger name per end-effector used
    outside: np.ndarray             # (T, E) bool: the sample is outside its end-effector's workspace
    first_exit: list                # per end-effector: the first sample index outside, or None


def exits_at_frame(task: Task, profile: Profile, fingers: list | None, frame: Placement) -> FrameExits:
    """The workspace check alone, at the frame as it stands (no placement searched): what the viewport
    colours red and the HUD reports."""
    names = fingers or task.finger_names[:profile.end_effectors]
    if len(names) > profile.end_effectors:
        raise FitError(f"{profile.name}: {len(names)} fingers given, the device has {profile.end_effectors}")
    idx = [task.index(n) for n in names]
    sub = Profile(**{**profile.__dict__, "workspaces": profile.workspaces[:len(idx)], "end_effectors": len(idx)})
    margins = _workspace_margins(sub, frame, [task.hip[:, i] for i in idx]) if idx else np.zeros((len(task.time), 0))
    outside = margins < -TOLERANCE
    first = [int(np.argmax(outside[:, e])) if outside[:, e].any() else None for e in range(len(idx))]
    return FrameExits(profile, frame, list(names), outside, first)


def exit_lines(exits: FrameExits, times) -> list:
    """The HUD's lines: which finger leaves which device's workspace first, and when."""
    lines = []
    for e, first in enumerate(exits.first_exit):
        if first is not None:
            lines.append((float(times[first]), f"{exits.profile.name}: {exits.fingers[e]} leaves its workspace at "
                                                f"{float(times[first]):.2f} s"))
    if not lines:
        return [f"{exits.profile.name}: every finger stays in its workspace"]
    return [text for _, text in sorted(lines)]


def workspace_triangles(ws, placement: Placement, segments: int = 32) -> np.ndarray:
    """A workspace's surface as world triangles (N, 3, 3) for drawing."""
    if ws.shape == "box":
        h = ws.size / 2
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64) * h
        quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
        tris = [[corners[a], corners[b], corners[c]] for q in quads for a, b, c in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))]
        local = np.array(tris)
    elif ws.shape == "cylinder":
        a = np.linspace(0, 2 * np.pi, segments + 1)
        ring = np.stack([ws.radius * np.cos(a), ws.radius * np.sin(a)], axis=1)
        lo, hi = -ws.height / 2, ws.height / 2
        tris = []
        for (x0, y0), (x1, y1) in zip(ring[:-1], ring[1:]):
            p00, p01, p10, p11 = [x0, y0, lo], [x0, y0, hi], [x1, y1, lo], [x1, y1, hi]
            tris += [[p00, p10, p11], [p00, p11, p01], [[0, 0, lo], p10, p00], [[0, 0, hi], p01, p11]]
        local = np.array(tris, dtype=np.float64)
    else:
        th = np.linspace(0, np.pi, segments // 2 + 1)
        ph = np.linspace(0, 2 * np.pi, segments + 1)
        p = ws.radius * np.stack([np.sin(th)[:, None] * np.cos(ph), np.sin(th)[:, None] * np.sin(ph),
                                  np.cos(th)[:, None] * np.ones_like(ph)], axis=-1)
        tris = []
        for i in range(len(th) - 1):
            for j in range(len(ph) - 1):
                tris += [[p[i, j], p[i + 1, j], p[i + 1, j + 1]], [p[i, j], p[i + 1, j + 1], p[i, j + 1]]]
        local = np.array(tris)
    return (local + ws.center) @ placement.rotation.T + placement.translation
