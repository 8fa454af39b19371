"""Writing a recording: ``RecordingWriter`` writes the header, blocks of tick records and
events, and closes (flushes) a chunk at least every ``flush_interval`` seconds, so a killed
session loses at most that much. ``SessionRecorder`` feeds a writer from a running world: from
``World.tick_record`` after every synchronous step (EXEC), or on its own thread from the C
tick log that the haptic loop fills (threaded runtime); it derives the events (events.py)."""
from __future__ import annotations

import errno
import json
import sys
import threading
import time

import numpy as np

from ..outputs import AtomicFile, OutputError, uninterrupted
from .events import EventDetector
from .format import (BLOCK_TICKS, JSON_SCHEMA, PROFILE, TICK_ENCODING, TICK_SCHEMA, TOPIC_END, TOPIC_EVENTS,
                     TOPIC_HEADER, TOPIC_TICKS, RecordingError, schema_of, tick_dtype)
from .reader import open_recording, reuse_freed_memory

FLUSH_INTERVAL = 0.1        # s: at most this much of a session is lost to a kill -9
FLUSH_MARGIN = 0.02         # s: the recorder thread flushes this early (it may wake late: GIL, load)
COMPRESSIONS = ("lz4", "zstd", "none")   # lz4 by default: 3x faster to read back than zstd


class RecordingWriter:
    """Writes one recording. Not thread-safe: one thread writes (the recorder)."""

    def __init__(self, path: str, header: dict, compression: str = "lz4",
                 flush_interval: float = FLUSH_INTERVAL):
        from mcap.writer import CompressionType, Writer
        reuse_freed_memory()
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
        except (OSError, OutputError) as ex:
            self.abandon()
            raise OSError(getattr(ex, "errno", None) or errno.EIO, f"{getattr(ex, 'strerror', None) or ex}: the recording could not be finished; "
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
        self.listeners = []     # callables given each block of records written (engine.tick_tap)
        self.discard_on_finish = False      # the session failed at its start: nothing of it is kept

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
        for listen in self.listeners:
            listen(records)

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
                    for listen in self.listeners if n else ():
                        listen(buf[:n])
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
        if self.discard_on_finish:
            self.writer.discard()
        elif not self.writer.closed:
            try:
                self.writer.close(end)
            except OSError as ex:
                self.error = end["recorder_error"] = str(ex.strerror or ex)
        return end
