"""Hearing the grasp (docs/sound.md): the tick records of a session as sound. bpy-free, numpy only.

Per finger: a click at contact onset (loudness from the approach speed of its fingertip along the
contact normal), a tone while it touches whose pitch follows its normal force, filtered noise while
it slips (loudness from the slip speed); per held dynamic body a pulsed warning when its smallest
slip margin falls below a threshold. ``SoundMapping`` holds every number of that mapping.

One implementation for the whole recording and for a live session: ``Sonifier.feed(records)``
turns consecutive tick records into the samples of the time they cover (sample n is at session
time n / rate; the samples up to the last record's time go out, the rest wait for the next
records), carrying its state (phases, envelopes, noise streams, click tails) from call to call,
so feeding a recording in any pieces gives the same samples, bit for bit, as feeding it whole.
Nothing is random: the noise comes from fixed seeds. A record holds the state the tick ended
with; the samples from its time to the next record's hold that state (frequency, loudness), the
envelopes move linearly between records.
"""
from __future__ import annotations

import io
import struct
from dataclasses import dataclass, fields

import numpy as np

from . import analysis

SLIP = analysis.SLIP


@dataclass
class SoundMapping:
    """The mapping from the grasp to sound (docs/sound.md). Forces in N, speeds in m/s, times in s."""
    sample_rate: int = 48000
    pitch_low: float = 220.0        # Hz: the tone at zero normal force
    pitch_high: float = 880.0       # Hz: the tone at force_full and above
    force_full: float = 10.0        # N: the normal force of the highest pitch
    curve: float = 0.5              # exponent on force / force_full (< 1: more pitch change at light forces)
    tone_gain: float = 0.15
    click_gain: float = 0.6
    click_speed_full: float = 0.2   # approach speed of the loudest click
    click_min: float = 0.1          # the quietest click (a touch at zero speed), fraction of click_gain
    click_freq: float = 3000.0      # Hz: the click's ring
    click_decay: float = 0.0015     # s: its time constant
    slip_gain: float = 0.3
    slip_speed_full: float = 0.05   # slip speed of the loudest scrape
    warning_margin: float = 0.2     # N: a held body's smallest slip margin below this sounds the warning
    warning_gain: float = 0.1
    warning_freq: float = 1320.0    # Hz
    warning_period: float = 0.125   # s: one beep per period ...
    warning_on: float = 0.06        # s: ... this long
    attack: float = 0.005           # s: tone, scrape and warning fade in and out over this
    volume: float = 1.0             # the master gain

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if not np.isfinite(v):
                raise ValueError(f"sound mapping: {f.name} must be finite, got {v}")
        if int(self.sample_rate) != self.sample_rate or not 8000 <= self.sample_rate <= 192000:
            raise ValueError(f"sound mapping: sample_rate must be a whole number of Hz in 8000..192000, "
                             f"got {self.sample_rate}")
        for name in ("pitch_low", "pitch_high", "force_full", "curve", "click_speed_full", "click_freq",
                     "click_decay", "slip_speed_full", "warning_freq", "warning_period", "warning_on", "attack"):
            if not getattr(self, name) > 0:
                raise ValueError(f"sound mapping: {name} must be > 0, got {getattr(self, name)}")
        if self.pitch_high <= self.pitch_low:
            raise ValueError(f"sound mapping: pitch_high ({self.pitch_high} Hz) must be above pitch_low "
                             f"({self.pitch_low} Hz)")
        if max(self.pitch_high, self.click_freq, self.warning_freq) >= self.sample_rate / 2:
            raise ValueError(f"sound mapping: frequencies must stay below half the sample rate "
                             f"({self.sample_rate / 2:g} Hz)")
        if self.warning_on >= self.warning_period:
            raise ValueError("sound mapping: warning_on must be shorter than warning_period")
        for name in ("tone_gain", "click_gain", "click_min", "slip_gain", "warning_gain", "volume"):
            if getattr(self, name) < 0:
                raise ValueError(f"sound mapping: {name} must be >= 0, got {getattr(self, name)}")

    def pitch(self, normal_force):
        """The tone's frequency (Hz) at a normal force (N): from pitch_low at 0 to pitch_high at
        force_full, along (force / force_full) ** curve, in equal musical steps (log frequency)."""
        u = np.clip(np.asarray(normal_force, dtype=np.float64) / self.force_full, 0.0, 1.0) ** self.curve
        return self.pitch_low * (self.pitch_high / self.pitch_low) ** u


def mapping_from(settings) -> SoundMapping:
    """A SoundMapping from ``KEY=VALUE`` texts (``grasp-lab export --wav --sound-map``); ValueError
    naming the text for an unknown key or a value that is not a number."""
    names = {f.name for f in fields(SoundMapping)}
    values = {}
    for text in settings:
        key, eq, value = text.partition("=")
        key = key.strip()
        if not eq or key not in names:
            raise ValueError(f"--sound-map {text}: expected KEY=VALUE with KEY one of {', '.join(sorted(names))}")
        try:
            values[key] = int(value) if key == "sample_rate" else float(value)
        except ValueError:
            raise ValueError(f"--sound-map {text}: {value!r} is not a number") from None
    return SoundMapping(**values)


# The scrape's band: a windowed-sinc band-pass (1-6 kHz at 48 kHz) applied to white noise.
_NOISE_TAPS = 31
_CLICK_LENGTH = 8       # click time constants after which a click is over (e^-8: inaudible)


def _band_pass(rate: int, low: float = 1000.0, high: float = 6000.0, taps: int = _NOISE_TAPS) -> np.ndarray:
    n = np.arange(taps) - (taps - 1) / 2
    high = min(high, 0.45 * rate)
    h = (2 * high / rate) * np.sinc(2 * high / rate * n) - (2 * low / rate) * np.sinc(2 * low / rate * n)
    h *= np.hamming(taps)
    return h / np.sqrt(np.sum(h * h))       # unit noise power in, about unit power out


class _Gates:
    """Fades of on/off targets (one per column): from a change of target at time tau with value
    e there, the value moves toward the new target at 1 / attack per second. Computed from the
    last change, never step by step, so the values at a time are the same however the records
    were split between calls."""

    def __init__(self, columns: int, attack: float):
        self.attack = attack
        self.tau = np.zeros(columns)
        self.start = np.zeros(columns)
        self.target = np.zeros(columns)

    def _value(self, c, t):
        gap = self.start[c] - self.target[c]
        return self.target[c] + np.sign(gap) * np.maximum(np.abs(gap) - (t - self.tau[c]) / self.attack, 0.0)

    def at(self, targets: np.ndarray, times: np.ndarray) -> np.ndarray:
        """Values (len(times), columns) at ``times``; ``targets[k]`` holds from ``times[k]`` on
        (targets[0]: the one already held at times[0])."""
        out = np.empty(targets.shape)
        for c in range(targets.shape[1]):
            changes = np.flatnonzero(targets[1:, c] != targets[:-1, c]) + 1
            bounds = [0, *changes.tolist(), len(times)]
            for a, b in zip(bounds[:-1], bounds[1:]):
                if a > 0:
                    self.start[c] = self._value(c, times[a])
                    self.tau[c], self.target[c] = times[a], targets[a, c]
                out[a:b, c] = self._value(c, times[a:b])
        return out


class Sonifier:
    """Tick records in, samples (float32, mono, in -1..1) out; see the module's docstring.

    ``scene``: a recording header's ``scene`` dict or an engine.scene.SceneDesc (bodies' friction
    and which are static, for the slip margins)."""

    def __init__(self, scene, mapping: SoundMapping | None = None):
        self.mapping = mapping or SoundMapping()
        self.models = analysis.body_models(scene)
        self.dynamic = np.array([not m.is_static for m in self.models] + [False])
        self._mu_s = np.array([m.mu_s for m in self.models] + [0.0])
        self._mu_d = np.array([m.mu_d for m in self.models] + [0.0])
        fingers = scene["fingers"] if isinstance(scene, dict) else scene.fingers
        self.nf = len(fingers)
        self.nb = len(self.models)
        self.rate = int(self.mapping.sample_rate)
        self._h = _band_pass(self.rate)
        # One noise stream per finger, indexed by sample: skipped (advanced) where it is silent.
        self._noise = [np.random.PCG64(0x5C2A9E + f) for f in range(self.nf)]
        self._noise_tail = np.zeros((self.nf, _NOISE_TAPS - 1))
        self._gates = _Gates(2 * self.nf + 1, self.mapping.attack)     # tone, slip per finger; warning
        self._prev = None           # the last record fed (its state holds until the next)
        self._held = None           # its (frequency, gate targets, slip loudness)
        self._phase = np.zeros(self.nf)     # tone phase in cycles at the last record's time
        self._clicks = []           # (onset sample, amplitude) of clicks still sounding
        self.next_sample = 0        # the first sample not yet produced
        self.clicks = []            # every click: (session time of its onset, finger, amplitude)

    # ------------------------------------------------------------------ per record
    def _targets(self, rec, prev_time, prev_god_object):
        """Per record: the tone's frequency, the gate targets (touching per finger, slipping per
        finger, a held body's slip margin low), the scrape's loudness (slip speed)."""
        m = self.mapping
        contact = rec["contact"]
        touching = (contact >= 0) & (rec["state"] > 0)
        fn, ft = analysis.contact_forces(rec["force"], rec["normal"])
        freq = m.pitch(np.maximum(fn, 0.0))
        slipping = touching & (rec["state"] == SLIP)
        # Slip speed: the god-object's velocity over the body's surface point under it.
        dt = (rec["time"] - prev_time)[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            v_go = (rec["god_object"] - prev_god_object) / np.where(dt > 0, dt, np.inf)[..., None]
        if self.nb:
            body = np.where(contact >= 0, contact, 0)
            rows = np.arange(len(rec))[:, None]
            pose, vel = rec["pose"][rows, body], rec["velocity"][rows, body]
            v_go = v_go - vel[..., :3] - analysis._cross(vel[..., 3:], rec["god_object"] - pose[..., :3])
        n = rec["normal"]
        v_go = v_go - np.einsum("...k,...k->...", v_go, n)[..., None] * n
        slip_speed = np.sqrt(np.einsum("...k,...k->...", v_go, v_go))
        loud = np.where(slipping, np.clip(slip_speed / m.slip_speed_full, 0.0, 1.0), 0.0)
        # The warning: a dynamic body held with its smallest slip margin mu |Fn| - |Ft| below the threshold.
        on = np.where((contact >= 0) & (contact < self.nb), contact, self.nb)
        mu = np.where(rec["state"] == SLIP, self._mu_d[on], self._mu_s[on])      # analysis.cone_mu's
        held = touching & self.dynamic[np.where(contact >= 0, contact, self.nb)]
        warn = np.any(held & (mu * fn - ft < m.warning_margin), axis=1)
        gates = np.concatenate([touching, slipping, warn[:, None]], axis=1).astype(np.float64)
        return freq, gates, loud

    def _onsets(self, rec, touched_before, hip_before, time_before):
        """Clicks of the records: (record index, finger, amplitude) where a finger starts touching."""
        m = self.mapping
        touching = (rec["contact"] >= 0) & (rec["state"] > 0)
        before = np.concatenate([touched_before[None], touching[:-1]])
        hips = np.concatenate([hip_before[None], rec["hip"][:-1]])
        times = np.concatenate([[time_before], rec["time"][:-1]])
        out = []
        for k, f in zip(*np.nonzero(touching & ~before)):
            dt = rec["time"][k] - times[k]
            approach = -float(np.dot(rec["hip"][k, f] - hips[k, f], rec["normal"][k, f])) / dt if dt > 0 else 0.0
            loud = np.clip(approach / m.click_speed_full, m.click_min, 1.0)
            out.append((int(k), int(f), float(m.click_gain * loud)))
        return out

    # ------------------------------------------------------------------ feeding
    def feed(self, records: np.ndarray) -> np.ndarray:
        """The samples from the end of the previous call up to (not including) the last record's
        time. Records must follow each other in time (a record at or before the last one fed is
        skipped)."""
        m = self.mapping
        rate = self.rate
        records = np.asarray(records)
        if self._prev is not None and len(records):
            records = records[records["time"] > self._prev["time"][0]]
        if not len(records):
            return np.zeros(0, np.float32)
        if self._prev is None:
            # The session's start: silence from time 0 (or the first record, if earlier) to the
            # first record, nothing touched before it.
            self._prev = records[:1].copy()
            self._prev["time"] = min(0.0, float(records["time"][0]))
            self._prev["contact"] = -1
            self._prev["state"] = 0
            self._gates.tau[:] = self._prev["time"][0]
            self._held = (np.full(self.nf, m.pitch_low), np.zeros(2 * self.nf + 1), np.zeros(self.nf))
            records = records[records["time"] > self._prev["time"][0]]     # tick 0 at time 0: the start
        prev = self._prev
        if not len(records):
            return np.zeros(0, np.float32)
        times = np.concatenate([prev["time"], records["time"]])     # the held record's, then the new ones
        freq, gates, loud = self._targets(records, times[:-1],
                                          np.concatenate([prev["god_object"], records["god_object"][:-1]]))
        touched = ((prev["contact"] >= 0) & (prev["state"] > 0))[0]
        for k, f, amp in self._onsets(records, touched, prev["hip"][0], float(prev["time"][0])):
            self._clicks.append((int(np.ceil(records["time"][k] * rate - 1e-9)), amp))
            self.clicks.append((float(records["time"][k]), f, amp))
        # Each record's state holds from its time to the next record's: times[k]'s (the held
        # record's first).
        freq = np.concatenate([self._held[0][None], freq])
        gates = np.concatenate([self._held[1][None], gates])
        loud = np.concatenate([self._held[2][None], loud])
        env = self._gates.at(gates, times)                  # (len(times), 2 nf + 1) at the records
        phase = np.add.accumulate(np.concatenate([self._phase[None], freq[:-1] * np.diff(times)[:, None]]),
                                  axis=0)                   # cycles at each record
        n0 = self.next_sample
        n1 = max(n0, int(np.ceil(times[-1] * rate - 1e-9)))
        n = np.arange(n0, n1)
        t = n / rate
        seg = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
        frac = (t - times[seg]) / (times[seg + 1] - times[seg])
        out = np.zeros(len(n))
        nf = self.nf
        for f in range(nf):
            if np.any(env[:, f] > 0):
                a = env[seg, f] + frac * (env[seg + 1, f] - env[seg, f])
                out += m.tone_gain * a * np.sin(2 * np.pi * (phase[seg, f] + freq[seg, f] * (t - times[seg])))
            white = self._white(f, len(n), silent=not np.any(env[:, nf + f] > 0))
            if white is not None:
                a = (env[seg, nf + f] + frac * (env[seg + 1, nf + f] - env[seg, nf + f])) * \
                    (loud[seg, f] + frac * (loud[seg + 1, f] - loud[seg, f]))
                out += m.slip_gain * a * self._band(f, white)
        if np.any(env[:, -1] > 0):
            a = env[seg, -1] + frac * (env[seg + 1, -1] - env[seg, -1])
            cyc = np.mod(t, m.warning_period)
            pulse = np.where(cyc < m.warning_on, np.sin(np.pi * cyc / m.warning_on) ** 2, 0.0)
            out += m.warning_gain * a * pulse * np.sin(2 * np.pi * m.warning_freq * t)
        out += self._render_clicks(n0, len(n))
        self._prev = records[-1:].copy()
        self._held = (freq[-1], gates[-1], loud[-1])
        self._phase = phase[-1]
        self.next_sample = n1
        return np.clip(out * m.volume, -1.0, 1.0).astype(np.float32)

    def _white(self, f: int, count: int, silent: bool):
        """The next ``count`` white noise samples of finger f's stream, or None when ``silent``
        (the stream skips them: the same samples follow whatever was skipped)."""
        taps = len(self._h) - 1
        gen = self._noise[f]
        if silent and count > taps:
            gen.advance(count - taps)       # one 64-bit draw per sample, as random() takes
            self._noise_tail[f] = np.random.Generator(gen).random(taps) * 2.0 - 1.0
            return None
        white = np.random.Generator(gen).random(count) * 2.0 - 1.0
        if silent:
            self._noise_tail[f] = np.concatenate([self._noise_tail[f], white])[-taps:]
            return None
        return white

    def _band(self, f: int, white: np.ndarray) -> np.ndarray:
        """Finger f's white noise band-passed (FIR), continuing from its last samples."""
        h = self._h
        taps = len(h) - 1
        x = np.concatenate([self._noise_tail[f], white])
        y = np.zeros(len(white))
        for j in range(len(h)):             # tap by tap: the same sums whatever the pieces
            y += h[j] * x[taps - j:taps - j + len(white)]
        self._noise_tail[f] = x[-taps:]
        return y

    def _render_clicks(self, n0: int, count: int) -> np.ndarray:
        m = self.mapping
        out = np.zeros(count)
        length = int(np.ceil(_CLICK_LENGTH * m.click_decay * self.rate))
        keep = []
        for onset, amp in self._clicks:
            lo, hi = max(onset, n0), min(onset + length, n0 + count)
            if hi > lo:
                j = np.arange(lo, hi) - onset
                out[lo - n0:hi - n0] += amp * np.exp(-j / (m.click_decay * self.rate)) * \
                    np.sin(2 * np.pi * m.click_freq * j / self.rate + np.pi / 2)
            if onset + length > n0 + count:
                keep.append((onset, amp))
        self._clicks = keep
        return out


def sonify(scene, ticks: np.ndarray, mapping: SoundMapping | None = None, block: int = 4096):
    """The samples (float32) of a whole recording's ticks (fed in blocks of ``block`` records:
    the same samples as in one piece) and the Sonifier (its ``clicks``)."""
    s = Sonifier(scene, mapping)
    parts = [s.feed(ticks[i:i + block]) for i in range(0, len(ticks), block)]
    return (np.concatenate(parts) if parts else np.zeros(0, np.float32)), s


def wav_bytes(samples: np.ndarray, rate: int) -> bytes:
    """16-bit PCM mono WAV of samples in -1..1 (rounded to the nearest step: deterministic)."""
    pcm = np.round(np.clip(np.asarray(samples, dtype=np.float64), -1.0, 1.0) * 32767.0).astype("<i2")
    data = pcm.tobytes()
    head = b"RIFF" + struct.pack("<I", 36 + len(data)) + b"WAVE"
    fmt = b"fmt " + struct.pack("<IHHIIHH", 16, 1, 1, rate, rate * 2, 2, 16)
    return head + fmt + b"data" + struct.pack("<I", len(data)) + data


def read_wav(data: bytes):
    """(samples float64 in -1..1, rate) of a 16-bit PCM mono WAV as wav_bytes writes; ValueError
    naming what is wrong otherwise."""
    f = io.BytesIO(data)
    if f.read(4) != b"RIFF" or (f.read(4), f.read(4))[1] != b"WAVE":
        raise ValueError("not a RIFF/WAVE file")
    rate = None
    while True:
        head = f.read(8)
        if len(head) < 8:
            raise ValueError("no data chunk")
        kind, size = head[:4], struct.unpack("<I", head[4:])[0]
        body = f.read(size)
        if len(body) < size:
            raise ValueError(f"chunk {kind!r} cut short")
        if kind == b"fmt ":
            fmt, channels, rate, _, _, bits = struct.unpack("<HHIIHH", body[:16])
            if (fmt, channels, bits) != (1, 1, 16):
                raise ValueError(f"expected 16-bit PCM mono, got format {fmt}, {channels} channels, {bits} bits")
        elif kind == b"data":
            if rate is None:
                raise ValueError("data before fmt")
            return np.frombuffer(body, "<i2").astype(np.float64) / 32767.0, rate


def write_wav(path: str, scene, ticks: np.ndarray, mapping: SoundMapping | None = None) -> dict:
    """The sound of a recording's ticks as a WAV at ``path`` (written whole or not at all:
    outputs.AtomicFile). Returns {"path", "seconds", "samples", "clicks", "rate"}."""
    from .outputs import AtomicFile
    samples, s = sonify(scene, ticks, mapping)
    with AtomicFile(path) as out:
        out.file.write(wav_bytes(samples, s.rate))
    return {"path": out.path, "seconds": len(samples) / s.rate, "samples": len(samples),
            "clicks": len(s.clicks), "rate": s.rate}
