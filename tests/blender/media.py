"""Reading what a render wrote, without ffprobe: the sound track of a QuickTime / MP4 file (ISO
base media: nested atoms, moov > trak > mdia > hdlr 'soun', mdhd, minf > stbl)."""
from __future__ import annotations

import struct

import numpy as np


def _atoms(buf, off, end):
    while off + 8 <= end:
        size, kind = struct.unpack(">I4s", buf[off:off + 8])
        head = 8
        if size == 1:
            size, head = struct.unpack(">Q", buf[off + 8:off + 16])[0], 16
        elif size == 0:
            size = end - off
        if size < head or off + size > end:
            raise ValueError(f"atom {kind!r} at {off}: size {size} outside its parent")
        yield kind, off + head, off + size
        off += size


def _one(buf, off, end, path):
    """The body (start, end) of the first atom at ``path`` below [off, end)."""
    for kind, a, b in _atoms(buf, off, end):
        if kind == path[0]:
            return (a, b) if len(path) == 1 else _one(buf, a, b, path[1:])
    raise ValueError(f"no {path[0]!r} atom")


def sound_track(data: bytes) -> dict:
    """The file's sound track: ``rate`` (its time scale), ``duration`` (in it), ``codec`` (the
    sample description's four characters: b'sowt' 16-bit PCM, b'mp4a' AAC), and for 'sowt' in
    chunks of one sample count ``pcm`` (int16 samples). ValueError when there is none."""
    moov = _one(data, 0, len(data), [b"moov"])
    for kind, a, b in _atoms(data, *moov):
        if kind != b"trak":
            continue
        h0, _ = _one(data, a, b, [b"mdia", b"hdlr"])
        if data[h0 + 8:h0 + 12] != b"soun":
            continue
        m0, _ = _one(data, a, b, [b"mdia", b"mdhd"])
        if data[m0] == 1:       # version 1: 64-bit times
            rate, duration = struct.unpack(">IQ", data[m0 + 20:m0 + 32])
        else:
            rate, duration = struct.unpack(">II", data[m0 + 12:m0 + 20])
        stbl = _one(data, a, b, [b"mdia", b"minf", b"stbl"])
        s0, _ = _one(data, *stbl, [b"stsd"])
        track = {"rate": rate, "duration": duration, "codec": data[s0 + 12:s0 + 16]}
        if track["codec"] == b"sowt":
            c0, _ = _one(data, *stbl, [b"stco"])
            n = struct.unpack(">I", data[c0 + 4:c0 + 8])[0]
            offsets = struct.unpack(f">{n}I", data[c0 + 8:c0 + 8 + 4 * n])
            p0, _ = _one(data, *stbl, [b"stsc"])
            if struct.unpack(">I", data[p0 + 4:p0 + 8])[0] != 1:
                raise ValueError("PCM chunks of more than one size")
            per_chunk = struct.unpack(">III", data[p0 + 8:p0 + 20])[1]
            track["pcm"] = np.concatenate([np.frombuffer(data[o:o + 2 * per_chunk], "<i2") for o in offsets])
        return track
    raise ValueError("no sound track")
