"""The live sound of a session through Blender's own audio (``aud``, audaspace): docs/sound.md.

Every display update the session hands ``LiveSound.update`` the tick records of the interval
(engine/tick_tap.py); engine/sound.py's Sonifier turns them into the samples of that stretch of
session time, and they are placed in one playing ``aud.Sequence`` at their session time plus a
fixed offset (whole samples), so consecutive stretches follow each other whatever the display's
rhythm: no click is lost between updates (audaspace mixes the joins close to, not exactly as, the
recording's samples: docs/sound.md, "Known limits"). The offset is the latency: chosen at the
first update so that the next stretch still arrives before its place is played (1.5 display
intervals + 30 ms, at least the longest interval seen); a stretch that arrives late all the same
moves the offset later (a gap once, counted as ``late``), never earlier.

Headless Blender (``bpy`` module, ``blender -b``) opens no audio device (``aud.Device()`` answers
a null device of rate 0), and Debian's Blender has no ``aud`` module: ``open_live_sound`` then
says so and the session runs silent.
"""
from __future__ import annotations

import time

import numpy as np

from .engine.sound import Sonifier, SoundMapping

MARGIN = 0.03           # s of slack past 1.5 display intervals
KEEP = 2.0              # s: entries this far behind the playing position are removed


def mapping_of(settings) -> SoundMapping:
    """The scene's sound mapping (the Session panel's pitch settings; the rest as documented).
    ValueError naming the setting for a mapping that cannot be (a high pitch below the low)."""
    return SoundMapping(pitch_low=settings.sound_pitch_low, pitch_high=settings.sound_pitch_high,
                        force_full=settings.sound_force_full, curve=settings.sound_curve)


class NoAudioDevice(RuntimeError):
    """Blender has no audio output here; the message says why and what to do."""


def _device():
    import bpy
    try:
        import aud
    except ImportError:         # Debian's Blender 4.3 is built without audaspace's Python module
        raise NoAudioDevice("no audio device: this Blender has no audio module (aud): the session runs "
                            "without sound") from None
    device = aud.Device()
    if not device.rate or not device.channels:
        chosen = getattr(bpy.context.preferences.system, "audio_device", "")
        raise NoAudioDevice("no audio device (Blender's audio output is "
                            f"{chosen or 'None'}{', running in background mode' if bpy.app.background else ''}"
                            "; Preferences > System > Sound): the session runs without sound")
    return device


class LiveSound:
    """``device``: "default" (Blender's audio output; NoAudioDevice when there is none) or None:
    nothing plays, the sequence is only built, on the wall clock (``render`` gives what it holds:
    the tests)."""

    def __init__(self, scene_desc, display_rate: float, volume: float = 0.5, mapping: SoundMapping | None = None,
                 device="default"):
        self.device = _device() if device == "default" else device
        import aud
        self.sonifier = Sonifier(scene_desc, mapping)
        self.rate = self.sonifier.rate
        self.sequence = aud.Sequence(1, float(self.rate), 30.0)
        self.handle = self.device.play(self.sequence) if self.device is not None else None
        self._clock0 = time.perf_counter()
        self.volume = None
        self.set_volume(volume)
        self.offset = None          # sequence sample - session sample
        self.entries = []           # (entry, end in sequence time)
        self.placed = []            # (first sample, samples) of every stretch placed
        self.late = 0               # stretches that arrived after their place was played
        self.samples = 0            # samples placed
        self.clicks = 0
        self.cost_s = 0.0           # main-thread seconds spent (sonify + place)
        self.updates = 0
        self._last_wall = None
        self._longest = 1.0 / max(display_rate, 1.0)     # the longest display interval seen

    @property
    def latency(self) -> float:
        """Seconds from a tick's session time to its sound leaving Blender's mixer (the offset
        less what the session's own lag already holds; a device adds its buffer to this)."""
        return 0.0 if self.offset is None else self._latency

    def set_volume(self, volume: float) -> None:
        if volume != self.volume:
            self.volume = volume
            if self.handle is not None:
                self.handle.volume = volume

    @property
    def position(self) -> float:
        """Seconds of the sequence played (the device's; without one, the wall clock's)."""
        return self.handle.position if self.handle is not None else time.perf_counter() - self._clock0

    def render(self, seconds: float) -> np.ndarray:
        """The sequence's first ``seconds`` as aud mixes it (float32): what was placed to play."""
        import aud
        import os
        import tempfile
        fd, path = tempfile.mkstemp(suffix=".wav")
        os.close(fd)
        try:
            self.sequence.limit(0.0, seconds).write(path, self.rate, aud.CHANNELS_MONO, aud.FORMAT_FLOAT32,
                                                    aud.CONTAINER_WAV, aud.CODEC_PCM)
            with open(path, "rb") as fh:
                data = fh.read()
        finally:
            os.unlink(path)
        return np.frombuffer(data[data.index(b"data") + 8:], "<f4")

    def update(self, records: np.ndarray, session_time: float) -> None:
        """A display update: the interval's tick records in, their sound placed to play;
        ``session_time``: the session's time now (for the latency)."""
        import aud
        now = t0 = time.perf_counter()
        if self._last_wall is not None:
            self._longest = max(self._longest, now - self._last_wall)
        self._last_wall = now
        first = self.sonifier.next_sample                      # the stretch's first sample
        samples = self.sonifier.feed(records)
        self.clicks = len(self.sonifier.clicks)
        if samples.size:
            rate = self.rate
            position = self.position
            margin = 1.5 * self._longest + MARGIN
            # The offset in whole samples: each stretch begins where the one before ended.
            if self.offset is None:
                self.offset = int(np.ceil((position + margin) * rate)) - (first + samples.size)
            elif (first + self.offset) / rate < position:
                self.late += 1
                self.offset = int(np.ceil((position + margin) * rate)) - first
            self._latency = (self.offset + session_time * rate) / rate - position
            begin = (first + self.offset) / rate
            sound = aud.Sound.buffer(samples.reshape(-1, 1), float(rate))
            entry = self.sequence.add(sound, begin, begin + samples.size / rate, 0.0)
            self.entries.append((entry, begin + samples.size / rate))
            self.placed.append((first, samples.size))
            self.samples += samples.size
            while self.handle is not None and self.entries and self.entries[0][1] < position - KEEP:
                self.sequence.remove(self.entries.pop(0)[0])
        self.updates += 1
        self.cost_s += time.perf_counter() - t0

    def status(self) -> str:
        text = f"sound: {1e3 * self.latency:.0f} ms behind, {self.clicks} clicks"
        if self.late:
            text += f", {self.late} late"
        return text

    def close(self) -> None:
        try:
            if self.handle is not None:
                self.handle.stop()
        except Exception:           # the device went away with Blender: nothing to stop
            pass


def open_live_sound(scene_desc, settings):
    """(LiveSound, "") or (None, why not), with the scene ``settings``' rate, volume, mapping."""
    try:
        return LiveSound(scene_desc, settings.display_rate, settings.sound_volume, mapping_of(settings)), ""
    except (NoAudioDevice, ValueError) as ex:
        return None, str(ex)
    except Exception as ex:         # audaspace's own errors (aud.error): say them, run silent
        return None, f"no sound: {ex}"
