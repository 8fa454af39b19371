"""Every haptic tick of a running session, handed to the display thread (the live sound,
engine/sound.py): the records since the last ``take()``, none lost between display updates.

Where the records come from depends on what else reads them (docs/sound.md, "Live"):

* a recording session: the recorder already drains the core's tick log (one reader per ring),
  so the tap is one of its listeners (``SessionRecorder.listeners``) and gets each block it
  writes (its thread polls every 20 ms);
* the threaded runtime without a recording: the tap gives the world its own tick log
  (``set_tick_log``, before the runtime starts) and drains it at each ``take()``;
* synchronous steps (the live main-thread fallback): the tap copies the world's record after
  every step (with a recording too: the recorder writes its blocks a flush interval apart).

bpy-free; the session runner wires it (``SessionRunner(tap=...)``).
"""
from __future__ import annotations

import threading

import numpy as np


class TickTap:
    def __init__(self, world, dtype: np.dtype, haptic_rate: float, ring_seconds: float = 2.0):
        self.world = world
        self.dtype = dtype
        self.capacity = max(16, int(ring_seconds * haptic_rate))
        self.mode = ""              # "recorder", "log" or "steps" once started
        self.overflow = 0           # ticks the ring dropped (a display stalled for ring_seconds)
        self._lock = threading.Lock()
        self._blocks = []
        self._buf = None

    # ---- wiring (SessionRunner.start)
    def listen_to(self, recorder) -> None:
        self.mode = "recorder"
        recorder.listeners.append(self._push)

    def own_log(self) -> None:
        """Before the threaded runtime starts: the world's tick log is the tap's."""
        self.mode = "log"
        self._buf = np.zeros(self.capacity, dtype=self.dtype)
        self.world.set_tick_log(self.capacity)

    def after_step(self, tick: int) -> None:
        """Synchronous steps: the record of the step just taken."""
        self.mode = "steps"
        rec = np.zeros(1, dtype=self.dtype)
        self.world._tick_record(rec, tick)
        self._push(rec)

    def _push(self, records) -> None:
        with self._lock:
            self._blocks.append(np.array(records, copy=True))

    # ---- the display thread
    def take(self) -> np.ndarray:
        """The records that came since the last call, in tick order (empty: none)."""
        if self.mode == "log":
            n = self.world._drain_ticks(self._buf)
            if n:
                self._push(self._buf[:n])
            self.overflow = int(self.world.tick_log_overflow())
        with self._lock:
            blocks, self._blocks = self._blocks, []
        if not blocks:
            return np.zeros(0, dtype=self.dtype)
        return blocks[0] if len(blocks) == 1 else np.concatenate(blocks)
