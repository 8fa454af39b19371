"""The measures of a grasp as it is held (docs/analysis.md): per held body and snapshot, the
closure flags, epsilon and volume of its finger contacts (``graspcore.grasp_quality``), the
friction they need, per finger the friction use and slip margin, and the grip force against
the load. bpy-free: the live HUD, ``grasp-lab analyze`` and the bake call it.

Conventions (xFCA, native/src/xfca.c): a finger's god-object is its fingertip sphere's
centre, on the body's surface inflated by the finger's radius; the recorded ``normal`` is that
contact's outward plane normal (world); ``force`` is the coupling spring force the finger
exerts, k (GO - HIP) + damping, and the body gets its reaction (the core applies it at the GO).
So a contact's point on the body's surface is GO - radius * normal, its inward normal is
-normal and the force on the body is -force.

One implementation for one snapshot and for many: ``analyse_arrays`` takes arrays with a
leading snapshot axis and answers tables (one row per held body per snapshot, one per
contact); ``analyse`` is it for one snapshot, as objects.

Area contacts (docs/analysis.md "Area contacts and soft fingertips"): a convex finger's contact is its patch, the
tick record's ``patch`` corners about the contact point, and its friction cones stand at the
corners in the grasp wrench space; a soft fingertip (the scene finger's ``torsion`` rho) adds
its torsional friction +-mu rho about the normal. Recordings without ``patch`` are analysed as
point contacts.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from . import defaults


SLIP = 2                # gcFingerState
MU_MAX = 10.0           # mu_min searches friction up to this; above: inf (no friction closes it)
_TINY = 1e-12           # normals shorter than this are "no normal" (a free finger records 0)


def tangent_axes(n):
    """The grasp wrench space's tangent axes (t1, t2) of unit inward normals n (..., 3), as the
    core takes them (graspcore.h, gcGraspDef): t1 = normalize(n x a), a the world axis of smallest
    |n . a| (ties: x, then y, then z), t2 = n x t1. The tick record's ``patch`` is in them."""
    n = np.asarray(n, dtype=np.float64)
    c = np.abs(n)
    axis = np.where(c[..., 1] < c[..., 0], 1, 0)
    axis = np.where(c[..., 2] < np.take_along_axis(c, axis[..., None], -1)[..., 0], 2, axis)
    t1 = _cross(n, np.eye(3)[axis])
    t1 /= np.sqrt(np.einsum("...k,...k->...", t1, t1))[..., None]
    return t1, _cross(n, t1)


def finger_torsions(scene) -> np.ndarray:
    """Each finger's soft-contact radius rho (m; 0: none) of a recording header's ``scene`` dict
    or an ``engine.scene.SceneDesc`` (a finger without one has none)."""
    fingers = scene["fingers"] if isinstance(scene, dict) else scene.fingers
    return np.array([float(f.get("torsion", 0.0) if isinstance(f, dict) else getattr(f, "torsion", 0.0))
                     for f in fingers], dtype=np.float64)


def wrench_contacts(point, normal, mu, finger, patches=None, torsions=None):
    """The grasp wrench space's contacts of the analysis's finger contacts (c rows: point, inward
    normal, mu, finger): a point contact stays one; an area contact (a non-zero ``patches[k]``,
    (c, corners, 2) offsets along tangent_axes, a repeated corner counted once) is its patch's
    corners, each with the contact's normal and mu (a patch's cones at its corners span what the
    whole patch does: docs/analysis.md). Returns (points, normals, mu, torsion or None, owner: the
    contact row of each)."""
    c = len(point)
    if patches is None:
        corners = np.zeros((c, 0, 2))
    else:
        corners = np.asarray(patches, dtype=np.float64)
        corners = corners.reshape(c, corners.shape[-2] if corners.ndim >= 2 else 0, 2)
    area = np.any(corners != 0.0, axis=(1, 2))              # all zero: a point contact
    used = np.ones(corners.shape[:2], dtype=bool)           # (c, corners): each corner but a repeat
    for j in range(1, corners.shape[1]):
        used[:, j] = np.all(np.any(corners[:, j:j + 1] != corners[:, :j], axis=-1), axis=1)
    rows = np.where(area, used.sum(axis=1), 1)
    owner = np.repeat(np.arange(c), rows)
    points = point[owner].copy()
    if area.any():
        t1, t2 = tangent_axes(normal[area])
        off = corners[area][used[area]]                     # (corner rows, 2), in contact order
        k = np.repeat(np.arange(int(area.sum())), used[area].sum(axis=1))
        points[area[owner]] = point[area][k] + off[:, :1] * t1[k] + off[:, 1:] * t2[k]
    rho = None
    if torsions is not None:
        rho_finger = np.asarray(torsions, dtype=np.float64)
        if np.any(rho_finger > 0):
            rho = np.ascontiguousarray(rho_finger[finger][owner])
    return points, normal[owner], mu[owner], rho, owner


def _core():
    from . import core_loader
    return core_loader.load()


@dataclass
class BodyModel:
    name: str
    mass: float                 # kg (0 for a static body)
    com: np.ndarray             # (3,) centre of mass, body frame
    mu_s: float
    mu_d: float
    radius: float               # torque scale: largest distance from the COM to a part vertex, m
    is_static: bool


@dataclass
class FingerContact:
    finger: int
    point: np.ndarray           # (3,) on the body's surface, world
    normal: np.ndarray          # (3,) inward unit normal (into the body)
    mu: float                   # of its current cone: mu_s sticking, mu_d slipping
    fn: float                   # N, normal force on the body (> 0 pushes into it)
    ft: float                   # N, tangential force on the body
    friction_use: float         # |Ft| / (mu |Fn|); 1 at the cone's edge
    slip_margin: float          # mu |Fn| - |Ft|, N; < 0 outside the cone
    state: int                  # 1 stick, 2 slip


@dataclass
class BodyGrasp:
    body: int
    contacts: list
    force_closure: bool
    torque_closure: bool
    force_only_closure: bool
    epsilon: float
    volume: float
    weakest: np.ndarray         # (6,) unit wrench direction the grasp resists least
    mu_min: float
    friction_needed: float
    min_slip_margin: float
    min_slip_finger: int        # -1 if none
    grip_force: float
    load_force: float
    grip_ratio: float
    resisted_force: float
    center: np.ndarray          # (3,) centre of mass, world
    radius: float


def _part_points(part) -> np.ndarray:
    return np.asarray(part, dtype=np.float64).reshape(-1, 3)


def body_models(scene) -> list:
    """BodyModel per body of a recording header's ``scene`` dict or an ``engine.scene.SceneDesc``
    (prepared: mass properties included)."""
    models = []
    bodies = scene["bodies"] if isinstance(scene, dict) else scene.bodies
    for b in bodies:
        if isinstance(b, dict):
            name, static, parts = b["name"], bool(b["static"]), b["parts"]
            mass, com, mu_s, mu_d = b.get("mass"), b.get("center_of_mass"), b["mu_s"], b["mu_d"]
        else:
            mp = b.mass_properties
            name, static, parts, mu_s, mu_d = b.name, bool(b.static), b.parts, b.mu_s, b.mu_d
            mass, com = (None, None) if mp is None else (mp.mass, mp.center_of_mass)
        points = np.concatenate([_part_points(p) for p in parts]) if len(parts) else np.zeros((1, 3))
        com = points.mean(axis=0) if com is None else np.asarray(com, dtype=np.float64).reshape(3)
        radius = float(np.sqrt(np.max(np.einsum("ij,ij->i", points - com, points - com))))
        models.append(BodyModel(name, 0.0 if static or mass is None else float(mass), com, float(mu_s),
                                float(mu_d), radius, static))
    return models


def centres_of_mass(models, poses) -> np.ndarray:
    """World centres of mass (..., nb, 3) of body frame poses (..., nb, 7)."""
    com = np.array([m.com for m in models], dtype=np.float64)
    return poses[..., :3] + _rotate(poses[..., 3:], com)


def _cross(a, b):
    """a x b over the last axis (np.cross, without its axis handling: this runs per snapshot)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def _rotate(q, v):
    """runner.quat_rotate's rotation of v by unit quaternions q (w, x, y, z), with _cross."""
    u = q[..., 1:]
    t = 2.0 * _cross(u, np.broadcast_to(v, u.shape))
    return v + q[..., :1] * t + _cross(u, t)


def com_velocities(models, poses, velocities) -> np.ndarray:
    """Velocities of the centres of mass (..., nb, 3) from the recorded velocities of the body
    frame origins and angular velocities (..., nb, 6): v_com = v_origin + w x (R com)."""
    com = np.array([m.com for m in models], dtype=np.float64)
    return velocities[..., :3] + _cross(velocities[..., 3:], _rotate(poses[..., 3:], com))


def recorded_accelerations(models, ticks, rows) -> np.ndarray:
    """Centre-of-mass accelerations (len(rows), nb, 3) at the tick records ``ticks[rows]``: the
    change of the centre of mass's velocity from the record before (backward difference: the
    step that ended at the tick, which the tick's forces drove), or to the record after for the
    first record; 0 for a recording of one tick."""
    rows = np.asarray(rows, dtype=np.int64)
    n = len(ticks)
    nb = len(models)
    if n < 2:
        return np.zeros((len(rows), nb, 3))
    prev = np.where(rows > 0, rows - 1, 0)
    cur = np.where(rows > 0, rows, 1)
    both = np.concatenate([prev, cur])
    v = com_velocities(models, ticks["pose"][both], ticks["velocity"][both])
    t = ticks["time"][both]
    dt = t[len(rows):] - t[:len(rows)]
    dt = np.where(dt > 0, dt, np.inf)       # a repeated time (never recorded) gives no acceleration
    return (v[len(rows):] - v[:len(rows)]) / dt[:, None, None]


@dataclass
class GraspTable:
    """analyse_arrays's answer. Sets: one row per (snapshot, held body), in snapshot then body
    order; contacts: one row per finger in contact, grouped by set (``first`` / ``count``)."""
    snapshot: np.ndarray        # (m,) index of the snapshot
    body: np.ndarray            # (m,)
    count: np.ndarray           # (m,) contacts
    first: np.ndarray           # (m,) first contact row
    quality: np.ndarray         # (m,) graspcore.grasp_quality_batch's rows
    mu_min: np.ndarray
    friction_needed: np.ndarray
    min_slip_margin: np.ndarray
    min_slip_finger: np.ndarray
    grip_force: np.ndarray
    load_force: np.ndarray
    grip_ratio: np.ndarray
    resisted_force: np.ndarray
    center: np.ndarray          # (m, 3)
    radius: np.ndarray          # (m,)
    # contacts
    finger: np.ndarray
    point: np.ndarray           # (c, 3)
    normal: np.ndarray          # (c, 3) inward
    mu: np.ndarray
    fn: np.ndarray
    ft: np.ndarray
    friction_use: np.ndarray
    slip_margin: np.ndarray
    state: np.ndarray


def contact_forces(forces, normals):
    """(fn, ft) of the force each finger's contact puts on its body: the reaction -force of the
    coupling force split along the inward normal -normal (recorded normals: outward, world;
    any leading shape). fn > 0 pushes into the body; a zero normal gives fn 0, ft = |force|."""
    forces = np.asarray(forces, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    length = np.sqrt(np.einsum("...k,...k->...", normals, normals))
    unit = normals / np.where(length > _TINY, length, np.inf)[..., None]
    fn = np.einsum("...k,...k->...", forces, unit)          # (-force) . (-normal)
    tangential = forces - fn[..., None] * unit
    return fn, np.sqrt(np.einsum("...k,...k->...", tangential, tangential))


def cone_mu(models, states, bodies):
    """The friction coefficient of each contact's current cone: mu_d while it slips, mu_s
    otherwise (0 where ``bodies`` is not a body index)."""
    mu_s = np.array([m.mu_s for m in models] + [0.0])
    mu_d = np.array([m.mu_d for m in models] + [0.0])
    bodies = np.where((bodies >= 0) & (bodies < len(models)), bodies, len(models))
    return np.where(np.asarray(states) == SLIP, mu_d[bodies], mu_s[bodies])


def friction_use(ft, mu, fn):
    """|Ft| / (mu |Fn|) where the cone is open (mu fn > 0); else inf for any tangential force
    (a finger pulling, or a frictionless one, holds none), 0 for none."""
    cone = mu * fn
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(cone > 0, ft / np.where(cone > 0, cone, 1.0), np.where(ft > 0, np.inf, 0.0))


class GraspAnalysisError(ValueError):
    """The core refused a contact set; ``snapshot`` is its snapshot index (None if unknown)."""

    def __init__(self, message: str, snapshot=None):
        super().__init__(message)
        self.snapshot = snapshot


def _mu_min(core, point, normal, mu, quality, starts, count, centers, radii, edges, sets=None,
            reuse=False, torsion=None) -> np.ndarray:
    """graspcore.grasp_mu_min of each set (a root search over tens of LPs), once per distinct set:
    a body at rest in a still hand gives the same set, bit for bit, tick after tick. What the
    set's quality at its own friction already says is not searched again: with every mu > 0 the
    edge wrenches span the same space at any friction, so a set of rank < 6 (two contacts, one)
    is in closure at none (inf); a set in closure at its own mu is in closure at the largest of
    them (closure grows with each contact's mu), which bounds the search. sets: the indices of
    the sets to answer (default all; quality's rows of the others are not read, their entries
    are left unset); reuse: grasp_mu_min's; torsion: the rows' soft-contact radii or None."""
    out = np.empty(len(starts))
    seen = {}
    for i in range(len(starts)) if sets is None else sets:
        s, c = starts[i], count[i]
        mu_set = mu[s:s + c]
        if quality["rank"][i] < 6 and np.all(mu_set > 0):
            out[i] = np.inf
            continue
        bound = min(float(np.max(mu_set)) if quality["force_closure"][i] else MU_MAX, MU_MAX)
        rho = None if torsion is None else torsion[s:s + c]
        key = (point[s:s + c].tobytes(), normal[s:s + c].tobytes(), centers[i].tobytes(), float(radii[i]), bound,
               None if rho is None else rho.tobytes())
        if key not in seen:
            try:
                seen[key] = core.grasp_mu_min(point[s:s + c], normal[s:s + c], centers[i], radii[i], edges=edges,
                                              mu_max=bound, reuse=reuse, torsion=rho)
            except ValueError as ex:
                ex.set_index = i
                raise
        out[i] = seen[key]
    return out


def _remembered(core, memo, point, normal, mu, starts, count, centers, radii, edges, volume, reuse, torsion=None):
    """grasp_quality_batch and mu_min of each set, the core asked only for sets not in memo (a
    body at rest in a still hand gives the same set, bit for bit, display update after update);
    memo then holds exactly these sets' answers."""
    keys = [(point[s:s + c].tobytes(), normal[s:s + c].tobytes(), mu[s:s + c].tobytes(), centers[i].tobytes(),
             float(radii[i]), edges, bool(volume), None if torsion is None else torsion[s:s + c].tobytes())
            for i, (s, c) in enumerate(zip(starts, count))]
    new = [i for i, k in enumerate(keys) if k not in memo]
    if len(new) == len(keys):
        fresh = core.grasp_quality_batch(point, normal, mu, count, centers, radii, edges=edges, volume=volume,
                                         reuse=reuse, torsion=torsion)
    elif new:
        rows = np.repeat(np.isin(np.arange(len(keys)), new), count)
        try:
            fresh = core.grasp_quality_batch(point[rows], normal[rows], mu[rows], count[new], centers[new],
                                             radii[new], edges=edges, volume=volume, reuse=reuse,
                                             torsion=None if torsion is None else torsion[rows])
        except ValueError as ex:    # "set j: ..." of the new sets: set new[j] of the call's
            numbered = re.match(r"set (\d+): (.*)", str(ex), re.S)
            if not numbered:
                raise
            err = ValueError(numbered.group(2))
            err.set_index = new[int(numbered.group(1))]
            raise err from None
    answers = {keys[i]: memo[keys[i]] for i in range(len(keys)) if keys[i] in memo}
    if new:
        by_set = np.zeros(len(keys), dtype=fresh.dtype)
        by_set[new] = fresh
        fresh_mu_min = _mu_min(core, point, normal, mu, by_set, starts, count, centers, radii, edges, new, reuse,
                               torsion)
        answers.update((keys[i], (fresh[j], fresh_mu_min[i])) for j, i in enumerate(new))
    quality = np.empty(len(keys), dtype=fresh.dtype if new else answers[keys[0]][0].dtype) if keys else fresh
    mu_min = np.empty(len(keys))
    for i, k in enumerate(keys):
        quality[i], mu_min[i] = answers[k]
    memo.clear()
    memo.update(answers)
    return quality, mu_min


def analyse_arrays(models, poses, god_objects, forces, normals, states, contact_bodies, finger_radii,
                   accelerations=None, gravity=None, edges=8, volume=True,
                   with_mu_min=True, memo=None, reuse=False, patches=None, torsions=None) -> GraspTable:
    """The measures for T snapshots at once: poses (T, nb, 7), god_objects / forces / normals
    (T, nf, 3), states / contact_bodies (T, nf), finger_radii (nf,), accelerations (T, nb, 3)
    of the centres of mass or None (0: the load is the weight). ``volume=False``: the core's
    fast path, without the 6-D hull (volume -1: not computed; every other measure the same).
    ``with_mu_min=False`` skips mu_min (a search, most of the cost; NaN in the table): the
    sweep's samples.
    ``memo``: a dict kept by the caller between calls (the live view: one per session); a set
    of contacts equal bit for bit to one of the last call's gets that call's core answers (the
    core's answers depend on nothing else), and the dict then holds this call's sets only.
    ``reuse``: graspcore.grasp_quality_batch's and grasp_mu_min's (a set within rounding of one
    the core answered lately gets that answer re-certified, not a new search).
    ``patches`` (T, nf, corners, 2): the tick record's ``patch`` (a convex finger's contact patch),
    or None (every contact a point); ``torsions`` (nf,): each finger's soft-contact radius rho, or
    None (none): see wrench_contacts."""
    core = _core()
    poses = np.asarray(poses, dtype=np.float64)
    god_objects = np.asarray(god_objects, dtype=np.float64)
    forces = np.asarray(forces, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    states = np.asarray(states)
    contact_bodies = np.asarray(contact_bodies)
    finger_radii = np.asarray(finger_radii, dtype=np.float64)
    nb = len(models)
    if poses.ndim != 3 or poses.shape[1:] != (nb, 7):
        raise ValueError(f"poses: expected (snapshots, {nb}, 7), got shape {poses.shape}")
    T, nf = god_objects.shape[0], god_objects.shape[1] if god_objects.ndim == 3 else -1
    if patches is not None:
        patches = np.asarray(patches)
        if patches.ndim != 4 or patches.shape[:2] != (T, nf) or patches.shape[3] != 2:
            raise ValueError(f"patches: expected shape ({T}, {nf}, corners, 2), got {patches.shape}")
    if torsions is not None:
        torsions = np.asarray(torsions, dtype=np.float64)
        if torsions.shape != (nf,) or not np.all(np.isfinite(torsions)) or np.any(torsions < 0):
            raise ValueError(f"torsions: expected {nf} finite radii >= 0, got {torsions!r}")
    for name, a, shape in (("god_objects", god_objects, (T, nf, 3)), ("forces", forces, (T, nf, 3)),
                           ("normals", normals, (T, nf, 3)), ("states", states, (T, nf)),
                           ("contact_bodies", contact_bodies, (T, nf)), ("finger_radii", finger_radii, (nf,))):
        if a.shape != shape or nf < 0:
            raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    dynamic = np.array([not m.is_static for m in models] + [False])
    # Contacts: a finger touching a dynamic body, with a normal.
    body_of = np.where((contact_bodies >= 0) & (contact_bodies < nb), contact_bodies, nb)
    n_len = np.sqrt(np.einsum("tfk,tfk->tf", normals, normals))
    held = dynamic[body_of] & (states > 0) & (n_len > _TINY)
    t_idx, f_idx = np.nonzero(held)
    b_idx = body_of[t_idx, f_idx]
    order = np.lexsort((f_idx, b_idx, t_idx))         # by snapshot, body, finger
    t_idx, f_idx, b_idx = t_idx[order], f_idx[order], b_idx[order]
    n_in = -normals[t_idx, f_idx] / n_len[t_idx, f_idx][:, None]
    point = god_objects[t_idx, f_idx] + finger_radii[f_idx][:, None] * n_in
    fn, ft = contact_forces(forces[t_idx, f_idx], normals[t_idx, f_idx])
    state = states[t_idx, f_idx].astype(np.int32)
    mu = cone_mu(models, state, b_idx)
    use = friction_use(ft, mu, fn)
    margin = mu * fn - ft
    with np.errstate(divide="ignore", invalid="ignore"):
        needed = np.where(fn > 0, ft / np.where(fn > 0, fn, 1.0), np.where(ft > 0, np.inf, 0.0))

    # Sets: runs of equal (snapshot, body).
    key = t_idx * (nb + 1) + b_idx
    starts = np.flatnonzero(np.concatenate(([True], key[1:] != key[:-1]))) if len(key) else np.zeros(0, np.int64)
    count = np.diff(np.append(starts, len(key)))
    set_t, set_b = t_idx[starts], b_idx[starts]
    set_of = np.repeat(np.arange(len(starts)), count)
    centers = centres_of_mass(models, poses[set_t])[np.arange(len(starts)), set_b]
    radii = np.array([m.radius for m in models] + [1.0])[set_b]
    # The wrench space's contacts: an area contact's patch corners, soft contacts' torsion.
    g_point, g_normal, g_mu, g_rho, owner = wrench_contacts(
        point, n_in, mu, f_idx, None if patches is None else patches[t_idx, f_idx], torsions)
    g_count = np.bincount(set_of[owner], minlength=len(starts)) if len(owner) else np.zeros(len(starts), np.int64)
    g_starts = np.concatenate(([0], np.cumsum(g_count)[:-1])).astype(np.int64) if len(starts) else g_count
    try:
        if memo is None:
            quality = core.grasp_quality_batch(g_point, g_normal, g_mu, g_count, centers, radii, edges=edges,
                                               volume=volume, reuse=reuse, torsion=g_rho)
            mu_min = _mu_min(core, g_point, g_normal, g_mu, quality, g_starts, g_count, centers, radii, edges,
                             reuse=reuse, torsion=g_rho) if with_mu_min else np.full(len(starts), np.nan)
        else:
            quality, mu_min = _remembered(core, memo, g_point, g_normal, g_mu, g_starts, g_count, centers, radii,
                                          edges, volume, reuse, g_rho)
    except ValueError as ex:
        # Name the snapshot and body whose contacts the core refused (the batch's message starts
        # with the set: "set 3: points: ...").
        message, i = str(ex), getattr(ex, "set_index", None)
        numbered = re.match(r"set (\d+): (.*)", message, re.S)
        if i is None and numbered:
            i, message = int(numbered.group(1)), numbered.group(2)
        if i is None or not 0 <= i < len(set_t):
            raise
        raise GraspAnalysisError(f"snapshot {int(set_t[i])}, body {models[set_b[i]].name}: {message}",
                                 int(set_t[i])) from None
    if len(starts):
        grip = np.add.reduceat(fn, starts)
        friction_needed = np.maximum.reduceat(needed, starts)
        min_margin = np.minimum.reduceat(margin, starts)
        at_min = np.flatnonzero(margin == min_margin[set_of])
        first_at_min = at_min[np.concatenate(([True], set_of[at_min][1:] != set_of[at_min][:-1]))]
        min_finger = f_idx[first_at_min].astype(np.int32)
    else:
        grip = friction_needed = min_margin = np.zeros(0)
        min_finger = np.zeros(0, np.int32)
    mass = np.array([m.mass for m in models] + [0.0])[set_b]
    a = np.zeros((len(starts), 3)) if accelerations is None else \
        np.asarray(accelerations, dtype=np.float64)[set_t, set_b]
    inertial = a - np.asarray(defaults.world("gravity") if gravity is None else gravity, dtype=np.float64)
    load = mass * np.sqrt(np.einsum("ij,ij->i", inertial, inertial))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(load > 0, grip / np.where(load > 0, load, 1.0), np.inf)
    return GraspTable(snapshot=set_t, body=set_b, count=count, first=starts, quality=quality, mu_min=mu_min,
                      friction_needed=friction_needed, min_slip_margin=min_margin, min_slip_finger=min_finger,
                      grip_force=grip, load_force=load, grip_ratio=ratio,
                      resisted_force=quality["epsilon"] * grip, center=centers, radius=radii,
                      finger=f_idx.astype(np.int32), point=point, normal=n_in, mu=mu, fn=fn, ft=ft,
                      friction_use=use, slip_margin=margin, state=state)


def body_grasps(table: GraspTable, sets=None) -> list:
    """BodyGrasp objects of rows ``sets`` (default all) of a GraspTable."""
    out = []
    for i in range(len(table.body)) if sets is None else sets:
        s, c = int(table.first[i]), int(table.count[i])
        q = table.quality[i]
        contacts = [FingerContact(int(table.finger[k]), table.point[k].copy(), table.normal[k].copy(),
                                  float(table.mu[k]), float(table.fn[k]), float(table.ft[k]),
                                  float(table.friction_use[k]), float(table.slip_margin[k]), int(table.state[k]))
                    for k in range(s, s + c)]
        out.append(BodyGrasp(
            body=int(table.body[i]), contacts=contacts, force_closure=bool(q["force_closure"]),
            torque_closure=bool(q["torque_closure"]), force_only_closure=bool(q["force_only_closure"]),
            epsilon=float(q["epsilon"]), volume=float(q["volume"]), weakest=np.array(q["weakest"], dtype=np.float64),
            mu_min=float(table.mu_min[i]), friction_needed=float(table.friction_needed[i]),
            min_slip_margin=float(table.min_slip_margin[i]), min_slip_finger=int(table.min_slip_finger[i]),
            grip_force=float(table.grip_force[i]), load_force=float(table.load_force[i]),
            grip_ratio=float(table.grip_ratio[i]), resisted_force=float(table.resisted_force[i]),
            center=table.center[i].copy(), radius=float(table.radius[i])))
    return out


def analyse(models, poses, god_objects, forces, normals, states, contact_bodies, finger_radii,
            accelerations=None, gravity=None, edges=8, volume=True, memo=None, reuse=False,
            patches=None, torsions=None) -> list:
    """The measures of one snapshot: one BodyGrasp per dynamic body with at least one finger in
    contact. Arrays as in the tick record: poses (nb, 7), god_objects, forces (the coupling
    spring force the finger exerts), normals (nf, 3), states, contact_bodies (nf,), finger_radii
    (nf,); accelerations (nb, 3) of the centres of mass, or None (0: the load is the weight).
    ``volume=False`` skips the grasp wrench space's volume (-1), the live view's choice; ``memo``,
    ``reuse``, ``patches`` (nf, corners, 2: the snapshot's) and ``torsions`` as in analyse_arrays."""
    one = lambda a, dtype=np.float64: np.asarray(a, dtype=dtype)[None]  # noqa: E731
    table = analyse_arrays(models, one(poses), one(god_objects), one(forces), one(normals),
                           one(states, np.int32), one(contact_bodies, np.int32), finger_radii,
                           None if accelerations is None else one(accelerations), gravity, edges, volume=volume,
                           memo=memo, reuse=reuse, patches=None if patches is None else one(patches, np.float32),
                           torsions=torsions)
    return body_grasps(table)


def analyse_recording(rec, every: int = 1, edges: int = 8, rows=None, chunk: int = 4096,
                      with_mu_min: bool = True, volume: bool = True) -> GraspTable:
    """The measures at the tick records of a Recording whose tick number is a multiple of
    ``every`` (all of them for 1), or at its records ``rows``, with the centres of mass's
    accelerations from the recorded velocities (each tick against the record before it: read
    with ``open_recording(path, every=every)`` or ``previous=True``, that is the tick before).
    Snapshot indices in the answer are rows of ``rec.ticks``. Raises ValueError for a
    recording without contact normals. A recording without ``patch`` (made before it) is analysed
    with point contacts (point_contacts_note says so)."""
    check_recording(rec)
    models = body_models(rec.header["scene"])
    torsions = finger_torsions(rec.header["scene"])
    with_patch = "patch" in (rec.ticks.dtype.names or ())
    radii = np.array([f["radius"] for f in rec.header["scene"]["fingers"]], dtype=np.float64)
    gravity = tuple(rec.header["scene"]["gravity"])
    if rows is not None:
        rows = np.asarray(rows, dtype=np.int64)
    elif every > 1:
        rows = np.flatnonzero(rec.ticks["tick"] % every == 0)
    else:
        rows = np.arange(len(rec.ticks))
    parts = []
    for lo in range(0, len(rows), chunk):
        r = rows[lo:lo + chunk]
        t = rec.ticks[r]
        acc = recorded_accelerations(models, rec.ticks, r)
        try:
            table = analyse_arrays(models, t["pose"], t["god_object"], t["force"], t["normal"], t["state"],
                                   t["contact"], radii, acc, gravity, edges, volume=volume,
                                   with_mu_min=with_mu_min, patches=t["patch"] if with_patch else None,
                                   torsions=torsions)
        except GraspAnalysisError as ex:
            if ex.snapshot is None:
                raise
            row = int(r[ex.snapshot])
            raise GraspAnalysisError(f"tick {int(rec.ticks['tick'][row])} (t = {rec.ticks['time'][row]:.6g} s), "
                                     f"{str(ex).split(', ', 1)[1]}", row) from None
        table.snapshot = r[table.snapshot]
        parts.append(table)
    if not parts:
        parts.append(analyse_arrays(models, np.zeros((0, len(models), 7)), *(np.zeros((0, len(radii), 3)),) * 3,
                                    np.zeros((0, len(radii)), np.int32), np.zeros((0, len(radii)), np.int32),
                                    radii, None, gravity, edges))
    return _concatenate(parts)


def _concatenate(parts) -> GraspTable:
    parts = [p for p in parts if len(p.body)] or parts[:1]
    if len(parts) == 1:
        return parts[0]
    fields = GraspTable.__dataclass_fields__
    offsets = np.cumsum([0] + [len(p.finger) for p in parts[:-1]])
    merged = {}
    for name in fields:
        arrays = [getattr(p, name) for p in parts]
        if name == "first":
            arrays = [a + o for a, o in zip(arrays, offsets)]
        merged[name] = np.concatenate(arrays)
    return GraspTable(**merged)


# Animated custom properties of a bake, per dynamic body (docs/analysis.md): name -> (the value
# of a GraspTable row, the value while no finger holds the body: the measure of no contacts).
# A value with no finite answer (mu_min when no friction up to MU_MAX closes the grasp,
# grip/load at zero load) is keyed NONE.
NONE = -1.0
BAKED = {
    "gl_held": (lambda t: np.ones(len(t.body)), 0.0),
    "gl_closure": (lambda t: t.quality["force_closure"].astype(np.float64), 0.0),
    "gl_epsilon": (lambda t: t.quality["epsilon"], 0.0),
    "gl_mu_min": (lambda t: t.mu_min, NONE),
    "gl_slip_margin": (lambda t: t.min_slip_margin, 0.0),
    "gl_grip_load": (lambda t: t.grip_ratio, 0.0),
}


def body_series(table: GraspTable, rows, num_bodies: int) -> dict:
    """BAKED's measures per body at the records ``rows`` (in order) of the recording the table
    was made of: name -> (len(rows), num_bodies)."""
    rows = np.asarray(rows, dtype=np.int64)
    if np.any(rows[1:] < rows[:-1]):
        raise ValueError("rows: expected the records in order")
    where = np.searchsorted(rows, table.snapshot)
    first = np.searchsorted(rows, rows)     # a repeated row (two frames on one tick) takes the first's
    out = {}
    for name, (value, idle) in BAKED.items():
        series = np.full((len(rows), num_bodies), idle)
        v = np.asarray(value(table), dtype=np.float64)
        series[where, table.body] = np.where(np.isfinite(v), v, NONE)
        out[name] = series[first]
    return out


def check_recording(rec) -> None:
    """A recording analysis can read: its ticks carry the contact normals (recordings made by
    Grasp Lab versions before them do not)."""
    names = rec.ticks.dtype.names or ()
    if "normal" not in names:
        version = rec.header.get("versions", {}).get("grasp_lab", "unknown")
        raise ValueError(f"{rec.path}: made by an older version of Grasp Lab ({version}): its ticks carry no "
                         f"contact normals, which the analysis needs; record the session again")


def point_contacts_note(rec):
    """A line for a recording whose convex fingers are analysed as point contacts (made before the
    tick record's ``patch``), else None."""
    convex = [f["name"] for f in rec.header["scene"]["fingers"] if f.get("points") is not None]
    if convex and "patch" not in (rec.ticks.dtype.names or ()):
        return (f"note: recorded before contact patches: {', '.join(convex)} analysed as point contacts "
                f"(the pressure centroid), without their area contacts' pressure torque")
    return None


def summary(table: GraspTable, times, body_names, finger_names, period: float) -> list:
    """Lines for the command line, per body: the time held and in force closure (samples times
    the analysis period), the weakest moment (out of closure: the first time; else the
    smallest epsilon, and when) and the finger closest to slipping (smallest slip margin)."""
    lines = []
    closure = table.quality["force_closure"]
    eps = table.quality["epsilon"]
    for b in np.unique(table.body):
        rows = np.flatnonzero(table.body == b)
        held = len(rows) * period
        closed = rows[closure[rows]]
        lines.append(f"{body_names[b]}: held {held:.3f} s, in force closure {len(closed) * period:.3f} s "
                     f"({100.0 * len(closed) / len(rows):.1f} % of the time held)")
        open_rows = rows[~closure[rows]]
        if len(open_rows):
            lines.append(f"  weakest: out of force closure (epsilon 0) for {len(open_rows) * period:.3f} s, "
                         f"first at t = {times[open_rows[0]]:.3f} s")
        if len(closed):
            k = closed[np.argmin(eps[closed])]
            lines.append(f"  weakest in closure: t = {times[k]:.3f} s, epsilon {eps[k]:.6g} (resists "
                         f"{table.resisted_force[k]:.4g} N in its weakest direction)")
        k = rows[np.argmin(table.min_slip_margin[rows])]
        f = int(table.min_slip_finger[k])
        lines.append(f"  closest to slipping: {finger_names[f] if f >= 0 else '-'} at t = {times[k]:.3f} s, "
                     f"slip margin {table.min_slip_margin[k]:.4g} N")
    if not lines:
        lines.append("no finger touched a dynamic body")
    return lines
