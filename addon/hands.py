"""Hands in Blender (docs/hands.md): the Finger bones of armatures as fingers of the scene, and
the rendered armature ``<armature> Rendered`` whose bones sit at their god-poses, updated at
every display update and keyed by the bake. The geometry is engine/hands.py's (no bpy)."""
from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from . import anim
from .engine import hands as eh
from .engine.scene import SceneError

CORRECTION_PROPERTY = "gl_correction_mm"    # per rendered pose bone: input to rendered, mm


class BoneFinger:
    """A Finger bone as the session sees a finger object: a name, a ``grasp_lab`` (the bone's
    properties), a ``matrix_world`` (its pose: head, bone axes) it can read and set."""
    type = "BONE"

    def __init__(self, armature, bone_name: str):
        self.armature = armature
        self.bone_name = bone_name
        self.name = eh.finger_name(armature.name, bone_name)

    @property
    def pose_bone(self):
        return self.armature.pose.bones[self.bone_name]

    @property
    def grasp_lab(self):
        return self.pose_bone.grasp_lab

    @property
    def matrix_world(self) -> Matrix:
        return self.armature.matrix_world @ self.pose_bone.matrix

    @matrix_world.setter
    def matrix_world(self, m):
        self.pose_bone.matrix = self.armature.matrix_world.inverted() @ m

    def length(self) -> float:
        pb = self.pose_bone
        return float((pb.tail - pb.head).length)

    def desc(self):
        gl = self.grasp_lab
        return eh.bone_finger_desc(self.armature.name, self.bone_name, np.array(self.matrix_world),
                                   self.length(), radius=gl.radius, stiffness=gl.stiffness,
                                   damping=gl.damping, channel=gl.channel,
                                   rendered_of=str(self.armature.get(eh.RENDERED_OF_PROPERTY, "")))


def bone_finger_named(name: str):
    """The Finger bone a recording names ``<armature>:<bone>`` (either may hold a colon), or None."""
    for i, ch in enumerate(name):
        if ch == ":":
            arm = bpy.data.objects.get(name[:i])
            if arm is not None and arm.type == "ARMATURE" and name[i + 1:] in arm.pose.bones:
                return BoneFinger(arm, name[i + 1:])
    return None


def finger_bones(context) -> list:
    """Every Finger bone of every armature of the view layer (armatures by name, bones in order)."""
    out = []
    for obj in sorted(context.view_layer.objects, key=lambda o: o.name):
        if obj.type == "ARMATURE" and obj.pose is not None:
            out += [BoneFinger(obj, pb.name) for pb in obj.pose.bones if pb.grasp_lab.role == "FINGER"]
    return out


def _parents_first(arm) -> list:
    order, seen = [], set()

    def visit(bone):
        if bone.name in seen:
            return
        if bone.parent is not None:
            visit(bone.parent)
        seen.add(bone.name)
        order.append(bone)
    for b in arm.data.bones:
        visit(b)
    return order


def rig_of(arm, finger_index: dict) -> eh.HandRig:
    """The armature's bones as an engine HandRig; ``finger_index``: bone name -> scene finger."""
    bones = _parents_first(arm)
    index = {b.name: i for i, b in enumerate(bones)}
    return eh.HandRig(armature=arm.name, bones=[b.name for b in bones],
                      parents=[index[b.parent.name] if b.parent is not None else -1 for b in bones],
                      lengths=np.array([b.length for b in bones]),
                      rest=np.array([np.array(b.matrix_local) for b in bones]),
                      fingers=[finger_index.get(b.name, -1) for b in bones],
                      connected=[b.parent is not None and (b.use_connect or (b.head_local - b.parent.tail_local).length
                                                           < 1e-6) for b in bones])


def _link_like(obj, like) -> None:
    for coll in like.users_collection:
        if obj.name not in coll.objects:
            coll.objects.link(obj)


def ensure_rendered(arm):
    """The rendered armature of ``arm`` (made on first use: a copy sharing its bones, no
    animation, no constraints, no Finger roles) and rendered copies of the meshes skinned to it."""
    name = eh.rendered_name(arm.name)
    out = bpy.data.objects.get(name)
    if out is not None and out.get(eh.RENDERED_OF_PROPERTY) != arm.name:
        raise SceneError(name, f'is in the way of the rendered armature of "{arm.name}" (an object of that name '
                               f'that is not its rendered armature); rename it')
    if out is None:
        out = arm.copy()
        out.name = name
        out.animation_data_clear()
        out[eh.RENDERED_OF_PROPERTY] = arm.name
        _link_like(out, arm)
    if out.type != "ARMATURE":
        raise SceneError(name, "the rendered armature is not an armature object; delete it")
    out.data = arm.data
    out.show_in_front = True
    for pb in out.pose.bones:
        pb.grasp_lab.role = "NONE"
        pb.rotation_mode = "QUATERNION"
        for c in list(pb.constraints):
            pb.constraints.remove(c)
        if CORRECTION_PROPERTY not in pb:
            pb[CORRECTION_PROPERTY] = 0.0
    for mesh in [o for o in bpy.data.objects if o.type == "MESH" and not o.get(eh.RENDERED_OF_PROPERTY)]:
        if any(m.type == "ARMATURE" and m.object == arm for m in mesh.modifiers):
            _ensure_rendered_mesh(mesh, arm, out)
    return out


def _ensure_rendered_mesh(mesh, arm, rendered):
    name = eh.rendered_name(mesh.name)
    copy = bpy.data.objects.get(name)
    if copy is None:
        copy = mesh.copy()              # shares the mesh data: the same skin, weights and materials
        copy.name = name
        copy.animation_data_clear()
        copy[eh.RENDERED_OF_PROPERTY] = mesh.name
        _link_like(copy, mesh)
    copy.grasp_lab.role = "NONE"
    for m in copy.modifiers:
        if m.type == "ARMATURE" and (m.object is None or m.object in (arm, rendered)):
            m.object = rendered
    if mesh.parent == arm:
        copy.parent = rendered
        copy.matrix_parent_inverse = mesh.matrix_parent_inverse.copy()
    return copy


def _bone_matrices(arm, rig) -> np.ndarray:
    mw = np.array(arm.matrix_world)
    return np.array([mw @ np.array(arm.pose.bones[b].matrix) for b in rig.bones])


class Hand:
    """One input armature with Finger bones and its rendered armature."""

    def __init__(self, arm, rig, finger_desc):
        self.arm = arm
        self.rig = rig
        self.rendered = ensure_rendered(arm)
        self.points = {f: finger_desc[f].points for f in rig.fingers if f >= 0}
        self.radii = {f: finger_desc[f].radius for f in rig.fingers if f >= 0}
        self.live = False           # posed live (not animated): read at every update, not sampled
        self.samples = []           # per sampled frame: (armature world 4x4, bone world matrices)
        self.corrections = np.zeros(len(rig.bones))
        self.baked = []             # per applied frame: (frame, object transform, bases, corrections)

    def finger_indices(self) -> list:
        """The scene's fingers that are this hand's bones."""
        return [f for f in self.rig.fingers if f >= 0]

    def sample(self):
        self.samples.append((np.array(self.arm.matrix_world), _bone_matrices(self.arm, self.rig)))

    def update(self, snap, bodies, sample_index, bake: bool, frame):
        """The rendered armature at the snapshot's god-poses; ``sample_index``: the input pose
        sampled at that frame (None: the armature as it is now, live)."""
        if sample_index is None:
            arm_world, inputs = np.array(self.arm.matrix_world), _bone_matrices(self.arm, self.rig)
        else:
            arm_world, inputs = self.samples[min(sample_index, len(self.samples) - 1)]
        gods = eh.god_matrices({self.rig.fingers[i]: inputs[i] for i in self.rig.finger_bones()}, snap, bodies,
                               self.points, self.radii)
        rendered = eh.rendered_matrices(self.rig, inputs, gods)
        self.corrections = eh.corrections(inputs, rendered, self.rig.lengths)
        bases = eh.local_bases(self.rig, arm_world, rendered)
        out = self.rendered
        out.matrix_world = Matrix(arm_world.tolist())
        for name, basis, c in zip(self.rig.bones, bases, self.corrections):
            pb = out.pose.bones[name]
            pb.matrix_basis = Matrix(basis.tolist())
            pb[CORRECTION_PROPERTY] = float(c * 1e3)
        if bake:
            self.baked.append((frame, anim.read_transform(out), bases, self.corrections.copy()))

    def hud_line(self) -> str:
        i = int(np.argmax(self.corrections)) if len(self.corrections) else 0
        return (f"{self.arm.name}: correction max {1e3 * self.corrections[i]:.1f} mm ({self.rig.bones[i]})"
                if len(self.corrections) else "")

    def write_bake(self) -> int:
        """Key the rendered armature at every applied frame: its object transform, each pose
        bone's location, rotation and scale, and its correction (mm). Returns keys written."""
        if not self.baked:
            return 0
        frames = np.array([b[0] for b in self.baked], dtype=np.float64)
        anim.bake(self.rendered, frames, np.array([b[1] for b in self.baked]))
        bases = np.array([b[2] for b in self.baked])            # (frames, bones, 4, 4)
        corr = np.array([b[3] for b in self.baked]) * 1e3
        quats = np.array([[eh.quat_from_matrix(m) for m in row] for row in bases])
        for j in range(1, len(quats)):                            # the short way between keys
            flip = np.einsum("bk,bk->b", quats[j], quats[j - 1]) < 0
            quats[j][flip] *= -1
        scales = np.linalg.norm(bases[:, :, :3, :3], axis=2)
        channels = []
        for k, name in enumerate(self.rig.bones):
            path = f'pose.bones["{name}"]'
            channels += [(f"{path}.location", i, bases[:, k, i, 3]) for i in range(3)]
            channels += [(f"{path}.rotation_quaternion", i, quats[:, k, i]) for i in range(4)]
            channels += [(f"{path}.scale", i, scales[:, k, i]) for i in range(3)]
            channels.append((f'{path}["{CORRECTION_PROPERTY}"]', 0, corr[:, k]))
        return anim.bake_channels(self.rendered, frames, channels)


class RecordedSnapshot:
    """What Hand.update reads of a snapshot, from a tick record (bake of a recording)."""

    def __init__(self, tick):
        self.hips, self.contacts, self.normals, self.poses = tick["hip"], tick["contact"], tick["normal"], tick["pose"]


def bake_recorded_hands(scene, desc, ticks, frames) -> list:
    """Key the rendered armature of every hand among a recording's fingers (``<armature>:<bone>``
    names of the scene's armatures) at ``frames`` from ``ticks`` (one record a frame), the input
    armatures sampled at those frames. Returns [(rendered armature, keys written)]; the fingers
    found are not missing."""
    hands = make_hands([bone_finger_named(f.name) for f in desc.fingers], desc)
    if not hands or "normal" not in (ticks.dtype.names or ()):
        return []
    current = scene.frame_current
    try:
        for fr in frames:
            scene.frame_set(int(np.floor(fr)), subframe=float(fr - np.floor(fr)))
            for hand in hands:
                hand.sample()
        for k, fr in enumerate(frames):
            snap = RecordedSnapshot(ticks[k])
            for hand in hands:
                hand.update(snap, desc.bodies, k, True, float(fr))
    finally:
        scene.frame_set(current)
    return [(hand.rendered, hand.write_bake()) for hand in hands]


def make_hands(finger_objects, desc) -> list:
    """The Hand of each armature with Finger bones among the session's fingers."""
    by_arm = {}
    for f, obj in enumerate(finger_objects):
        if isinstance(obj, BoneFinger):
            by_arm.setdefault(obj.armature.name, (obj.armature, {}))[1][obj.bone_name] = f
    return [Hand(arm, rig_of(arm, index), desc.fingers) for arm, index in by_arm.values()]
