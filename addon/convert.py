"""Blender scene -> ``engine.scene.SceneDesc``.

Reads evaluated meshes (modifiers applied) and world matrices (scale, shear and
parenting applied). Each body's frame is its object's world matrix with scale and
shear removed; mesh points are expressed in that frame. ``BodyLink`` remembers how
to turn a simulated rigid pose back into the object's world matrix.
"""
from __future__ import annotations

from dataclasses import dataclass

import bpy
import numpy as np
from mathutils import Matrix, Quaternion

from . import hands
from .engine.decompose import decompose
from .engine.scene import BodyDesc, FingerDesc, MeshData, SceneDesc, SceneError


@dataclass
class BodyLink:
    """Maps a body's simulated pose back to its Blender object."""
    name: str
    static: bool
    frame_to_world: Matrix      # F0^-1 @ M0: object matrix relative to its body frame

    def matrix_world(self, position, orientation) -> Matrix:
        f = Quaternion(orientation).to_matrix().to_4x4()
        f.translation = position
        return f @ self.frame_to_world


def _frame(m: Matrix):
    """Rigid frame (translation, unit quaternion) of a world matrix."""
    q = m.to_quaternion().normalized()
    return m.translation.copy(), q


def _np_matrix(m: Matrix) -> np.ndarray:
    return np.array(m, dtype=np.float64)


def mesh_in_frame(obj, depsgraph, frame_t, frame_q):
    """Evaluated mesh of ``obj`` as MeshData in the rigid frame (t, q)."""
    ev = obj.evaluated_get(depsgraph)
    me = ev.to_mesh()
    try:
        me.calc_loop_triangles()
        nv, nt = len(me.vertices), len(me.loop_triangles)
        co = np.empty(nv * 3, dtype=np.float32)
        me.vertices.foreach_get("co", co)
        tri = np.empty(nt * 3, dtype=np.int32)
        me.loop_triangles.foreach_get("vertices", tri)
    finally:
        ev.to_mesh_clear()
    m = _np_matrix(ev.matrix_world)
    r = _np_matrix(frame_q.to_matrix())
    world = co.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    local = (world - np.array(frame_t)) @ r
    tri = tri.reshape(-1, 3).astype(np.int64)
    if np.linalg.det(m[:3, :3]) < 0:      # mirrored by a negative scale: keep outward normals
        tri = tri[:, ::-1]
    return MeshData(local, tri, source=obj.name)


def _dynamic_ancestor(obj):
    p = obj.parent
    while p is not None:
        if p.grasp_lab.role == "DYNAMIC":
            return p
        p = p.parent
    return None


def scene_objects(context):
    """Objects of the view layer with a role, bodies and fingers (with the Finger bones of its
    armatures: hands.BoneFinger), sorted for determinism."""
    bodies, fingers = [], []
    for obj in context.view_layer.objects:
        role = obj.grasp_lab.role
        if role in {"DYNAMIC", "STATIC"}:
            bodies.append(obj)
        elif role == "FINGER":
            fingers.append(obj)
    fingers += hands.finger_bones(context)
    bodies.sort(key=lambda o: o.name)
    fingers.sort(key=lambda o: (o.grasp_lab.channel, o.name))
    return bodies, fingers


def body_desc(obj, depsgraph) -> tuple:
    gl = obj.grasp_lab
    if obj.grasp_lab.role == "DYNAMIC" and (anc := _dynamic_ancestor(obj)) is not None:
        raise SceneError(obj.name, f'dynamic body is parented to dynamic body "{anc.name}"; '
                                   f"unparent it or make it a child part (shape: Child Parts)")
    t, q = _frame(obj.matrix_world)
    if obj.type not in {"MESH", "EMPTY"}:
        raise SceneError(obj.name, f"a body must be a mesh object, or an empty with child mesh "
                                   f"parts (this is a {obj.type.lower()} object)")
    own = None
    if obj.type == "MESH":
        own = mesh_in_frame(obj, depsgraph, t, q)
        if len(own.triangles) == 0:
            own = None
    meshes = []
    if gl.shape == "CHILDREN":
        if own is not None:
            meshes.append(own)
        for child in sorted(obj.children, key=lambda o: o.name):
            if child.type == "MESH" and child.grasp_lab.role == "NONE":
                md = mesh_in_frame(child, depsgraph, t, q)
                if len(md.triangles):
                    meshes.append(md)
        if not meshes:
            raise SceneError(obj.name, "shape is Child Parts but it has no child mesh objects "
                                       "(with role None)")
        parts = [m.vertices for m in meshes]
    else:
        if own is None:
            raise SceneError(obj.name, "has no mesh faces to collide with")
        meshes.append(own)
        if gl.shape == "AUTO":
            parts = decompose(own.vertices, own.triangles)
            if not parts:
                raise SceneError(obj.name, "automatic decomposition found no convex parts")
        else:
            parts = [own.vertices]
    desc = BodyDesc(
        name=obj.name, static=gl.role == "STATIC", parts=parts, meshes=meshes,
        position=np.array(t, dtype=np.float64), orientation=np.array(q, dtype=np.float64),
        mass=gl.mass if gl.mass_mode == "MASS" else None, density=gl.density,
        mu_s=gl.mu_s, mu_d=gl.mu_d, viscosity=gl.viscosity)
    link = BodyLink(name=obj.name, static=desc.static,
                    frame_to_world=_frame_matrix(t, q).inverted() @ obj.matrix_world)
    return desc, link


def _frame_matrix(t, q) -> Matrix:
    f = q.to_matrix().to_4x4()
    f.translation = t
    return f


def finger_desc(obj, depsgraph) -> FingerDesc:
    """An Empty is a fingertip sphere of Radius (with Soft Tip Radius, a soft fingertip: its
    ``torsion``); a mesh is a convex finger of its mesh's hull (a pad, a palm: docs/physics.md
    "Area contacts") in its rigid frame, Radius not used (its torsion must stay 0: prepare says so);
    a Finger bone a capsule (docs/hands.md)."""
    if isinstance(obj, hands.BoneFinger):
        return obj.desc()
    gl = obj.grasp_lab
    desc = FingerDesc(name=obj.name, position=np.array(obj.matrix_world.translation, dtype=np.float64),
                      radius=gl.radius, stiffness=gl.stiffness, damping=gl.damping, channel=gl.channel,
                      renderer=gl.renderer.lower(), cursor_mass=gl.cursor_mass, torsion=gl.torsion)
    if obj.type == "MESH":
        t, q = _frame(obj.matrix_world)
        mesh = mesh_in_frame(obj, depsgraph, t, q)
        if len(mesh.triangles) == 0:
            raise SceneError(obj.name, "a mesh finger needs faces (its hull is the finger); "
                                       "use an Empty for a fingertip sphere")
        desc.points = mesh.vertices
        desc.orientation = np.array((q.w, q.x, q.y, q.z), dtype=np.float64)
        desc.radius = 0.0
    return desc


def scene_description(context):
    """(SceneDesc, [BodyLink], [finger objects]) of the current view layer. Raises SceneError."""
    scene = context.scene
    s = scene.grasp_lab
    depsgraph = context.evaluated_depsgraph_get()
    bodies, fingers = scene_objects(context)
    desc = SceneDesc(gravity=tuple(s.gravity), gyroscopic=s.gyroscopic,
                     haptic_rate=s.haptic_rate, display_rate=s.display_rate)
    links = []
    for obj in bodies:
        b, link = body_desc(obj, depsgraph)
        desc.bodies.append(b)
        links.append(link)
    for obj in fingers:
        desc.fingers.append(finger_desc(obj, depsgraph))
    return desc, links, fingers


def finger_rotation(obj):
    """A finger object's rigid world rotation (w, x, y, z) as the core takes it: a mesh's, the
    identity for an Empty (a sphere has none); a Finger bone's."""
    if obj.type not in {"MESH", "BONE"}:
        return (1.0, 0.0, 0.0, 0.0)
    q = _frame(obj.matrix_world)[1]
    return (q.w, q.x, q.y, q.z)


def sample_fingers(context, fingers, frame_start: int, frame_end: int, on_frame=None):
    """World poses of the finger objects at every frame (the scripted device).

    Returns (times relative to frame_start, positions (n_frames, n_fingers, 3), orientations
    (n_frames, n_fingers, 4) w x y z: a mesh finger's rigid world rotation, identity for an
    Empty, whose sphere has none). ``on_frame()``: called at every frame too (the hands sample
    their whole armatures). Leaves the scene at ``frame_start``.
    """
    scene = context.scene
    fps = scene.render.fps / scene.render.fps_base
    frames = list(range(frame_start, max(frame_end, frame_start) + 1))
    pos = np.zeros((len(frames), len(fingers), 3))
    quat = np.zeros((len(frames), len(fingers), 4))
    for i, f in enumerate(frames):
        scene.frame_set(f)
        for j, obj in enumerate(fingers):
            pos[i, j] = obj.matrix_world.translation
            quat[i, j] = finger_rotation(obj)
        if on_frame is not None:
            on_frame()
    scene.frame_set(frame_start)
    bad = np.argwhere(~np.isfinite(pos).all(axis=2))
    if len(bad):
        i, j = bad[0]
        raise SceneError(fingers[j].name, f"fingertip position at frame {frames[i]} is not finite "
                                          f"({tuple(pos[i, j])}; {len(bad)} frame-finger samples are "
                                          f"not): fix its animation keys")
    times = (np.array(frames, dtype=np.float64) - frame_start) / fps
    return times, pos, quat
