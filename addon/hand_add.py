"""Add Hand (an armature of our own with a skinned low-poly mesh, Finger roles set, optionally
Finger empties at the tips driving it by IK) and Set Hand Roles (Finger roles on any armature's
hand bones by their names: Rigify, BVH / mocap). The layout and the name patterns are
engine/hand_rig.py's; docs/hands.md, "Add Hand, Rigify, BVH"."""
from __future__ import annotations

import math

import bpy
from bpy.props import BoolProperty, EnumProperty

from .engine import hand_rig
from .prefs import get_prefs

SIDE_ITEMS = (("RIGHT", "Right", "A right hand"), ("LEFT", "Left", "A left hand"))
RING_SIDES = 8                  # the low-poly mesh's tubes are octagons
TIP_EMPTY_PREFIX = "Tip "


# --------------------------------------------------------------------------- the armature

def _new_object(context, name, data):
    obj = bpy.data.objects.new(name, data)
    context.collection.objects.link(obj)
    return obj


def _build_armature(context, name, bones):
    from mathutils import Vector
    arm = _new_object(context, name, bpy.data.armatures.new(name))
    arm.show_in_front = True
    arm.data.display_type = "BBONE"
    view_layer = context.view_layer
    for o in context.selected_objects:
        o.select_set(False)
    arm.select_set(True)
    view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    try:
        for spec in bones:
            eb = arm.data.edit_bones.new(spec.name)
            eb.head, eb.tail = Vector(spec.head), Vector(spec.tail)
            eb.align_roll(Vector(spec.palmar))
            if spec.radius:             # the B-Bone drawn as thick as the capsule
                eb.bbone_x = eb.bbone_z = spec.radius
            if spec.parent:
                eb.parent = arm.data.edit_bones[spec.parent]
                eb.use_connect = spec.connected
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")
    for spec in bones:
        pb = arm.pose.bones[spec.name]
        pb.rotation_mode = "XYZ"
        _set_limits(pb, spec.limits)
    return arm


def _set_limits(pb, limits):
    """The joint's range twice: a Limit Rotation constraint (keyed and hand-posed rotations)
    and IK limits (the IK solver, which ignores constraints)."""
    con = pb.constraints.new("LIMIT_ROTATION")
    con.name = "Joint Limits"
    con.owner_space = "LOCAL"
    for axis, (lo, hi) in zip("xyz", limits):
        setattr(con, f"use_limit_{axis}", True)
        setattr(con, f"min_{axis}", math.radians(lo))
        setattr(con, f"max_{axis}", math.radians(hi))
        if lo == hi == 0.0:
            setattr(pb, f"lock_ik_{axis}", True)
        else:
            setattr(pb, f"use_ik_limit_{axis}", True)
            setattr(pb, f"ik_min_{axis}", math.radians(lo))
            setattr(pb, f"ik_max_{axis}", math.radians(hi))


def _set_roles(arm, bones, stiffness, first_channel=0):
    channel = first_channel
    for spec in bones:
        if spec.radius:
            gl = arm.pose.bones[spec.name].grasp_lab
            gl.role, gl.radius, gl.stiffness, gl.channel = "FINGER", spec.radius, stiffness, channel
            channel += 1


# --------------------------------------------------------------------------- the skinned mesh

def _ring(center, forward, palmar, radius):
    from mathutils import Vector
    f = Vector(forward).normalized()
    p = (Vector(palmar) - f * Vector(palmar).dot(f)).normalized()
    s = f.cross(p)
    return [Vector(center) + radius * (math.cos(a) * p + math.sin(a) * s)
            for a in (2 * math.pi * k / RING_SIDES for k in range(RING_SIDES))]


def _tube(chain, parent_name):
    """Rings along a finger's bones: (rings of points, weights {bone: w} per ring), the tip closed
    by one vertex. A ring in a bone's middle follows that bone; a ring at a joint, both bones."""
    from mathutils import Vector
    rings, weights = [], []
    first = chain[0]
    rings.append(_ring(first.head, Vector(first.tail) - Vector(first.head), first.palmar, first.radius))
    weights.append({first.name: 0.5, parent_name: 0.5})
    for k, b in enumerate(chain):
        head, tail = Vector(b.head), Vector(b.tail)
        for t in (0.25, 0.75):
            rings.append(_ring(head.lerp(tail, t), tail - head, b.palmar, b.radius))
            weights.append({b.name: 1.0})
        if k + 1 < len(chain):
            nxt = chain[k + 1]
            forward = (tail - head).normalized() + (Vector(nxt.tail) - Vector(nxt.head)).normalized()
            palmar = Vector(b.palmar) + Vector(nxt.palmar)
            rings.append(_ring(tail, forward, palmar, (b.radius + nxt.radius) / 2))
            weights.append({b.name: 0.5, nxt.name: 0.5})
    last = chain[-1]
    head, tail = Vector(last.head), Vector(last.tail)
    rings.append(_ring(tail, tail - head, last.palmar, 0.8 * last.radius))
    weights.append({last.name: 1.0})
    tip = tail + (tail - head).normalized() * 0.9 * last.radius
    return rings, weights, tip


def _palm_loops(bones):
    """Two closed cross-sections of the palm (at the carpus and at the knuckles) through the four
    metacarpals: dorsal points left to right, then palmar right to left; weights per point."""
    from mathutils import Vector
    palms = [b for b in bones if b.name.startswith("palm.")]
    palms.sort(key=lambda b: b.tail[0])
    loops, weights = [], []
    for end in ("head", "tail"):
        dorsal, palmar, w = [], [], []
        pts = [Vector(getattr(b, end)) for b in palms]
        outer = [pts[0] + (pts[0] - pts[1]) * 0.5, pts[-1] + (pts[-1] - pts[-2]) * 0.5]
        column = [(outer[0], palms[0])] + list(zip(pts, palms)) + [(outer[1], palms[-1])]
        for p, b in column:
            r = b.radius * (0.8 if end == "head" else 1.0)
            dorsal.append(p + Vector((0.0, 0.0, r)))
            palmar.append(p - Vector((0.0, 0.0, 1.15 * r)))      # the palm's pad is thicker
            w.append({b.name: 1.0} if end == "tail" else {b.name: 0.5, bones[0].name: 0.5})
        loops.append(dorsal + palmar[::-1])
        weights.append(w + w[::-1])
    return loops, weights


def _build_mesh(context, name, arm, bones):
    import bmesh
    bm = bmesh.new()
    vertex_weights = []                    # per vertex: {bone: weight}

    def add(points, w):
        out = []
        for p, ww in zip(points, w):
            out.append(bm.verts.new(p))
            vertex_weights.append(ww)
        return out

    def bridge(a, b):
        n = len(a)
        for k in range(n):
            bm.faces.new((a[k], a[(k + 1) % n], b[(k + 1) % n], b[k]))

    hand = bones[0].name
    chains = {}
    for b in bones:
        if b.radius and not b.name.startswith("palm."):
            chains.setdefault(b.name.split(".")[0], []).append(b)
    by_name = {b.name: b for b in bones}
    for chain in chains.values():
        parent = by_name[chain[0].name].parent or hand
        rings, weights, tip = _tube(chain, parent)
        loops = [add(r, [w] * len(r)) for r, w in zip(rings, weights)]
        bm.faces.new(loops[0][::-1])
        for a, b in zip(loops, loops[1:]):
            bridge(a, b)
        end = add([tip], [weights[-1]])[0]
        last = loops[-1]
        for k in range(len(last)):
            bm.faces.new((last[k], last[(k + 1) % len(last)], end))
    (loop_a, loop_b), (w_a, w_b) = _palm_loops(bones)
    a, b = add(loop_a, w_a), add(loop_b, w_b)
    bm.faces.new(a[::-1])
    bm.faces.new(b)
    bridge(a, b)
    bmesh.ops.recalc_face_normals(bm, faces=bm.faces)
    me = bpy.data.meshes.new(name)
    bm.to_mesh(me)
    bm.free()
    me.polygons.foreach_set("use_smooth", [True] * len(me.polygons))
    obj = _new_object(context, name, me)
    groups = {}
    for i, ww in enumerate(vertex_weights):
        for bone, w in ww.items():
            if bone not in groups:
                groups[bone] = obj.vertex_groups.new(name=bone)
            groups[bone].add([i], w, "REPLACE")
    obj.parent = arm
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = arm
    return obj


# --------------------------------------------------------------------------- tip targets

def _add_tip_targets(context, arm, side, stiffness):
    """A Finger empty at each fingertip (channels 0-4, thumb first) and an IK constraint on each
    finger's last bone reaching for it over the whole finger (the thumb's CMC joint included)."""
    empties = []
    by_name = {b.name: b for b in hand_rig.hand_bones(side)}
    for channel, (finger, bone) in enumerate(hand_rig.tip_bones(side).items()):
        spec = by_name[bone]
        empty = _new_object(context, f"{TIP_EMPTY_PREFIX}{finger}{hand_rig.SUFFIX[side]}", None)
        empty.empty_display_type = "SPHERE"
        empty.empty_display_size = spec.radius
        empty.location = arm.matrix_world @ _vector(spec.tail)
        gl = empty.grasp_lab
        gl.role, gl.radius, gl.stiffness, gl.channel = "FINGER", spec.radius, stiffness, channel
        ik = arm.pose.bones[bone].constraints.new("IK")
        ik.name = "Reach Tip"
        ik.target = empty
        ik.chain_count = 3
        ik.use_tail = True
        ik.use_stretch = False
        empties.append(empty)
    return empties


def _vector(v):
    from mathutils import Vector
    return Vector(v)


def build_hand(context, side="RIGHT", location=(0.0, 0.0, 0.0), tip_targets=False, stiffness=None, name=None):
    """Build a hand at ``location``: (armature, mesh, tip empties). The armature's Finger bones take
    channels after the tip empties' (0-4) when there are any."""
    bones = hand_rig.hand_bones(side)
    if stiffness is None:
        stiffness = get_prefs(context).finger_stiffness
    name = name or f"Hand{hand_rig.SUFFIX[side]}"
    arm = _build_armature(context, name, bones)
    arm.location = location
    context.view_layer.update()             # its matrix_world, where the tip empties go
    mesh = _build_mesh(context, f"{arm.name} Mesh", arm, bones)
    empties = _add_tip_targets(context, arm, side, stiffness) if tip_targets else []
    _set_roles(arm, bones, stiffness, first_channel=len(empties))
    context.view_layer.update()
    return arm, mesh, empties


class GRASPLAB_OT_add_hand(bpy.types.Operator):
    """Add an adult hand at the 3D cursor: an armature (palm, five fingers, the thumb's CMC joint,
    joint limits) with a skinned mesh, its bones Finger capsules"""
    bl_idname = "grasp_lab.add_hand"
    bl_label = "Add Hand"
    bl_options = {"REGISTER", "UNDO"}

    side: EnumProperty(name="Side", items=SIDE_ITEMS, default="RIGHT")
    tip_targets: BoolProperty(name="Fingertip Empties", default=False,
                              description="Also add a Finger empty at each fingertip with an IK constraint "
                                          "on the hand: keyed empties or a device move the tips and the "
                                          "hand follows")

    def execute(self, context):
        if context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        arm, _, empties = build_hand(context, self.side, context.scene.cursor.location.copy(),
                                     tip_targets=self.tip_targets)
        n = sum(pb.grasp_lab.role == "FINGER" for pb in arm.pose.bones)
        self.report({"INFO"}, f"{arm.name}: {n} Finger bones" + (f", {len(empties)} fingertip empties"
                                                                   if empties else ""))
        return {"FINISHED"}


# --------------------------------------------------------------------------- roles by name

def set_hand_roles(arm, stiffness):
    """Finger roles (and radii, scaled to the hand's size) on the bones of ``arm`` that
    hand_rig.classify_bone recognises; returns their names. Other bones are left as they are."""
    found = {}
    for pb in arm.pose.bones:
        kind = hand_rig.classify_bone(pb.name)
        if kind is not None and pb.bone.length > 0.0:
            found[pb.name] = kind
    scale = _hand_scale(arm, found)
    for channel, name in enumerate(sorted(found, key=lambda n: (hand_rig.FINGERS.index(found[n][0]), found[n][1], n))):
        finger, segment = found[name]
        gl = arm.pose.bones[name].grasp_lab
        gl.role, gl.stiffness, gl.channel = "FINGER", stiffness, channel
        gl.radius = hand_rig.role_radius(finger, segment, scale)
    return sorted(found)


def _hand_scale(arm, found):
    """The armature's middle finger length (world units) over ours; 1 when it has none."""
    scale = max(arm.matrix_world.to_scale())
    segments = {}
    for name, (finger, segment) in found.items():
        if finger == "middle" and segment:
            segments.setdefault(segment, []).append(arm.pose.bones[name].bone.length * scale)
    if len(segments) < 3:
        return 1.0
    # a hand has two middle fingers at most: average per segment, then add the segments up
    length = sum(sum(v) / len(v) for v in segments.values())
    return length / hand_rig.reference_length("middle")


class GRASPLAB_OT_set_hand_roles(bpy.types.Operator):
    """Give the Finger role to the finger and palm bones of the active armature, recognised by their
    names (Rigify's f_index.01.L, thumb.01.L, palm.01.L; mocap's LeftHandIndex1, index_01_l, ...),
    with radii scaled to the hand's size"""
    bl_idname = "grasp_lab.set_hand_roles"
    bl_label = "Set Hand Roles"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "ARMATURE"

    def execute(self, context):
        arm = context.active_object
        names = set_hand_roles(arm, get_prefs(context).finger_stiffness)
        if not names:
            self.report({"ERROR"}, f"{arm.name}: no bone is named like a finger or palm bone "
                                   "(f_index.01.L, thumb.02.R, palm.01.L, LeftHandIndex1, index_01_l, ...)")
            return {"CANCELLED"}
        self.report({"INFO"}, f"{arm.name}: {len(names)} bones set to Finger")
        return {"FINISHED"}


# --------------------------------------------------------------------------- menu

class VIEW3D_MT_grasp_lab_add(bpy.types.Menu):
    bl_idname = "VIEW3D_MT_grasp_lab_add"
    bl_label = "Grasp Lab"

    def draw(self, context):
        layout = self.layout
        layout.operator_context = "EXEC_REGION_WIN"
        layout.operator("grasp_lab.add_finger", icon="EMPTY_AXIS")
        for side, label, _ in SIDE_ITEMS:
            layout.operator("grasp_lab.add_hand", text=f"{label} Hand", icon="VIEW_PAN").side = side
        op = layout.operator("grasp_lab.add_hand", text="Right Hand with Fingertip Empties", icon="VIEW_PAN")
        op.side, op.tip_targets = "RIGHT", True


def _menu_add(self, context):
    self.layout.menu(VIEW3D_MT_grasp_lab_add.bl_idname, icon="VIEW_PAN")


CLASSES = (GRASPLAB_OT_add_hand, GRASPLAB_OT_set_hand_roles, VIEW3D_MT_grasp_lab_add)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.VIEW3D_MT_add.append(_menu_add)


def unregister():
    bpy.types.VIEW3D_MT_add.remove(_menu_add)
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
