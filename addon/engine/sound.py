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


# The scrape's band: a windowed-sinc band-pass (1-6 kHz at 48 kHz) applied to white noise.
_NOISE_TAPS = 31
_CLICK_LENGTH = 8       # click time constants after which a click is over (e^-8: inaudible)


def _band_pass(rate: int, low: float = 1000.0, high: float = 6000.0, taps: int = _NOISE_TAPS) -> np.ndarray:
    n = np.arange(taps) - (taps - 1) / 2
    high = min(high, 0.45 * rate)
    h = (2 * high / rate) * np.sinc(2 * high / rate * n) - (2 * low / rate) * np.sinc(2 * low / rate * n)
    h *= np.hamming(taps)
    return h / np.sqrt(np.sum(h * h))       # unit noise power in, about unit power out


class Sonifier:
    """Tick records in, samples (float32, mono, in -1..1) out; see the module's docstring.

    ``scene``: a recording header's ``scene`` dict or an engine.scene.SceneDesc (bodies' friction
    and which are static, for the slip margins)."""

    def __init__(self, scene, mapping: SoundMapping | None = None):
        self.mapping = mapping or SoundMapping()
        self.models = analysis.body_models(scene)
        self.dynamic = np.array([not m.is_static for m in self.models] + [False])
        fingers = scene["fingers"] if isinstance(scene, dict) else scene.fingers
        self.nf = len(fingers)
        self.nb = len(self.models)
        self.rate = int(self.mapping.sample_rate)
        self._h = _band_pass(self.rate)
        self._noise = [np.random.Generator(np.random.PCG64(0x5C2A9E + f)) for f in range(self.nf)]
        self._noise_tail = np.zeros((self.nf, _NOISE_TAPS - 1))
        self._prev = None           # the last record fed (its state holds until the next)
        self._held = None           # its (frequency, tone, slip, warning targets)
        self._env = None            # (tone, slip, warning) envelopes at the last record
        self._phase = np.zeros(self.nf)     # tone phase in cycles at the last record's time
        self._clicks = []           # (onset sample, amplitude) of clicks still sounding
        self.next_sample = 0        # the first sample not yet produced
        self.clicks = []            # every click: (session time of its onset, finger, amplitude)

    # ------------------------------------------------------------------ per record
    def _targets(self, rec, prev):
        """Per record: tone frequency, tone / slip / warning envelope targets, and the slip
        loudness. ``prev``: the records before (same length) for speeds; None: no speed."""
        m = self.mapping
        contact = rec["contact"]
        touching = (contact >= 0) & (rec["state"] > 0)
        fn, ft = analysis.contact_forces(rec["force"], rec["normal"])
        freq = m.pitch(np.maximum(fn, 0.0))
        slipping = touching & (rec["state"] == SLIP)
        slip_speed = np.zeros(fn.shape)
        if prev is not None:
            dt = (rec["time"] - prev["time"])[:, None]
            with np.errstate(divide="ignore", invalid="ignore"):
                v_go = (rec["god_object"] - prev["god_object"]) / np.where(dt > 0, dt, np.inf)[..., None]
            body = np.where(contact >= 0, contact, 0)
            rows = np.arange(len(rec))[:, None]
            pose = rec["pose"][rows, body] if self.nb else np.zeros(contact.shape + (7,))
            vel = rec["velocity"][rows, body] if self.nb else np.zeros(contact.shape + (6,))
            v_surface = vel[..., :3] + analysis._cross(vel[..., 3:], rec["god_object"] - pose[..., :3])
            rel = v_go - v_surface
            n = rec["normal"]
            rel = rel - np.einsum("...k,...k->...", rel, n)[..., None] * n
            slip_speed = np.sqrt(np.einsum("...k,...k->...", rel, rel))
        slip_level = np.where(slipping, np.clip(slip_speed / m.slip_speed_full, 0.0, 1.0), 0.0)
        # The warning: per dynamic body held, its smallest slip margin mu |Fn| - |Ft| below the threshold.
        mu = analysis.cone_mu(self.models, rec["state"], contact)
        margin = np.where(touching & self.dynamic[np.where(contact >= 0, contact, self.nb)], mu * fn - ft, np.inf)
        warn = np.zeros((len(rec), self.nb), dtype=bool)
        for b in range(self.nb):
            on_b = contact == b
            low = np.where(on_b, margin, np.inf).min(axis=1) if self.nf else np.full(len(rec), np.inf)
            warn[:, b] = low < m.warning_margin
        return freq, touching.astype(np.float64), slip_level, warn.any(axis=1).astype(np.float64)

    def _onsets(self, rec, prev_state, prev_hip):
        """Clicks of the records: (record index, finger, amplitude) where a finger starts touching."""
        m = self.mapping
        touching = (rec["contact"] >= 0) & (rec["state"] > 0)
        before = np.concatenate([prev_state[None], touching[:-1]])
        hips = np.concatenate([prev_hip[None], rec["hip"][:-1]])
        out = []
        for k, f in zip(*np.nonzero(touching & ~before)):
            dt = rec["time"][k] - (self._prev["time"][0] if k == 0 else rec["time"][k - 1])
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
            records = records[records["time"] > self._prev["time"][0]]     # tick 0 at time 0: the start
            self._env = (np.zeros(self.nf), np.zeros(self.nf), 0.0)
            self._held = (np.full(self.nf, m.pitch_low), np.zeros(self.nf), np.zeros(self.nf), 0.0)
        prev = self._prev
        if not len(records):
            return np.zeros(0, np.float32)
        seq = np.concatenate([prev, records])            # the held record, then the new ones
        freq, tone_t, slip_t, warn_t = self._targets(records, seq[:-1])
        touched = ((prev["contact"] >= 0) & (prev["state"] > 0))[0]
        for k, f, amp in self._onsets(records, touched, prev["hip"][0]):
            onset = int(np.ceil(records["time"][k] * rate - 1e-9))
            self._clicks.append((onset, amp))
            self.clicks.append((float(records["time"][k]), f, amp))
        # Each record's state holds from its time to the next record's: seq[k]'s (the held
        # record's first) frequency and envelope targets.
        held_freq = np.concatenate([self._held[0][None], freq])
        tone_t = np.concatenate([self._held[1][None], tone_t])
        slip_t = np.concatenate([self._held[2][None], slip_t])
        warn_t = np.concatenate([[self._held[3]], warn_t])
        # Envelopes at each record: linear moves toward their targets, attack seconds end to end.
        times = seq["time"]
        tone_env = np.empty((len(seq), self.nf))
        slip_env = np.empty((len(seq), self.nf))
        warn_env = np.empty(len(seq))
        tone_env[0], slip_env[0], warn_env[0] = self._env
        step = np.diff(times) / m.attack
        for k in range(1, len(seq)):
            s = step[k - 1]
            tone_env[k] = np.clip(tone_t[k - 1], tone_env[k - 1] - s, tone_env[k - 1] + s)
            slip_env[k] = np.clip(slip_t[k - 1], slip_env[k - 1] - s, slip_env[k - 1] + s)
            warn_env[k] = min(max(warn_t[k - 1], warn_env[k - 1] - s), warn_env[k - 1] + s)
        phase = np.add.accumulate(np.concatenate([self._phase[None], held_freq[:-1] * np.diff(times)[:, None]]),
                                  axis=0)                               # cycles at each record
        n0 = self.next_sample
        n1 = int(np.ceil(times[-1] * rate - 1e-9))
        n = np.arange(n0, max(n0, n1))
        t = n / rate
        seg = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(seq) - 2)
        frac = (t - times[seg]) / (times[seg + 1] - times[seg])
        out = np.zeros(len(n))
        if self.nf:
            tone_a = tone_env[seg] + frac[:, None] * (tone_env[seg + 1] - tone_env[seg])
            ph = phase[seg] + held_freq[seg] * (t - times[seg])[:, None]
            out += m.tone_gain * np.sum(tone_a * np.sin(2 * np.pi * ph), axis=1)
            slip_a = slip_env[seg] + frac[:, None] * (slip_env[seg + 1] - slip_env[seg])
            out += m.slip_gain * np.sum(slip_a * self._filtered_noise(len(n)), axis=1)
        warn_a = warn_env[seg] + frac * (warn_env[seg + 1] - warn_env[seg])
        if np.any(warn_a > 0):
            cyc = np.mod(t, m.warning_period)
            pulse = np.where(cyc < m.warning_on, np.sin(np.pi * cyc / m.warning_on) ** 2, 0.0)
            out += m.warning_gain * warn_a * pulse * np.sin(2 * np.pi * m.warning_freq * t)
        out += self._render_clicks(n0, len(n))
        self._prev = records[-1:].copy()
        self._held = (held_freq[-1], tone_t[-1], slip_t[-1], float(warn_t[-1]))
        self._env = (tone_env[-1], slip_env[-1], float(warn_env[-1]))
        self._phase = phase[-1]
        self.next_sample = max(n0, n1)
        return np.clip(out * m.volume, -1.0, 1.0).astype(np.float32)

    def _filtered_noise(self, count: int) -> np.ndarray:
        """(count, nf) band-passed white noise, continuing each finger's stream."""
        out = np.empty((count, self.nf))
        h = self._h
        for f in range(self.nf):
            white = self._noise[f].random(count) * 2.0 - 1.0
            x = np.concatenate([self._noise_tail[f], white])
            y = np.zeros(count)
            for j in range(len(h)):         # tap by tap: the same sums whatever the pieces
                y += h[j] * x[len(h) - 1 - j:len(h) - 1 - j + count]
            out[:, f] = y
            self._noise_tail[f] = x[-(len(h) - 1):]
        return out

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
