"""The live sound of a session through Blender's own audio (``aud``, audaspace): docs/sound.md.

Every display update the session hands ``LiveSound.update`` the tick records of the interval
(engine/tick_tap.py); engine/sound.py's Sonifier turns them into the samples of that stretch of
session time, and they are placed in one playing ``aud.Sequence`` at their session time plus a
fixed offset, so consecutive stretches join sample for sample whatever the display's rhythm (no
click is lost between updates). The offset is the latency: chosen at the first update so that
the next stretch still arrives before its place is played (1.5 display intervals + 30 ms, at
least the longest interval seen); a stretch that arrives late all the same moves the offset
later (a gap once, counted as ``late``), never earlier.

Headless Blender (``bpy`` module, ``blender -b``) opens no audio device (``aud.Device()`` answers
a null device of rate 0): ``open_live_sound`` then says so and the session runs silent.
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
    import aud
    import bpy
    device = aud.Device()
    if not device.rate or not device.channels:
        chosen = getattr(bpy.context.preferences.system, "audio_device", "")
        raise NoAudioDevice("no audio device (Blender's audio output is "
                            f"{chosen or 'None'}{', running in background mode' if bpy.app.background else ''}"
                            "; Preferences > System > Sound): the session runs without sound")
    return device


class LiveSound:
    def __init__(self, scene_desc, display_rate: float, volume: float = 0.5, mapping: SoundMapping | None = None):
        import aud
        self.device = _device()
        self.sonifier = Sonifier(scene_desc, mapping)
        self.rate = self.sonifier.rate
        self.sequence = aud.Sequence(1, float(self.rate), 30.0)
        self.handle = self.device.play(self.sequence)
        self.volume = volume
        self.handle.volume = volume
        self.interval = 1.0 / max(display_rate, 1.0)
        self.offset = None          # sequence time - session time
        self.entries = []           # (entry, end in sequence time)
        self.late = 0               # stretches that arrived after their place was played
        self.samples = 0            # samples placed
        self.clicks = 0
        self.cost_s = 0.0           # main-thread seconds spent (sonify + place)
        self.updates = 0
        self._last_wall = None
        self._longest = self.interval

    @property
    def latency(self) -> float:
        """Seconds from a tick's session time to its sound leaving Blender's mixer (the offset
        less what the session's own lag already holds; a device adds its buffer to this)."""
        return 0.0 if self.offset is None else self._latency

    def set_volume(self, volume: float) -> None:
        if volume != self.volume:
            self.volume = volume
            self.handle.volume = volume

    def update(self, records: np.ndarray, session_time: float) -> None:
        import aud
        t0 = time.perf_counter()
        now = time.perf_counter()
        if self._last_wall is not None:
            self._longest = max(self._longest, now - self._last_wall)
        self._last_wall = now
        start = self.sonifier.next_sample / self.rate           # session time of the first sample
        samples = self.sonifier.feed(records)
        self.clicks = len(self.sonifier.clicks)
        if samples.size:
            position = self.handle.position
            margin = 1.5 * self._longest + MARGIN
            if self.offset is None:
                self.offset = position + margin - (start + samples.size / self.rate)
            elif start + self.offset < position:
                self.late += 1
                self.offset = position + margin - start
            self._latency = self.offset - (position - session_time)
            begin = start + self.offset
            sound = aud.Sound.buffer(samples.reshape(-1, 1), float(self.rate))
            entry = self.sequence.add(sound, begin, begin + samples.size / self.rate, 0.0)
            self.entries.append((entry, begin + samples.size / self.rate))
            self.samples += samples.size
            while self.entries and self.entries[0][1] < position - KEEP:
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
            self.handle.stop()
        except Exception:           # the device went away with Blender: nothing to stop
            pass
        self.entries = []


def open_live_sound(scene_desc, settings):
    """(LiveSound, "") or (None, why not), with the scene ``settings``' rate, volume, mapping."""
    try:
        return LiveSound(scene_desc, settings.display_rate, settings.sound_volume, mapping_of(settings)), ""
    except (NoAudioDevice, ValueError) as ex:
        return None, str(ex)
    except Exception as ex:         # audaspace's own errors (aud.error): say them, run silent
        return None, f"no sound: {ex}"
