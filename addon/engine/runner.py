"""The session runner: advances a ``graspcore.World`` from an input source.

This is the only place that steps the world. The Blender side calls
``advance_to(t)`` once per display tick (modal timer) or once per frame (headless
EXEC) and then reads ``snapshot()``.

Two drivers share one interface:

* ``DirectDriver`` (today, and always for headless/EXEC runs): sub-steps the core
  on the calling thread at the haptic rate, HIPs sampled from the input at the end
  time of every step. Deterministic.
* ``RuntimeDriver``: the core's own threaded runtime (``world.start`` /
  ``push_hips`` / ``snapshot`` / ``stop``), used by live sessions when the world
  has it (``hasattr(world, "start")``). This is the single plug-in point for it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

STATE_CODES = {"free": 0, "stick": 1, "slip": 2}


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

    def __init__(self, world, source, dt, finger_ids):
        self.world = world
        self.source = source
        self.dt = dt
        self.steps = 0
        self._finger_ids = list(finger_ids)
        self._contiguous = self._finger_ids == list(range(len(self._finger_ids)))

    def start(self):
        pass

    def step_once(self):
        t_next = (self.steps + 1) * self.dt
        hips = np.ascontiguousarray(self.source.hips_at(t_next), dtype=np.float64)
        if self._finger_ids:
            if self._contiguous:
                self.world.set_hips(hips)
            else:
                for fid, h in zip(self._finger_ids, hips):
                    self.world.set_hip(fid, tuple(h))
        self.world.step(self.dt)
        self.steps += 1

    @property
    def time(self):
        return self.steps * self.dt

    def stop(self):
        pass


class RuntimeDriver:
    """The core's threaded runtime (haptic thread in C). Plug-in point for live sessions."""
    threaded = True

    def __init__(self, world, source, dt, finger_ids):
        self.world = world
        self.source = source
        self.dt = dt
        self._t = 0.0
        self._running = False

    def start(self):
        self.world.start(haptic_rate=1.0 / self.dt)
        self._running = True

    def push(self, t):
        self.world.push_hips(np.ascontiguousarray(self.source.hips_at(t), dtype=np.float64), t)
        self._t = t

    @property
    def time(self):
        return self._t

    def stop(self):
        if self._running:
            self._running = False
            self.world.stop()


class SessionRunner:
    """Advance a world from an input source; collect snapshots, stats and a recording."""

    def __init__(self, handle, source, haptic_rate=1000.0, use_runtime=False, record=False):
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
        use_runtime = bool(use_runtime) and hasattr(self.world, "start")
        cls = RuntimeDriver if use_runtime else DirectDriver
        self.driver = cls(self.world, source, self.dt, handle.finger_ids)
        self.dropped_time = 0.0     # session time given up to stay responsive (live only)
        self.step_wall = 0.0        # wall time spent stepping the core on this thread
        self.max_step_wall = 0.0    # longest single advance_to, seconds
        self.ticks = []             # wall clock of every advance_to (for jitter)
        self.recording = [] if record else None
        self._body_index = {bid: i for i, bid in enumerate(handle.body_ids)}
        self._coms = np.array([b.mass_properties.center_of_mass if b.mass_properties is not None
                               else np.zeros(3) for b in handle.desc.bodies]).reshape(-1, 3)
        self._started = False
        self._stopped = False

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
            try:
                self.driver.start()
            except BaseException:
                self.source.close()  # a runtime that cannot start is an error, never a quiet fallback
                raise
            self._started = True
            if self.recording is not None:
                self.recording.append(self.snapshot())

    def advance_to(self, t: float, max_steps: int | None = None) -> int:
        """Advance session time to ``t`` (seconds). Returns the number of core steps.

        With ``max_steps``, at most that many steps are taken; the rest of the interval
        is added to ``dropped_time``: session time falls behind real time instead of
        blocking the UI (live callers aim at ``wall_time - dropped_time``).
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
            todo = target - self.driver.steps
            if max_steps is not None and todo > max_steps:
                # Session time lags real time from now on (callers subtract dropped_time
                # from the wall clock); the input is not skipped.
                self.dropped_time += (todo - max_steps) * self.dt
                todo = max_steps
            for _ in range(max(todo, 0)):
                self.driver.step_once()
                n += 1
        elapsed = time.perf_counter() - w0
        self.step_wall += elapsed
        self.max_step_wall = max(self.max_step_wall, elapsed)
        if self.recording is not None:
            self.recording.append(self.snapshot())
        return n

    def stop(self):
        if not self._stopped:
            self._stopped = True
            self.driver.stop()
            self.source.close()

    # -------------------------------------------------------------- state
    def snapshot(self) -> Snapshot:
        w = self.world
        h = self.handle
        if hasattr(w, "snapshot") and self.driver.threaded:
            return self._snapshot_from_runtime(w.snapshot())
        n_b, n_f = len(h.body_ids), len(h.finger_ids)
        poses = np.array(w.body_poses, dtype=np.float64).reshape(-1, 7)[:n_b].copy() if n_b else np.zeros((0, 7))
        if n_b and h.body_ids != list(range(n_b)):
            poses = np.array([tuple(w.body_pose(b)[0]) + tuple(w.body_pose(b)[1]) for b in h.body_ids])
        force = np.zeros((n_b, 3))
        torque = np.zeros((n_b, 3))
        for i, b in enumerate(h.body_ids):
            if not h.desc.bodies[i].static:
                f, tq = w.residual_wrench(b)
                force[i], torque[i] = f, tq
        com = poses[:, :3] + quat_rotate(poses[:, 3:], self._coms) if n_b else np.zeros((0, 3))
        if n_f:
            fids = h.finger_ids
            gos = np.array([w.god_object(f) for f in fids], dtype=np.float64)
            ff = np.array([w.finger_force(f) for f in fids], dtype=np.float64)
            hips = np.array([self.source.hips_at(self.time)], dtype=np.float64).reshape(n_f, 3)
            states = np.array([STATE_CODES.get(w.finger_state(f), 0) for f in fids], dtype=np.int8)
            contacts = np.array([self._body_index.get(w.finger_contact(f), -1)
                                 if w.finger_contact(f) is not None else -1 for f in fids], dtype=np.int32)
        else:
            gos = ff = hips = np.zeros((0, 3))
            states = np.zeros(0, np.int8)
            contacts = np.zeros(0, np.int32)
        return Snapshot(self.time, poses, com, force, torque, hips, gos, ff, states, contacts)

    def _snapshot_from_runtime(self, snap: dict) -> Snapshot:
        """Map the core runtime's snapshot (graspcore.World.snapshot, docs/runtime.md)."""
        h = self.handle
        poses = np.asarray(snap["poses"], dtype=np.float64)[h.body_ids]
        com = poses[:, :3] + quat_rotate(poses[:, 3:], self._coms)
        fids = h.finger_ids
        contacts = np.array([self._body_index.get(int(b), -1) for b in snap["contact_bodies"][fids]],
                            dtype=np.int32)
        return Snapshot(float(snap["time"]), poses, com,
                        np.asarray(snap["residual_forces"])[h.body_ids],
                        np.asarray(snap["residual_torques"])[h.body_ids],
                        np.asarray(snap["hips"])[fids],
                        np.asarray(snap["god_objects"])[fids],
                        np.asarray(snap["forces"])[fids],  # what the device renders (clamped, ramped)
                        np.asarray(snap["finger_states"], dtype=np.int8)[fids],
                        contacts)

    def stats(self) -> dict:
        ticks = np.diff(np.array(self.ticks)) if len(self.ticks) > 2 else np.zeros(0)
        wall = (self.ticks[-1] - self.ticks[0]) if len(self.ticks) > 1 else 0.0
        steps = getattr(self.driver, "steps", 0)
        out = {
            "time": self.time,
            "steps": steps,
            "haptic_rate_target": self.haptic_rate,
            "step_us": 1e6 * self.step_wall / steps if steps else 0.0,
            "display_rate": (len(ticks) / wall) if wall > 0 else 0.0,
            "jitter_ms": float(np.std(ticks) * 1e3) if len(ticks) else 0.0,
            "max_tick_ms": self.max_step_wall * 1e3,
            "dropped_s": self.dropped_time,
            "threaded": self.threaded,
        }
        if wall > 0:
            out["haptic_rate"] = steps / wall
        elif self.step_wall > 0:
            out["haptic_rate"] = steps / self.step_wall
        else:
            out["haptic_rate"] = 0.0
        if hasattr(self.world, "stats") and self.threaded:
            # The core's own rates and jitter, under a prefix so they do not overwrite ours.
            out.update({f"runtime_{k}": v for k, v in self.world.stats().items()})
        return out

    def save_recording(self, path: str) -> str:
        """Write the recorded snapshots to ``path`` (.npz). Returns the path."""
        if not self.recording:
            raise ValueError("nothing recorded (start the runner with record=True)")
        r = self.recording
        desc = self.handle.desc
        np.savez_compressed(
            path,
            time=np.array([s.time for s in r]),
            body_names=np.array([b.name for b in desc.bodies]),
            finger_names=np.array([f.name for f in desc.fingers]),
            poses=np.stack([s.poses for s in r]),
            hips=np.stack([s.hips for s in r]),
            god_objects=np.stack([s.god_objects for s in r]),
            finger_forces=np.stack([s.finger_forces for s in r]),
            finger_states=np.stack([s.finger_states for s in r]),
            residual_force=np.stack([s.force for s in r]),
            residual_torque=np.stack([s.torque for s in r]),
            haptic_rate=self.haptic_rate,
        )
        return path
