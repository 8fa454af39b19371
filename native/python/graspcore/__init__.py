"""graspcore: friction-cone (god-object) haptic rendering and rigid-body dynamics.

The world lives in C (``graspcore._core``); this module adds argument handling
that is easier in Python (numpy conversion, inertia forms) and the zero-copy
numpy views. See docs/api.md.
"""
from __future__ import annotations

import functools

import numpy as np

from . import _core

__all__ = ["World", "FINGER_STATES", "RENDERERS", "SERIAL_STATES", "SERIAL_EVENTS", "WORLD_DEFAULTS",
           "BODY_DEFAULTS", "FINGER_DEFAULTS", "RUNTIME_DEFAULTS", "SERIAL_DEFAULTS", "TICK_FORCES_ENABLED",
           "tick_dtype", "trace_dtype", "grasp_quality", "grasp_quality_batch", "grasp_mu_min", "GRASP_QUALITY_DTYPE"]

# The core's own defaults (gc_default_*_def), not copies: one entry per keyword argument of
# World(), add_body, add_finger, start and attach_serial.
WORLD_DEFAULTS = dict(_core.WORLD_DEFAULTS)
BODY_DEFAULTS = dict(_core.BODY_DEFAULTS)
FINGER_DEFAULTS = dict(_core.FINGER_DEFAULTS)
RUNTIME_DEFAULTS = dict(_core.RUNTIME_DEFAULTS)
SERIAL_DEFAULTS = dict(_core.SERIAL_DEFAULTS)
_B = BODY_DEFAULTS

# The names of the core's enums, indexed by value (gcFingerState, gcFingerRenderer, gcSerialState,
# gcSerialEventCode; SERIAL_EVENTS[0] is "?", no event).
FINGER_STATES = _core.FINGER_STATES
# Bits of a tick record's ``flags``.
TICK_FORCES_ENABLED = _core.TICK_FORCES_ENABLED
RENDERERS = _core.RENDERERS
SERIAL_STATES = _core.SERIAL_STATES
SERIAL_EVENTS = _core.SERIAL_EVENTS


@functools.lru_cache(maxsize=64)     # made once per layout: a sweep asks for it twice a sample
def tick_dtype(num_bodies: int, num_fingers: int) -> np.dtype:
    """The numpy dtype of one tick log record (graspcore.h, docs/recording-format.md), built
    from the core's table of its fields (``_core.TICK_FIELDS``)."""
    nb, nf = int(num_bodies), int(num_fingers)
    units = {"finger": (nf,), "body": (nb,)}
    fields = []
    for name, type_, scope, shape in _core.TICK_FIELDS:
        shape = units.get(scope, ()) + tuple(shape)
        fields.append((name, type_, shape) if shape else (name, type_))
    dtype = np.dtype(fields)
    if dtype.itemsize != _core.tick_record_size(nb, nf):
        raise RuntimeError("graspcore.tick_dtype does not match the core's record layout (rebuild the core)")
    return dtype


@functools.lru_cache(maxsize=64)
def trace_dtype(num_bodies: int, num_fingers: int, ticks: int) -> np.dtype:
    """The numpy dtype of ``ticks`` ticks of ``World.step_hips_trace``: one record whose fields
    are contiguous arrays over the ticks of the tick record's fields the core names
    (``_core.TICK_TRACE_FIELDS``: time, contact, state, force, god_object, pose)."""
    nb, nf, n = int(num_bodies), int(num_fingers), int(ticks)
    record = tick_dtype(nb, nf)    # the trace's fields are the record's, named by the core
    dtype = np.dtype([(name, record[name].base, (n,) + record[name].shape) for name in _core.TICK_TRACE_FIELDS])
    if dtype.itemsize != n * _core.tick_trace_size(nb, nf):
        raise RuntimeError("graspcore.trace_dtype does not match the core's trace layout (rebuild the core)")
    return dtype


def _points_array(points, name: str) -> np.ndarray:
    try:
        array = np.ascontiguousarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected an (N, 3) array of numbers ({exc})") from None
    if array.ndim == 1 and array.size == 3:
        array = array.reshape(1, 3)
    if array.ndim != 2 or array.shape[1] != 3 or array.shape[0] < 1:
        raise ValueError(f"{name}: expected an (N, 3) array of points, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: contains NaN or infinite coordinates")
    return array


def _inertia_matrix(inertia) -> list[float] | None:
    if inertia is None:
        return None
    try:
        array = np.asarray(inertia, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("inertia: expected 3 principal moments or a 3x3 matrix") from None
    if array.shape == (3,):
        array = np.diag(array)
    if array.shape != (3, 3):
        raise ValueError(f"inertia: expected 3 principal moments or a 3x3 matrix, got shape {array.shape}")
    return array.ravel().tolist()


class World(_core.World):
    """A grasp world.

    ``World(gravity=(0, 0, -9.81), gyroscopic=True, max_bodies=256, max_fingers=32,
    max_parts=4096, threads=1, max_contacts=2048)``. Capacities are fixed at creation so
    that the numpy views (``body_poses``, ``god_objects``, ``finger_forces``, ``hips``)
    never dangle. ``threads``: threads solving collision chains (results do not depend on
    it); ``max_contacts``: body-body contact manifolds (docs/solver.md).
    """

    def add_body(
        self,
        points=None,
        mass: float = _B["mass"],
        position=(0.0, 0.0, 0.0),
        orientation=(1.0, 0.0, 0.0, 0.0),
        static: bool = False,
        mu_s: float = _B["mu_s"],
        mu_d: float = _B["mu_d"],
        viscosity: float = _B["viscosity"],
        inertia=None,
        parts=None,
        center_of_mass=None,
        radius: float = 0.0,
        linear_velocity=(0.0, 0.0, 0.0),
        angular_velocity=(0.0, 0.0, 0.0),
        linear_damping: float = _B["linear_damping"],
        angular_damping: float = _B["angular_damping"],
    ) -> int:
        """Add a rigid body; returns its id.

        ``points``: (N, 3) body-frame points whose convex hull is the body (N = 1 or 2
        with ``radius`` > 0 give a sphere or a capsule). ``parts``: a list of such point
        arrays for a compound of convex parts (instead of ``points``). ``inertia``: 3
        principal moments (body axes) or a 3x3 matrix about the centre of mass; None
        computes it from the hull and the mass at uniform density.
        """
        if parts is None:
            if points is None:
                raise ValueError("points: give the body's points, or parts for a compound")
            part_arrays = [_points_array(points, "points")]
        else:
            if points is not None:
                raise ValueError("parts: give either points or parts, not both")
            if isinstance(parts, np.ndarray) or len(parts) == 0:
                raise ValueError("parts: expected a non-empty list of (N, 3) point arrays")
            part_arrays = [_points_array(p, f"parts[{i}]") for i, p in enumerate(parts)]
        radii = [float(radius)] * len(part_arrays)
        return self._add_body(
            part_arrays, radii, mass=float(mass), position=position, orientation=orientation, static=bool(static),
            mu_s=float(mu_s), mu_d=float(mu_d), viscosity=float(viscosity), inertia=_inertia_matrix(inertia),
            center_of_mass=center_of_mass, linear_velocity=linear_velocity, angular_velocity=angular_velocity,
            linear_damping=float(linear_damping), angular_damping=float(angular_damping),
        )

    @property
    def body_poses(self) -> np.ndarray:
        """(n_bodies, 7) read-only view: x, y, z, qw, qx, qy, qz of each body frame."""
        return np.asarray(self._view(0))

    @property
    def god_objects(self) -> np.ndarray:
        """(n_fingers, 3) read-only view of god-object positions (the HIP when free)."""
        return np.asarray(self._view(1))

    @property
    def finger_forces(self) -> np.ndarray:
        """(n_fingers, 3) read-only view of forces rendered to the devices, N."""
        return np.asarray(self._view(2))

    @property
    def hips(self) -> np.ndarray:
        """(n_fingers, 3) read-only view of the HIPs as last set."""
        return np.asarray(self._view(3))

    def set_hips(self, positions) -> None:
        """HIPs of fingers 0..n-1 from an (n, 3) array."""
        super().set_hips(_points_array(positions, "positions"))

    # ---- Runtime (docs/runtime.md): start / stop / advance / stats come from the core.

    def set_hip_track(self, times, positions, scripted=None, orientations=None) -> None:
        """A scripted HIP track for the runtime (set while stopped): ``times`` (n,) strictly
        increasing seconds, ``positions`` (n, m, 3) for fingers 0..m-1. At its tick k the
        haptic loop samples it at ``times[0] + k / haptic_rate`` (linear, held past either
        end): the same HIPs as ``set_hips`` before every synchronous step. ``scripted`` (m,)
        bools says which fingers it drives (default all); the others follow ``push_hips``.
        ``orientations`` (n, m, 4) quaternions (w, x, y, z) turn convex fingers too: sampled
        by normalised lerp (shorter arc), the same pose as ``set_finger_pose`` before every
        step. ``set_hip_track(None, None)`` clears it."""
        if times is None:
            self._set_hip_track(np.zeros(0), np.zeros(0), 1, None)
            return
        t = np.ascontiguousarray(times, dtype=np.float64)
        p = np.ascontiguousarray(positions, dtype=np.float64)
        if t.ndim != 1 or p.ndim != 3 or p.shape[0] != t.shape[0] or p.shape[2] != 3:
            raise ValueError(f"set_hip_track: expected times (n,) and positions (n, m, 3), "
                             f"got {t.shape} and {p.shape}")
        mask = None if scripted is None else np.ascontiguousarray(scripted, dtype=np.uint8)
        q = None
        if orientations is not None:
            q = np.ascontiguousarray(orientations, dtype=np.float64)
            if q.shape != p.shape[:2] + (4,):
                raise ValueError(f"set_hip_track: expected orientations {p.shape[:2] + (4,)} "
                                 f"(w, x, y, z per sample and finger), got {q.shape}")
        self._set_hip_track(t, p, int(p.shape[1]), mask, q)

    def push_hips(self, positions, t: float, orientations=None) -> bool:
        """HIPs of fingers 0..n-1 ((n, 3) array) sampled at time ``t`` (s), from any thread
        while the runtime runs. The haptic loop walks each HIP to the sample over the interval
        since the previous one (at most 0.25 s, at most ``max_hip_speed``), so a slow caller
        gives a smooth path and a caller pushing every tick gets its HIPs at the next tick. Returns False when the input was rejected (NaN/Inf, or ``t``
        older than the last push): it is counted in ``stats()['rejected_inputs']`` and
        ignored. ``orientations`` ((n, 4) quaternions w, x, y, z) turn convex fingers too, over
        the same interval (normalised lerp, the shorter arc; a zero or non-finite one rejects
        the push); without them the fingers keep their orientation. Raises RuntimeError when the
        runtime is not running."""
        try:
            array = np.ascontiguousarray(positions, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"positions: expected an (n, 3) array of numbers ({exc})") from None
        if array.ndim == 1 and array.size == 3:
            array = array.reshape(1, 3)
        if array.ndim != 2 or array.shape[1] != 3 or array.shape[0] < 1:
            raise ValueError(f"positions: expected an (n, 3) array, got shape {array.shape}")
        if orientations is None:
            return self._push_hips(array, float(t))
        try:
            q = np.ascontiguousarray(orientations, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"orientations: expected an (n, 4) array of numbers ({exc})") from None
        if q.ndim == 1 and q.size == 4:
            q = q.reshape(1, 4)
        if q.shape != (array.shape[0], 4):
            raise ValueError(f"orientations: expected ({array.shape[0]}, 4) quaternions (w, x, y, z), "
                             f"got shape {q.shape}")
        return self._push_hips(array, float(t), q)

    def snapshot(self) -> dict:
        """A consistent copy of one haptic tick (the world's own state when stopped):

        ``time``, ``object_time`` (s), ``tick``, ``forces_enabled``; per body ``poses``
        (n, 7), ``residual_forces`` / ``residual_torques`` (n, 3), ``adopted`` (n,) bool;
        per finger ``god_objects``, ``hips``, ``forces`` (device: clamped, ramped, zero
        under the watchdog), ``spring_forces`` (physics, unclamped) (m, 3),
        ``finger_states`` (m,) int32 (0 free, 1 stick, 2 slip), ``contact_bodies``
        (m,) int32 (-1 when free) and ``normals`` (m, 3): the plane normal of the contact
        whose god-object it reports (the deepest), world, pointing out of the body touched (0
        when free), ``patches`` (m, 4, 2) float32: a convex finger's contact patch (the tick
        record's ``patch``, docs/recording-format.md; zeros for a sphere); per body ``linear_velocities``
        (of the body frame origin, as ``body_velocity``) and ``angular_velocities`` (n, 3).
        While the runtime runs, the world's queries and views answer from the last snapshot."""
        (time, object_time, tick, enabled, nb, nf, poses, wrenches, adopted, gos, hips, forces,
         springs, states, contacts, normals, velocities, patches) = self._snapshot()
        wrenches = np.frombuffer(wrenches, dtype=np.float64).reshape(nb, 6)
        velocities = np.frombuffer(velocities, dtype=np.float64).reshape(nb, 6)
        return {
            "time": time,
            "object_time": object_time,
            "tick": tick,
            "forces_enabled": bool(enabled),
            "poses": np.frombuffer(poses, dtype=np.float64).reshape(nb, 7),
            "residual_forces": wrenches[:, :3],
            "residual_torques": wrenches[:, 3:],
            "adopted": np.frombuffer(adopted, dtype=np.uint8).astype(bool),
            "god_objects": np.frombuffer(gos, dtype=np.float64).reshape(nf, 3),
            "hips": np.frombuffer(hips, dtype=np.float64).reshape(nf, 3),
            "forces": np.frombuffer(forces, dtype=np.float64).reshape(nf, 3),
            "spring_forces": np.frombuffer(springs, dtype=np.float64).reshape(nf, 3),
            "finger_states": np.frombuffer(states, dtype=np.int32),
            "contact_bodies": np.frombuffer(contacts, dtype=np.int32),
            "normals": np.frombuffer(normals, dtype=np.float64).reshape(nf, 3),
            "linear_velocities": velocities[:, :3],
            "angular_velocities": velocities[:, 3:],
            "patches": np.frombuffer(patches, dtype=np.float32).reshape(nf, _core.FINGER_PATCH_CORNERS, 2),
        }

    # ---- Tick log (docs/recording-format.md): one record per tick for recorders.

    def tick_dtype(self) -> np.dtype:
        """dtype of this world's tick records (its current bodies and fingers)."""
        return tick_dtype(self.body_count, self.finger_count)

    def tick_record(self, out=None, tick: int = 0) -> np.ndarray:
        """The stopped world as one tick record (a 0-d structured array; ``out`` to reuse one)."""
        if out is None:
            out = np.zeros((), dtype=self.tick_dtype())
        self._tick_record(out, int(tick))
        return out

    def step_hips(self, hips, dt: float, out: np.ndarray | None, first_tick: int = 1) -> np.ndarray | None:
        """A HIP stream replayed in C with the GIL released: for each row of ``hips`` ((steps,
        fingers, 3)), ``set_hips(row)``, ``step(dt)`` and the tick record (numbered
        ``first_tick``, ``first_tick + 1``, ...) into ``out`` (a 1-d array of ``tick_dtype()``,
        at least steps long; None: no records, the steps alone). Bit for bit those calls one
        by one. Returns the filled part of ``out``."""
        # aligned too: an array rebuilt by Dask's deserialiser may sit unaligned in its frame
        h = np.require(hips, dtype=np.float64, requirements=["C_CONTIGUOUS", "ALIGNED"])
        if h.ndim != 3 or h.shape[2] != 3:
            raise ValueError(f"hips: expected a (steps, fingers, 3) array, got shape {h.shape}")
        if out is not None and (out.dtype != self.tick_dtype() or out.ndim != 1 or not out.flags.c_contiguous
                                or len(out) < len(h)):
            raise ValueError(f"out: expected a C-contiguous 1-d array of World.tick_dtype(), at least {len(h)} long")
        self._step_hips(h, int(h.shape[0]), int(h.shape[1]), float(dt), out, int(first_tick))
        return None if out is None else out[:len(h)]

    def replay_ticks(self, hips, object_ticks, object_reads, out: np.ndarray | None,
                     orientations=None) -> np.ndarray | None:
        """A recorded threaded session replayed on the manual clock (``start(realtime=False)``
        with the rates and adoption settings it ran with): for each row of ``hips`` ((steps,
        fingers, 3), every finger) one haptic tick with those HIPs (and ``orientations``, (steps,
        fingers, 4), as recorded), the object manager's ticks run and their results taken on the
        recorded hand-over schedule (``object_ticks``, ``object_reads``: the records' fields), so
        each tick equals the recorded one bit for bit. Records into ``out`` (as ``step_hips``;
        None: none). A schedule that cannot have happened raises ValueError naming the step."""
        h = np.require(hips, dtype=np.float64, requirements=["C_CONTIGUOUS", "ALIGNED"])
        if h.ndim != 3 or h.shape[2] != 3:
            raise ValueError(f"hips: expected a (steps, fingers, 3) array, got shape {h.shape}")
        n = h.shape[0]
        q = None
        if orientations is not None:
            q = np.require(orientations, dtype=np.float64, requirements=["C_CONTIGUOUS", "ALIGNED"])
            if q.shape != h.shape[:2] + (4,):
                raise ValueError(f"orientations: expected {h.shape[:2] + (4,)}, got {q.shape}")
        schedule = []
        for name, column in (("object_ticks", object_ticks), ("object_reads", object_reads)):
            c = np.asarray(column)
            if c.shape != (n,) or not np.issubdtype(c.dtype, np.integer) or (c.size and c.min() < 0):
                raise ValueError(f"{name}: expected ({n},) counts >= 0, got shape {c.shape}, dtype {c.dtype}")
            schedule.append(np.ascontiguousarray(c, dtype=np.uint64))
        if out is not None and (out.dtype != self.tick_dtype() or out.ndim != 1 or not out.flags.c_contiguous
                                or len(out) < n):
            raise ValueError(f"out: expected a C-contiguous 1-d array of World.tick_dtype(), at least {n} long")
        self._replay_ticks(h, q, schedule[0], schedule[1], int(n), int(h.shape[1]), out)
        return None if out is None else out[:n]

    def trace_dtype(self, ticks: int) -> np.dtype:
        """dtype of ``ticks`` ticks of this world's step traces (its current bodies and fingers)."""
        return trace_dtype(self.body_count, self.finger_count, ticks)

    def step_hips_trace(self, hips, dt: float, out: np.ndarray, first: int = 0) -> np.ndarray:
        """``step_hips`` with a short trace of each step instead of its tick record: the record's
        time, contact, state, force, god_object and pose (the same values, two fifths of the bytes,
        no state hash), step k into tick ``first + k`` of ``out`` (a 0-d array of
        ``trace_dtype(ticks)``, each field a contiguous array over the ticks). Returns ``out``."""
        h = np.require(hips, dtype=np.float64, requirements=["C_CONTIGUOUS", "ALIGNED"])
        if h.ndim != 3 or h.shape[2] != 3:
            raise ValueError(f"hips: expected a (steps, fingers, 3) array, got shape {h.shape}")
        shape = out.dtype["time"].shape if out.dtype.names and "time" in out.dtype.names else ()
        total = shape[0] if len(shape) == 1 else -1
        if out.ndim != 0 or total < 0 or out.dtype != self.trace_dtype(total) or not out.flags.c_contiguous:
            raise ValueError("out: expected a 0-d array of World.trace_dtype(ticks)")
        if not 0 <= first <= total - len(h):
            raise ValueError(f"first: steps {first}..{first + len(h)} do not fit {total} ticks")
        self._step_hips_trace(h, int(h.shape[0]), int(h.shape[1]), float(dt), out, int(first), int(total))
        return out

    def set_tick_log(self, capacity: int) -> None:
        """While stopped: keep the last ``capacity`` undrained haptic ticks (0 = off). start()
        sizes and empties the ring; a full ring drops ticks and counts them
        (``tick_log_overflow()``), the haptic loop never waits. A capacity outside
        0 .. 2**31 - 1 is refused (the core takes a C int: it would wrap)."""
        capacity = int(capacity)
        if not 0 <= capacity <= 2**31 - 1:
            raise ValueError(f"set_tick_log: capacity {capacity} is outside 0 .. {2**31 - 1} ticks")
        self._set_tick_log(capacity)

    def drain_ticks(self, out: np.ndarray) -> np.ndarray:
        """Move the oldest undrained tick records into ``out`` (a 1-d array of
        ``tick_dtype()``); returns the filled part of it."""
        if out.dtype != self.tick_dtype() or out.ndim != 1 or not out.flags.c_contiguous:
            raise ValueError("out: expected a C-contiguous 1-d array of World.tick_dtype()")
        return out[:self._drain_ticks(out)]


# ---- Grasp quality (docs/api.md "Grasp quality"): the grasp wrench space of point contacts.

# The core's gcGraspQuality record (its fields' offsets from the binding's table), and the
# structured array grasp_quality_batch returns (closures as bools).
_KINDS = {"double": ("<f8", "<f8"), "int": ("<i4", "<i4"), "bool": ("<i4", "?"), "u64": ("<u8", "<u8")}
_GRASP_RECORD = np.dtype({
    "names": [name for name, _, _, _ in _core.GRASP_QUALITY_FIELDS],
    "formats": [(_KINDS[kind][0], (n,)) if n > 1 else _KINDS[kind][0]
                for _, kind, _, n in _core.GRASP_QUALITY_FIELDS],
    "offsets": [offset for _, _, offset, _ in _core.GRASP_QUALITY_FIELDS],
    "itemsize": _core.GRASP_QUALITY_SIZE,
})
GRASP_QUALITY_DTYPE = np.dtype([
    (name, (_KINDS[kind][1], (n,)) if n > 1 else _KINDS[kind][1]) for name, kind, _, n in _core.GRASP_QUALITY_FIELDS
])


def _rows3(value, name: str) -> np.ndarray:
    try:
        array = np.ascontiguousarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected an (N, 3) array of numbers ({exc})") from None
    if array.ndim == 1 and array.size == 3:
        array = array.reshape(1, 3)
    if array.ndim == 1 and array.size == 0:
        array = array.reshape(0, 3)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name}: expected an (N, 3) array, got shape {array.shape}")
    return array


def _vector(value, size: int, name: str) -> np.ndarray:
    try:
        array = np.ascontiguousarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected {size} numbers ({exc})") from None
    if array.shape != (size,):
        raise ValueError(f"{name}: expected shape ({size},), got {array.shape}")
    return array


def _contacts(points, normals, mu):
    points = _rows3(points, "points")
    normals = _rows3(normals, "normals")
    if normals.shape != points.shape:
        raise ValueError(f"normals: expected shape {points.shape} like points, got {normals.shape}")
    n = points.shape[0]
    try:
        mu_array = np.asarray(mu, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"mu: expected a number or {n} numbers ({exc})") from None
    if mu_array.ndim == 0:
        mu_array = np.full(n, float(mu_array))
    if mu_array.shape != (n,):
        raise ValueError(f"mu: expected a number or shape ({n},), got {mu_array.shape}")
    return points, normals, np.ascontiguousarray(mu_array)


def _torsion(torsion, n: int):
    """None (point contacts), or one soft-contact radius rho >= 0 (m) per contact row."""
    if torsion is None:
        return None
    try:
        array = np.asarray(torsion, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"torsion: expected a number or {n} numbers ({exc})") from None
    if array.ndim == 0:
        array = np.full(n, float(array))
    if array.shape != (n,):
        raise ValueError(f"torsion: expected a number or shape ({n},), got {array.shape}")
    if not np.all(np.isfinite(array)) or np.any(array < 0):
        raise ValueError("torsion: expected finite numbers >= 0 (the soft contacts' patch radii, m)")
    return np.ascontiguousarray(array)


def _number(value, name: str, kind=float):
    try:
        if kind is int:
            if isinstance(value, bool) or int(value) != value:
                raise ValueError("not an integer")
            return int(value)
        return float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected {'an integer' if kind is int else 'a number'}, got {value!r} ({exc})") from None


def _flag(value, name: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name}: expected True or False, got {value!r}")
    return bool(value)


def grasp_quality(points, normals, mu, center, radius, edges: int = 8, volume: bool = True,
                  reuse: bool = False, torsion=None) -> dict:
    """Quality of a grasp by point contacts with friction (docs/api.md "Grasp quality").

    points (n, 3) contact points, normals (n, 3) inward normals (into the object), mu one number
    or (n,), center the object's centre of mass, radius > 0 the torque scale, edges >= 3 per
    linearised friction cone. Returns force_closure, force_only_closure, torque_closure, epsilon,
    volume, weakest (6 floats), rank, facets. volume=False takes the fast path (no 6-D hull:
    closure by a linear program, epsilon and weakest by support queries, the same values) and
    returns volume -1.0 and facets -1 (not computed). reuse=True (with volume=False): a set within
    rounding of one of the last few answered in closure gets that answer's facet re-certified
    instead of a new search (docs/api.md, "Reusing an answer"). torsion: None (point contacts) or a
    number or (n,) of soft-contact patch radii rho (m): each contact with mu rho > 0 also has the
    wrenches (n, ((p - center) x n +- mu rho n) / radius), torsional friction about its normal up to
    mu rho Fn (GraspIt's soft contacts; docs/analysis.md). Bad input raises ValueError naming the
    argument."""
    points, normals, mu = _contacts(points, normals, mu)
    return _core._grasp_quality(points, normals, mu, _vector(center, 3, "center"), _number(radius, "radius"),
                                _number(edges, "edges", int), _flag(volume, "volume"), _flag(reuse, "reuse"),
                                _torsion(torsion, len(mu)))


def grasp_quality_batch(points, normals, mu, counts, centers, radii, edges: int = 8,
                        volume: bool = True, reuse: bool = False, torsion=None) -> np.ndarray:
    """grasp_quality of many contact sets: counts[s] contacts in set s, their rows of points,
    normals and mu (one number or one per row) concatenated; centers (m, 3), radii (m,).
    volume and reuse as in grasp_quality (volume False: volume -1.0 and facets -1 in every row,
    much faster); torsion as in grasp_quality, one per row.
    Returns a structured array of GRASP_QUALITY_DTYPE, one row per set."""
    points, normals, mu = _contacts(points, normals, mu)
    try:
        counts_array = np.asarray(counts)
        if counts_array.ndim != 1 or (counts_array.size and not np.issubdtype(counts_array.dtype, np.integer)):
            raise ValueError(f"shape {counts_array.shape}, dtype {counts_array.dtype}")
        if counts_array.size and (counts_array.min() < 0 or counts_array.max() > np.iinfo(np.int32).max):
            raise ValueError("a count is negative or too large")
    except (TypeError, ValueError) as exc:
        raise ValueError(f"counts: expected a 1-d array of contact counts >= 0 ({exc})") from None
    counts_array = np.ascontiguousarray(counts_array, dtype=np.int32)
    m = counts_array.shape[0]
    if int(counts_array.sum(dtype=np.int64)) != points.shape[0]:
        raise ValueError(f"counts: they add up to {int(counts_array.sum(dtype=np.int64))} contacts, "
                         f"points has {points.shape[0]} rows")
    centers_array = _rows3(centers, "centers") if m else np.zeros((0, 3))
    if centers_array.shape != (m, 3):
        raise ValueError(f"centers: expected shape ({m}, 3), got {centers_array.shape}")
    radii_array = _vector(radii, m, "radii")
    raw = np.zeros(m, dtype=_GRASP_RECORD)
    if m:
        _core._grasp_quality_batch(points, normals, mu, counts_array, np.ascontiguousarray(centers_array),
                                   radii_array, _number(edges, "edges", int), _flag(volume, "volume"),
                                   _flag(reuse, "reuse"), raw.view(np.uint8), _torsion(torsion, len(mu)))
    out = np.zeros(m, dtype=GRASP_QUALITY_DTYPE)
    for name in GRASP_QUALITY_DTYPE.names:
        out[name] = raw[name]
    return out


def grasp_mu_min(points, normals, center, radius, edges: int = 8, mu_max: float = 10.0,
                 reuse: bool = False, torsion=None) -> float:
    """The smallest friction coefficient (the same at every contact) at which the contact set is
    in force closure, by bisection to 1e-6 (each step the closure linear program, no hull); 0.0 for
    frictionless closure, math.inf when not in closure at mu_max. reuse=True: the answer for
    contacts within 1e-9 of one of the last few, checked (closed there, open 2e-6 below), instead
    of a new search (docs/api.md, "Reusing an answer"; not with torsion). torsion as in
    grasp_quality: the soft contacts' torsional friction mu rho grows with the searched mu."""
    points, normals, _ = _contacts(points, normals, 0.0)
    return _core._grasp_mu_min(points, normals, _vector(center, 3, "center"), _number(radius, "radius"),
                               _number(edges, "edges", int), _number(mu_max, "mu_max"), _flag(reuse, "reuse"),
                               _torsion(torsion, len(points)))
