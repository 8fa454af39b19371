"""The session runner: advances a ``graspcore.World`` from an input source.

This is the only place that steps the world. The Blender side calls
``advance_to(t)`` once per display tick (modal timer) or once per frame (headless
EXEC) and then reads ``snapshot()``.

Two drivers share one interface:

* ``DirectDriver`` (headless/EXEC runs, and the live main-thread fallback): sub-steps
  the core on the calling thread at the haptic rate, HIPs sampled from the input at the
  end time of every step. Deterministic.
* ``RuntimeDriver``: the core's own threaded runtime (``set_hip_track`` / ``start`` /
  ``push_hips`` / ``snapshot`` / ``stop``), used by live sessions.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from . import defaults
from .inputs import core_unit_quaternions


# The threaded runtime's settings that decide its physics (their defaults: the core's,
# graspcore.RUNTIME_DEFAULTS; the others, its safety layer, decide only what a device is sent).
# Live sessions run with these and their recordings' headers say so: a re-simulation replays
# with them.
RUNTIME_PHYSICS = ("object_rate", "max_adopted_bodies", "release_delay")


@dataclass
class Snapshot:
    time: float
    poses: np.ndarray           # (n_bodies, 7) x y z qw qx qy qz (body frame origin)
    com: np.ndarray             # (n_bodies, 3) centre of mass, world
    force: np.ndarray           # (n_bodies, 3) residual force
    torque: np.ndarray          # (n_bodies, 3) residual torque about the centre of mass
    hips: np.ndarray            # (n_fingers, 3)
    god_objects: np.ndarray     # (n_fingers, 3)
    finger_forces: np.ndarray   # (n_fingers, 3) force rendered to the device
    finger_states: np.ndarray   # (n_fingers,) 0 free, 1 stick, 2 slip
    contacts: np.ndarray        # (n_fingers,) body index in the description, -1 none
    spring_forces: np.ndarray   # (n_fingers, 3) coupling spring force on the body touched (physics)
    normals: np.ndarray         # (n_fingers, 3) reported contact's plane normal, out of the body; 0 free
    velocities: np.ndarray      # (n_bodies, 6) linear (body frame origin), angular; world
    patches: np.ndarray | None = None   # (n_fingers, 4, 2) float32 convex fingers' contact patches (tick record's)

    @property
    def n_contacts(self) -> int:
        return int(np.count_nonzero(self.contacts >= 0))


def quat_rotate(q, v):
    """Rotate vectors v (..., 3) by unit quaternions q (..., 4) in w, x, y, z order."""
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


class DirectDriver:
    """Steps the world synchronously on the calling thread."""
    threaded = False

    def __init__(self, world, source, dt, finger_ids, options):
        self.world = world
        self.source = source
        self.dt = dt
        self.steps = 0
        self.on_step = None         # called with the step count after every step (the recorder)
        self._finger_ids = list(finger_ids)
        self._contiguous = self._finger_ids == list(range(len(self._finger_ids)))

    def start(self):
        pass

    def step_once(self):
        t_next = (self.steps + 1) * self.dt
        hips = np.ascontiguousarray(self.source.hips_at(t_next), dtype=np.float64)
        # Whole poses, as the runtime's track (scripted fingers) and pushes (live ones) give them.
        script = self.source.script()
        scripted = np.zeros(len(hips), dtype=bool) if script is None else \
            (np.ones(len(hips), dtype=bool) if script[2] is None else np.asarray(script[2], dtype=bool))
        for mask, turns in ((scripted, self.source.orientations_at(t_next)),
                            (~scripted, self.source.live_orientations())):
            if turns is not None:
                turns = core_unit_quaternions(turns)        # recorded as given: resim sets them again
                for i in np.flatnonzero(mask):
                    self.world.set_finger_pose(self._finger_ids[i], tuple(hips[i]), tuple(turns[i]))
        if self._finger_ids:
            if self._contiguous:
                self.world.set_hips(hips)
            else:
                for fid, h in zip(self._finger_ids, hips):
                    self.world.set_hip(fid, tuple(h))
        self.world.step(self.dt)
        self.steps += 1
        if self.on_step is not None:
            self.on_step(self.steps)

    @property
    def time(self):
        return self.steps * self.dt

    def stop(self):
        pass


class RuntimeDriver:
    """The core's threaded runtime: the haptic loop in C at its own rate. The scripted part
    of the input goes to it whole (``set_hip_track``), sampled at every haptic tick; live
    fingers are pushed with their time stamp and walked at a bounded speed. The caller's
    rate (a Blender display) only decides how often the picture is updated."""
    threaded = True

    def __init__(self, world, source, dt, finger_ids, options):
        if list(finger_ids) != list(range(len(finger_ids))):
            raise ValueError("the threaded runtime needs fingers 0..n-1 in the world")
        self.world = world
        self.source = source
        self.dt = dt
        self.options = dict(options)
        self._time = 0.0
        self._running = False

    def start(self):
        script = self.source.script()
        if script is not None:
            self.world.set_hip_track(*script)
        self.world.start(haptic_rate=1.0 / self.dt, **self.options)
        self._running = True

    def push(self, t):
        if self.source.interactive:
            self.world.push_hips(np.ascontiguousarray(self.source.hips_at(t), dtype=np.float64), t,
                                 orientations=self.source.live_orientations())

    def observe(self, snapshot_time):
        self._time = snapshot_time

    @property
    def time(self):
        return self._time

    def stop(self):
        if self._running:
            self._running = False
            self.world.stop()


class SessionRunner:
    """Advance a world from an input source; collect snapshots and stats. With a
    ``recorder`` (engine.recording.SessionRecorder) every haptic tick is recorded.

    ``runtime_options`` go to ``World.start`` (max_hip_speed, hip_timeout, ...)."""

    def __init__(self, handle, source, haptic_rate=None, use_runtime=False, recorder=None,
                 runtime_options=None, tap=None):
        if haptic_rate is None:
            haptic_rate = defaults.runtime("haptic_rate")
        if not (haptic_rate > 0):
            raise ValueError(f"haptic_rate must be > 0, got {haptic_rate}")
        if source.n_fingers != len(handle.finger_ids):
            raise ValueError(f"input source gives {source.n_fingers} fingertips, "
                             f"the scene has {len(handle.finger_ids)} fingers")
        self.handle = handle
        self.world = handle.world
        self.source = source
        self.dt = 1.0 / float(haptic_rate)
        self.haptic_rate = float(haptic_rate)
        cls = RuntimeDriver if use_runtime else DirectDriver
        self.driver = cls(self.world, source, self.dt, handle.finger_ids, runtime_options or {})
        self.lag = 0.0              # s the session time is behind the time asked for (live)
        self.step_wall = 0.0        # wall time spent stepping the core on this thread
        self.max_step_wall = 0.0    # longest single advance_to, seconds
        self.ticks = []             # wall clock of every advance_to (display rate, jitter)
        self.recorder = recorder
        self.tap = tap              # engine.tick_tap.TickTap: every tick for the display thread
        self.recording_end = {}     # what the recorder reported when it closed the file
        self.events = []    # (time s, source, event, value): safety events of devices, recorded too
        self._body_index = {bid: i for i, bid in enumerate(handle.body_ids)}
        self._coms = np.array([b.mass_properties.center_of_mass if b.mass_properties is not None
                               else np.zeros(3) for b in handle.desc.bodies]).reshape(-1, 3)
        self._started = False
        self._stopped = False
        self._wall0 = None
        self._last_runtime_stats = None

    # -------------------------------------------------------------- control
    @property
    def time(self) -> float:
        return self.driver.time

    @property
    def threaded(self) -> bool:
        return self.driver.threaded

    def start(self):
        if not self._started:
            self.source.open()
            if self.recorder is not None:
                self.recorder.begin(threaded=self.driver.threaded)
            if self.tap is not None and self.driver.threaded:
                if self.recorder is not None:
                    self.tap.listen_to(self.recorder)   # one reader per tick log: the recorder's
                else:
                    self.tap.own_log()
            self.driver.start()
            if self.recorder is not None:
                if self.driver.threaded:
                    self.recorder.runtime_started()
                else:
                    self.driver.on_step = self.recorder.after_step
            if self.tap is not None and not self.driver.threaded:
                # Synchronous steps: the tap copies each step's record itself (the recorder
                # writes blocks far apart in wall time).
                record, tap = self.driver.on_step, self.tap.after_step

                def both(tick):
                    record(tick)
                    tap(tick)
                self.driver.on_step = tap if record is None else both
            self._started = True
            self._wall0 = time.perf_counter()

    def advance_to(self, t: float, budget: float | None = None) -> int:
        """Advance session time to ``t`` (seconds). Returns the number of core steps taken
        on this thread (0 on the threaded runtime, which steps by itself).

        With ``budget`` (seconds of wall time), stepping stops once that much time is spent:
        the session falls behind (``lag``) instead of blocking the UI, and catches up on
        later calls when it can.
        """
        if not self._started:
            self.start()
        w0 = time.perf_counter()
        self.ticks.append(w0)
        n = 0
        if self.driver.threaded:
            self.driver.push(t)
        else:
            target = int(np.floor(t / self.dt + 1e-9))
            deadline = None if budget is None else w0 + budget
            while self.driver.steps < target:
                self.driver.step_once()
                n += 1
                if deadline is not None and (n & 7) == 0 and time.perf_counter() > deadline:
                    break
            self.lag = max(0.0, t - self.driver.time)
        elapsed = time.perf_counter() - w0
        self.step_wall += elapsed
        self.max_step_wall = max(self.max_step_wall, elapsed)
        return n

    def stop(self):
        if not self._stopped:
            if self.threaded and self._started:
                self.snapshot()                 # the last tick's time, for the report
                self._last_runtime_stats = self.world.stats()
            self._stopped = True
            self.driver.stop()
            self.source.close()
            if self.recorder is not None:
                self.recording_end = self.recorder.finish()

    # -------------------------------------------------------------- state
    def snapshot(self) -> Snapshot:
        w = self.world
        h = self.handle
        if self.driver.threaded and w.running:
            snap = self._snapshot_from_runtime(w.snapshot())
            self.driver.observe(snap.time)
            return snap
        n_b, n_f = len(h.body_ids), len(h.finger_ids)
        raw = w.snapshot()      # stopped: the world's own state
        poses = np.asarray(raw["poses"])[h.body_ids].reshape(n_b, 7)
        wrenches = np.concatenate([raw["residual_forces"], raw["residual_torques"]], axis=1)[h.body_ids]
        wrenches[[b.static for b in h.desc.bodies]] = 0.0
        com = poses[:, :3] + quat_rotate(poses[:, 3:], self._coms) if n_b else np.zeros((0, 3))
        fids = h.finger_ids
        hips = np.array([self.source.hips_at(self.time)], dtype=np.float64).reshape(n_f, 3) if n_f \
            else np.zeros((0, 3))
        spring = np.asarray(raw["spring_forces"])[fids].reshape(n_f, 3)
        return Snapshot(self.time, poses, com, wrenches[:, :3], wrenches[:, 3:], hips,
                        np.asarray(raw["god_objects"])[fids].reshape(n_f, 3), spring,
                        np.asarray(raw["finger_states"], dtype=np.int8)[fids].reshape(n_f),
                        self._contact_indices(raw["contact_bodies"][fids]), spring,
                        np.asarray(raw["normals"])[fids].reshape(n_f, 3), self._velocities(raw),
                        np.asarray(raw["patches"])[fids])

    def _contact_indices(self, world_bodies) -> np.ndarray:
        return np.array([self._body_index.get(int(b), -1) for b in world_bodies], dtype=np.int32)

    def _velocities(self, raw) -> np.ndarray:
        ids = self.handle.body_ids
        return np.concatenate([raw["linear_velocities"], raw["angular_velocities"]], axis=1)[ids].reshape(-1, 6)

    def _snapshot_from_runtime(self, snap: dict) -> Snapshot:
        """Map the core runtime's snapshot (graspcore.World.snapshot, docs/runtime.md)."""
        h = self.handle
        poses = np.asarray(snap["poses"], dtype=np.float64)[h.body_ids]
        com = poses[:, :3] + quat_rotate(poses[:, 3:], self._coms)
        fids = h.finger_ids
        return Snapshot(float(snap["time"]), poses, com,
                        np.asarray(snap["residual_forces"])[h.body_ids],
                        np.asarray(snap["residual_torques"])[h.body_ids],
                        np.asarray(snap["hips"])[fids],
                        np.asarray(snap["god_objects"])[fids],
                        np.asarray(snap["forces"])[fids],  # what the device renders (clamped, ramped)
                        np.asarray(snap["finger_states"], dtype=np.int8)[fids],
                        self._contact_indices(snap["contact_bodies"][fids]),
                        np.asarray(snap["spring_forces"])[fids],
                        np.asarray(snap["normals"])[fids],
                        self._velocities(snap), np.asarray(snap["patches"])[fids])

    def stats(self) -> dict:
        """What the session did, for the HUD and reports. On the threaded runtime the rates,
        step time and step count are the C haptic loop's own (``runtime_*`` has all of its
        statistics); on the main thread they are this runner's."""
        ticks = np.diff(np.array(self.ticks)) if len(self.ticks) > 2 else np.zeros(0)
        wall_display = (self.ticks[-1] - self.ticks[0]) if len(self.ticks) > 1 else 0.0
        wall = time.perf_counter() - self._wall0 if self._wall0 is not None else 0.0
        out = {
            "time": self.time,
            "haptic_rate_target": self.haptic_rate,
            "display_rate": (len(ticks) / wall_display) if wall_display > 0 else 0.0,
            "display_jitter_ms": float(np.std(ticks) * 1e3) if len(ticks) else 0.0,
            "max_tick_ms": self.max_step_wall * 1e3,
            "lag_s": self.lag,
            "realtime_factor": self.time / wall if wall > 0 else 0.0,
            "threaded": self.threaded,
        }
        if self.threaded and self._started and not self._stopped:
            rt = self.world.stats()
            self._last_runtime_stats = rt
        else:
            rt = self._last_runtime_stats
        if self.threaded and rt is not None:
            out.update({f"runtime_{k}": v for k, v in rt.items()})
            out["steps"] = int(rt["haptic_ticks"])
            out["haptic_rate"] = float(rt["haptic_rate"])
            out["step_us"] = float(rt["tick_mean_us"])
        else:
            steps = getattr(self.driver, "steps", 0)
            out["steps"] = steps
            out["step_us"] = 1e6 * self.step_wall / steps if steps else 0.0
            out["haptic_rate"] = steps / wall if wall > 0 else 0.0
        return out
