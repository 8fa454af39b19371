"""A keyed test hand (docs/hands.md): an armature of a palm bone and 5 chains of 3 bones hanging
down on both sides of a box on a table, every bone a Finger. The chains close by turning their
proximal joints until the capsules go ``SQUEEZE`` (3 mm) into the box's sides, the palm lifts the
hand ``LIFT`` (10 cm), and it holds. A low-poly skin (a cylinder a bone) is skinned to it. Used by
tests/blender/test_hands.py and the GUI test (tests/gui)."""
from __future__ import annotations

import math

import numpy as np

BOX_HALF = (0.025, 0.04, 0.02)          # m: the box's half extents; it stands on the table at z = 0
BOX_MASS = 0.05
RADIUS = 0.008                          # phalanx capsules
PALM_RADIUS = 0.01
PALM_Z = 0.10
LENGTHS = (0.03, 0.025, 0.02)           # proximal, middle, distal (down from PALM_Z to z 0.025)
CLEARANCE = 0.005                       # open hand: capsules this far from the box's sides
SQUEEZE = 0.003                         # closed: the fingertips' capsules this deep in the box
LIFT = 0.10
# (side: +1 on the +X face, -1 on the -X face, y of the chain)
CHAINS = ((1, -0.025), (1, 0.0), (1, 0.025), (-1, -0.0125), (-1, 0.0125))
FRAMES = {"open": 1, "closed": 13, "lift_start": 17, "lifted": 41, "end": 49}
FPS = 24


def chain_names(k):
    return [f"f{k}.{j}" for j in (1, 2, 3)]


def closing_angle():
    """The proximal joint's turn that puts the deepest capsule point SQUEEZE into the box."""
    reach = sum(LENGTHS)        # the tip, head of the proximal to the distal's tail
    return math.asin((CLEARANCE + SQUEEZE) / reach)


def build(bpy, skinned=True):
    """The scene; returns (armature, box)."""
    scene = bpy.context.scene
    scene.render.fps = FPS
    scene.frame_start, scene.frame_end = FRAMES["open"], FRAMES["end"]
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, -0.01))
    table = bpy.context.object
    table.name = "Table"
    table.scale = (0.4, 0.4, 0.02)
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    table.grasp_lab.role = "STATIC"
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, BOX_HALF[2]))
    box = bpy.context.object
    box.name = "Box"
    box.scale = tuple(2 * h for h in BOX_HALF)
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    box.grasp_lab.role = "DYNAMIC"
    box.grasp_lab.mass = BOX_MASS

    data = bpy.data.armatures.new("Hand")
    arm = bpy.data.objects.new("Hand", data)
    scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    palm = data.edit_bones.new("palm")
    palm.head, palm.tail = (0, -0.03, PALM_Z), (0, 0.03, PALM_Z)
    x0 = BOX_HALF[0] + RADIUS + CLEARANCE
    for k, (side, y) in enumerate(CHAINS):
        parent, z = palm, PALM_Z
        for name, length in zip(chain_names(k), LENGTHS):
            b = data.edit_bones.new(name)
            b.head, b.tail = (side * x0, y, z), (side * x0, y, z - length)
            b.parent = parent
            b.use_connect = parent is not palm
            parent, z = b, z - length
    bpy.ops.object.mode_set(mode="OBJECT")
    for pb in arm.pose.bones:
        pb.rotation_mode = "QUATERNION"
        pb.grasp_lab.role = "FINGER"
        pb.grasp_lab.radius = PALM_RADIUS if pb.name == "palm" else RADIUS

    for frame, closed, lifted in ((FRAMES["open"], 0, 0), (FRAMES["closed"], 1, 0), (FRAMES["lift_start"], 1, 0),
                                  (FRAMES["lifted"], 1, 1), (FRAMES["end"], 1, 1)):
        pose(arm, closed, lifted)
        arm.pose.bones["palm"].keyframe_insert("location", frame=frame)
        for k in range(len(CHAINS)):
            arm.pose.bones[chain_names(k)[0]].keyframe_insert("rotation_quaternion", frame=frame)
    if skinned:
        skin_hand(bpy, arm)
    return arm, box


def pose(arm, closed: float, lifted: float) -> None:
    """The hand ``closed`` (0 open, 1 the capsules SQUEEZE into the box) and ``lifted`` (0 to 1
    of LIFT): the palm's location, each chain's turn at its first joint."""
    palm_pb = arm.pose.bones["palm"]
    rest = np.array(palm_pb.bone.matrix_local)[:3, :3]
    palm_pb.location = tuple(rest.T @ np.array((0.0, 0.0, LIFT * lifted)))
    theta = closing_angle()
    for k, (side, _) in enumerate(CHAINS):
        pb = arm.pose.bones[chain_names(k)[0]]
        # Turn about world Y (+: the tip toward -X), in the bone's rest axes.
        axis = np.array(pb.bone.matrix_local)[:3, :3].T @ np.array((0.0, 1.0, 0.0))
        half = 0.5 * side * theta * closed
        pb.rotation_quaternion = (math.cos(half), *(math.sin(half) * axis))


def skin_hand(bpy, arm):
    """A low-poly skin: a 10-sided cylinder of each bone's radius along it, each skinned wholly to
    its bone (an Armature modifier, a vertex group a bone), parented to the armature."""
    import bmesh
    from mathutils import Matrix
    bm = bmesh.new()
    members = {}
    for bone in arm.data.bones:
        r = arm.pose.bones[bone.name].grasp_lab.radius
        first = len(bm.verts)
        place = bone.matrix_local @ Matrix.Translation((0.0, bone.length / 2, 0.0)) @ Matrix.Rotation(-math.pi / 2, 4, "X")
        bmesh.ops.create_cone(bm, cap_ends=True, segments=10, radius1=r, radius2=r, depth=bone.length, matrix=place)
        members[bone.name] = list(range(first, len(bm.verts)))
    me = bpy.data.meshes.new("Hand Skin")
    bm.to_mesh(me)
    bm.free()
    skin = bpy.data.objects.new("Hand Skin", me)
    bpy.context.scene.collection.objects.link(skin)
    for name, verts in members.items():
        skin.vertex_groups.new(name=name).add(verts, 1.0, "REPLACE")
    skin.modifiers.new("Armature", "ARMATURE").object = arm
    skin.parent = arm
    return skin
