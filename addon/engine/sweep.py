"""Robustness by re-simulation (docs/sweeps.md): ``grasp-lab sweep``.

A sweep re-simulates a recording's HIP streams (``resim.replay``) many times, each sample with
its own variations (friction, mass, centre of mass, fingertip placement, a push) drawn from
its own seed, and says how often the grasp holds. Sample i's seed comes from the sweep's seed
and i alone, and every sample is a deterministic re-simulation, so the same seed gives the same
samples and outcomes bit for bit on one process, many, or a Dask cluster. bpy-free: workers
import this module, numpy and the core.

Output in DIR: ``sweep.json`` (what the sweep is, for resuming), ``samples.csv`` (one row per
sample; appended as samples finish, sorted when the sweep ends), ``summary.json``, ``map.png``
and ``outcomes.png``.
"""
from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from . import outputs
from . import recording as _recording
from .recording import scene_from_dict, scene_to_dict
from . import resim as _resim
from .resim import BODY_KEYS, FINGER_KEYS, Override, OverrideError, apply_to_desc, replay
from .scene import build_world

PUSH_DURATION = 0.05        # s: a push is a force held this long (an impulse of N x 0.05 N s)
DROP_GRACE = 0.05           # s: losing the body for longer than this is a drop
HOLD_FINGERS = 2            # fingers on a body for it to count as held
ANALYSIS_PERIOD = 0.02      # s: the grasp measures are taken every this (50 Hz) while held
Z95 = 1.959963984540054     # two-sided 95 % normal quantile
CHUNK_SECONDS_LOCAL = 0.25  # s of work per chunk in this process (progress, resume granularity)
LOCAL_CHUNK_MAX = 64        # samples per task on the local pool at most (balance, resume granularity)
CHUNK_SECONDS_DASK = 1.0    # s of work per task on a Dask cluster at least (its per-task overhead)
CONNECT_TIMEOUT = 30.0      # s to reach a --scheduler
SPEC_FILE, SAMPLES_FILE, SUMMARY_FILE = "sweep.json", "samples.csv", "summary.json"
MANIFEST_FILE = "sweep_files.txt"   # the files a sweep wrote in its folder: it never overwrites another's
PICTURES = ("map.png", "outcomes.png")
RECORDING_FILE = "recording.mcap"   # a sweep of a .blend records it here first
MAX_SAMPLES = 1_000_000     # per cell: the finished rows are held in memory for the summary
STRICTLY_POSITIVE = ("mass", "stiffness")


class SweepError(ValueError):
    """A sweep that cannot run; the message names the spec, key or file at fault."""


# ------------------------------------------------------------------------ specs

@dataclass(frozen=True)
class Dist:
    """How one number varies: uniform LO:HI, normal MEAN~SD (clipped to legal values) or a grid
    axis A,B,C (one value: a constant)."""
    kind: str                   # "uniform" | "normal" | "grid"
    a: float = 0.0
    b: float = 0.0
    values: tuple = ()

    def draw(self, rng, lo: float, positive: bool) -> float:
        if self.kind == "uniform":
            return float(rng.uniform(self.a, self.b))
        v = float(rng.normal(self.a, self.b))
        floor = lo if not positive else max(lo, 1e-3 * abs(self.a))   # > 0 keys: 0.1 % of the mean
        return max(v, floor)

    def __str__(self):
        if self.kind == "uniform":
            return f"{self.a!r}:{self.b!r}"
        if self.kind == "normal":
            return f"{self.a!r}~{self.b!r}"
        return ",".join(repr(v) for v in self.values)


@dataclass(frozen=True)
class Vary:
    text: str                   # as given
    column: str                 # its column in samples.csv
    kind: str                   # "scalar" | "gravity" | "com" | "hip_offset" | "hip_noise" | "push"
    obj: str = ""
    prop: str = ""
    dist: Dist | None = None    # scalar, gravity, push magnitude
    sd: float = 0.0             # com, hip_offset, hip_noise: metres
    at: float = 0.0             # push: time, s
    names: tuple = ()           # device: the profiles, a grid axis (the column holds the index)

    @property
    def grid(self) -> tuple:
        return self.dist.values if self.dist is not None and self.dist.kind == "grid" else ()


def _number(text, spec, what):
    try:
        v = float(text)
    except ValueError:
        raise SweepError(f"--vary {spec!r}: {what} expects a number, got {text!r}") from None
    if not math.isfinite(v):
        raise SweepError(f"--vary {spec!r}: {what} must be finite, got {text!r}")
    return v


def parse_dist(text: str, spec: str, prop: str) -> Dist:
    """LO:HI, MEAN~SD, A,B,C or one number; values checked against ``prop``'s legal range."""
    positive = prop in STRICTLY_POSITIVE
    legal = "> 0" if positive else ">= 0"

    def check(v):
        if v < 0 or (positive and v == 0):
            raise SweepError(f"--vary {spec!r}: {prop} must be {legal}, got {v!r}")
        return v
    if ":" in text:
        lo, hi = (_number(t, spec, prop) for t in text.split(":", 1))
        if hi < lo:
            raise SweepError(f"--vary {spec!r}: LO:HI needs LO <= HI")
        return Dist("uniform", check(lo), check(hi))
    if "~" in text:
        mean, sd = (_number(t, spec, prop) for t in text.split("~", 1))
        if sd < 0:
            raise SweepError(f"--vary {spec!r}: MEAN~SD needs SD >= 0")
        return Dist("normal", check(mean), sd)
    values = tuple(check(_number(t, spec, prop)) for t in text.split(","))
    return Dist("grid", values=values)


def parse_vary(text: str) -> Vary:
    """One ``--vary`` SPEC (docs/sweeps.md). Raises SweepError naming what is wrong."""
    if "=" not in text:
        raise SweepError(f"--vary {text!r}: expected KEY=LO:HI, KEY=MEAN~SD or KEY=A,B,C")
    key, value = (s.strip() for s in text.split("=", 1))
    if key in ("hip_noise", "hip_offset"):
        sd = _number(value, text, key + " (SD in metres)")
        if sd < 0:
            raise SweepError(f"--vary {text!r}: {key} is a standard deviation, >= 0")
        return Vary(text, key, key, sd=sd)
    if key == "push":
        mag, at, when = value.partition("@")
        if not at:
            raise SweepError(f"--vary {text!r}: expected push=NEWTONS@SECONDS (NEWTONS may be LO:HI, "
                             f"MEAN~SD or A,B,C)")
        t = _number(when, text, "push time")
        if t < 0:
            raise SweepError(f"--vary {text!r}: the push time must be >= 0")
        return Vary(text, "push", "push", dist=parse_dist(mag, text, "push"), at=t)
    if key == "gravity":
        return Vary(text, key, "gravity", dist=parse_dist(value, text, "gravity"))
    if key == "device":
        names = tuple(n.strip() for n in value.split(","))
        if not all(names):
            raise SweepError(f"--vary {text!r}: expected device=PROFILE,PROFILE,... (grasp-lab fit --list)")
        return Vary(text, key, "device", dist=Dist("grid", values=tuple(float(i) for i in range(len(names)))),
                    names=names)
    obj, dot, prop = key.rpartition(".")
    if not dot or not obj:
        raise SweepError(f"--vary {text!r}: unknown key {key!r} (OBJECT.PROPERTY, OBJECT.com, gravity, "
                         f"hip_noise, hip_offset or push)")
    if prop == "com":
        sd = _number(value, text, "com (SD in metres)")
        if sd < 0:
            raise SweepError(f"--vary {text!r}: com is a standard deviation, >= 0")
        return Vary(text, key, "com", obj=obj, sd=sd)
    if prop not in BODY_KEYS + FINGER_KEYS:
        raise SweepError(f"--vary {text!r}: unknown property {prop!r} (one of "
                         f"{', '.join(BODY_KEYS + FINGER_KEYS)}, com)")
    return Vary(text, key, "scalar", obj=obj, prop=prop, dist=parse_dist(value, text, prop))


# ------------------------------------------------------------------------ the job

@dataclass
class Job:
    """Everything a worker needs (picklable, no file): the recorded scene and HIPs, the specs,
    the held body and the recording's hold window."""
    scene: dict
    rate: float
    hips: np.ndarray            # (steps, fingers, 3): each step's HIPs
    has_start: bool
    times: np.ndarray           # (ticks,) the recording's tick times, for the window
    varies: list
    seed: int
    body: int                   # the held body (index in the scene)
    window: tuple               # (first, last) record the recording holds the body
    analysis: bool
    analysis_period: float = ANALYSIS_PERIOD
    cells: int = 1
    grid_shape: tuple = ()
    devices: dict = field(default_factory=dict)     # a varied device's profile: name -> its file's text
    turns: np.ndarray | None = None     # (steps, fingers, 4): turning fingers' orientations (resim.recorded_turns)

    @property
    def columns(self) -> list:
        return [v.column for v in self.varies]

    def state(self) -> dict:
        """As plain data (numbers, strings, arrays): what goes to Dask workers, which have no
        copy of this module's classes to unpickle."""
        return {k: (list(getattr(self, k)) if k == "grid_shape" else getattr(self, k))
                for k in self.__dataclass_fields__ if k != "varies"} | {"varies": [v.text for v in self.varies]}

    @classmethod
    def from_state(cls, state: dict) -> "Job":
        state = dict(state)
        state["varies"] = [parse_vary(t) for t in state["varies"]]
        state["grid_shape"] = tuple(state["grid_shape"])
        state["window"] = tuple(state["window"])
        return cls(**state)


def sample_seed(seed: int, i: int) -> int:
    """Sample i's own seed: from the sweep's seed and i only (any worker, any order)."""
    return int(np.random.SeedSequence([int(seed), int(i)]).generate_state(1, np.uint64)[0])


def hold_counts(ticks, body: int) -> np.ndarray:
    return (ticks["contact"] == body).sum(axis=1)


def choose_body(header: dict, ticks, name: str | None) -> int:
    """The held body: ``name``, else the dynamic body the recording holds longest."""
    scene = header["scene"]
    names = [b["name"] for b in scene["bodies"]]
    if name is not None:
        if name not in names:
            raise SweepError(f"--body {name!r}: no such body in the recording (bodies: {', '.join(names)})")
        i = names.index(name)
        if scene["bodies"][i]["static"]:
            raise SweepError(f"--body {name!r} is static: it cannot be held")
        return i
    best, longest = -1, 0
    for i, b in enumerate(scene["bodies"]):
        if not b["static"]:
            n = int((hold_counts(ticks, i) >= HOLD_FINGERS).sum())
            if n > longest:
                best, longest = i, n
    if best < 0:
        raise SweepError(f"the recording never holds a body (no tick with {HOLD_FINGERS} fingers on one "
                         f"dynamic body): nothing to sweep")
    return best


def _check_varies(varies, desc, body: int):
    """Each key names something in the recorded scene (resim's own messages)."""
    columns = set()
    for v in varies:
        if v.column in columns:
            raise SweepError(f"--vary {v.text!r}: {v.column} is varied twice")
        columns.add(v.column)
        if v.kind == "scalar":
            value = v.dist.values[0] if v.dist.kind == "grid" else v.dist.a
            try:
                apply_to_desc(_copy_desc(desc), [Override(v.prop, value, v.obj)])
            except OverrideError as ex:
                if "mu_d <= mu_s" not in str(ex):    # a lone mu_s or mu_d is kept legal per sample
                    raise SweepError(str(ex).replace("--set", "--vary", 1)) from None
        elif v.kind == "com":
            b = next((b for b in desc.bodies if b.name == v.obj), None)
            if b is None or b.static:
                raise SweepError(f"--vary {v.text!r}: no dynamic body named {v.obj!r} (bodies: "
                                 f"{', '.join(b.name for b in desc.bodies if not b.static)})")
        elif v.kind == "gravity" and not np.any(desc.gravity):
            raise SweepError(f"--vary {v.text!r}: the recording has no gravity to scale")
        elif v.kind in ("hip_offset", "hip_noise") and not desc.fingers:
            raise SweepError(f"--vary {v.text!r}: the recording has no fingers")


def _device_texts(varies) -> dict:
    """The varied devices' profiles, name -> the text of its file (workers read them from the job)."""
    from .devices.device_profiles import ProfileError, find
    texts = {}
    for v in varies:
        for name in v.names:
            try:
                path = find(name).path
            except ProfileError as ex:
                raise SweepError(f"--vary {v.text!r}: {ex}") from None
            with open(path, encoding="utf-8") as fh:
                texts[name] = fh.read()
    return texts


def _copy_desc(desc):
    import copy
    return copy.deepcopy(desc)


def make_job(rec, varies, seed: int, body_name: str | None = None, analysis: bool = True,
             analysis_period: float = ANALYSIS_PERIOD) -> Job:
    if len(rec.ticks) < 2:
        raise SweepError(f"{rec.path}: too few ticks to re-simulate")
    if not (0 <= int(seed) < 2 ** 63):
        raise SweepError(f"--seed {seed}: expected a whole number in 0..2**63-1")
    body = choose_body(rec.header, rec.ticks, body_name)
    held = np.flatnonzero(hold_counts(rec.ticks, body) >= HOLD_FINGERS)
    if len(held) == 0:
        raise SweepError(f"the recording never holds {rec.header['scene']['bodies'][body]['name']!r}")
    desc = scene_from_dict(rec.header["scene"])
    _check_varies(varies, desc, body)
    end = float(rec.ticks["time"][-1])
    for v in varies:
        if v.kind == "push" and v.at >= end:
            raise SweepError(f"--vary {v.text!r}: the recording ends at {end:.3f} s, before the push")
    has_start = int(rec.ticks["tick"][0]) == 0
    hips = np.ascontiguousarray(rec.ticks["hip"])
    if has_start:
        hips = hips[1:]
    grid_shape = tuple(len(v.grid) for v in varies if v.grid)
    if analysis:
        analysis = _analysis_module() is not None and "normal" in (rec.ticks.dtype.names or ())
    return Job(scene=rec.header["scene"], rate=float(rec.haptic_rate), hips=np.ascontiguousarray(hips),
               has_start=has_start, times=np.ascontiguousarray(rec.ticks["time"]), varies=list(varies),
               seed=int(seed), body=body, window=(int(held[0]), int(held[-1])), analysis=bool(analysis),
               analysis_period=float(analysis_period),
               cells=int(np.prod(grid_shape)) if grid_shape else 1, grid_shape=grid_shape,
               devices=_device_texts(varies), turns=_resim.recorded_turns(rec, True, has_start))


def _analysis_module():
    try:
        from . import analysis
    except ImportError:
        return None
    return analysis if hasattr(analysis, "analyse_recording") else None


# ------------------------------------------------------------------------ one sample

@dataclass
class Draw:
    """One sample's variations."""
    values: dict = field(default_factory=dict)     # column -> number (samples.csv)
    overrides: list = field(default_factory=list)
    com: dict = field(default_factory=dict)        # body name -> offset (3,)
    hip_offset: np.ndarray | None = None           # (fingers, 3)
    hip_noise: float = 0.0
    push: tuple | None = None                      # (newtons, direction (3,), time)
    device: str = ""                               # the device profile the sample is evaluated against


def draw(job: Job, i: int, rng) -> Draw:
    """Sample i's variations, in the order the specs were given (the draws are the seed's)."""
    d = Draw()
    cell = i % job.cells
    grid_index = np.unravel_index(cell, job.grid_shape) if job.grid_shape else ()
    g = 0
    bodies = {b["name"]: b for b in job.scene["bodies"]}
    nf = job.hips.shape[1]
    for v in job.varies:
        if v.grid:
            value = float(v.grid[grid_index[g]])
            g += 1
        elif v.dist is not None:
            value = v.dist.draw(rng, 0.0, v.prop in STRICTLY_POSITIVE)
        if v.kind == "scalar":
            d.overrides.append(Override(v.prop, value, v.obj))
        elif v.kind == "gravity":
            g0 = np.asarray(job.scene["gravity"], dtype=np.float64)
            d.overrides.append(Override("gravity", tuple(float(x) for x in g0 / np.linalg.norm(g0) * value)))
        elif v.kind == "push":
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            d.push = (value, direction, v.at)
        elif v.kind == "com":
            offset = rng.normal(0.0, v.sd, 3)
            d.com[v.obj] = offset
            value = float(np.linalg.norm(offset))
        elif v.kind == "hip_offset":
            d.hip_offset = rng.normal(0.0, v.sd, (nf, 3))
            value = float(np.linalg.norm(d.hip_offset, axis=1).max())
        elif v.kind == "hip_noise":
            d.hip_noise = v.sd
            value = v.sd
        elif v.kind == "device":
            d.device = v.names[int(value)]
        d.values[v.column] = value
    _keep_friction_legal(d.overrides, bodies)
    return d


def _keep_friction_legal(overrides, bodies):
    """A varied mu_s alone scales mu_d with it (the recorded ratio); a varied mu_d is at most mu_s."""
    by_body = {}
    for o in overrides:
        if o.key in ("mu_s", "mu_d"):
            by_body.setdefault(o.obj, {})[o.key] = o
    for name, os_ in by_body.items():
        b = bodies.get(name)
        if b is None:
            continue
        if "mu_s" in os_ and "mu_d" not in os_:
            ratio = b["mu_d"] / b["mu_s"] if b["mu_s"] > 0 else 1.0
            overrides.append(Override("mu_d", os_["mu_s"].value * ratio, name))
        elif "mu_d" in os_:
            mu_s = os_["mu_s"].value if "mu_s" in os_ else b["mu_s"]
            os_["mu_d"].value = min(os_["mu_d"].value, mu_s)


def _fresh_desc(job: Job):
    """The recorded scene for one sample to change: the job's SceneDesc read once (its point
    arrays, the bulk of reading it, shared and never written), the parts a sample's overrides
    set (bodies, their mass properties, fingers) copied."""
    import dataclasses
    base = job.__dict__.get("_desc")
    if base is None:
        base = job.__dict__["_desc"] = scene_from_dict(job.scene)
    bodies = [dataclasses.replace(b, mass_properties=None if b.mass_properties is None
                                  else dataclasses.replace(b.mass_properties)) for b in base.bodies]
    return dataclasses.replace(base, bodies=bodies, fingers=[dataclasses.replace(f) for f in base.fingers])


def run_sample(job: Job, i: int, graspcore) -> dict:
    """Re-simulate sample i; its row of samples.csv."""
    seed = sample_seed(job.seed, i)
    rng = np.random.default_rng(seed)
    d = draw(job, i, rng)
    desc = _fresh_desc(job)
    apply_to_desc(desc, d.overrides)
    for name, offset in d.com.items():
        mp = next(b for b in desc.bodies if b.name == name).mass_properties
        mp.center_of_mass = np.asarray(mp.center_of_mass, dtype=np.float64) + offset
    hips = job.hips
    if d.hip_offset is not None or d.hip_noise:
        hips = hips.copy()
        if d.hip_offset is not None:
            hips += d.hip_offset
        if d.hip_noise:
            hips += rng.normal(0.0, d.hip_noise, hips.shape)
    handle = build_world(desc, graspcore, exact=True)
    dt = 1.0 / job.rate
    before = None
    if d.push is not None:
        before = _pusher(handle.body_ids[job.body], desc.bodies[job.body].mass_properties.mass,
                              d.push, dt, job.has_start)
    # The grasp measures read whole tick records; the outcomes alone, a step's short trace
    ticks = (replay if job.analysis else replay_trace)(handle.world, hips, dt, job.has_start, before, turns=job.turns)
    row = {"sample": i, "seed": seed, **d.values}
    row.update(outcomes(job, ticks, desc))
    if d.device:
        row.update(device_outcomes(job, d.device, ticks, hips, desc))
    return row


def device_outcomes(job: Job, name: str, ticks, hips, desc) -> dict:
    """The sample's task against its device (engine/fit.py, as ``grasp-lab fit``: the device frame at
    the scene origin, its best placement searched): whether it renders it (fits or placed) and, if
    not, the first failure's time."""
    from .devices.device_profiles import loads
    from .fit import Task, evaluate
    profiles = job.__dict__.setdefault("_profiles", {})
    if name not in profiles:
        profiles[name] = loads(job.devices[name], f"{name}.toml")
    if job.has_start:           # tick 0: the fingers where the scene starts them
        hips = np.concatenate([np.array([f.position for f in desc.fingers], dtype=np.float64)[None], hips])
    n = len(ticks)
    task = Task([f.name for f in desc.fingers], np.asarray(ticks["time"], dtype=np.float64), hips[:n],
                np.asarray(ticks["force"], dtype=np.float64), np.asarray(ticks["contact"]) >= 0,
                np.tile([float(f.stiffness) for f in desc.fingers], (n, 1)), job.rate)
    r = evaluate(task, profiles[name])
    fails = [f.first_fail_time for f in r.fingers if f.verdict == "fails"]
    return {"device_fits": int(r.verdict != "fails"), "device_fail_time": min(fails) if fails else None}


class Columns:
    """Tick fields as contiguous arrays (a replay's traces) that read like a record array:
    ``ticks["contact"]`` the (ticks, fingers) array, ``ticks[a:b]`` those ticks, ``len(ticks)``."""

    def __init__(self, fields: dict):
        self.fields = fields

    def __len__(self):
        return len(self.fields["time"])

    def __getitem__(self, key):
        if isinstance(key, str):
            return self.fields[key]
        return Columns({name: v[key] for name, v in self.fields.items()})


def replay_trace(world, hips: np.ndarray, dt: float, has_start: bool = True, before: dict | None = None,
                 turns: np.ndarray | None = None) -> Columns:
    """``resim.replay`` with each step's short trace (``World.step_hips_trace``: the records'
    time, contact, state, force, god_object and pose, no state hash) instead of its record: all
    ``outcomes`` reads of a tick, field by field in contiguous arrays. Tick 0 from the world's
    record. ``turns``: as ``resim.replay``'s."""
    n = len(hips)
    out = np.empty((), dtype=world.trace_dtype(n + 1))
    start = world.tick_record()
    for name in out.dtype.names:
        out[name][0] = start[name]
    k = 0
    if turns is not None:
        for k in range(n):
            if before and k in before:
                before[k](world)
            _resim.set_turns(world, hips, turns, k)
            world.step_hips_trace(hips[k:k + 1], dt, out, first=k + 1)
        ticks = Columns({name: out[name] for name in out.dtype.names})
        return ticks if has_start else ticks[1:]
    for stop in sorted(k for k in (before or ()) if 0 <= k < n) + [n]:
        while k < stop:     # at most STRETCH steps a call: signals are seen between
            end = min(stop, k + _resim.STRETCH)
            world.step_hips_trace(hips[k:end], dt, out, first=k + 1)
            k = end
        if stop < n:
            before[stop](world)
    ticks = Columns({name: out[name] for name in out.dtype.names})
    return ticks if has_start else ticks[1:]


def _pusher(body_id, mass, push, dt, has_start) -> dict:
    """resim.replay's ``before`` hooks: a force of ``newtons`` along ``direction`` through the
    centre of mass for PUSH_DURATION from ``time``, as the velocity it adds each step (F dt / m)."""
    newtons, direction, at = push
    first = int(round(at / dt)) - (0 if has_start else 1)
    dv = np.asarray(direction) * (newtons * dt / mass)

    def kick(world):
        lin, ang = world.body_velocity(body_id)
        world.set_body_velocity(body_id, tuple(np.add(lin, dv)), ang)
    return {k: kick for k in range(max(0, first), first + max(1, int(round(PUSH_DURATION / dt))))}


def outcomes(job: Job, ticks, desc) -> dict:
    """Held through the recording's hold or dropped (when), how long held, the largest slip of
    a finger's contact over the body's surface, the largest finger force, and (with the
    analysis) the time in force closure and the smallest epsilon while held."""
    dt = 1.0 / job.rate
    n = len(ticks)
    first, last = job.window
    last = min(last, n - 1)
    if isinstance(ticks, Columns):      # a replay's traces: each field a contiguous array
        few = ticks
    else:   # records: the fields every tick is read for, copied out in one pass (each field read
        # on its own is a pass over megabytes of records)
        packed = np.dtype([(name, ticks.dtype.fields[name][0]) for name in ("contact", "state", "force")])
        few = ticks[["contact", "state", "force"]].astype(packed)
    contact = np.ascontiguousarray(few["contact"])
    on = contact == job.body                        # (n, fingers)
    held = on[:, 0].astype(np.int32) if on.shape[1] else np.zeros(n, np.int32)
    for k in range(1, on.shape[1]):
        held += on[:, k]
    held = held >= HOLD_FINGERS
    grace = max(1, int(round(DROP_GRACE / dt)))
    starts = np.flatnonzero(held[first:last + 1])
    out = {"held": 0, "drop_time": None, "held_time": 0.0, "max_slip": 0.0}
    if few["force"].size:
        sq = np.ascontiguousarray(few["force"]).reshape(n, -1)
        sq = sq * sq
        out["max_force"] = float(np.sqrt(np.max(sq[:, 0::3] + sq[:, 1::3] + sq[:, 2::3])))  # x² + y² + z²
    else:
        out["max_force"] = 0.0
    if len(starts) == 0:
        out["drop_time"] = float(ticks["time"][first])
        if job.analysis:
            out.update(closure_time=0.0, min_epsilon=0.0)
        return out
    start = first + int(starts[0])
    # a drop: fewer than HOLD_FINGERS fingers for longer than the grace, beginning while the
    # recording still holds the body and at least the grace before it lets go
    lost = np.concatenate([[0], np.cumsum(~held)])
    end = max(start, last - grace + 1)
    run = lost[start + grace:end + grace] - lost[start:end]        # ticks lost in [k, k + grace)
    candidates = np.flatnonzero(run >= grace)
    stop = last
    if len(candidates):
        stop = start + int(candidates[0])
        out["drop_time"] = float(ticks["time"][stop])
    else:
        out["held"] = 1
    out["held_time"] = float(ticks["time"][stop] - ticks["time"][start])
    out["max_slip"] = max_slip(ticks[start:stop + 1], job.body, on[start:stop + 1],
                               np.ascontiguousarray(few["state"][start:stop + 1]))
    if job.analysis:
        out.update(_analysis_outcomes(job, ticks, desc, start, stop, held))
    return out


SLIP = 2        # gcFingerState: a finger sliding over the body's surface


def max_slip(ticks, body: int, on=None, state=None) -> float:
    """The largest distance a finger's contact point moved over the body's surface (its
    god-object in the body frame) since that contact began, m. A sticking contact does not
    move over the surface, so only the ticks where one slides are looked at (and the ticks
    their contacts began). ``on``: ticks["contact"] == body, ``state``: ticks["state"], if known."""
    on = ticks["contact"] == body if on is None else on      # (n, fingers)
    sliding = on & ((ticks["state"] if state is None else state) == SLIP)
    if not sliding.any():
        return 0.0
    rows = np.flatnonzero(sliding.any(axis=1))
    n, nf = on.shape
    begins = on & ~np.concatenate([np.zeros((1, nf), bool), on[:-1]])
    first = np.maximum.accumulate(np.where(begins, np.arange(n)[:, None], 0), axis=0)[rows]   # (r, fingers)
    needed, where = np.unique(np.concatenate([rows, first.ravel()]), return_inverse=True)
    pose = ticks["pose"][needed, body]
    w, x, y, z = pose[:, 3], pose[:, 4], pose[:, 5], pose[:, 6]
    rot = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),       # body to world
                    2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                    2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1).reshape(-1, 3, 3)
    local = np.matmul(ticks["god_object"][needed] - pose[:, None, :3], rot)     # R^T (GO - p), body frame
    at, anchor = where[:len(rows)], where[len(rows):].reshape(len(rows), nf)
    moved = local[at] - local[anchor, np.arange(nf)]
    return float(np.sqrt(np.max((moved * moved).sum(axis=2)[sliding[rows]])))


def _analysis_outcomes(job, ticks, desc, start, stop, held):
    """Time in force closure and the smallest epsilon while held, from analysis.py's measures
    every analysis_period (mu_min, a search, and the hull's volume skipped: not reported here). A contact set
    the quality routine refuses leaves both empty (None) rather than losing the sample."""
    analysis = _analysis_module()
    every = max(1, int(round(job.analysis_period * job.rate)))
    rows = np.arange(start, stop + 1, every)
    rows = rows[held[rows]]
    if len(rows) == 0:
        return {"closure_time": 0.0, "min_epsilon": 0.0}

    class _Run:     # the sample's run as analyse_recording reads a recording
        path = "sample"
        header = {"scene": scene_to_dict(desc)}
    _Run.ticks = ticks
    try:
        table = analysis.analyse_recording(_Run, rows=rows, with_mu_min=False, volume=False)
    except ValueError:
        return {"closure_time": None, "min_epsilon": None}
    mine = table.body == job.body
    closure = table.quality["force_closure"][mine]
    eps = table.quality["epsilon"][mine]
    return {"closure_time": float(closure.sum()) * every / job.rate,
            "min_epsilon": float(eps.min()) if len(eps) == len(rows) else 0.0}


def run_chunk(job, indices) -> list:
    """Samples ``indices``, each on its own; their rows. ``job``: a Job or its state()."""
    from . import core_loader
    gc = core_loader.load()
    _recording.reuse_freed_memory()       # each sample's records: heap, not a fresh mapping each
    if isinstance(job, dict):
        job = Job.from_state(job)
    return [run_sample(job, int(i), gc) for i in indices]


# ------------------------------------------------------------------------ where it runs

_WORKER_JOB = None


def _init_local_worker(job):
    global _WORKER_JOB
    _WORKER_JOB = job
    _exit_with_parent()


def _exit_with_parent():
    """A pool worker whose sweep was killed (kill -9, a lost terminal) would wait for tasks for
    ever: it ends when its parent does (checked every 0.2 s)."""
    import threading
    parent = os.getppid()

    def watch():
        while os.getppid() == parent:
            time.sleep(0.2)
        os._exit(1)
    threading.Thread(target=watch, name="grasp-lab sweep: parent watch", daemon=True).start()


def _local_chunk(indices):
    return run_chunk(_WORKER_JOB, indices)


def _chunks(todo, size):
    return [todo[k:k + size] for k in range(0, len(todo), size)]


def run_local(job: Job, todo, workers: int, on_rows) -> None:
    """On this machine: in this process for one worker, else a pool of ``workers`` processes
    (spawned: they import this module, numpy and the core, never bpy). The first sample runs
    here while the pool starts, so a scene the core refuses fails at once."""
    from . import core_loader
    if __name__.startswith("bl_ext."):
        # Inside Blender the engine is a module of Blender's extension package, which a plain
        # worker process cannot import: the sweep runs in this process (docs/sweeps.md).
        workers = 1
    if workers <= 1 or len(todo) <= 1:
        t = time.perf_counter()
        on_rows(run_chunk(job, todo[:1]))
        size = max(1, int(CHUNK_SECONDS_LOCAL / max(time.perf_counter() - t, 1e-6)))
        for chunk in _chunks(todo[1:], size):
            on_rows(run_chunk(job, chunk))
        return
    import concurrent.futures as cf
    import multiprocessing
    rest = todo[1:]
    size = max(1, min(LOCAL_CHUNK_MAX, len(rest) // (8 * workers)))     # load balance and resume granularity
    with cf.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                initializer=_init_local_worker, initargs=(job,)) as pool:
        futures = [pool.submit(_local_chunk, c) for c in _chunks(rest, size)]
        try:
            on_rows([run_sample(job, todo[0], core_loader.load())])
            for f in cf.as_completed(futures):
                on_rows(f.result())
        except BaseException:
            for f in futures:
                f.cancel()
            raise


def engine_zip(folder: str) -> tuple[str, str]:
    """This package's bpy-free part (engine/, without a vendored core: workers have the graspcore
    wheel) as an importable zip for Dask workers, under a name with its content hash (a changed
    engine is a new module). Returns (path, package name)."""
    import zipfile
    addon = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    files = []
    for root, dirs, names in os.walk(os.path.join(addon, "engine")):
        dirs[:] = sorted(d for d in dirs if d not in ("__pycache__", "graspcore"))
        for n in sorted(names):
            if n.endswith(".py"):
                full = os.path.join(root, n)
                files.append((os.path.relpath(full, addon), full))
    digest = hashlib.sha256()
    for rel, full in files:
        with open(full, "rb") as fh:
            digest.update(rel.encode() + b"\0" + fh.read())
    package = f"grasp_lab_sweep_{digest.hexdigest()[:12]}"
    path = os.path.join(folder, package + ".zip")
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr(f"{package}/__init__.py", "")
        for rel, full in files:
            zf.write(full, f"{package}/{rel}")
    return path, package


def _trampoline(package: str):
    """A function Dask pickles by value (its module is nowhere importable) that runs a chunk
    with the uploaded engine, so workers need the graspcore wheel and nothing else."""
    namespace = {"__name__": "grasp_lab_sweep_task"}
    exec("def run(job, indices):\n"
         "    import importlib\n"
         f"    return importlib.import_module({package + '.engine.sweep'!r}).run_chunk(job, indices)\n",
         namespace)
    return namespace["run"]


def run_dask(job: Job, todo, address: str, on_rows, folder: str) -> None:
    """On an existing Dask cluster (never one of our own): the engine uploaded to every worker
    (and to any that joins later), the samples in tasks of at least CHUNK_SECONDS_DASK of work
    (the first sample, run here, says how many that is). A worker lost mid-sweep has its tasks
    run again elsewhere: the same rows."""
    from . import core_loader
    try:
        from distributed import Client, as_completed
        from distributed.diagnostics.plugin import UploadFile
    except ImportError as ex:
        raise SweepError(f"--scheduler needs dask.distributed (pip install 'dask[distributed]'): {ex}") from None
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError) as ex:
        raise SweepError(f"--scheduler {address}: cannot connect ({ex})") from None
    try:
        t = time.perf_counter()
        on_rows([run_sample(job, todo[0], core_loader.load())])   # a scene the core refuses fails here
        seconds_per_sample = time.perf_counter() - t
        todo = todo[1:]
        if not todo:
            return
        path, package = engine_zip(folder)
        client.register_plugin(UploadFile(path), name="grasp_lab_sweep")
        job_future = client.scatter([job.state()], broadcast=True, hash=False)[0]   # a list: a dict would scatter per key
        size = max(1, math.ceil(CHUNK_SECONDS_DASK / max(seconds_per_sample, 1e-6)))
        task = _trampoline(package)
        tag = hashlib.sha256(f"{job.seed}{time.time_ns()}".encode()).hexdigest()[:8]
        futures = [client.submit(task, job_future, chunk, key=f"grasp-lab-sweep-{tag}-{k}", retries=2)
                   for k, chunk in enumerate(_chunks(todo, size))]
        for f in as_completed(futures):
            on_rows(f.result())
    finally:
        client.close()


# ------------------------------------------------------------------------ samples.csv

def fieldnames(job: Job) -> list:
    names = ["sample", "seed", *job.columns, "held", "drop_time", "held_time", "max_slip", "max_force"]
    names += ["closure_time", "min_epsilon"] if job.analysis else []
    return names + (["device_fits", "device_fail_time"] if any(v.kind == "device" for v in job.varies) else [])


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return repr(float(v))           # shortest exact repr: read back bit for bit


def _parse_cell(name: str, text: str):
    if text == "":
        return None
    if name in ("sample", "seed", "held", "device_fits"):
        return int(text)
    return float(text)


def read_rows(path: str, names: list) -> dict:
    """The finished samples in samples.csv (sample -> row); a torn last line (a sweep killed
    mid-write) is dropped. Raises SweepError when the columns are not this sweep's."""
    rows = {}
    with open(path, newline="") as fh:
        text = fh.read()
    lines = text.splitlines(keepends=True)
    if lines and not lines[-1].endswith("\n"):
        lines = lines[:-1]
    reader = csv.reader(lines)
    header = next(reader, None)
    if header is None:
        return rows
    if header != names:
        raise SweepError(f"{path}: its columns ({','.join(header)}) are not this sweep's "
                         f"({','.join(names)})")
    for record in reader:
        if len(record) != len(names):
            continue
        try:
            row = {n: _parse_cell(n, t) for n, t in zip(names, record)}
        except ValueError:
            continue
        rows[row["sample"]] = row
    return rows


def write_sorted(path: str, names: list, rows: dict) -> None:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(names)
    for i in sorted(rows):
        w.writerow([_cell(rows[i][n]) for n in names])
    outputs.write_whole(path, buf.getvalue(), verify=outputs.csv_rows(len(rows)))


def claim_folder(folder: str, names, force: bool = False) -> None:
    """``folder`` made the sweep's: refused (SweepError naming them) when it holds files that no
    sweep wrote there (a user's own map.png), unless ``force``; ``names`` are added to its
    manifest before any of them is written, so a sweep stopped half-way still owns them."""
    os.makedirs(folder, exist_ok=True)
    manifest = os.path.join(folder, MANIFEST_FILE)
    try:
        with open(manifest) as fh:
            ours = {line.strip() for line in fh if line.strip()}
    except FileNotFoundError:
        ours = set()
    except OSError as ex:
        raise SweepError(f"{manifest}: not readable ({ex.strerror or ex})") from None
    foreign = sorted(n for n in os.listdir(folder)
                     if n not in ours | {MANIFEST_FILE} and not n.endswith(outputs.PARTIAL))
    if foreign and not force:
        shown = ", ".join(foreign[:6]) + (f" and {len(foreign) - 6} more" if len(foreign) > 6 else "")
        raise SweepError(f"--out {folder}: holds files this sweep did not write ({shown}); name an empty or "
                         f"new folder, or give --force to write beside them (a file of a sweep's name "
                         f"is then replaced)")
    if not set(names) <= ours:
        outputs.write_whole(manifest, "".join(f"{n}\n" for n in sorted(ours | set(names))))


# ------------------------------------------------------------------------ statistics

def wilson(k: int, n: int, z: float = Z95) -> tuple:
    """Wilson score interval of a proportion k/n (95 % for the default z)."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    # It holds p: rounding once put the lower end of 0 of n above 0 (a negative error bar).
    return (max(0.0, min(centre - half, p)), min(1.0, max(centre + half, p)))


def _stats(values) -> dict:
    v = np.asarray([x for x in values if x is not None], dtype=np.float64)
    if len(v) == 0:
        return {"n": 0}
    return {"n": int(len(v)), "mean": float(v.mean()), "min": float(v.min()),
            "p05": float(np.quantile(v, 0.05)), "median": float(np.median(v)),
            "p95": float(np.quantile(v, 0.95)), "max": float(v.max())}


def sensitivity(job: Job, rows: list) -> dict:
    """Per varied key: held probability per grid value, or per quartile of the drawn values,
    and the correlation of the value with holding (point-biserial; None when either is constant)."""
    held = np.array([r["held"] for r in rows], dtype=np.float64)
    out = {}
    for v in job.varies:
        x = np.array([r[v.column] for r in rows], dtype=np.float64)
        entry = {"spec": v.text}
        corr = None
        if len(x) > 1 and x.std() > 0 and held.std() > 0:
            corr = float(np.corrcoef(x, held)[0, 1])
        entry["correlation_with_held"] = corr
        if v.grid:
            entry["by_value"] = [{"value": float(g), "n": int((x == g).sum()),
                                  "p_held": float(held[x == g].mean()) if (x == g).any() else None}
                                 for g in v.grid]
        elif len(x) and x.std() > 0:
            edges = np.quantile(x, [0, 0.25, 0.5, 0.75, 1.0])
            which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, 3)
            entry["by_quartile"] = [{"low": float(edges[q]), "high": float(edges[q + 1]),
                                     "n": int((which == q).sum()),
                                     "p_held": float(held[which == q].mean()) if (which == q).any() else None}
                                    for q in range(4)]
        out[v.column] = entry
    return out


def summarize(job: Job, rows: list, spec: dict) -> dict:
    n = len(rows)
    k = int(sum(r["held"] for r in rows))
    lo, hi = wilson(k, n)
    summary = {"recording": spec["recording"], "fingerprint": spec["fingerprint"], "body": spec["body"],
               "seed": job.seed, "varied": [v.text for v in job.varies], "samples": n, "held": k,
               "p_held": k / n if n else None, "ci95": [lo, hi], "ci_method": "Wilson score, 95 %",
               "hold_window": [float(job.times[job.window[0]]), float(job.times[job.window[1]])],
               "sensitivity": sensitivity(job, rows),
               "analysis_refused": sum(1 for r in rows if job.analysis and r["min_epsilon"] is None),
               "outcomes": {name: _stats(r[name] for r in rows)
                            for name in fieldnames(job)[len(job.columns) + 3:]}}
    for v in job.varies:
        if v.kind == "device":      # per device: how many of its samples it renders
            summary["devices"] = {name: {"samples": sum(1 for r in rows if r[v.column] == i),
                                         "fits": sum(r["device_fits"] for r in rows if r[v.column] == i)}
                                  for i, name in enumerate(v.names)}
    return summary


# ------------------------------------------------------------------------ pictures

def _map_keys(job: Job, rows: list) -> list:
    """The map's axes: the first two varied keys whose samples differ."""
    return [v for v in job.varies if len({r[v.column] for r in rows}) > 1][:2]


# RdYlGn's ends and middle: P(held) 0 red, 0.5 yellow, 1 green; grey where no sample fell
_PLAIN_COLOURS = np.array([[215, 48, 39], [255, 255, 191], [26, 152, 80]], dtype=np.float64)


def plain_map(job: Job, rows: list) -> np.ndarray:
    """map.png without matplotlib (Blender's Python has none): the held probability per cell of
    the map's bins as an RGB image (y up), cells 32 px, no axes. (H, W, 3) uint8."""
    held = np.array([r["held"] for r in rows], dtype=bool)
    keys = _map_keys(job, rows)
    index, shape = [], []
    for v in keys:
        x = np.array([r[v.column] for r in rows], dtype=np.float64)
        edges, i = _bins(v, x, rows, len(keys))
        index.append(i)
        shape.append(len(edges) - 1)
    nx = shape[0] if keys else 1
    ny = shape[1] if len(keys) == 2 else 1
    xi = index[0] if keys else np.zeros(len(rows), dtype=int)
    yi = index[1] if len(keys) == 2 else np.zeros(len(rows), dtype=int)
    count = np.zeros((ny, nx))
    kept = np.zeros((ny, nx))
    np.add.at(count, (yi, xi), 1)
    np.add.at(kept, (yi, xi), held)
    p = np.divide(kept, count, out=np.full_like(count, np.nan), where=count > 0)
    t = np.clip(np.nan_to_num(p) * 2, 0, 2)
    lo = np.minimum(t.astype(int), 1)
    frac = (t - lo)[..., None]
    rgb = _PLAIN_COLOURS[lo] * (1 - frac) + _PLAIN_COLOURS[lo + 1] * frac
    rgb[count == 0] = 128
    return np.repeat(np.repeat(rgb[::-1].round().astype(np.uint8), 32, axis=0), 32, axis=1)


def write_png(path: str, rgb: np.ndarray) -> None:
    """An 8-bit RGB PNG (zlib, no filter), atomically."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    h, w, _ = rgb.shape
    raw = b"".join(b"\0" + rgb[y].tobytes() for y in range(h))
    data = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    outputs.write_whole(path, data)


def draw_pictures(job: Job, rows: list, folder: str) -> list:
    """map.png (held probability over the first two varied keys, or along the one) and
    outcomes.png (what happened to the samples). Returns the paths written. Without matplotlib
    (Blender's Python): map.png alone, the probability grid without axes (plain_map)."""
    try:
        import matplotlib
    except ImportError:
        path = os.path.join(folder, "map.png")
        write_png(path, plain_map(job, rows))
        return [path]
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    held = np.array([r["held"] for r in rows], dtype=bool)
    keys = _map_keys(job, rows)
    paths = []
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=100)
    if len(keys) == 2:
        x = np.array([r[keys[0].column] for r in rows], dtype=np.float64)
        y = np.array([r[keys[1].column] for r in rows], dtype=np.float64)
        xe, xi = _bins(keys[0], x, rows, 2)
        ye, yi = _bins(keys[1], y, rows, 2)
        p = np.full((len(ye) - 1, len(xe) - 1), np.nan)
        for a in range(len(xe) - 1):
            for b in range(len(ye) - 1):
                sel = (xi == a) & (yi == b)
                if sel.any():
                    p[b, a] = held[sel].mean()
        mesh = ax.pcolormesh(xe, ye, p, vmin=0, vmax=1, cmap="RdYlGn", shading="flat")
        fig.colorbar(mesh, ax=ax, label="P(held)")
        if len(rows) <= 2000:
            ax.scatter(x[held], y[held], s=6, c="k", marker="o", label="held", alpha=0.5)
            ax.scatter(x[~held], y[~held], s=10, c="k", marker="x", label="dropped", alpha=0.5)
            ax.legend(loc="upper right", fontsize=8)
        ax.set_xlabel(keys[0].column)
        ax.set_ylabel(keys[1].column)
    elif len(keys) == 1:
        x = np.array([r[keys[0].column] for r in rows], dtype=np.float64)
        xe, xi = _bins(keys[0], x, rows)
        centres, ps, los, his = [], [], [], []
        for a in range(len(xe) - 1):
            sel = xi == a
            if sel.any():
                k, n = int(held[sel].sum()), int(sel.sum())
                lo, hi = wilson(k, n)
                centres.append((xe[a] + xe[a + 1]) / 2)
                ps.append(k / n)
                los.append(k / n - lo)
                his.append(hi - k / n)
        ax.errorbar(centres, ps, yerr=[los, his], fmt="o-", capsize=3)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel(keys[0].column)
        ax.set_ylabel("P(held), 95 % Wilson interval")
    else:
        k, n = int(held.sum()), len(rows)
        ax.bar(["held", "dropped"], [k, n - k], color=["tab:green", "tab:red"])
        ax.set_ylabel("samples")
    ax.set_title(f"held {int(held.sum())} of {len(rows)}")
    fig.tight_layout()
    paths.append(_save_figure(fig, os.path.join(folder, "map.png")))

    names = [("drop_time", "drop time, s (dropped samples)"), ("max_slip", "largest slip, mm"),
             ("max_force", "largest finger force, N"), ("held_time", "time held, s")]
    if job.analysis:
        names[3] = ("min_epsilon", "smallest epsilon while held")
    fig, axes = plt.subplots(2, 2, figsize=(8, 6), dpi=100)
    for ax, (name, label) in zip(axes.flat, names):
        scale = 1000.0 if name == "max_slip" else 1.0
        for sel, colour, what in ((held, "tab:green", "held"), (~held, "tab:red", "dropped")):
            v = np.array([r[name] for r, s in zip(rows, sel) if s and r[name] is not None], dtype=np.float64)
            if len(v):
                ax.hist(v * scale, bins=30, color=colour, alpha=0.6, label=what)
        ax.set_xlabel(label)
        ax.set_ylabel("samples")
    for ax in axes.flat:        # one legend, on a plot with both kinds when there is one
        if len(ax.get_legend_handles_labels()[0]) == 2 or ax is axes.flat[-1]:
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=8)
            break
    fig.tight_layout()
    paths.append(_save_figure(fig, os.path.join(folder, "outcomes.png")))
    return paths


def _save_figure(fig, path: str) -> str:
    import matplotlib.pyplot as plt
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", metadata={"Software": None})
    finally:
        plt.close(fig)
    return outputs.write_whole(path, buf.getvalue())


SAMPLES_PER_CELL = 4        # the map's aim: about this many samples in each cell
MAX_BINS = 20               # per axis: 400 cells at most


def bin_count(samples: int, axes: int) -> int:
    """Bins per axis of a map of ``samples`` over ``axes`` (1 or 2) ranged axes: about
    SAMPLES_PER_CELL samples a cell, 2 to MAX_BINS per axis (50 samples: 12 bins on one
    axis, 3 x 3 cells on two; 2000: 20 and 20 x 20)."""
    k = (max(samples, 1) / SAMPLES_PER_CELL) ** (1.0 / max(axes, 1))
    return int(np.clip(np.floor(k), 2, MAX_BINS))


def _bins(vary: Vary, x, rows, axes: int = 1):
    """Bin edges and each sample's bin: a grid axis's values, else bin_count even bins."""
    if vary.grid:
        values = np.array(sorted(set(vary.grid)), dtype=np.float64)
        mids = (values[1:] + values[:-1]) / 2
        step = (values[-1] - values[0]) / max(1, len(values) - 1) or 1.0
        edges = np.concatenate([[values[0] - step / 2], mids, [values[-1] + step / 2]])
    else:
        edges = np.linspace(x.min(), x.max(), bin_count(len(rows), axes) + 1)
    index = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    return edges, index


# ------------------------------------------------------------------------ the sweep

def spec_of(job: Job, rec, samples_per_cell: int) -> dict:
    return {"recording": os.path.abspath(rec.path), "fingerprint": rec.header.get("fingerprint", ""),
            "ticks": int(len(rec.ticks)), "body": job.scene["bodies"][job.body]["name"], "seed": job.seed,
            "vary": [v.text for v in job.varies], "analysis": job.analysis,
            "analysis_period": job.analysis_period, "samples_per_cell": samples_per_cell,
            "cells": job.cells, "total": samples_per_cell * job.cells}


def _check_resume(folder: str, spec: dict) -> None:
    path = os.path.join(folder, SPEC_FILE)
    if not os.path.exists(path):
        return
    try:
        with open(path) as fh:
            old = json.load(fh)
    except (OSError, ValueError) as ex:
        raise SweepError(f"{path}: not readable ({ex}); use another --out") from None
    for key in ("fingerprint", "ticks", "body", "seed", "vary", "analysis", "analysis_period", "cells"):
        if old.get(key) != spec[key]:
            raise SweepError(f"{folder} holds another sweep ({key}: {old.get(key)!r} there, {spec[key]!r} "
                             f"now); use another --out to start a new one")


@dataclass
class SweepResult:
    summary: dict
    rows: list
    ran: int                    # samples run now (the rest were in DIR already)
    seconds: float
    paths: list


def sweep(rec, varies, samples: int, seed: int, folder: str, workers: int = 1, scheduler: str | None = None,
          body: str | None = None, analysis: bool = True, analysis_period: float = ANALYSIS_PERIOD,
          pictures: bool = True, progress=None, force: bool = False) -> SweepResult:
    """Run (or finish) a sweep of ``rec`` into ``folder``; samples already there are kept."""
    if not 1 <= samples <= MAX_SAMPLES:
        raise SweepError(f"--samples {samples}: must be in 1 .. {MAX_SAMPLES:,}")
    job = make_job(rec, varies, seed, body, analysis, analysis_period)
    spec = spec_of(job, rec, samples)
    claim_folder(folder, (SPEC_FILE, SAMPLES_FILE, SUMMARY_FILE) + PICTURES, force)
    _check_resume(folder, spec)
    outputs.write_whole(os.path.join(folder, SPEC_FILE), json.dumps(spec, indent=1) + "\n")
    names = fieldnames(job)
    csv_path = os.path.join(folder, SAMPLES_FILE)
    done = read_rows(csv_path, names) if os.path.exists(csv_path) else {}
    total = spec["total"]
    # A fresh sweep's to-do list is a range (no list of every index); a resumed one lists what is left.
    todo = range(total) if not done else [i for i in range(total) if i not in done]
    write_sorted(csv_path, names, done)          # whole lines only, then append
    t0 = time.perf_counter()
    ran = 0
    if todo:
        with open(csv_path, "a", newline="") as fh:
            writer = csv.writer(fh, lineterminator="\n")

            def on_rows(new):
                nonlocal ran
                for row in new:
                    writer.writerow([_cell(row[n]) for n in names])
                    done[row["sample"]] = row
                fh.flush()
                ran += len(new)
                outputs.note_kept(csv_path, f"{len(done)} samples")
                if progress:
                    progress(len(done), total, time.perf_counter() - t0)
            if scheduler:
                run_dask(job, todo, scheduler, on_rows, folder)
            else:
                run_local(job, todo, workers, on_rows)
    seconds = time.perf_counter() - t0
    rows = [done[i] for i in sorted(done) if i < total]
    write_sorted(csv_path, names, {r["sample"]: r for r in rows})
    summary = summarize(job, rows, spec)
    outputs.write_whole(os.path.join(folder, SUMMARY_FILE), json.dumps(summary, indent=1) + "\n")
    paths = [csv_path, os.path.join(folder, SUMMARY_FILE)]
    if pictures and rows:
        paths += draw_pictures(job, rows, folder)
    return SweepResult(summary, rows, ran, seconds, paths)


# ------------------------------------------------------------------------ command line
