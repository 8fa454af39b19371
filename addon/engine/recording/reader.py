"""Reading a recording back: ``open_recording`` reads a file linearly, recovering everything
before any damage; ``summarize`` answers ``grasp-lab info`` from the summary section when the
file is whole. Plain Python + numpy + ``mcap``; no bpy, no graspcore (a recording opens anywhere)."""
from __future__ import annotations

import io
import json
import math
import os
import platform
import struct
import sys
import threading
import zlib
from dataclasses import dataclass
from dataclasses import dataclass, field

import numpy as np

from .format import (BLOCK_TICKS, TOPIC_END, TOPIC_EVENTS, TOPIC_HEADER, TOPIC_TICKS, RecordingError,
                     check_version, dtype_of)


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


MAX_CHUNK = 1 << 30         # bytes: a chunk claiming more is damage, not a reason to allocate it


class ChunkCRCError(ValueError):
    """A chunk whose bytes are not what its CRC says: skipped, the reading goes on after it."""


@dataclass
class SkippedChunk:
    """What ``_records`` yields for a chunk it skipped (its CRC): where, and its time span."""
    offset: int
    start_ns: int
    end_ns: int


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
        raise ChunkCRCError("chunk CRC mismatch")
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
            try:
                records = list(_chunk_records(body, validate))    # all of it checked before any is used
            except ChunkCRCError:
                start_ns, end_ns = struct.unpack_from("<QQ", body, 0) if len(body) >= 16 else (0, 0)
                yield SkippedChunk(cursor.pos, start_ns, end_ns)
                continue
            yield from records
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


def reuse_freed_memory() -> None:
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
    skipped = []            # chunks whose CRC failed: skipped, the rest read
    rows = None
    end = None
    footer = False
    next_tick = None
    cursor = _Cursor(size)
    reuse_freed_memory()
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
                        check_version(path, header)
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
                elif isinstance(rec, SkippedChunk):
                    skipped.append(rec)
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
    for c in skipped:
        damage.append(f"chunk at byte {c.offset} fails its CRC (t = {c.start_ns / 1e9:.3f} .. {c.end_ns / 1e9:.3f} s): "
                      f"skipped, its ticks and events lost; everything after it was read")
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
                        check_version(path, data)
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
