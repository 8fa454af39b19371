"""Re-simulation: a recording's HIP streams replayed through the core, with overrides.

With no override a recording is reproduced bit for bit: every tick's ``World.state_hash()``
equals the recorded one. A synchronous session (EXEC) replays through synchronous steps; a
threaded (live) one on the manual clock with its recorded hand-over schedule. Otherwise the
divergence report says when and where the two runs part (and what could not be replayed).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import defaults
from .inputs import turning_fingers
from .limits import DEFAULT_MAX_SIZE, check_memory, check_recording_size, check_set_value
from .recording import EventDetector, Recording, RecordingWriter, make_header, scene_from_dict
from .runner import RUNTIME_PHYSICS
from .scene import build_world, torsion_problem

OBJECT_KEYS = ("mass", "mu_s", "mu_d", "viscosity", "radius", "stiffness", "damping", "cursor_mass", "renderer",
               "torsion")
BODY_KEYS = ("mass", "mu_s", "mu_d", "viscosity")
FINGER_KEYS = ("radius", "stiffness", "damping", "cursor_mass", "renderer", "torsion")   # torsion: Soft Tip Radius
SCENE_KEYS = ("haptic_rate", "gravity", "gyroscopic")


class OverrideError(ValueError):
    """A KEY=VALUE that is malformed (usage) or names nothing in the scene."""


@dataclass
class Override:
    key: str                # "haptic_rate" | "gravity" | "gyroscopic" | property name
    value: object           # float, (x, y, z) or bool
    obj: str = ""           # object name for an object property, "" for a scene setting

    def __str__(self):
        target = f"{self.obj}.{self.key}" if self.obj else self.key
        return f"{target}={self.value}"


def parse_override(text: str) -> Override:
    """``OBJECT.PROPERTY=VALUE`` or ``haptic_rate=HZ`` / ``gravity=X,Y,Z`` / ``gyroscopic=0|1``."""
    if "=" not in text:
        raise OverrideError(f"--set {text!r}: expected KEY=VALUE")
    key, value = text.split("=", 1)
    key, value = key.strip(), value.strip()
    try:
        if key in SCENE_KEYS:
            if key == "gravity":
                g = tuple(float(v) for v in value.split(","))
                if len(g) != 3:
                    raise ValueError
                bad = next((why for why in map(lambda v: check_set_value(key, v), g) if why), "")
                if bad:
                    raise OverrideError(f"--set {text!r}: {bad}")
                return Override(key, g)
            if key == "gyroscopic":
                if value not in ("0", "1"):
                    raise ValueError
                return Override(key, value == "1")
            hz = float(value)
            if check_set_value(key, hz):
                raise OverrideError(f"--set {text!r}: {check_set_value(key, hz)}")
            return Override(key, hz)
    except ValueError as ex:
        if isinstance(ex, OverrideError):
            raise
        want = {"gravity": "X,Y,Z in m/s^2", "gyroscopic": "0 or 1", "haptic_rate": "a rate in Hz"}[key]
        raise OverrideError(f"--set {text!r}: {key} expects {want}") from None
    obj, dot, prop = key.rpartition(".")
    if not dot or not obj:
        raise OverrideError(f"--set {text!r}: expected OBJECT.PROPERTY=VALUE (PROPERTY one of "
                            f"{', '.join(OBJECT_KEYS)}) or a scene setting ({', '.join(SCENE_KEYS)})")
    if prop not in OBJECT_KEYS:
        raise OverrideError(f"--set {text!r}: unknown property {prop!r} (one of {', '.join(OBJECT_KEYS)})")
    if prop == "renderer":
        if value not in defaults.renderers():
            raise OverrideError(f"--set {text!r}: renderer expects {' or '.join(defaults.renderers())}")
        return Override(prop, value, obj)
    try:
        v = float(value)
    except ValueError:
        raise OverrideError(f"--set {text!r}: {prop} expects a number") from None
    if check_set_value(prop, v):
        raise OverrideError(f"--set {text!r}: {check_set_value(prop, v)}")
    return Override(prop, v, obj)


def apply_to_desc(desc, overrides) -> None:
    """Overrides on a prepared SceneDesc (a recording's). Raises OverrideError naming what is missing."""
    for o in overrides:
        if not o.obj:
            setattr(desc, o.key, o.value)
            continue
        body = next((b for b in desc.bodies if b.name == o.obj), None)
        finger = next((f for f in desc.fingers if f.name == o.obj), None)
        if body is None and finger is None:
            raise OverrideError(f"--set {o}: no body or finger named {o.obj!r} in the recording "
                                f"(bodies: {', '.join(b.name for b in desc.bodies) or 'none'}; fingers: "
                                f"{', '.join(f.name for f in desc.fingers) or 'none'})")
        if body is not None and o.key in BODY_KEYS:
            if o.key == "mass":
                if body.static:
                    raise OverrideError(f"--set {o}: {o.obj!r} is static (no mass)")
                mp = body.mass_properties
                scale = o.value / mp.mass
                mp.mass, mp.inertia = o.value, np.asarray(mp.inertia) * scale
                body.mass = o.value
            else:
                setattr(body, o.key, o.value)
        elif finger is not None and o.key in FINGER_KEYS:
            setattr(finger, o.key, o.value)
        else:
            kind = "body" if body is not None else "finger"
            raise OverrideError(f"--set {o}: {o.obj!r} is a {kind}; {o.key} is not a {kind} property")
    for b in desc.bodies:       # after all of them: mu_s and mu_d may change together
        if not (0 <= b.mu_d <= b.mu_s):
            raise OverrideError(f"--set: {b.name!r} needs 0 <= mu_d <= mu_s (now mu_s={b.mu_s}, mu_d={b.mu_d})")
    for f in desc.fingers:      # a soft tip on a mesh finger, or with the cursor renderer
        if why := torsion_problem(f):
            raise OverrideError(f"--set: finger {f.name!r}: {why}")


@dataclass
class Divergence:
    identical: bool                 # every tick's state hash equal (bit for bit)
    ticks: int                      # ticks compared
    tolerance: float
    first_tick: int | None = None   # first tick where a body or god-object is off by > tolerance
    first_time: float | None = None
    first_subject: str = ""
    first_distance: float = 0.0
    first_hash_tick: int | None = None   # first tick whose state hash differs
    worst: list = field(default_factory=list)        # (subject, max distance, at time)
    timeline: list = field(default_factory=list)     # (time, max body distance, max finger distance)
    note: str = ""                  # what of the recording could not be replayed as it ran
    damage: str = ""                # the recording's damage: what was read is not the whole session

    def report(self) -> str:
        if self.identical and self.damage:
            return (f"identical over the {self.ticks} ticks that could be read, which are not the whole "
                    f"session: the recording is damaged ({self.damage})")
        if self.identical:
            return "identical"
        lines = [f"diverged: {self.ticks} ticks compared, tolerance {self.tolerance:g} m"]
        if self.note:
            lines.append(self.note)
        if self.first_hash_tick is not None:
            lines.append(f"state hashes differ from tick {self.first_hash_tick}")
        if self.first_tick is None:
            lines.append(f"no body or god-object is ever more than {self.tolerance:g} m off")
        else:
            lines.append(f"first over tolerance: tick {self.first_tick} (t = {self.first_time:.4f} s), "
                         f"{self.first_subject} off by {self.first_distance:.3g} m")
        lines.append("largest distance per body / finger:")
        for subject, dist, t in self.worst:
            lines.append(f"  {subject:<24} {dist:10.3g} m  at t = {t:.4f} s")
        lines.append("over time (largest body distance, largest god-object distance):")
        for t, db, df in self.timeline:
            lines.append(f"  t = {t:8.3f} s  {db:10.3g} m  {df:10.3g} m")
        return "\n".join(lines)


def _check_size(ticks: int, bytes_per_tick: int, record_path, max_size) -> None:
    """The new run in memory (its records, the comparison's and the writer's working copies:
    3 x, bench/bench_memory.py); its recording under max_size and the free space."""
    check_memory("resim", ticks, bytes_per_tick, copies=3)
    if record_path:
        check_recording_size("--record", record_path, ticks, bytes_per_tick, max_size)


@dataclass
class ResimResult:
    ticks: np.ndarray               # the new run's tick records
    divergence: Divergence
    header: dict                    # the new run's header (overrides applied)
    path: str = ""                  # where the new run was written, if asked


def compare(recorded: Recording, new_ticks: np.ndarray, tolerance: float, same_rate: bool,
            samples: int = 10) -> Divergence:
    names_b, names_f = recorded.body_names, recorded.finger_names
    if same_rate:
        n = min(len(recorded.ticks), len(new_ticks))
        old = recorded.ticks[:n]
        new = new_ticks[:n]
    else:   # the recorded tick at or before each new tick's time
        new = new_ticks
        old = recorded.ticks[recorded.sample(new_ticks["time"])]
        n = len(new)
    damage = "; ".join(recorded.damage)
    if n == 0:
        return Divergence(identical=len(recorded.ticks) == len(new_ticks), ticks=0, tolerance=tolerance,
                          damage=damage)
    hashes_equal = old["state_hash"] == new["state_hash"]
    identical = bool(same_rate and len(recorded.ticks) == len(new_ticks) and hashes_equal.all())
    d_body = np.linalg.norm(old["pose"][:, :, :3] - new["pose"][:, :, :3], axis=2)           # (n, nb)
    d_fing = np.linalg.norm(old["god_object"] - new["god_object"], axis=2)                   # (n, nf)
    dist = np.concatenate([d_body, d_fing], axis=1)
    subjects = [f"body {b}" for b in names_b] + [f"finger {f}" for f in names_f]
    div = Divergence(identical=identical, ticks=n, tolerance=tolerance, damage=damage)
    if not hashes_equal.all():
        div.first_hash_tick = int(new["tick"][np.argmin(hashes_equal)])
    over = dist > tolerance
    if dist.size and over.any():
        k = int(np.argmax(over.any(axis=1)))
        j = int(np.argmax(dist[k]))
        div.first_tick, div.first_time = int(new["tick"][k]), float(new["time"][k])
        div.first_subject, div.first_distance = subjects[j], float(dist[k, j])
    times = new["time"]
    for j, subject in enumerate(subjects):
        k = int(np.argmax(dist[:, j]))
        div.worst.append((subject, float(dist[k, j]), float(times[k])))
    edges = np.linspace(0, n, min(samples, n) + 1).astype(int)
    for a, b in zip(edges[:-1], edges[1:]):
        db = float(d_body[a:b].max()) if d_body.size else 0.0
        df = float(d_fing[a:b].max()) if d_fing.size else 0.0
        div.timeline.append((float(times[b - 1]), db, df))
    return div


STRETCH = 8192      # steps replayed in C per call (a few ms: Python handles signals in between)


def replay(world, hips: np.ndarray, dt: float, has_start: bool = True, before: dict | None = None,
           turns: np.ndarray | None = None) -> np.ndarray:
    """Step ``world`` once per row of ``hips`` ((steps, fingers, 3): each step's HIPs) and
    return every tick's record; tick 0, the state before the first step, only ``if has_start``.
    The stretches run in C (``World.step_hips``); ``before`` ({step: f(world)}, 0-based steps)
    runs Python before those steps: the sweep's pushes. ``turns`` ((steps, fingers, 4) or None;
    ``recorded_turns``): each step's HIP orientations of the turning fingers (a hand's bones, a
    turning palm), set before every step as a session's driver does; the steps then run one a
    call."""
    n = len(hips)
    ticks = np.empty(n + 1, dtype=world.tick_dtype())       # every byte of a record is written
    world._tick_record(ticks[:1], 0)
    if turns is not None:
        for k in range(n):
            if before and k in before:
                before[k](world)
            set_turns(world, hips, turns, k)
            world.step_hips(hips[k:k + 1], dt, ticks[k + 1:k + 2], first_tick=k + 1)
        return ticks if has_start else ticks[1:]
    k = 0
    for stop in sorted(k for k in (before or ()) if 0 <= k < n) + [n]:
        while k < stop:     # at most STRETCH steps a call: signals (Ctrl-C, SIGTERM) are seen between
            end = min(stop, k + STRETCH)
            world.step_hips(hips[k:end], dt, ticks[k + 1:end + 1], first_tick=k + 1)
            k = end
        if stop < n:
            before[stop](world)
    return ticks if has_start else ticks[1:]


def set_turns(world, hips, turns, k: int) -> None:
    """Step ``k``'s orientations of the fingers that turn (``turns[k]``, NaN rows: fingers that
    do not), before the step, as a session's driver sets them."""
    for f in np.flatnonzero(~np.isnan(turns[k, :, 0])):
        world.set_finger_pose(int(f), tuple(hips[k, f]), tuple(turns[k, f]))


def recorded_turns(recorded: Recording, same_rate: bool, has_start: bool):
    """The recorded HIP orientations to replay with, when some finger turns (a hand's bones, a
    turning palm); None when none does (replayed in C as before) or the rate changes (not
    resampled: at another rate the fingers keep their start orientations, docs/hands.md)."""
    names = recorded.ticks.dtype.names or ()
    if "orientation" not in names or not same_rate:
        return None
    q = np.array(recorded.ticks["orientation"], dtype=np.float64)
    turning = turning_fingers(q)
    if not turning.any():
        return None
    q[:, ~turning] = np.nan          # set_turns leaves those alone
    return q[1:] if has_start else q


def runtime_schedule(recorded: Recording, same_rate: bool):
    """A recording of the threaded runtime replays on its hand-over schedule (the object
    manager's ticks and the haptic tick each result was taken at, in every tick record) when it
    has one and every tick is there. Returns (the runtime settings to replay with, or None;
    why not, "" when it is not a threaded recording)."""
    rt = recorded.header.get("runtime") or {}
    if not rt.get("threaded"):
        return None, ""
    if "object_tick" not in (recorded.ticks.dtype.names or ()):
        return None, ("recorded by the threaded runtime before its hand-over schedule was recorded: "
                      "replayed through synchronous steps, which its object manager does not follow bit for bit")
    if not same_rate:
        return None, ("recorded by the threaded runtime: at another haptic_rate its hand-over schedule does "
                      "not apply; replayed through synchronous steps")
    ticks = recorded.ticks["tick"].astype(np.int64)
    gaps = np.flatnonzero(np.diff(ticks) != 1)
    if int(ticks[0]) > 1 or len(gaps):
        where = f"after tick {int(ticks[gaps[0]])}" if len(gaps) else f"before tick {int(ticks[0])}"
        return None, (f"ticks of the threaded runtime are missing ({where}; dropped while recording): its "
                      f"hand-over schedule cannot be replayed; replayed through synchronous steps")
    rate = recorded.haptic_rate
    # the watchdog changes only device forces, but the runtime refuses one shorter than a tick
    watchdog = max(float(rt.get("watchdog_timeout", 0.005)), 2.0 / rate)
    return {"haptic_rate": rate, "watchdog_timeout": watchdog,
            **{k: rt.get(k, defaults.runtime(k)) for k in RUNTIME_PHYSICS}}, ""


def replay_runtime(world, ticks_in: np.ndarray, settings: dict, has_start: bool) -> np.ndarray:
    """A threaded recording's ticks replayed on the manual clock on their hand-over schedule
    (``World.replay_ticks``), in stretches as ``replay``; tick 0 the world before it starts."""
    rows = ticks_in[1:] if has_start else ticks_in
    n = len(rows)
    out = np.empty(n + 1, dtype=world.tick_dtype())
    world._tick_record(out[:1], 0)
    hips = np.ascontiguousarray(rows["hip"])
    turns = np.ascontiguousarray(rows["orientation"]) if "orientation" in rows.dtype.names else None
    done, reads = np.ascontiguousarray(rows["object_tick"]), np.ascontiguousarray(rows["object_reads"])
    world.start(realtime=False, **settings)
    try:
        for k in range(0, n, STRETCH):
            end = min(n, k + STRETCH)
            world.replay_ticks(hips[k:end], done[k:end], reads[k:end], out[k + 1:end + 1],
                               orientations=None if turns is None else turns[k:end])
    finally:
        world.stop()
    return out if has_start else out[1:]


def resimulate(recorded: Recording, graspcore, overrides=(), tolerance: float = 1e-6,
               record_path: str | None = None, compression: str = "lz4",
               max_size: float = DEFAULT_MAX_SIZE) -> ResimResult:
    """Replay ``recorded``'s HIPs, tick by tick, through a world built from its header. The
    new run's tick count is checked against memory (and ``max_size``, the free disk space
    when it is recorded) before anything is allocated."""
    if len(recorded.ticks) == 0:
        raise ValueError(f"{recorded.path}: no ticks to re-simulate")
    desc = scene_from_dict(recorded.header["scene"])
    desc.haptic_rate = recorded.haptic_rate
    apply_to_desc(desc, overrides)
    rate = float(desc.haptic_rate)
    same_rate = rate == recorded.haptic_rate
    handle = build_world(desc, graspcore)
    world = handle.world
    dt = 1.0 / rate
    t_rec = recorded.ticks["time"]
    hip_rec = recorded.ticks["hip"]
    if same_rate:
        _check_size(len(t_rec), world.tick_dtype().itemsize + hip_rec[0].nbytes, record_path, max_size)
        hips = np.ascontiguousarray(hip_rec)     # out of the records: one array, rows set_hips takes
    else:   # the HIP stream resampled at the new rate (linear between recorded ticks)
        start = float(t_rec[0]) if int(recorded.ticks["tick"][0]) == 0 else \
            float(t_rec[0]) - 1.0 / recorded.haptic_rate
        n_new = int(np.floor((float(t_rec[-1]) - start) * rate + 1e-9))
        _check_size(n_new + 1, world.tick_dtype().itemsize + hip_rec[0].nbytes, record_path, max_size)
        times = start + dt * np.arange(1, n_new + 1)
        hips = np.stack([np.stack([np.interp(times, t_rec, hip_rec[:, f, a]) for a in range(3)], axis=1)
                         for f in range(hip_rec.shape[1])], axis=1) if hip_rec.shape[1] else \
            np.zeros((n_new, 0, 3))
    # Tick 0 is the state before the first step (the header rebuilt); the others each follow
    # one step with that tick's HIPs.
    has_start = int(recorded.ticks["tick"][0]) == 0
    if same_rate and has_start:
        hips = hips[1:]
    settings, note = runtime_schedule(recorded, same_rate)
    if settings is not None:    # a live session: its object manager's ticks where they fell
        ticks = replay_runtime(world, recorded.ticks, settings, has_start)
    else:
        ticks = replay(world, hips, dt, has_start, turns=recorded_turns(recorded, same_rate, has_start))
    div = compare(recorded, ticks, tolerance, same_rate)
    div.note = note
    header = make_header(desc, mode="resim", haptic_rate=rate, source=recorded.path,
                         fps=recorded.header["rates"].get("fps"), device=recorded.header.get("device"),
                         runtime={"threaded": False} if settings is None else
                         {"threaded": False, "replayed_schedule": True, **settings},
                         extra={"resim_of": recorded.header.get("fingerprint"),
                                "overrides": [str(o) for o in overrides]})
    result = ResimResult(ticks=ticks, divergence=div, header=header)
    if record_path:
        writer = RecordingWriter(record_path, header, compression=compression)
        try:
            events = EventDetector(header)
            writer.write_ticks(ticks)
            for tick, t, kind, subject, detail in events(ticks):
                writer.event(t, kind, subject, detail, tick=tick)
            writer.close({"overflow": 0})
        except BaseException:       # a full disk, a signal: the target stays as it was
            writer.discard()
            raise
        result.path = record_path
    return result
