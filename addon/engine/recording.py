"""Session recordings: MCAP files with every haptic tick (docs/recording-format.md).

Plain Python + numpy + ``mcap``; no bpy, no graspcore (a recording opens anywhere).

* ``RecordingWriter`` writes the header, blocks of tick records and events, and closes
  (flushes) a chunk at least every ``flush_interval`` seconds, so a killed session loses
  at most that much.
* ``SessionRecorder`` feeds a writer from a running world: from ``World.tick_record`` after
  every synchronous step (EXEC), or on its own thread from the C tick log that the haptic
  loop fills (threaded runtime); it derives the events (contacts, stick/slip, safety).
* ``open_recording`` reads a file back linearly, recovering everything before any damage;
  ``summarize`` answers ``grasp-lab info`` from the summary section when the file is whole.
"""
from __future__ import annotations

import hashlib
import io
import json
import math
import os
import platform
import struct
import sys
import threading
import time
import zlib
from dataclasses import dataclass, field

import numpy as np

from .outputs import AtomicFile, uninterrupted

FORMAT_VERSION = 1
PROFILE = "grasp_lab"
TOPIC_HEADER = "/grasp_lab/header"
TOPIC_TICKS = "/grasp_lab/ticks"
TOPIC_EVENTS = "/grasp_lab/events"
TOPIC_END = "/grasp_lab/end"
TICK_SCHEMA = "grasp_lab.TickBlock"
TICK_ENCODING = "grasp_lab.tick_records"    # message: whole records, back to back
JSON_SCHEMA = {"type": "object"}
FLUSH_INTERVAL = 0.1        # s: at most this much of a session is lost to a kill -9
FLUSH_MARGIN = 0.02         # s: the recorder thread flushes this early (it may wake late: GIL, load)
BLOCK_TICKS = 256           # ticks per message at most
STATE_NAMES = ("free", "stick", "slip")  # the file's state codes: graspcore.FINGER_STATES (test_recording.py)
UNITS = {"length": "m", "mass": "kg", "time": "s", "force": "N", "torque": "N m",
         "velocity": "m/s", "angular_velocity": "rad/s (world)", "orientation": "quaternion w x y z",
         "stiffness": "N/m", "damping": "N s/m", "rate": "Hz", "period_us": "us", "work_us": "us"}
COMPRESSIONS = ("lz4", "zstd", "none")   # lz4 by default: 3x faster to read back than zstd

# The tick record's layout is the core's (graspcore.tick_dtype, checked against
# gc_tick_record_size): the writer takes it from there and stores it in the file's schema,
# which readers build their record type from (a recording opens without the core). The
# fields every reader needs:
REQUIRED_FIELDS = ("tick", "time", "object_time", "state_hash", "period_us", "work_us", "flags", "adopted",
                   "log_us")
FLAG_FORCES_ENABLED = 1  # the file's flags bit: graspcore.TICK_FORCES_ENABLED (test_recording.py)


class RecordingError(ValueError):
    """A file that cannot be read as a recording. The message names the file and the problem."""


def tick_dtype(n_bodies: int, n_fingers: int) -> np.dtype:
    """The core's tick record type (graspcore.tick_dtype): what a recording is written with."""
    from .. import core_loader
    return core_loader.load().tick_dtype(n_bodies, n_fingers)


def schema_of(dtype: np.dtype) -> dict:
    """The tick schema stored in the file: every field with its type, shape and offset."""
    fields = []
    for name in dtype.names:
        sub, offset = dtype.fields[name][:2]
        base, shape = (sub.base, list(sub.shape)) if sub.shape else (sub, [])
        fields.append({"name": name, "type": base.str, "shape": shape, "offset": offset})
    return {"record_size": dtype.itemsize, "byte_order": "little", "fields": fields,
            "message": "a whole number of records back to back, in tick order"}


def dtype_of(schema: dict) -> np.dtype:
    try:
        spec = {"names": [f["name"] for f in schema["fields"]],
                "formats": [np.dtype((f["type"], tuple(f["shape"]))) if f["shape"] else np.dtype(f["type"])
                            for f in schema["fields"]],
                "offsets": [int(f["offset"]) for f in schema["fields"]],
                "itemsize": int(schema["record_size"])}
        dtype = np.dtype(spec)
    except (KeyError, TypeError, ValueError) as ex:
        raise ValueError(f"tick schema is malformed ({ex})") from None
    missing = set(REQUIRED_FIELDS) - set(dtype.names)
    if missing:
        raise ValueError(f"tick schema lacks {sorted(missing)}")
    return dtype


# --------------------------------------------------------------------------- header

def addon_version() -> str:
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    for folder in (here, os.path.dirname(here)):
        path = os.path.join(folder, "blender_manifest.toml")
        if os.path.exists(path):
            with open(path) as fh:
                for line in fh:
                    if line.startswith("version"):
                        return line.split("=", 1)[1].strip().strip('"')
    return "unknown"


def scene_to_dict(desc) -> dict:
    """A prepared ``engine.scene.SceneDesc`` as JSON-able data, exact (floats round-trip)."""
    def arr(a):
        return np.asarray(a, dtype=np.float64).tolist()
    bodies = []
    for b in desc.bodies:
        mp = b.mass_properties
        bodies.append({
            "name": b.name, "static": bool(b.static), "parts": [arr(p) for p in b.parts],
            "position": arr(b.position), "orientation": arr(b.orientation),
            "mu_s": float(b.mu_s), "mu_d": float(b.mu_d), "viscosity": float(b.viscosity),
            "mass": None if mp is None else float(mp.mass),
            "volume": None if mp is None else float(mp.volume),
            "center_of_mass": None if mp is None else arr(mp.center_of_mass),
            "inertia": None if mp is None else arr(mp.inertia)})
    fingers = []
    for f in desc.fingers:
        finger = {"name": f.name, "position": arr(f.position), "radius": float(f.radius),
                  "stiffness": float(f.stiffness), "damping": float(f.damping), "channel": int(f.channel),
                  "renderer": str(f.renderer), "cursor_mass": float(f.cursor_mass)}
        if f.points is not None:  # a convex finger; a sphere's entry has no points
            finger.update(points=arr(f.points), orientation=arr(f.orientation))
        fingers.append(finger)
    return {"gravity": [float(g) for g in desc.gravity], "gyroscopic": bool(desc.gyroscopic),
            "haptic_rate": float(desc.haptic_rate), "display_rate": float(desc.display_rate),
            "bodies": bodies, "fingers": fingers}


def scene_from_dict(data: dict):
    """The ``SceneDesc`` a recording was made with (prepared: mass properties included)."""
    from .scene import BodyDesc, FingerDesc, MassProperties, SceneDesc
    bodies = []
    for b in data["bodies"]:
        mp = None if b.get("mass") is None else MassProperties(
            mass=b["mass"], volume=b["volume"], center_of_mass=np.array(b["center_of_mass"]),
            inertia=np.array(b["inertia"]))
        bodies.append(BodyDesc(name=b["name"], static=b["static"],
                               parts=[np.array(p, dtype=np.float64).reshape(-1, 3) for p in b["parts"]],
                               meshes=[], position=np.array(b["position"]),
                               orientation=np.array(b["orientation"]), mass=b.get("mass"),
                               mu_s=b["mu_s"], mu_d=b["mu_d"], viscosity=b["viscosity"], mass_properties=mp))
    fingers = [FingerDesc(name=f["name"], position=np.array(f["position"]), radius=f["radius"],
                          stiffness=f["stiffness"], damping=f["damping"], channel=f.get("channel", 0),
                          points=None if f.get("points") is None else np.array(f["points"], dtype=np.float64).reshape(-1, 3),
                          orientation=np.array(f.get("orientation", (1.0, 0.0, 0.0, 0.0)), dtype=np.float64),
                          **{k: f[k] for k in ("renderer", "cursor_mass") if k in f})
               for f in data["fingers"]]
    return SceneDesc(gravity=tuple(data["gravity"]), gyroscopic=data["gyroscopic"],
                     haptic_rate=data["haptic_rate"], display_rate=data.get("display_rate", 30.0),
                     bodies=bodies, fingers=fingers)


def fingerprint(scene: dict) -> str:
    """sha256 of the scene as recorded (geometry, masses, friction, fingers, gravity)."""
    text = json.dumps(scene, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def make_header(desc, *, mode: str, haptic_rate: float, source: str = "", fps: float | None = None,
                device: dict | None = None, runtime: dict | None = None, extra: dict | None = None) -> dict:
    """Everything needed to read, bake and re-simulate a recording."""
    import mcap
    scene = scene_to_dict(desc)
    versions = {"grasp_lab": addon_version(), "python": platform.python_version(),
                "numpy": np.__version__, "mcap": getattr(mcap, "__version__", "")}
    try:
        import graspcore
        versions["graspcore"] = getattr(graspcore, "__version__", "present")
    except ImportError:
        pass
    bpy = sys.modules.get("bpy")       # only when running inside Blender (never imported here)
    if bpy is not None:
        versions["blender"] = bpy.app.version_string
    header = {
        "format": "grasp_lab recording", "format_version": FORMAT_VERSION,
        "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "mode": mode, "source": source, "versions": versions, "units": UNITS,
        "rates": {"haptic_hz": float(haptic_rate), "display_hz": float(desc.display_rate),
                  "fps": None if fps is None else float(fps)},
        "device": device or {}, "runtime": runtime or {},
        "body_names": [b.name for b in desc.bodies], "finger_names": [f.name for f in desc.fingers],
        "fingerprint": fingerprint(scene), "scene": scene,
    }
    header.update(extra or {})
    return header


# --------------------------------------------------------------------------- writer

class RecordingWriter:
    """Writes one recording. Not thread-safe: one thread writes (the recorder)."""

    def __init__(self, path: str, header: dict, compression: str = "lz4",
                 flush_interval: float = FLUSH_INTERVAL):
        from mcap.writer import CompressionType, Writer
        _reuse_freed_memory()
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression: expected one of {COMPRESSIONS}, got {compression!r}")
        self.header = header
        self.dtype = tick_dtype(len(header["body_names"]), len(header["finger_names"]))
        self.flush_interval = float(flush_interval)
        # Written as PATH.partial (a readable prefix at every flush), renamed to PATH when closed.
        self._out = AtomicFile(path, keep_partial=_holds_ticks)
        self.path = self._out.path
        self.partial = self._out.partial
        self._file = self._out.file
        self._good = 0          # bytes on disk at the last flush: a valid prefix
        kind = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        # Chunks close on the flush timer (far below this size), CRCs on every chunk and on the
        # whole data section (so `info` checks a whole file without decompressing it).
        self._mcap = Writer(self._file, chunk_size=64 << 20, compression=kind[compression],
                            enable_data_crcs=True)
        self._mcap.start(profile=PROFILE, library=f"grasp_lab {header['versions'].get('grasp_lab', '')}")
        json_schema = self._mcap.register_schema("grasp_lab.Json", "jsonschema",
                                                 json.dumps(JSON_SCHEMA).encode())
        tick_schema = self._mcap.register_schema(TICK_SCHEMA, TICK_ENCODING,
                                                 json.dumps(schema_of(self.dtype)).encode())
        self._ch = {topic: self._mcap.register_channel(topic, "json", json_schema)
                    for topic in (TOPIC_HEADER, TOPIC_EVENTS, TOPIC_END)}
        self._ch[TOPIC_TICKS] = self._mcap.register_channel(TOPIC_TICKS, TICK_ENCODING, tick_schema)
        self._seq = 0
        self._flushed_ticks = 0
        self.ticks = 0
        self.events = 0
        self.first_time = None
        self.last_time = 0.0
        self._write_json(TOPIC_HEADER, header, 0.0)
        self.flush()
        self.closed = False

    @staticmethod
    def _ns(t: float) -> int:
        return max(0, int(round(t * 1e9)))

    def _write_json(self, topic, data, t):
        with uninterrupted():
            self._mcap.add_message(self._ch[topic], log_time=self._ns(t), publish_time=self._ns(t),
                                   data=json.dumps(data).encode(), sequence=self._seq)
            self._seq += 1

    def write_ticks(self, records: np.ndarray) -> None:
        """Tick records (``self.dtype``), in tick order."""
        if records.dtype != self.dtype:
            raise ValueError(f"records: dtype does not match the header's bodies and fingers")
        with uninterrupted():       # the blocks and the count that the end record gives
            for start in range(0, len(records), BLOCK_TICKS):
                block = np.ascontiguousarray(records[start:start + BLOCK_TICKS])
                t = float(block["time"][0])
                self._mcap.add_message(self._ch[TOPIC_TICKS], log_time=self._ns(t), publish_time=self._ns(t),
                                       data=block.tobytes(), sequence=self._seq)
                self._seq += 1
            if len(records):
                if self.first_time is None:
                    self.first_time = float(records["time"][0])
                self.ticks += len(records)
                self.last_time = float(records["time"][-1])

    def event(self, t: float, kind: str, subject: str = "", detail: str = "", tick: int = -1, **extra):
        data = {"tick": int(tick), "time": float(t), "kind": kind, "subject": subject, "detail": detail}
        data.update(extra)
        self._write_json(TOPIC_EVENTS, data, t)
        self.events += 1

    def flush(self) -> None:
        """Close the chunk in progress and hand the bytes to the OS (a kill -9 keeps them)."""
        with uninterrupted():
            self._mcap.flush()
            self._file.flush()
            self._good = self._file.tell()
            self._flushed_ticks = self.ticks
            self._out.keep = self.ticks > 0     # a readable prefix with ticks: kept after a crash

    def close(self, end: dict | None = None) -> None:
        """The end record (counts, overflow, how the session ended: ``clean`` false and
        ``ended_by`` when it did not end as asked), the summary and the footer; then the file
        is renamed into place. A write that fails (a full disk) leaves PATH as it was and
        PATH.partial cut back to its last flush (a readable prefix); the OSError says so."""
        if self.closed:
            return
        start = self.last_time if self.first_time is None else self.first_time
        data = {"ticks": self.ticks, "events": self.events, "start_time": start, "end_time": self.last_time,
                "duration": self.last_time - start, "clean": True}
        data.update(end or {})
        try:
            self._write_json(TOPIC_END, data, self.last_time)
            self._mcap.finish()
            self._out.commit()
        except OSError as ex:
            self.abandon()
            raise OSError(ex.errno, f"{ex.strerror or ex}: the recording could not be finished; "
                                    f"{self.partial} holds its first {self.ticks_flushed()} ticks "
                                    f"(a readable prefix, `grasp-lab info` reads it), {self.path} is "
                                    f"as it was") from None
        self.closed = True

    def ticks_flushed(self) -> int:
        return self._flushed_ticks

    def abandon(self) -> None:
        """Stop writing without finishing (a write failed): the partial file cut back to its
        last flush, left beside the untouched target."""
        if self.closed:
            return
        self.closed = True
        if self._flushed_ticks:
            self._out.leave(self._good)
        else:
            self._out.discard()

    def discard(self) -> None:
        """Nothing of it is worth keeping (refused before it started, or a copy that failed):
        the partial file removed, the target as it was."""
        self.closed = True
        self._out.discard()


def _holds_ticks(path: str) -> bool:
    """A partial recording left by a crash holds ticks (worth keeping); a header cut short does not."""
    try:
        return len(open_recording(path).ticks) > 0
    except (RecordingError, OSError):
        return False


# --------------------------------------------------------------------------- events

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


# --------------------------------------------------------------------------- recorder

_stop_reason = ""


def set_stop_reason(why: str) -> None:
    """A signal is stopping the process (the command line's handler says which): recordings
    finished from now on say ``clean: false`` and this."""
    global _stop_reason
    _stop_reason = why


def stop_reason() -> str:
    return _stop_reason


def _in_flight() -> str:
    """The exception a ``finally`` is running for, as the end record's ``ended_by``."""
    ex = sys.exc_info()[1]
    if ex is None:
        return ""
    if isinstance(ex, KeyboardInterrupt):
        return "SIGINT (Ctrl-C)"
    return f"{type(ex).__name__}: {ex}"


class SessionRecorder:
    """Records every tick of a session into a RecordingWriter.

    EXEC (synchronous steps): ``after_step(tick)`` copies the stepped world into a block
    (one C call); the block is written and the chunk closed when ``flush_interval`` of wall
    time has passed. Threaded runtime: ``begin(threaded=True)`` gives the world a tick log
    (the haptic loop fills it, never waits); a thread drains it every ``poll`` seconds and
    writes. Ticks the full ring dropped are counted (``overflow``) and reported.
    """

    def __init__(self, writer: RecordingWriter, world, ring_seconds: float = 2.0, poll: float = 0.02):
        self.writer = writer
        self.world = world
        self.dtype = writer.dtype
        rate = writer.header["rates"]["haptic_hz"]
        self.capacity = max(16, int(ring_seconds * rate))
        self.poll = poll
        self.events = EventDetector(writer.header)
        self.overflow = 0
        self.error = ""
        self._block = np.zeros(max(256, int(rate * writer.flush_interval) + 1), dtype=self.dtype)
        self._n = 0
        self._last_flush = time.perf_counter()
        self._wall0 = None
        self._thread = None
        self._stop = threading.Event()
        self._lock = threading.Lock()       # writer: recorder thread vs parameter events
        self.finished = False

    # ---- setup
    def begin(self, threaded: bool) -> None:
        """Before the world starts stepping (before ``world.start`` when threaded): tick 0 is
        the state the session starts from."""
        if self._n == 0 and self.writer.ticks == 0:
            self.world._tick_record(self._block[:1], 0)
            self._n = 1
        if threaded:
            self._write_block()
            self.world.set_tick_log(self.capacity)

    def runtime_started(self) -> None:
        self._thread = threading.Thread(target=self._drain_loop, name="grasp_lab recorder", daemon=True)
        self._thread.start()

    # ---- EXEC
    def after_step(self, tick: int) -> None:
        now = time.perf_counter()
        self.world._tick_record(self._block[self._n:self._n + 1], tick)
        if self._wall0 is not None:
            self._block["period_us"][self._n] = (now - self._wall0) * 1e6
        self._wall0 = now
        self._n += 1
        if self._n == len(self._block) or now - self._last_flush >= self.writer.flush_interval:
            self._write_block()

    def _write_block(self) -> None:
        # Uninterrupted as a whole: a stop signal is raised only once the block is written and
        # marked written, so finish() never writes it a second time.
        with uninterrupted():
            if self.writer.closed:
                self._n = 0
                return
            try:
                if self._n:
                    self._write(self._block[:self._n])
                self.writer.flush()
            except OSError as ex:       # a full disk: the session goes on, the file keeps its prefix
                self._fail(ex)
            self._n = 0
            self._last_flush = time.perf_counter()

    def _fail(self, ex: OSError) -> None:
        with self._lock:
            self.writer.abandon()
        self.error = self.error or (f"recording stopped after {self.writer.ticks_flushed()} ticks "
                                    f"({ex.strerror or ex}); {self.writer.partial} holds them (a "
                                    f"readable prefix), {self.writer.path} is as it was")

    def _write(self, records) -> None:
        with self._lock:
            self.writer.write_ticks(records)
            for tick, t, kind, subject, detail in self.events(records):
                self.writer.event(t, kind, subject, detail, tick=tick)

    # ---- threaded
    def _drain_loop(self) -> None:
        buf = np.zeros(self.capacity, dtype=self.dtype)
        last_flush = time.perf_counter()
        try:
            while True:
                # Wake for the next poll or the flush deadline, whichever comes first.
                due = last_flush + self.writer.flush_interval - FLUSH_MARGIN
                wait = min(self.poll, max(0.0, due - time.perf_counter()))
                stopping = self._stop.wait(wait)
                n = self.world._drain_ticks(buf)
                if self.writer.closed:      # abandoned (a write failed): the ring is drained only
                    if stopping:
                        return
                    continue
                if n:
                    self._write(buf[:n])
                overflow = int(self.world.tick_log_overflow())
                if overflow > self.overflow:
                    with self._lock:
                        self.writer.event(self.writer.last_time, "overflow", "recorder",
                                          f"{overflow - self.overflow} ticks dropped (ring of "
                                          f"{self.capacity} full)", dropped=overflow - self.overflow)
                    self.overflow = overflow
                now = time.perf_counter()
                if stopping or now >= due - 1e-3:
                    with self._lock:
                        self.writer.flush()
                    last_flush = now
                if stopping and n == 0:
                    return
        except OSError as ex:       # a full disk: the session goes on; finish() reports it
            self._fail(ex)
        except Exception as ex:     # the session goes on; finish() reports it
            self.error = f"recorder stopped: {ex}"

    # ---- both
    def event(self, t: float, kind: str, subject: str = "", detail: str = "", **extra) -> None:
        """An event from outside the ticks (devices, parameters), from any thread."""
        with self._lock:
            self.writer.event(t, kind, subject, detail, **extra)

    def parameter_change(self, t: float, subject: str, name: str, value) -> None:
        self.event(t, "parameter", subject, f"{name} = {value}", name=name, value=value)

    def finish(self) -> dict:
        """After the world stopped: write what is left, the end record, close the file. A
        session stopped before its end (a signal, the exception a ``finally`` finishes it for,
        a failed write) gets ``clean: false`` and ``ended_by`` saying which."""
        if self.finished:
            return {}
        self.finished = True
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self.overflow = int(self.world.tick_log_overflow())
        else:
            self._write_block()
        end = {"overflow": self.overflow, "recorder_error": self.error}
        why = stop_reason() or _in_flight() or self.error
        if why:
            end.update(clean=False, ended_by=why)
        if not self.writer.closed:
            try:
                self.writer.close(end)
            except OSError as ex:
                self.error = end["recorder_error"] = str(ex.strerror or ex)
        return end


# --------------------------------------------------------------------------- reader

@dataclass
class Recording:
    path: str
    header: dict
    dtype: np.dtype
    ticks: np.ndarray                       # all tick records read, in order
    events: list = field(default_factory=list)
    end: dict | None = None                 # the end record (None: cut short)
    damage: list = field(default_factory=list)   # what was wrong, where (empty: intact)

    @property
    def body_names(self):
        return self.header["body_names"]

    @property
    def finger_names(self):
        return self.header["finger_names"]

    @property
    def haptic_rate(self) -> float:
        return float(self.header["rates"]["haptic_hz"])

    @property
    def duration(self) -> float:
        """Session time from the first tick (tick 0: the start state) to the last."""
        return float(self.ticks["time"][-1] - self.ticks["time"][0]) if len(self.ticks) else 0.0

    def warnings(self) -> list:
        return [f"{self.path}: {d}" for d in self.damage]

    def sample(self, times) -> np.ndarray:
        """Indices of the ticks a session shows at session times ``times`` (s from the start):
        the last tick at or before each, on the haptic grid as the runner steps it (the
        nearest earlier tick where the ring dropped some)."""
        ticks = self.ticks["tick"].astype(np.int64)
        first = int(ticks[0])
        start = float(self.ticks["time"][0]) - first / self.haptic_rate
        wanted = np.floor((np.asarray(times, dtype=np.float64) - start) * self.haptic_rate + 1e-9)
        return np.clip(np.searchsorted(ticks, wanted, side="right") - 1, 0, len(ticks) - 1)


def _check_version(path, header):
    if header.get("format") != "grasp_lab recording":
        raise RecordingError(f"{path}: not a Grasp Lab recording (its header says format "
                             f"{header.get('format')!r})")
    version = header.get("format_version")
    if not isinstance(version, int):
        raise RecordingError(f"{path}: header has no format version")
    if version > FORMAT_VERSION:
        raise RecordingError(f"{path}: recording format version {version} is newer than this Grasp Lab "
                             f"reads (version {FORMAT_VERSION}); open it with a newer Grasp Lab")


MAX_CHUNK = 1 << 30         # bytes: a chunk claiming more is damage, not a reason to allocate it


def _chunk_data(compression: str, packed, size: int, crc: int, validate: bool) -> bytes:
    """The uncompressed records of an MCAP chunk, CRC checked when ``validate``."""
    if size > MAX_CHUNK:
        raise ValueError(f"chunk claims {size} bytes")
    if compression == "zstd":
        import zstandard
        data = zstandard.ZstdDecompressor().decompress(packed, max_output_size=size)
    elif compression == "lz4":
        import lz4.frame
        data = lz4.frame.decompress(packed)
    elif compression == "":
        data = bytes(packed)            # out of the reader's reused buffer
    else:
        raise ValueError(f"unknown chunk compression {compression!r}")
    if len(data) != size:
        raise ValueError(f"chunk holds {len(data)} bytes, its header says {size}")
    if validate and crc != 0 and zlib.crc32(data) != crc:
        raise ValueError("chunk CRC mismatch")
    return data


MCAP_MAGIC = b"\x89MCAP0\r\n"


class _Cursor:
    """Where the linear read is (the start of the record being read), for the damage message."""
    def __init__(self, size: int):
        self.size, self.pos = size, 0
        self.trailing = 0       # bytes after the footer's magic


SLAB = 4 << 20      # bytes the linear read takes from the file at a time


def _records(fh, validate: bool, cursor: _Cursor):
    """MCAP records in file order: Schema and Channel records, a message (in a chunk or not) as
    (channel id, data: valid until the next record), True for the footer. The file is read a
    slab at a time into one reused buffer (fresh memory for every chunk costs more in page
    faults than decompressing it). A record running past the end raises EndOfFile (a file cut
    short); anything malformed raises ValueError."""
    from mcap.exceptions import EndOfFile
    from mcap.opcode import Opcode
    unpack_u64 = struct.Struct("<Q").unpack_from
    buffer = bytearray(SLAB)
    view = memoryview(buffer)
    have = fh.readinto(view)
    if have < len(MCAP_MAGIC):
        raise EndOfFile()
    if bytes(view[:len(MCAP_MAGIC)]) != MCAP_MAGIC:
        raise ValueError("not an MCAP file (no magic bytes)")
    base, pos = 0, len(MCAP_MAGIC)         # file offset of buffer[0]; the next record in it

    def refill(need):
        """At least ``need`` bytes from ``pos`` in the buffer (fewer only at the end of the file)."""
        nonlocal buffer, view, have, base, pos
        rest = have - pos
        if need > len(buffer):
            grown = bytearray(max(need, 2 * len(buffer)))
            grown[:rest] = view[pos:have]
            buffer, view = grown, memoryview(grown)
        else:
            view[:rest] = bytes(view[pos:have])
        base, pos, have = base + pos, 0, rest
        while have < need:
            got = fh.readinto(view[have:])
            if not got:
                break
            have += got

    while True:
        if have - pos < 9:
            refill(9)
            if have == 0:
                return                  # no footer: the caller says so
            if have < 9:
                raise EndOfFile()
        cursor.pos = base + pos
        opcode = view[pos]
        (length,) = unpack_u64(view, pos + 1)
        if length > cursor.size - cursor.pos - 9:
            raise EndOfFile()
        if have - pos < 9 + length:
            refill(9 + length)
            if have < 9 + length:
                raise EndOfFile()
        body = view[pos + 9:pos + 9 + length]
        pos += 9 + length
        if opcode == Opcode.CHUNK:
            yield from _chunk_records(body, validate)
        elif opcode in (Opcode.MESSAGE, Opcode.SCHEMA, Opcode.CHANNEL):
            yield _parse_record(opcode, body, copy=True)   # outside chunks (other writers)
        elif opcode == Opcode.FOOTER:
            if have - pos < len(MCAP_MAGIC):
                refill(len(MCAP_MAGIC))
            cursor.pos = base + pos
            if have - pos < len(MCAP_MAGIC):
                raise EndOfFile()
            if bytes(view[pos:pos + len(MCAP_MAGIC)]) != MCAP_MAGIC:
                raise ValueError("no magic bytes after the footer")
            cursor.trailing = cursor.size - (cursor.pos + len(MCAP_MAGIC))
            yield True
            return


def _chunk_records(body: memoryview, validate: bool):
    """The records of one MCAP chunk record's body (decompressed, CRC checked when ``validate``)."""
    from mcap.opcode import Opcode
    if len(body) < 32:
        raise ValueError("chunk record too short")
    size, crc, name_len = struct.unpack_from("<QII", body, 16)
    if 32 + name_len + 8 > len(body):
        raise ValueError("chunk record overruns itself")
    compression = bytes(body[32:32 + name_len]).decode("utf-8", "replace")
    (stored,) = struct.unpack_from("<Q", body, 32 + name_len)
    packed = body[40 + name_len:40 + name_len + stored]
    if len(packed) != stored:
        raise ValueError("chunk data overruns its record")
    data = memoryview(_chunk_data(compression, packed, size, crc, validate))
    pos = 0
    while pos < len(data):
        if pos + 9 > len(data):
            raise ValueError("chunk ends inside a record header")
        opcode = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        rec = data[pos + 9:pos + 9 + length]
        if len(rec) != length:
            raise ValueError("a record overruns its chunk")
        pos += 9 + length
        if opcode in (Opcode.MESSAGE, Opcode.SCHEMA, Opcode.CHANNEL):
            yield _parse_record(opcode, rec, copy=False)


def _parse_record(opcode: int, body: memoryview, copy: bool):
    """A Message record as (channel id, data: a view, or bytes when ``copy``), a Schema or
    Channel record as mcap's record."""
    from mcap.data_stream import ReadDataStream
    from mcap.opcode import Opcode
    from mcap.records import Channel, Schema
    if opcode == Opcode.MESSAGE:
        if len(body) < 22:
            raise ValueError("message record too short")
        return struct.unpack_from("<H", body, 0)[0], bytes(body[22:]) if copy else body[22:]
    cls = Schema if opcode == Opcode.SCHEMA else Channel
    return cls.read(ReadDataStream(io.BytesIO(bytes(body))))


def _frame_ticks(ticks: np.ndarray, rate: float, fps: float, previous: bool = False) -> np.ndarray:
    """Mask of the ticks (numbers, tick 0 at the start) a session shows at frames of ``fps``:
    for frame k the last tick at or before k / fps, on the haptic grid as the runner steps.
    Tick t is one when the first frame at or after it, k = ceil(t fps / rate), maps back to t.
    ``previous``: the record before each too, and the block's last (the next block's first
    record may be a frame's)."""
    t = ticks.astype(np.int64)
    k = np.ceil(t * (fps / rate) - 1e-9)
    mask = np.floor(k * (rate / fps) + 1e-9).astype(np.int64) == t
    if previous and len(mask):
        mask[:-1] |= mask[1:]
        mask[-1] = True
    return mask


def _reuse_freed_memory() -> None:
    """Let glibc serve the chunk-sized buffers the (de)compressors return (and numpy's arrays
    of a few hundred kB) from its heap rather than a fresh mapping each, whose page faults cost
    several times the decompression (3.1 s against 0.4 s for 2.6 GB of records on our 2-core
    VM). glibc raises these two thresholds by itself, to these values at most, after the first
    large block is freed; this sets them where it would take them. Off glibc: nothing to do."""
    global _malloc_tuned
    if _malloc_tuned or not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc":
        return
    _malloc_tuned = True
    try:
        import ctypes
        libc = ctypes.CDLL(None)
        libc.mallopt(M_MMAP_THRESHOLD, 32 << 20)     # DEFAULT_MMAP_THRESHOLD_MAX (64-bit)
        libc.mallopt(M_TRIM_THRESHOLD, 64 << 20)     # twice that, as glibc sets it
    except (OSError, AttributeError):
        pass


_malloc_tuned = False
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3      # glibc <malloc.h>


def open_recording(path: str, fps: float | None = None, every: int | None = None,
                   previous: bool = False) -> Recording:
    """Read a recording, all of it that is intact. Damage (a file cut short, a bad CRC, garbage)
    ends the read: what came before it is kept and ``damage`` says what and where. Raises
    RecordingError when nothing usable is there (not MCAP, no header, a newer format).

    ``fps``: keep only the ticks a session shows at frames of that rate (what baking at the
    frame rate needs), instead of every tick; with ``previous``, the tick before each of them
    too (what the grasp analysis of a bake needs for accelerations). ``every``: keep only the ticks whose number is a
    multiple of it and the tick before each (what ``grasp-lab analyze --every`` needs: the tick
    and its predecessor give the acceleration).

    A whole file (footer, summary, data section CRC) is read without checking each chunk's CRC:
    the data section's CRC is computed on a second thread meanwhile, and only if it does not
    match is the file read again, chunk by chunk checked, to find where the damage is."""
    path = os.fspath(path)
    try:
        length, expected, span = _data_section(path)
    except (OSError, ValueError, IndexError, struct.error):
        return _read_linear(path, fps, validate=True, every=every, previous=previous)
    crc = []
    check = threading.Thread(target=lambda: crc.append(_checked_crc(path, length)), name="gl-crc",
                             daemon=True)
    check.start()
    try:
        rec = _read_linear(path, fps, validate=False, span=span, every=every, previous=previous)
    except RecordingError:
        rec = None          # raised again below unless the CRC says the data is damaged
    finally:
        check.join()
    if rec is None or crc[0] != expected:
        return _read_linear(path, fps, validate=True, every=every, previous=previous)
    return rec


def _checked_crc(path: str, length: int):
    try:
        return _crc_of(path, length)
    except (OSError, ValueError):
        return None


def _frame_rows(first: int, count: int, rate: float, fps: float) -> list:
    """Rows of a block of consecutive ticks first .. first + count - 1 that a session shows at
    frames of ``fps`` (as _frame_ticks, the same float operations), by arithmetic on the frame
    numbers; plain Python, as a block holds a few frames (numpy's call overhead is more)."""
    if fps >= rate:
        return list(range(count))          # every tick is some frame's
    step = rate / fps
    lo = math.ceil(first * (fps / rate) - 1e-9)
    hi = math.ceil((first + count - 1) * (fps / rate) - 1e-9)
    rows = [math.floor(k * step + 1e-9) - first for k in range(lo, hi + 1)]
    return [r for r in rows if 0 <= r < count]


class _Rows:
    """Tick records appended as rows of bytes into one array that grows by doubling: numpy
    backs large arrays with huge pages, where a list of small blocks and a concatenation
    fault in every 4 kB page twice (page faults cost more than the rest of a read here)."""

    def __init__(self, width: int, capacity: int = 1024):
        self.buffer = np.empty((max(int(capacity), 16), width), np.uint8)
        self.count = 0

    def append(self, block: np.ndarray) -> None:
        end = self.count + len(block)
        if end > len(self.buffer):
            grown = np.empty((max(end, 2 * len(self.buffer)), self.buffer.shape[1]), np.uint8)
            grown[:self.count] = self.buffer[:self.count]
            self.buffer = grown
        self.buffer[self.count:end] = block
        self.count = end

    def records(self, dtype: np.dtype) -> np.ndarray:
        used = self.buffer[:self.count]
        if self.count < len(self.buffer) * 3 // 4:
            used = used.copy()          # give back what the doubling left unused
        return used.view(dtype)[:, 0]


def _read_linear(path: str, fps: float | None, validate: bool, span: float | None = None,
                 every: int | None = None, previous: bool = False) -> Recording:
    """open_recording's linear read; ``validate``: check each chunk's CRC; ``span``: the
    session's length in seconds if known (to size the records' array once)."""
    if every is not None and (fps is not None or int(every) < 1):
        raise ValueError(f"every: expected a whole number >= 1 and no fps, got {every!r}")
    every = None if every is None or int(every) == 1 else int(every)
    from mcap.exceptions import EndOfFile
    from mcap.records import Channel, Schema
    try:
        size = os.path.getsize(path)
        fh = open(path, "rb", buffering=0)
    except OSError as ex:
        raise RecordingError(f"{path}: cannot open ({ex.strerror or ex})") from None
    schemas, channels = {}, {}
    header = dtype = None
    events, damage = [], []
    rows = None
    end = None
    footer = False
    next_tick = None
    cursor = _Cursor(size)
    _reuse_freed_memory()
    with fh:
        try:
            for rec in _records(fh, validate=validate, cursor=cursor):
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    channels[rec.id] = rec
                elif isinstance(rec, tuple):
                    channel_id, data = rec
                    ch = channels.get(channel_id)
                    if ch is None:
                        raise ValueError(f"message on unknown channel {channel_id}")
                    if ch.topic == TOPIC_TICKS and dtype is not None:
                        width = dtype.itemsize
                        if len(data) % width:
                            raise ValueError(f"tick block of {len(data)} bytes is not a whole number "
                                             f"of {width}-byte records")
                        # Records as rows of bytes, their tick numbers a strided view: numpy's
                        # structured-array paths (fields, masks, concatenate) cost more than
                        # all the rest of the read on wide records.
                        count = len(data) // width
                        if count == 0:
                            continue
                        ticks = np.ndarray(count, "<u8", data, tick_offset, (width,))
                        first, last = int(ticks[0]), int(ticks[-1])
                        if next_tick is not None and first < next_tick:
                            raise ValueError(f"tick {first} after tick {next_tick - 1}")
                        consecutive = last - first == count - 1
                        if not consecutive and (ticks[1:] <= ticks[:-1]).any():
                            raise ValueError("tick numbers out of order inside a block")
                        next_tick = last + 1
                        block = np.frombuffer(data, np.uint8).reshape(count, width)
                        if every is not None:
                            phase = ticks % every
                            rows.append(block[(phase == 0) | (phase == every - 1)])
                        elif fps is None:
                            rows.append(block)
                        elif consecutive and not previous:
                            rows.append(block[_frame_rows(first, count, rate, fps)])
                        else:
                            rows.append(block[_frame_ticks(ticks, rate, fps, previous)])
                    elif ch.topic == TOPIC_HEADER:
                        header = json.loads(bytes(data))
                        _check_version(path, header)
                        schema = schemas[channels_by_topic(channels, TOPIC_TICKS).schema_id]
                        try:
                            dtype = dtype_of(json.loads(schema.data))
                        except ValueError as ex:
                            raise RecordingError(f"{path}: {ex}") from None
                        tick_offset = dtype.fields["tick"][1]
                        rate = float(header["rates"]["haptic_hz"])
                        per_second = rate if fps is None else min(rate, fps)
                        if every is not None or (previous and fps is not None):
                            per_second = 2.0 * (rate / every if every else per_second) + rate / BLOCK_TICKS
                        rows = _Rows(dtype.itemsize, span * per_second + 16 if span else 1024)
                    elif header is None:
                        raise ValueError(f"{ch.topic} message before the header")
                    elif ch.topic == TOPIC_EVENTS:
                        ev = json.loads(bytes(data))
                        if not isinstance(ev, dict) or "kind" not in ev:
                            raise ValueError("malformed event")
                        events.append(ev)
                    elif ch.topic == TOPIC_END:
                        end = json.loads(bytes(data))
                elif rec is True:
                    footer = True
        except RecordingError:
            raise
        except EndOfFile:
            damage.append(f"file ends mid-record at byte {size} (cut short: the session did not end "
                          f"cleanly); everything before it was read")
        except Exception as ex:     # any damage: keep what came before it
            damage.append(f"damaged near byte {cursor.pos} of {size} ({type(ex).__name__}: {ex}); "
                          f"everything before it was read")
    if header is None:
        detail = f"no Grasp Lab header in its {size} bytes"
        if damage and "cut short" not in damage[0]:
            detail += f"; {damage[0]}"
        raise RecordingError(f"{path}: not a readable Grasp Lab recording ({detail})")
    if footer and cursor.trailing:
        damage.append(f"{cursor.trailing} bytes after the footer (byte {size - cursor.trailing} on): not "
                      f"part of the recording (appended or written over by something else); ignored")
    if not damage and not footer:
        damage.append("file ends without its summary: the session did not end cleanly (cut short)")
    elif not damage and end is None:
        damage.append("no end record")
    ticks = rows.records(dtype) if rows is not None else np.zeros(0, dtype=dtype)
    if fps is None and every is None and end is not None and not damage and end.get("ticks") not in (None, len(ticks)):
        damage.append(f"end record counts {end['ticks']} ticks, {len(ticks)} read")
    return Recording(path, header, dtype, ticks, events, end, damage)


def channels_by_topic(channels: dict, topic: str):
    for ch in channels.values():
        if ch.topic == topic:
            return ch
    raise ValueError(f"no {topic} channel before the header")


def _data_section(path: str) -> tuple[int, int, float | None]:
    """(length, CRC) of the data section as its DataEnd record states it, and the span of the
    messages' log times in seconds from the summary's Statistics record (None: none there);
    ValueError saying why when the file has no footer, summary or DataEnd (a file cut short)
    or no CRC."""
    from mcap.opcode import Opcode
    with open(path, "rb") as fh:
        try:
            fh.seek(-(8 + 1 + 8 + 8 + 8 + 4), os.SEEK_END)     # footer record + magic
        except OSError:
            raise ValueError("no footer") from None
        footer = fh.read(1 + 8 + 8 + 8 + 4)
        if footer[0] != Opcode.FOOTER:
            raise ValueError("no footer")
        summary_start = struct.unpack_from("<Q", footer, 9)[0]
        if summary_start < 13:
            raise ValueError("no summary")
        # DataEnd: opcode, length, crc (13 bytes) right before the summary.
        fh.seek(summary_start - 13)
        data_end = fh.read(13)
        if len(data_end) < 13 or data_end[0] != Opcode.DATA_END:
            raise ValueError("no data end record before the summary")
        expected = struct.unpack_from("<I", data_end, 9)[0]
        if expected == 0:
            raise ValueError("no data section CRC")
        # The Statistics record follows the schemas and channels at the summary's start.
        summary = fh.read(1 << 16)
        span, pos = None, 0
        while pos + 9 <= len(summary):
            opcode = summary[pos]
            (length,) = struct.unpack_from("<Q", summary, pos + 1)
            if opcode == Opcode.STATISTICS and pos + 9 + 42 <= len(summary):
                first, last = struct.unpack_from("<QQ", summary, pos + 9 + 26)
                span = (last - first) * 1e-9 if last >= first else None
                break
            pos += 9 + length
        return summary_start - 13, expected, span


def _crc_of(path: str, length: int) -> int:
    """CRC-32 of the first ``length`` bytes of the file (zlib releases the GIL while it runs)."""
    crc = 0
    with open(path, "rb", buffering=0) as fh:
        while length > 0:
            buf = fh.read(min(length, 16 << 20))
            if not buf:
                raise ValueError("file shorter than its footer says")
            crc = zlib.crc32(buf, crc)
            length -= len(buf)
    return crc


def _data_section_intact(path: str) -> tuple[bool, str]:
    """CRC of the whole data section against its DataEnd record, without decompressing."""
    length, expected, _ = _data_section(path)
    crc = _crc_of(path, length)
    if crc != expected:
        return False, f"data section CRC {crc:08x}, expected {expected:08x}"
    return True, ""


def summarize(path: str) -> dict:
    """What ``grasp-lab info`` prints. A whole file answers from its summary section (only the
    header, event and end messages are decompressed) after checking the data section CRC; a
    damaged or cut file is read linearly (open_recording) and the damage reported."""
    from mcap.reader import SeekingReader
    path = os.fspath(path)
    if not os.path.exists(path):
        raise RecordingError(f"{path}: no such file")
    intact, why = False, ""
    try:
        intact, why = _data_section_intact(path)
    except (OSError, ValueError, IndexError):
        intact = False
    if intact:
        try:
            with open(path, "rb") as fh:
                reader = SeekingReader(fh, validate_crcs=True)
                header, events, end = None, [], None
                for _schema, channel, message in reader.iter_messages(
                        topics=[TOPIC_HEADER, TOPIC_EVENTS, TOPIC_END]):
                    data = json.loads(message.data)
                    if channel.topic == TOPIC_HEADER:
                        _check_version(path, data)
                        header = data
                    elif channel.topic == TOPIC_EVENTS:
                        events.append(data)
                    else:
                        end = data
                if header is not None and end is not None:
                    stats = reader.get_summary().statistics
                    return _summary(path, header, events, end, ticks=end["ticks"],
                                    duration=end["duration"], damage=[],
                                    chunks=stats.chunk_count if stats else None)
        except RecordingError:
            raise
        except Exception:       # fall through to the linear read
            pass
    rec = open_recording(path)
    return _summary(path, rec.header, rec.events, rec.end or {}, ticks=len(rec.ticks),
                    duration=rec.duration, damage=rec.damage, chunks=None)


def _disagreements(header: dict, events: list) -> list:
    """Parameters set at the start (``parameter`` events at time 0, from --set) that the
    header's scene does not hold: the file contradicts itself."""
    scene = header.get("scene") or {}
    objects = {o["name"]: o for o in scene.get("bodies", []) + scene.get("fingers", [])}
    found = []
    for e in events:
        if e.get("kind") != "parameter" or e.get("time", 0.0) != 0.0 or "name" not in e:
            continue
        name, value, subject = e["name"], e.get("value"), e.get("subject", "")
        if subject == "scene":
            held = header["rates"]["haptic_hz"] if name == "haptic_rate" else scene.get(name)
        else:
            held = objects.get(subject, {}).get(name)
        if held is None:
            continue
        if isinstance(held, list) and isinstance(value, list):
            same = len(held) == len(value) and all(float(a) == float(b) for a, b in zip(held, value))
        else:
            same = float(held) == float(value)
        if not same:
            found.append(f"header and events disagree: the header's scene has {subject}.{name} = {held}, "
                         f"its parameter event says {value}")
    return found


def _summary(path, header, events, end, ticks, duration, damage, chunks) -> dict:
    rate = float(header["rates"]["haptic_hz"])
    damage = list(damage) + _disagreements(header, events)
    kinds = {}
    for e in events:
        kinds[e.get("kind", "?")] = kinds.get(e.get("kind", "?"), 0) + 1
    return {"path": path, "size": os.path.getsize(path), "format_version": header["format_version"],
            "mode": header.get("mode"), "created": header.get("created"), "source": header.get("source"),
            "ticks": int(ticks), "duration": float(duration), "haptic_rate": rate,
            "rates": header["rates"], "bodies": header["body_names"], "fingers": header["finger_names"],
            "scene": header["scene"], "fingerprint": header["fingerprint"], "device": header.get("device"),
            "runtime": header.get("runtime"), "versions": header.get("versions"),
            "events": kinds, "event_list": events, "overflow": end.get("overflow"),
            "recorder_error": end.get("recorder_error", ""), "damage": damage, "chunks": chunks,
            "ended_by": "" if end.get("clean", True) else end.get("ended_by") or "an unknown cause"}
