"""Hands: armature bones as fingers (bpy-free part; docs/hands.md).

A Finger bone is a capsule from its head to its tail with its radius. The core takes it as a
convex finger: two small triangles (circumradius ``CAPSULE_CORE_FRACTION`` of the radius) at
the head and at the tail, turned 60 degrees to each other, inflated by the radius. That shape
contains the capsule and lies within 2 % of the radius of it, so the capsule is never deeper in
a body than the core's finger. Its HIP is the bone's pose: position the head, orientation the
bone's (Blender's bone frame: +Y from head to tail).

The rendered hand. A Finger bone's *god-pose* is its input pose moved out of the body it
touches along the contact normal the core reports, until the finger lies on the body's
supporting plane along that normal (``god_pose``): for a face that is the face itself, and the
convex body lies wholly on the other side, so the god-pose never overlaps it. The rendered
armature is then solved root first by a *chain correction* (``rendered_matrices``): a root Finger
bone sits at its god-pose; a chain of connected Finger bones (a finger's phalanges) starts where
its rendered parent carries its first joint and is solved by FABRIK from the god-poses' joints
toward the last bone's god-pose tail, its last pass from that joint: every bone keeps its length,
every joint is connected exactly, and the bones turn (each keeping its god-pose's roll) to put the
fingertip where its god-pose is; non-Finger bones follow the input relative to their rendered
parent.

The names shared with the Add Hand builder and the bake: the rendered armature of input
armature ``A`` is the object ``A Rendered`` with the custom property
``grasp_lab_rendered_of = "A"``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .scene import FingerDesc, SceneError

RENDERED_SUFFIX = " Rendered"
RENDERED_OF_PROPERTY = "grasp_lab_rendered_of"
# The core's finger for a capsule: triangles of this fraction of the radius at head and tail.
CAPSULE_CORE_FRACTION = 0.02
MIN_BONE_LENGTH = 1e-4      # m: a shorter bone is "zero length"
SCALE_TOLERANCE = 1e-5      # relative: a bone's world scale must be 1 within this
CHAIN_ITERATIONS = 100      # most FABRIK passes of the chain correction (each keeps the joints exact)
CHAIN_TOLERANCE = 1e-5      # m: a fingertip this near its god-pose's is there (well under the 0.5 mm asked)


def rendered_name(armature_name: str) -> str:
    """The object name of the rendered armature of ``armature_name``."""
    return armature_name + RENDERED_SUFFIX


def finger_name(armature_name: str, bone_name: str) -> str:
    """A Finger bone's name as a finger of the scene (recordings, the HUD)."""
    return f"{armature_name}:{bone_name}"


def capsule_points(length: float, radius: float) -> np.ndarray:
    """The core finger's hull points (6, 3) in the bone frame: head at the origin, +Y to the tail."""
    e = CAPSULE_CORE_FRACTION * radius
    out = []
    for y, start in ((0.0, 0.0), (length, np.pi / 3)):
        for k in range(3):
            a = start + k * 2 * np.pi / 3
            out.append((e * np.cos(a), y, e * np.sin(a)))
    return np.array(out, dtype=np.float64)


def _scale_problem(matrix: np.ndarray) -> str:
    scales = np.linalg.norm(np.asarray(matrix, dtype=np.float64)[:3, :3], axis=0)
    if not np.all(np.isfinite(scales)):
        return "its world matrix is not finite"
    if np.ptp(scales) > SCALE_TOLERANCE * max(scales.max(), 1e-12):
        return (f"has a non-uniform scale ({', '.join(f'{s:.4g}' for s in scales)}): a capsule needs one "
                f"length unit; apply the scale (Ctrl+A) of the armature and clear the bone's pose scale")
    if abs(scales[0] - 1.0) > SCALE_TOLERANCE:
        return (f"has a scale of {scales[0]:.4g}: the bone's length and radius would not be what they say; "
                f"apply the armature's scale (Ctrl+A) and clear the bone's pose scale")
    return ""


def bone_finger_desc(armature_name: str, bone_name: str, matrix, length: float, *, radius: float,
                     stiffness: float, damping: float, channel: int,
                     rendered_of: str = "") -> FingerDesc:
    """A Finger bone as a convex finger, or a SceneError naming the bone. ``matrix``: the pose
    bone's world matrix (4x4: armature world @ pose matrix); ``length``: head to tail in the
    pose (m); ``rendered_of``: the armature is the rendered armature of that one (output only)."""
    name = finger_name(armature_name, bone_name)
    if rendered_of:
        raise SceneError(name, f'is a Finger bone of "{armature_name}", the rendered armature of '
                               f'"{rendered_of}": a rendered hand is output only; set the bone\'s role to None '
                               f'(the input hand is "{rendered_of}")')
    if not (np.isfinite(length) and length >= MIN_BONE_LENGTH):
        raise SceneError(name, f"Finger bone has zero length ({length:.3g} m, at least {MIN_BONE_LENGTH:g} m): "
                               f"give the bone a length or set its role to None")
    m = np.asarray(matrix, dtype=np.float64)
    if problem := _scale_problem(m):
        raise SceneError(name, problem)
    if not (np.isfinite(radius) and radius > 0):
        raise SceneError(name, f"Finger bone has a zero radius ({radius:.3g} m): a capsule needs a radius > 0")
    return FingerDesc(name=name, position=m[:3, 3].copy(), radius=float(radius), stiffness=float(stiffness),
                      damping=float(damping), channel=int(channel), points=capsule_points(length, radius),
                      orientation=quat_from_matrix(m[:3, :3]))


# --------------------------------------------------------------------------- rotations

def quat_from_matrix(r) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (3x3; a scaled one is normalised)."""
    r = np.asarray(r, dtype=np.float64)[:3, :3]
    r = r / np.linalg.norm(r, axis=0)
    t = np.trace(r)
    if t > 0:
        s = 2.0 * np.sqrt(1.0 + t)
        q = (0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s)
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        q = np.zeros(4)
        q[0] = (r[k, j] - r[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + k] = (r[k, i] + r[i, k]) / s
    q = np.asarray(q, dtype=np.float64)
    return q / np.linalg.norm(q)


def matrix_from_quat(q) -> np.ndarray:
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def pose_matrix(position, orientation) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = matrix_from_quat(orientation)
    m[:3, 3] = position
    return m


def swing(a, b) -> np.ndarray:
    """The smallest rotation (3x3) taking unit vector ``a`` to unit vector ``b``."""
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    if c < -1.0 + 1e-12:        # opposite: half a turn about any axis normal to a
        axis = np.cross(a, (1.0, 0.0, 0.0) if abs(a[0]) < 0.9 else (0.0, 1.0, 0.0))
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


# --------------------------------------------------------------------------- god-poses

def body_support(parts, pose, normal) -> float:
    """max over the body's points of x . normal, the body at ``pose`` (x y z qw qx qy qz)."""
    pts = np.concatenate([np.asarray(p, dtype=np.float64) for p in parts])
    world = pts @ matrix_from_quat(pose[3:]).T + np.asarray(pose[:3])
    return float(np.max(world @ normal))


def god_pose(hip, orientation, points, radius, normal, support) -> tuple:
    """The finger at its input pose (``hip``, ``orientation``) moved along the contact ``normal``
    (out of the body) until its hull inflated by ``radius`` lies beyond the body's supporting plane
    ``x . normal = support``. Returns (position, distance moved, m)."""
    n = np.asarray(normal, dtype=np.float64)
    norm = np.linalg.norm(n)
    hip = np.asarray(hip, dtype=np.float64)
    if not norm > 0:
        return hip, 0.0
    n = n / norm
    world = np.asarray(points) @ matrix_from_quat(orientation).T + hip
    depth = support - (float(np.min(world @ n)) - radius)
    if not depth > 0:
        return hip, 0.0
    return hip + depth * n, depth


def god_matrices(inputs: dict, snap, bodies, points: dict, radii: dict) -> dict:
    """The god-poses (4x4 world matrices) of Finger bones: ``inputs`` scene finger index -> the
    bone's input world matrix (its orientation; the position is the snapshot's HIP), ``snap`` a
    runner Snapshot (HIPs, contacts, normals, body poses), ``bodies`` the scene's BodyDescs (their
    convex parts), ``points``/``radii`` per finger: its hull points and radius."""
    out = {}
    for f, m in inputs.items():
        q = quat_from_matrix(m)
        position = np.asarray(snap.hips[f], dtype=np.float64)
        b = int(snap.contacts[f])
        n = np.asarray(snap.normals[f], dtype=np.float64)
        if b >= 0 and np.linalg.norm(n) > 0:
            n = n / np.linalg.norm(n)
            support = body_support(bodies[b].parts, snap.poses[b], n)
            position, _ = god_pose(position, q, points[f], radii[f], n, support)
        out[f] = pose_matrix(position, q)
    return out


@dataclass
class HandRig:
    """One input armature: its bones parents first, and which are fingers of the scene."""
    armature: str
    bones: list                     # bone names, every parent before its children
    parents: list                   # index of each bone's parent in ``bones``, -1 for a root
    lengths: np.ndarray             # (n,) rest length, m
    rest: np.ndarray                # (n, 4, 4) each bone's rest matrix in armature space (matrix_local)
    fingers: list = field(default_factory=list)     # per bone: index in the scene's fingers, -1 none
    connected: list = field(default_factory=list)   # per bone: its head is its parent's tail

    def finger_bones(self) -> list:
        return [i for i, f in enumerate(self.fingers) if f >= 0]


def _chain(rig: HandRig, first: int) -> list:
    """``first`` and the Finger bones that continue it: each the only child of the one before,
    connected to it (its head at the parent's tail)."""
    children = {}
    for k, p in enumerate(rig.parents):
        children.setdefault(p, []).append(k)
    chain = [first]
    while len(kids := children.get(chain[-1], [])) == 1 and rig.connected[kids[0]] and rig.fingers[kids[0]] >= 0:
        chain.append(kids[0])
    return chain


def solve_chain(anchor, lengths, heads, tip, iterations: int = CHAIN_ITERATIONS, tolerance: float = CHAIN_TOLERANCE):
    """Joints (n + 1, 3) of a chain of bones of ``lengths`` from ``anchor`` toward ``tip``,
    starting from the joints ``heads`` (n, 3; the first is moved to the anchor): FABRIK (Aristidou
    & Lasenby 2011), its last pass from the anchor, so every bone has its length and every joint is
    connected exactly; the tip is within ``tolerance`` of ``tip`` when the chain reaches it.
    Plain floats: a chain is a few 3-vectors, where numpy's per-call cost is most of the work."""
    lengths = [float(v) for v in lengths]
    anchor = [float(v) for v in anchor]
    tip = [float(v) for v in tip]
    n = len(lengths)
    reach = [t - a for t, a in zip(tip, anchor)]
    dist = math.sqrt(sum(v * v for v in reach))
    if dist >= sum(lengths):
        # Out of reach: straight toward it (FABRIK's own answer, without its slow approach to it).
        direction = [v / dist for v in reach]
        out, along = [anchor], 0.0
        for length in lengths:
            along += length
            out.append([a + along * d for a, d in zip(anchor, direction)])
        return np.array(out)
    joints = [anchor] + [[float(v) for v in h] for h in np.asarray(heads)[1:]] + [tip]

    def toward(a, b, length):
        d = [q - p for p, q in zip(a, b)]
        norm = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        if norm < 1e-15:
            return [a[0], a[1] + length, a[2]]
        s = length / norm
        return [a[0] + d[0] * s, a[1] + d[1] * s, a[2] + d[2] * s]

    for _ in range(iterations):
        joints[n] = tip
        for k in range(n - 1, -1, -1):
            joints[k] = toward(joints[k + 1], joints[k], lengths[k])
        joints[0] = anchor
        for k in range(n):
            joints[k + 1] = toward(joints[k], joints[k + 1], lengths[k])
        if math.dist(joints[n], tip) < tolerance:
            break
    return np.array(joints)


def rigid_inverse(m) -> np.ndarray:
    """The inverse of a rigid 4x4 matrix (rotation and translation)."""
    m = np.asarray(m, dtype=np.float64)
    out = np.eye(4)
    out[:3, :3] = m[:3, :3].T
    out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return out


def rendered_matrices(rig: HandRig, inputs, gods: dict) -> np.ndarray:
    """The rendered armature's bone world matrices (n, 4, 4) from the input ones (``inputs``,
    (n, 4, 4), unit scale) and the Finger bones' god-poses (``gods``: scene finger index -> 4x4
    world matrix): the chain correction of the module's doc."""
    inputs = np.asarray(inputs, dtype=np.float64)
    out = np.empty_like(inputs)
    done = set()
    y = np.array([0.0, 1.0, 0.0])
    for i, p in enumerate(rig.parents):
        if i in done:
            continue
        # Under a parent where the input is (nothing corrected above): the input itself, exactly.
        carried = inputs[i] if p < 0 or np.array_equal(out[p], inputs[p]) else \
            out[p] @ rigid_inverse(inputs[p]) @ inputs[i]
        f = rig.fingers[i]
        if f < 0:
            out[i] = carried
            continue
        if p < 0:
            out[i] = gods[f]
            continue
        chain = _chain(rig, i)
        g = [gods[rig.fingers[k]] for k in chain]
        lengths = rig.lengths[chain]
        tip = g[-1][:3, :3] @ (y * lengths[-1]) + g[-1][:3, 3]
        joints = solve_chain(carried[:3, 3], lengths, [m[:3, 3] for m in g], tip)
        for k, m, head, tail in zip(chain, g, joints[:-1], joints[1:]):
            r = m[:3, :3]
            r = swing(r @ y, (tail - head) / np.linalg.norm(tail - head)) @ r
            out[k] = np.eye(4)
            out[k][:3, :3] = r
            out[k][:3, 3] = head
            done.add(k)
    return out


def bone_ends(matrices, lengths) -> tuple:
    """(heads, tails), (n, 3) each, of bones at world ``matrices`` (n, 4, 4)."""
    m = np.asarray(matrices)
    heads = m[:, :3, 3]
    return heads, heads + m[:, :3, 1] * np.asarray(lengths)[:, None]


def corrections(inputs, rendered, lengths) -> np.ndarray:
    """Per bone: how far its rendered pose is from its input pose, m (the larger of the heads'
    and the tails' distances)."""
    hi, ti = bone_ends(inputs, lengths)
    hr, tr = bone_ends(rendered, lengths)
    return np.maximum(np.linalg.norm(hi - hr, axis=1), np.linalg.norm(ti - tr, axis=1))


def local_bases(rig: HandRig, armature_world, matrices) -> np.ndarray:
    """Pose bones' ``matrix_basis`` (n, 4, 4) that put the bones at world ``matrices`` (n, 4, 4),
    the armature object at ``armature_world``, with Blender's default inheritance (rotation and
    scale inherited, local location)."""
    pose = rigid_inverse(armature_world) @ np.asarray(matrices)
    out = np.empty_like(pose)
    for i, p in enumerate(rig.parents):
        if p < 0:
            rest_in_pose = rig.rest[i]
        else:
            rest_in_pose = pose[p] @ rigid_inverse(rig.rest[p]) @ rig.rest[i]
        out[i] = rigid_inverse(rest_in_pose) @ pose[i]
    return out
