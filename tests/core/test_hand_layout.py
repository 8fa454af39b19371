"""The hand of our own as data (addon/engine/hand_rig.py) and the bone-name patterns that give
other hands (Rigify, BVH / mocap) their Finger roles."""
import math
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))

from addon.engine import hand_rig  # noqa: E402


def _dist(a, b):
    return math.dist(a, b)


@pytest.mark.parametrize("side", hand_rig.SIDES)
def test_the_hand_has_a_palm_five_fingers_of_three_and_a_wrist(side):
    bones = hand_rig.hand_bones(side)
    names = [b.name for b in bones]
    assert len(names) == len(set(names)) == 1 + 4 + 5 * 3
    suffix = hand_rig.SUFFIX[side]
    assert all(n.endswith(suffix) for n in names)
    assert sum(1 for b in bones if b.radius > 0) == 19          # every bone but the wrist is a capsule
    by_name = {b.name: b for b in bones}
    for b in bones:
        if b.parent is not None:
            assert names.index(b.parent) < names.index(b.name)  # parents first: buildable in order
        if b.connected:                                        # a joint: the child starts at the parent's end
            assert _dist(b.head, by_name[b.parent].tail) < 1e-12
    for finger in ("index", "middle", "ring", "pinky"):
        chain = [by_name[f"f_{finger}.0{k}{suffix}"] for k in (1, 2, 3)]
        assert [round(b.length, 6) for b in chain] == [round(x, 6) for x in hand_rig.LENGTHS[finger][1:]]
        assert chain[0].parent == f"palm.0{('index', 'middle', 'ring', 'pinky').index(finger) + 1}{suffix}"
    thumb = [by_name[f"thumb.0{k}{suffix}"] for k in (1, 2, 3)]
    assert thumb[0].parent == "hand" + suffix and not thumb[0].connected      # the CMC joint, in the carpus
    assert [round(b.length, 6) for b in thumb] == [round(x, 6) for x in hand_rig.LENGTHS["thumb"]]


def test_adult_sized_wrist_to_middle_fingertip_and_across_the_knuckles():
    by_name = {b.name: b for b in hand_rig.hand_bones("RIGHT")}
    tip = by_name["f_middle.03.R"]
    hand_length = tip.tail[1] + tip.radius          # wrist at y = 0, the pad's cap beyond the tail
    # adult hand lengths (wrist crease to middle fingertip): about 17-20 cm
    assert 0.165 < hand_length < 0.20
    knuckles = [by_name[f"palm.0{k}.R"].tail for k in (1, 2, 3, 4)]
    breadth = _dist(knuckles[0], knuckles[-1]) + 2 * hand_rig.PALM_RADIUS
    assert 0.070 < breadth < 0.095                  # hand breadth at the metacarpals, about 8-9 cm


def test_left_is_the_mirror_of_right():
    right, left = hand_rig.hand_bones("RIGHT"), hand_rig.hand_bones("LEFT")
    for r, l in zip(right, left):
        assert l.name == r.name[:-2] + ".L"
        assert l.head == (-r.head[0], r.head[1], r.head[2]) and l.tail == (-r.tail[0], r.tail[1], r.tail[2])
        assert l.limits == r.limits and l.radius == r.radius
    assert right[-1].tail[0] < 0 < left[-1].tail[0]     # the right thumb toward -x


def test_rest_pose_lies_inside_every_joint_range_and_flexion_bends_toward_the_palm():
    for b in hand_rig.hand_bones("RIGHT"):
        for lo, hi in b.limits:
            assert lo <= 0.0 <= hi
        # the bone's palmar axis is perpendicular to it
        d = [t - h for t, h in zip(b.tail, b.head)]
        assert abs(sum(x * y for x, y in zip(d, b.palmar))) < 1e-9 * max(1.0, b.length)
    by_name = {b.name: b for b in hand_rig.hand_bones("RIGHT")}
    pip = by_name["f_index.02.R"]
    assert pip.limits[0] == (0.0 - 15.0, 100.0 - 15.0)   # AAOS 0-100 degrees less the rest flexion
    assert by_name["f_index.03.R"].tail[2] < by_name["f_index.01.R"].head[2]   # the relaxed finger curls down


def test_bad_side_is_named():
    with pytest.raises(ValueError, match="'MIDDLE'"):
        hand_rig.hand_bones("MIDDLE")


@pytest.mark.parametrize("name, expected", [
    ("f_index.01.L", ("index", 1)), ("f_pinky.03.R", ("pinky", 3)), ("thumb.01.L", ("thumb", 1)),
    ("palm.01.L", ("index", 0)), ("palm.04.R", ("pinky", 0)),
    ("mixamorig:LeftHandIndex1", ("index", 1)), ("RightHandMiddle3", ("middle", 3)),
    ("LeftHandThumb1", ("thumb", 1)), ("LeftInHandRing", ("ring", 0)), ("RightHandPinky2", ("pinky", 2)),
    ("index_02_l", ("index", 2)), ("pinky_metacarpal_r", ("pinky", 0)), ("thumb_metacarpal_l", ("thumb", 1)),
    ("LeftRingProximal", ("ring", 1)), ("RightIndexIntermediate", ("index", 2)), ("LeftLittleDistal", ("pinky", 3)),
    ("RightThumbDistal", ("thumb", 3)), ("LeftThumbMetacarpal", ("thumb", 1)),
    ("Bip01 L Finger0", ("thumb", 1)), ("Bip01 R Finger42", ("pinky", 3)), ("Bip01 L Finger11", ("index", 2)),
])
def test_finger_and_palm_bones_are_recognised_by_name(name, expected):
    assert hand_rig.classify_bone(name) == expected


@pytest.mark.parametrize("name", [
    "hand.L", "LeftHand", "forearm.R", "Spine", "LeftHandIndex4",      # end bones are no segment
    "f_index.01.L.001x", "spring1", "ringmaster", "", "Bip01 L Finger5", "LeftUpLeg",
])
def test_other_bones_are_not_fingers(name):
    assert hand_rig.classify_bone(name) is None


def test_radius_of_a_recognised_bone_scales_with_the_hand():
    assert hand_rig.role_radius("index", 3) == hand_rig.RADII["index"][2]
    assert hand_rig.role_radius("ring", 0, scale=2.0) == 2 * hand_rig.PALM_RADIUS
    assert hand_rig.reference_length("middle") == pytest.approx(sum(hand_rig.LENGTHS["middle"][1:]))


def test_fingertips_at_rest_are_the_last_bones_tails_and_flexing_curls_them_in():
    by_name = {b.name: b for b in hand_rig.hand_bones("LEFT")}
    rest = hand_rig.fingertips("LEFT")
    for finger, bone in hand_rig.tip_bones("LEFT").items():
        assert _dist(rest[finger], by_name[bone].tail) < 1e-12
    curled = hand_rig.fingertips("LEFT", (40.0, 50.0, 30.0), (20.0, 20.0, 20.0))
    for finger in hand_rig.FINGERS:
        # flexed, the tip comes back toward the wrist (y) and down toward the palm's side (z)
        assert curled[finger][1] < rest[finger][1] and curled[finger][2] < rest[finger][2]


def test_fingertips_outside_a_joints_range_are_refused_naming_the_finger():
    with pytest.raises(ValueError, match=r"index: 110 degrees is outside its joint's range -30\.\.90"):
        hand_rig.fingertips("RIGHT", (100.0, 0.0, 0.0))
