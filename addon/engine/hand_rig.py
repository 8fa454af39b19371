"""The hand of our own and the bone-name patterns of other hands (bpy-free; docs/hands.md,
"Add Hand, Rigify, BVH").

``hand_bones(side)`` is the layout *Add Hand* builds: a wrist bone ``hand``, four metacarpals
``palm.01``..``palm.04`` (the palm, as four capsules side by side), the thumb ``thumb.01``..``03``
(metacarpal, moving at the carpometacarpal joint; proximal; distal phalanx) and the fingers
``f_index`` / ``f_middle`` / ``f_ring`` / ``f_pinky`` ``.01``..``.03`` (proximal, middle, distal
phalanx): Rigify's names, so one name-pattern helper sets the roles of both.

Dimensions (an adult hand, men and women together, rounded to the millimetre):
- bone lengths: the mean lengths of the hand's bones measured by Buryanov & Kotiuk, "Proportions of
  Hand Segments", Int. J. Morphol. 28(3):755-758, 2010;
- capsule radii: half the finger breadths at the joints (about 20 mm at the index's proximal
  joint, 15 mm at the little finger's distal one; ANSUR anthropometric survey, 1988, order of
  magnitude), the palm's 21 mm thick between knuckles 19 mm apart;
- joint limits: the normal ranges of motion of the American Academy of Orthopaedic Surgeons
  ("Joint Motion: Method of Measuring and Recording", 1965): finger MCP 30° extension to 90°
  flexion and ±20° spread, PIP 0-100°, DIP 10° extension to 90°, thumb MCP 0-50°, thumb IP 20°
  extension to 80° flexion; the thumb's CMC joint (a saddle) 25° extension to 50° flexion, ±35°
  abduction and ±20° of axial turn (opposition); the ring and little metacarpals flex 10° and 20°
  at their carpometacarpal joints, the index and middle ones not at all.

Frame: the right hand, palm down, fingers along +y, the thumb toward -x, the wrist at the origin;
the left hand is its mirror in x. Every bone's local z axis points palmar, so flexion is a
positive turn about the bone's x axis and spread a turn about its z axis (both hands).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

SIDES = ("RIGHT", "LEFT")
SUFFIX = {"RIGHT": ".R", "LEFT": ".L"}
FINGERS = ("thumb", "index", "middle", "ring", "pinky")

# Bone lengths, m (Buryanov & Kotiuk 2010): metacarpal, proximal, middle, distal.
LENGTHS = {
    "thumb": (0.046, 0.032, 0.022),          # metacarpal, proximal, distal (no middle phalanx)
    "index": (0.068, 0.040, 0.022, 0.016),
    "middle": (0.065, 0.045, 0.026, 0.017),
    "ring": (0.058, 0.041, 0.026, 0.017),
    "pinky": (0.054, 0.033, 0.018, 0.016),
}
# Capsule radii, m: the three moving segments of each finger (the thumb's metacarpal is the thenar
# eminence), and the palm's metacarpals.
RADII = {
    "thumb": (0.0125, 0.0105, 0.0098),
    "index": (0.0098, 0.0090, 0.0083),
    "middle": (0.0100, 0.0092, 0.0085),
    "ring": (0.0094, 0.0087, 0.0080),
    "pinky": (0.0085, 0.0078, 0.0073),
}
PALM_RADIUS = 0.0105
# Metacarpals, right hand: base (at the carpus) and the knuckle's x and z (the transverse arch).
METACARPALS = {
    "index": ((-0.013, 0.018, 0.0), -0.028, -0.003),
    "middle": ((-0.004, 0.020, 0.0), -0.009, 0.0),
    "ring": ((0.005, 0.020, 0.0), 0.010, -0.002),
    "pinky": ((0.013, 0.018, 0.0), 0.027, -0.006),
}
THUMB_BASE = (-0.020, 0.014, -0.010)                     # the CMC joint
THUMB_FORWARD = (-0.50, 0.78, -0.38)                     # out, forward and palmar
THUMB_PALMAR = (0.62, 0.25, -0.74)                       # its pad toward the fingers
# Rest flexion, degrees: the relaxed hand bends a little, which also tells IK which way to bend.
REST_FLEX = {"finger": (10.0, 15.0, 10.0), "thumb": (0.0, 10.0, 10.0)}
# Anatomical ranges, degrees (AAOS 1965): ((x flexion), (y axial turn), (z spread)) per joint.
FINGER_LIMITS = (((-30.0, 90.0), (0.0, 0.0), (-20.0, 20.0)),      # MCP
                 ((0.0, 100.0), (0.0, 0.0), (0.0, 0.0)),          # PIP
                 ((-10.0, 90.0), (0.0, 0.0), (0.0, 0.0)))         # DIP
THUMB_LIMITS = (((-25.0, 50.0), (-20.0, 20.0), (-35.0, 35.0)),    # CMC
                ((0.0, 50.0), (0.0, 0.0), (0.0, 0.0)),            # MCP
                ((-20.0, 80.0), (0.0, 0.0), (0.0, 0.0)))          # IP
PALM_FLEX = {"index": 0.0, "middle": 0.0, "ring": 10.0, "pinky": 20.0}
WRIST_LENGTH = 0.018                                     # the hand bone, wrist to carpus


@dataclass(frozen=True)
class BoneSpec:
    name: str                   # with the side suffix, e.g. "f_index.02.R"
    parent: str | None
    head: tuple                 # m, in the hand's frame
    tail: tuple
    palmar: tuple               # where the bone's local z axis points
    radius: float               # capsule radius, m; 0: not a Finger bone (the wrist)
    limits: tuple               # ((min, max) x, y, z), degrees, relative to the rest pose
    connected: bool = False

    @property
    def length(self) -> float:
        return _norm(_sub(self.tail, self.head))


def _sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def _add(a, b):
    return tuple(x + y for x, y in zip(a, b))


def _scale(a, s):
    return tuple(x * s for x in a)


def _norm(a):
    return math.sqrt(sum(x * x for x in a))


def _unit(a):
    n = _norm(a)
    return tuple(x / n for x in a)


def _dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def _orthonormal(forward, palmar):
    """``forward`` normalised and ``palmar`` made perpendicular to it."""
    f = _unit(forward)
    p = _unit(_sub(palmar, _scale(f, _dot(palmar, f))))
    return f, p


def _chain(prefix, start, forward, palmar, lengths, radii, rest, limits, first_parent, first_connected):
    """Bones of one finger: each bends ``rest`` degrees more than the one before, toward palmar."""
    f0, p0 = _orthonormal(forward, palmar)
    bones, head, bend, parent, connected = [], start, 0.0, first_parent, first_connected
    for k, (length, radius, flex, lim) in enumerate(zip(lengths, radii, rest, limits)):
        bend += math.radians(flex)
        direction = _add(_scale(f0, math.cos(bend)), _scale(p0, math.sin(bend)))
        pal = _add(_scale(f0, -math.sin(bend)), _scale(p0, math.cos(bend)))
        tail = _add(head, _scale(direction, length))
        name = f"{prefix}.{k + 1:02d}"
        rel = tuple((lo - (flex if axis == 0 else 0.0), hi - (flex if axis == 0 else 0.0))
                    for axis, (lo, hi) in enumerate(lim))
        bones.append(BoneSpec(name, parent, head, tail, pal, radius, rel, connected))
        head, parent, connected = tail, name, True
    return bones


def _right_hand():
    down = (0.0, 0.0, -1.0)
    bones = [BoneSpec("hand", None, (0.0, 0.0, 0.0), (0.0, WRIST_LENGTH, 0.0), down, 0.0,
                      ((0.0, 0.0),) * 3)]
    for k, finger in enumerate(("index", "middle", "ring", "pinky")):
        base, knuckle_x, knuckle_z = METACARPALS[finger]
        length = LENGTHS[finger][0]
        dx, dz = knuckle_x - base[0], knuckle_z - base[2]
        knuckle = (knuckle_x, base[1] + math.sqrt(length * length - dx * dx - dz * dz), knuckle_z)
        flex = PALM_FLEX[finger]
        palm = BoneSpec(f"palm.{k + 1:02d}", "hand", base, knuckle, _orthonormal(_sub(knuckle, base), down)[1],
                        PALM_RADIUS,
                        ((0.0, flex), (0.0, 0.0), (0.0, 0.0)))
        bones.append(palm)
        bones += _chain(f"f_{finger}", knuckle, _sub(knuckle, base), down, LENGTHS[finger][1:],
                        RADII[finger], REST_FLEX["finger"], FINGER_LIMITS, palm.name, True)
    bones += _chain("thumb", THUMB_BASE, THUMB_FORWARD, THUMB_PALMAR, LENGTHS["thumb"], RADII["thumb"],
                    REST_FLEX["thumb"], THUMB_LIMITS, "hand", False)
    return bones


def hand_bones(side: str = "RIGHT") -> list:
    """The bones of *Add Hand*'s hand, parents before children, in the hand's frame."""
    if side not in SIDES:
        raise ValueError(f"hand side must be one of {', '.join(SIDES)}, not {side!r}")
    suffix = SUFFIX[side]
    mirror = (lambda v: (-v[0], v[1], v[2])) if side == "LEFT" else (lambda v: v)
    return [BoneSpec(b.name + suffix, b.parent and b.parent + suffix, mirror(b.head), mirror(b.tail),
                     mirror(b.palmar), b.radius, b.limits, b.connected) for b in _right_hand()]


def fingertips(side: str = "RIGHT", finger_flex=(0.0, 0.0, 0.0), thumb_flex=(0.0, 0.0, 0.0)) -> dict:
    """finger -> its tip (the last bone's tail) in the hand's frame, each joint flexed so many
    degrees more than at rest (within its range): where a grasp's fingertips can be."""
    flex = {"finger": tuple(r + f for r, f in zip(REST_FLEX["finger"], finger_flex)),
            "thumb": tuple(r + f for r, f in zip(REST_FLEX["thumb"], thumb_flex))}
    tips = {}
    for finger in FINGERS:
        if finger == "thumb":
            start, forward, palmar, lengths, limits = THUMB_BASE, THUMB_FORWARD, THUMB_PALMAR, LENGTHS["thumb"], \
                THUMB_LIMITS
        else:
            base, knuckle_x, knuckle_z = METACARPALS[finger]
            length = LENGTHS[finger][0]
            dx, dz = knuckle_x - base[0], knuckle_z - base[2]
            start = (knuckle_x, base[1] + math.sqrt(length * length - dx * dx - dz * dz), knuckle_z)
            forward, palmar, lengths, limits = _sub(start, base), (0.0, 0.0, -1.0), LENGTHS[finger][1:], FINGER_LIMITS
        angles = flex["thumb" if finger == "thumb" else "finger"]
        for a, ((lo, hi), _, _) in zip(angles, limits):
            if not lo <= a <= hi:
                raise ValueError(f"{finger}: {a:g} degrees is outside its joint's range {lo:g}..{hi:g}")
        chain = _chain("tip", start, forward, palmar, lengths, (1.0,) * 3, angles, limits, None, False)
        tip = chain[-1].tail
        tips[finger] = (-tip[0], tip[1], tip[2]) if side == "LEFT" else tip
    return tips


def tip_bones(side: str = "RIGHT") -> dict:
    """finger -> the name of its last bone (whose tail is the fingertip), thumb first."""
    return {f: ("thumb.03" if f == "thumb" else f"f_{f}.03") + SUFFIX[side] for f in FINGERS}


# --------------------------------------------------------------------------- roles by name
# What a bone of someone else's hand is, from its name: (finger, segment) with segment 0 for a
# metacarpal / palm bone and 1..3 from the hand outward, or None. One pattern per naming
# convention; the first that matches wins.

_FINGER_WORDS = {"thumb": "thumb", "index": "index", "middle": "middle", "ring": "ring", "pinky": "pinky",
                 "little": "pinky", "pinkie": "pinky"}
_NUMBERED_FINGERS = {"0": "thumb", "1": "index", "2": "middle", "3": "ring", "4": "pinky"}
_WORD = "thumb|index|middle|ring|pinky|pinkie|little"
_SIDE = r"(?:[._ -]?(?:l|r|left|right))?"
NAME_PATTERNS = (
    # Rigify and this add-on: f_index.01.L, thumb.02.R, palm.03.L
    ("rigify", re.compile(rf"^(?:f_)?(?P<finger>{_WORD})\.0?(?P<seg>[123])(?:\.[lr])?$")),
    ("rigify palm", re.compile(r"^palm\.0?(?P<palm>[1-4])(?:\.[lr])?$")),
    # Mixamo / Perception Neuron / many BVH exports: LeftHandIndex1..3 (4 is the end), and
    # Neuron's LeftInHandIndex (the metacarpal)
    ("mocap", re.compile(rf"^(?:left|right)?(?:hand)?(?P<finger>{_WORD})(?P<seg>[123])$")),
    ("mocap palm", re.compile(rf"^(?:left|right)?inhand(?P<finger>{_WORD})$")),
    # Unreal / Unity style: index_01_l, thumb_03_r, index_metacarpal_l
    ("game", re.compile(rf"^(?P<finger>{_WORD})_0?(?P<seg>[123]){_SIDE}$")),
    ("game palm", re.compile(rf"^(?P<finger>{_WORD})_metacarpal{_SIDE}$")),
    # Rokoko / anatomical words: LeftIndexProximal, RightThumbDistal, LeftRingMetacarpal
    ("anatomical", re.compile(rf"^(?:left|right)?(?:hand)?(?P<finger>{_WORD})"
                              r"(?P<anat>metacarpal|proximal|intermediate|medial|middle|distal)$")),
    # 3ds Max Biped / CMU-style BVH: "Bip01 L Finger0" .. "Bip01 L Finger42" (finger 0 = thumb)
    ("biped", re.compile(r"^(?:bip\d*)?[lr]?finger(?P<num>[0-4])(?P<seg>[12]?)$")),
)
_ANATOMICAL = {"metacarpal": 0, "proximal": 1, "intermediate": 2, "medial": 2, "middle": 2, "distal": 3}


def _normalised(name: str) -> str:
    """Lower case, a namespace ("mixamorig:") dropped, Biped's spaces out."""
    name = name.split(":")[-1].strip().lower()
    return re.sub(r"\s+", "", name) if name.startswith("bip") else name


def classify_bone(name: str):
    """(finger, segment) of a hand bone named ``name`` (segment 0: a metacarpal, part of the palm;
    1..3 outward; the thumb's metacarpal is its segment 1, it moves), or None when the name is no
    finger or palm bone of a known convention."""
    found = _classify(_normalised(name))
    if found is not None and found[0] == "thumb" and found[1] == 0:
        return "thumb", 1
    return found


def _classify(n: str):
    for kind, pattern in NAME_PATTERNS:
        m = pattern.match(n)
        if not m:
            continue
        groups = m.groupdict()
        if "palm" in groups and groups["palm"]:
            return ("index", "middle", "ring", "pinky")[int(groups["palm"]) - 1], 0
        if "num" in groups and groups["num"] is not None:
            finger = _NUMBERED_FINGERS[groups["num"]]
            return finger, (int(groups["seg"]) + 1 if groups["seg"] else 1)
        finger = _FINGER_WORDS[groups["finger"]]
        if "anat" in groups and groups["anat"]:
            seg = _ANATOMICAL[groups["anat"]]
            # the thumb's three: metacarpal 1, proximal (or intermediate) 2, distal 3
            return finger, ({0: 1, 1: 2, 2: 2, 3: 3}[seg] if finger == "thumb" else seg)
        if kind.endswith("palm"):
            return finger, 0
        return finger, int(groups["seg"])
    return None


def role_radius(finger: str, segment: int, scale: float = 1.0) -> float:
    """The capsule radius of a recognised bone: this hand's radius for that segment, times
    ``scale`` (the other hand's size over ours)."""
    if segment == 0:
        return PALM_RADIUS * scale
    return RADII[finger][segment - 1] * scale


def reference_length(finger: str = "middle") -> float:
    """Our hand's finger length (its three moving segments), what another hand is scaled by."""
    return sum(LENGTHS[finger][-3:])
