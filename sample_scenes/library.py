"""The grasp library: the source chapter's grasps (§2.2) as sample scenes, built by one builder
from a declarative description per scene (``SCENES``).

Every scene is a table (or a stand) with the objects of the grasp on it and fingertip spheres
(empties with role Finger; a palm or a finger pad is a mesh with role Finger, a convex finger)
animated on the timeline: the scripted device. Each finger has a
*closed* position (its HIP inside the object by the squeeze depth) and an *outward* direction;
a scene's timeline (``keys``) says, per key frame, how far the fingers stand open along their
outward directions and where the hand has carried them (an offset added to every finger), with
Bézier ease-in/out between keys. The same fingertip animation is what the device emulator plays
with ``--from SCENE.blend`` (docs/devices.md). A scene's one-line description is stored in the
.blend as the scene's custom property ``grasp_lab_description``.

Each scene also states what it shows (``claim``), in numbers the tests check against the
simulated result (tests/blender/test_scene_library.py) and docs/scenes.md reports.

Usage (with the extension enabled: from the tests, or standalone as below):

    python sample_scenes/library.py [--out build/scenes] [--only NAME ...] [--run] [--zip ZIP]

builds every scene (or those named) into OUT/NAME.blend; ``--run`` also runs each one
headless and prints what it measured against what it claims.
``build(bpy, name)``, ``run(bpy)``, ``measure(scene, result)`` and ``verdict(scene, measured)``
are importable.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from dataclasses import dataclass, field

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
FPS = 24
G = 9.81
DESCRIPTION_KEY = "grasp_lab_description"


# --------------------------------------------------------------------------- shapes
# Each shape is a closed, outward-facing mesh about the object's origin.

@dataclass(frozen=True)
class Box:
    size: tuple                             # x, y, z extents, m


@dataclass(frozen=True)
class Prism:
    """A right prism about z: ``sides`` = 6 for a hexagonal pencil, 32 for a can."""
    radius: float                           # circumradius, m
    height: float
    sides: int
    angle: float = 0.0                      # first vertex's angle about z, rad


@dataclass(frozen=True)
class Ring:
    """A torus in the x-z plane about its origin (a mug's handle)."""
    major: float                            # ring radius, m
    minor: float                            # tube radius, m
    segments: int = 24
    tube_segments: int = 8


@dataclass(frozen=True)
class Union:
    """Closed shapes side by side in one mesh, each at an offset (islands may overlap)."""
    shapes: tuple                           # ((shape, (dx, dy, dz)), ...)


# --------------------------------------------------------------------------- scene parts

@dataclass
class Body:
    name: str
    shape: object
    location: tuple
    static: bool = False
    mass: float = 0.1                       # kg (dynamic bodies)
    mu: tuple = (0.8, 0.6)                  # mu_s, mu_d
    collision: str = "HULL"                 # HULL or AUTO (the add-on's Collision Shape)


@dataclass
class Finger:
    name: str
    closed: tuple                           # HIP when the grasp is closed, before the hand moves
    outward: tuple                          # unit direction the finger opens along
    radius: float = 0.008
    stiffness: float = 1000.0
    damping: float = 2.0
    group: str = "hand"                     # which hand / person (several devices)
    shape: object = None                    # a Box: a convex finger of its hull (a pad, a palm), else a sphere
    torsion: float = 0.0                    # a sphere's Soft Tip Radius (m): torsional friction; 0 a hard point


@dataclass
class Key:
    frame: int
    phase: str                              # the phase that starts at this frame
    opening: float                          # m along each finger's outward direction
    offset: tuple = (0.0, 0.0, 0.0)         # where the hand has carried every finger
    moves: dict = field(default_factory=dict)   # finger name -> its own offset besides (a thumb's stroke)


@dataclass
class Held:
    """The body rises with the fingers and stays in them: from ``grasp_frame`` to the end its
    displacement relative to the fingers' centroid stays below ``max_slip`` (the finger springs'
    give included), no finger slips during the ``hold`` phases, and it is ``rise`` higher when
    the first hold starts."""
    body: str
    rise: float
    max_slip: float
    grasp_frame: int
    max_tilt_deg: float = 180.0             # largest turn from its pose at grasp_frame


@dataclass
class Slides:
    """The grip is let off below "just enough": the body slides out of the fingers and falls
    at least ``min_drop`` relative to them, and starts slipping when the grip force per finger
    has fallen to ``m g / (n mu_s)``: that grip lies between the grips of the frames before and
    at the first slip (within ``onset_tolerance``, relative)."""
    body: str
    min_drop: float
    onset_tolerance: float = 0.02


@dataclass
class Hangs:
    """Hooked: the body rises at least ``rise`` and hangs from the finger: it swings about the
    vertical through the god-object, its centre of mass on average (over the last ``window``
    frames) within ``max_offset`` of it horizontally."""
    body: str
    finger: str
    rise: float
    max_offset: float
    window: int = 48


@dataclass
class Carried:
    """A held body carrying others resting on it: those stay put on it within ``max_shift``,
    and the fingers feel the whole load (their upward force, averaged over the ``hold``
    frames, is the weight of all within ``load_tolerance``, relative)."""
    body: str
    riders: tuple
    rise: float
    max_shift: float
    grasp_frame: int
    load_tolerance: float = 0.03


@dataclass
class Scene:
    name: str
    description: str
    bodies: list
    fingers: list
    keys: list
    claim: object
    interpolation: str = "BEZIER"           # of the fingertip keys: BEZIER eases in and out
    shown: str = "hold"                     # the phase whose middle frame pictures the scene
    view: tuple = None                      # toward the camera (default VIEW_DIRECTION)
    hand: object = None                     # a Hand: Add Hand's hand grasps (its bones the fingers)

    @property
    def frame_end(self) -> int:
        return self.keys[-1].frame

    def body(self, name):
        return next(b for b in self.bodies if b.name == name)

    def frames_of(self, phase):
        """Frames (inclusive start, exclusive end) of every key range of ``phase``."""
        out = []
        for a, b in zip(self.keys, self.keys[1:]):
            if a.phase == phase:
                out.extend(range(a.frame, b.frame))
        return out

    def phase_at(self, frame):
        name = self.keys[0].phase
        for k in self.keys:
            if frame >= k.frame:
                name = k.phase
        return name


# --------------------------------------------------------------------------- the library

def _table(size=(0.40, 0.30, 0.02), center=(0.0, 0.0, -0.01), mu=(0.6, 0.5), name="Table"):
    return Body(name, Box(size), center, static=True, mu=mu)


def _unit(v):
    n = math.sqrt(sum(c * c for c in v))
    return tuple(c / n for c in v)


def _lift_keys(lift, clearance, squeeze_end=25, hold_frames=36, carry=None):
    """rest, close, squeeze, lift ``lift`` m over 1 s, hold; optionally carry, hold."""
    up = (0.0, 0.0, lift)
    keys = [Key(1, "rest", clearance), Key(7, "close", clearance), Key(squeeze_end - 6, "squeeze", 0.0),
            Key(squeeze_end, "lift", 0.0), Key(squeeze_end + 24, "hold", 0.0, up)]
    end = squeeze_end + 24 + hold_frames
    if carry is not None:
        moved = tuple(u + c for u, c in zip(up, carry))
        keys += [Key(end, "carry", 0.0, up), Key(end + 24, "hold", 0.0, moved)]
        end += 24 + hold_frames
        up = moved
    keys.append(Key(end, "end", 0.0, up))
    return keys


def _pinch_and_lift_module():
    import importlib.util
    name = "grasp_lab_build_pinch_and_lift"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, os.path.join(HERE, "build_pinch_and_lift.py"))
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


def pinch_and_lift() -> Scene:
    # The first sample scene; its numbers and timeline are build_pinch_and_lift.py's (the demo).
    p = _pinch_and_lift_module()
    fingers = [Finger(f"Finger {i}", (s * p.CLOSED_X, 0.0, p.BOX_Z), (s, 0.0, 0.0), radius=p.FINGER_RADIUS,
                      stiffness=p.STIFFNESS, damping=p.DAMPING) for i, s in enumerate((-1.0, 1.0))]
    keys = [Key(f, phase, x - p.CLOSED_X, (0.0, y, z - p.BOX_Z)) for f, phase, x, y, z in p.KEYS]
    return Scene("pinch_and_lift", "Pinch: two fingertips pick a box off the table, lift it, carry it "
                 "and put it back down",
                 [Body("Table", Box(p.TABLE_SIZE), p.TABLE_CENTER, static=True, mu=p.TABLE_MU),
                  Body("Box", Box((p.BOX_SIZE,) * 3), (0.0, 0.0, p.BOX_Z), mass=p.BOX_MASS, mu=p.BOX_MU)],
                 fingers, keys, Held("Box", rise=p.LIFT, max_slip=0.001, grasp_frame=31, max_tilt_deg=1.0),
                 interpolation="LINEAR")


def key_pinch() -> Scene:
    # A credit card (85.6 x 54 x 0.76 mm, 5 g) standing in a slot. Lateral (key) pinch: the
    # thumb tip on one face, the side of the curled index on the other, met as two spheres
    # (distal and middle phalanx) 2 cm apart, so the card cannot pivot about the pinch axis.
    t = 0.00076
    card = Body("Card", Box((t, 0.0856, 0.054)), (0.0, 0.0, 0.027), mass=0.005, mu=(0.6, 0.5))
    slot_wall = Box((0.01, 0.10, 0.012))
    gap = 0.0005                                            # per side
    walls = [Body(f"Slot {s}", slot_wall, (sgn * (t / 2 + gap + 0.005), 0.0, 0.006), static=True)
             for s, sgn in (("-x", -1), ("+x", 1))]
    z = 0.045                                               # pinch height, 9 mm below the top edge
    squeeze = 0.002
    r_thumb, r_index = 0.009, 0.008
    fingers = [
        Finger("Thumb", (t / 2 + r_thumb - 2 * squeeze, 0.0, z), (1.0, 0.0, 0.0), radius=r_thumb),
        Finger("Index distal", (-(t / 2 + r_index - squeeze), -0.01, z), (-1.0, 0.0, 0.0), radius=r_index),
        Finger("Index middle", (-(t / 2 + r_index - squeeze), 0.01, z), (-1.0, 0.0, 0.0), radius=r_index),
    ]
    return Scene("key_pinch", "Key pinch: the thumb presses a card against the side of the index and "
                 "draws it out of its slot",
                 [_table(), card] + walls, fingers, _lift_keys(0.06, 0.012),
                 Held("Card", rise=0.06, max_slip=0.0015, grasp_frame=25, max_tilt_deg=3.0))


def tripod_pencil() -> Scene:
    # A 10 g hexagonal pencil (7 mm across flats, 175 mm) standing on end; thumb, index and
    # middle fingertips on alternate flats 3 cm below its top lift it 8 cm and carry it 10 cm
    # sideways: the pencil hangs in the grip and hardly swings.
    flats = 0.007
    length = 0.175
    r = flats / math.sqrt(3.0)                              # circumradius
    pencil = Body("Pencil", Prism(r, length, 6), (0.0, 0.0, length / 2), mass=0.010, mu=(0.7, 0.5))
    z = length - 0.03
    squeeze = 0.0015
    tip = 0.007
    fingers = []
    for name, deg in (("Thumb", 30.0), ("Index", 150.0), ("Middle", 270.0)):
        n = (math.cos(math.radians(deg)), math.sin(math.radians(deg)), 0.0)
        d = flats / 2 + tip - squeeze
        fingers.append(Finger(name, (n[0] * d, n[1] * d, z), n, radius=tip))
    return Scene("tripod_pencil", "Tripod (stylus) grasp: thumb, index and middle fingertips lift a "
                 "10 g hexagonal pencil and hold it steady",
                 [_table(), pencil], fingers, _lift_keys(0.08, 0.01, carry=(0.10, 0.0, 0.0)),
                 Held("Pencil", rise=0.08, max_slip=0.001, grasp_frame=25, max_tilt_deg=2.0))


WEAK_BOX = 0.05
WEAK_MASS = 0.1
WEAK_MU = (0.8, 0.6)


def weak_grip_slide() -> Scene:
    # The pinch of pinch_and_lift (5 cm, 100 g box, two 1000 N/m fingertips 3 mm deep: 3 N
    # each, 2.4 N of friction per finger against 0.49 N of weight each), lifted 8 cm; then the
    # fingers ease off slowly, past "just enough" (m g / (2 mu_s) = 0.61 N per finger, at
    # 0.61 mm deep), and the box slides out of them onto the table.
    half = WEAK_BOX / 2
    r, squeeze = 0.008, 0.003
    fingers = [Finger(f"Finger {i}", (s * (half + r - squeeze), 0.0, half), (s, 0.0, 0.0), radius=r)
               for i, s in enumerate((-1.0, 1.0))]
    box = Body("Box", Box((WEAK_BOX,) * 3), (0.0, 0.0, half), mass=WEAK_MASS, mu=WEAK_MU)
    up = (0.0, 0.0, 0.08)
    keys = [Key(1, "rest", 0.015), Key(7, "close", 0.015), Key(19, "squeeze", 0.0), Key(25, "lift", 0.0),
            Key(49, "hold", 0.0, up), Key(61, "ease off", 0.0, up), Key(109, "hold", 0.0028, up),
            Key(133, "end", 0.0028, up)]
    return Scene("weak_grip_slide", "Weak grip: a lifted box is held less and less firmly until the "
                 "grip falls below just enough and the box slides out of the fingers",
                 [_table(), box], fingers, keys, Slides("Box", min_drop=0.05))


def can_power() -> Scene:
    # A full 330 ml can (66 mm x 115 mm, 350 g) on the table, in a power grasp: the palm flat
    # against one side (a convex finger, 12 x 70 x 90 mm, shorter than the can: it meets the
    # can along the edges of the face it lies on), the four fingertips round the other side and
    # the thumb across the front, each pressing 3 mm; they press the can into the palm and the
    # hand lifts it 10 cm.
    rad, h = 0.033, 0.115
    n_sides = 32
    apothem = rad * math.cos(math.pi / n_sides)
    # a face (not an edge) toward the palm, at -x
    can = Body("Can", Prism(rad, h, n_sides, angle=math.pi / n_sides), (0.0, 0.0, h / 2), mass=0.35, mu=(0.6, 0.5))
    zc = h / 2
    r, squeeze, k = 0.008, 0.003, 1000.0
    palm_size = (0.012, 0.07, 0.09)
    fingers = [Finger("Palm", (-(apothem + palm_size[0] / 2 - squeeze), 0.0, zc), (-1.0, 0.0, 0.0), radius=0.0,
                      stiffness=k, shape=Box(palm_size))]
    # Fingertips 45 deg either side of +x, alternating so that their sideways pushes cancel in
    # force and in moment (sum of sin = sum of z sin = 0): the can is not twisted.
    wrap = (("Index", 45.0, 0.03), ("Middle", -45.0, 0.01), ("Ring", -45.0, -0.01), ("Little", 45.0, -0.03))
    r_t = 0.010
    fingers.append(Finger("Thumb", (apothem + r_t - squeeze, 0.0, zc + 0.02), (1.0, 0.0, 0.0),
                          radius=r_t, stiffness=k))
    for name, deg, dz in wrap:
        n = (math.cos(math.radians(deg)), math.sin(math.radians(deg)), 0.0)
        d = rad + r - squeeze
        fingers.append(Finger(name, (n[0] * d, n[1] * d, zc + dz), n, radius=r, stiffness=k))
    return Scene("can_power", "Power grasp: the palm against a full 350 g can, four fingertips round it "
                 "and the thumb across, lift it off the table",
                 [_table(), can], fingers, _lift_keys(0.10, 0.015),
                 Held("Can", rise=0.10, max_slip=0.002, grasp_frame=25, max_tilt_deg=3.0))


def mug_hook() -> Scene:
    # A full mug (solid 80 x 90 mm cylinder, 350 g) with a ring handle on its +x side, its top
    # at the rim: the centre of mass is below the handle. The mesh is one object, Collision
    # Shape Automatic: the decomposition cuts the ring into convex pieces. One fingertip goes
    # through the handle and lifts: the mug tips until its centre of mass hangs below the finger.
    rad, h = 0.04, 0.09
    ring = Ring(major=0.024, minor=0.006)
    ring_x, ring_z = rad + 0.010, h / 2 - 0.030              # ring top level with the rim
    mug = Body("Mug", Union(((Prism(rad, h, 32), (0.0, 0.0, 0.0)), (ring, (ring_x, 0.0, ring_z)))),
               (0.0, 0.0, h / 2), mass=0.35, mu=(0.6, 0.5), collision="AUTO")
    r = 0.007
    inside = (ring_x + 0.006, 0.0, h / 2 + ring_z)          # in the handle's hole, near its outer side
    finger = Finger("Index", inside, (0.0, -1.0, 0.0), radius=r, stiffness=1500.0, damping=3.0)
    keys = [Key(1, "rest", 0.04), Key(7, "reach in", 0.04), Key(25, "lift", 0.0),
            Key(73, "hold", 0.0, (0.0, 0.0, 0.12)), Key(145, "end", 0.0, (0.0, 0.0, 0.12))]
    return Scene("mug_hook", "Hook grasp: one finger through a mug's handle lifts the full mug, which "
                 "hangs with its centre of mass below the finger",
                 [_table(), mug], [finger], keys, Hangs("Mug", "Index", rise=0.05, max_offset=0.003))


def tray_two_hands() -> Scene:
    # A 50 x 30 cm, 400 g tray overhanging a 30 cm stand at both ends, two 150 g cups on it.
    # Each hand: the thumb on top, two fingertips under the overhang 8 cm apart. Lifted 8 cm
    # and carried 10 cm sideways: the cups ride on the tray.
    tray_t = 0.012
    tray = Body("Tray", Box((0.50, 0.30, tray_t)), (0.0, 0.0, tray_t / 2), mass=0.4, mu=(0.6, 0.5))
    stand = _table(size=(0.30, 0.30, 0.02), name="Stand")
    cup = Prism(0.04, 0.09, 24)
    cups = [Body(f"Cup {i}", cup, (x, 0.02 * (1 - 2 * i), tray_t + 0.045), mass=0.15, mu=(0.5, 0.4))
            for i, x in enumerate((-0.08, 0.09))]
    r, k = 0.008, 1500.0
    load = (0.4 + 2 * 0.15) * G / 2                         # per hand
    d_thumb = 0.003
    d_below = (load / k + d_thumb) / 2                      # 2 k d_below - k d_thumb = load
    fingers = []
    for hand, sx in (("Left", -1.0), ("Right", 1.0)):
        x = sx * 0.22
        fingers.append(Finger(f"{hand} thumb", (x, 0.0, tray_t + r - d_thumb), (0.0, 0.0, 1.0),
                              radius=r, stiffness=k, group=hand))
        for name, y in (("index", 0.04), ("middle", -0.04)):
            fingers.append(Finger(f"{hand} {name}", (x, y, -r + d_below), (0.0, 0.0, -1.0),
                                  radius=r, stiffness=k, group=hand))
    keys = _lift_keys(0.08, 0.012, carry=(0.0, 0.10, 0.0))
    return Scene("tray_two_hands", "Two hands carry a tray with two cups: the cups ride on the tray and "
                 "the fingers feel their weight through it",
                 [stand, tray] + cups, fingers, keys,
                 Carried("Tray", riders=("Cup 0", "Cup 1"), rise=0.08, max_shift=0.001, grasp_frame=25))


def two_people_box() -> Scene:
    # A 40 cm, 2 kg box; two people squeeze it from either side with three fingertips each
    # (2000 N/m, 4 mm: 24 N a side, 19 N of friction against 9.8 N), lift it and carry it.
    size = 0.40
    box = Body("Box", Box((size, 0.30, 0.25)), (0.0, 0.0, 0.125), mass=2.0, mu=(0.8, 0.6))
    r, k, squeeze = 0.009, 2000.0, 0.004
    fingers = []
    for person, s in (("A", -1.0), ("B", 1.0)):
        for i, (y, dz) in enumerate(((-0.06, 0.02), (0.0, -0.02), (0.06, 0.02))):
            fingers.append(Finger(f"{person} finger {i}", (s * (size / 2 + r - squeeze), y, 0.125 + dz),
                                  (s, 0.0, 0.0), radius=r, stiffness=k, damping=4.0, group=person))
    keys = _lift_keys(0.10, 0.02, carry=(0.0, 0.15, 0.0))
    return Scene("two_people_box", "Two people, three fingertips each, lift a 2 kg box together and "
                 "carry it",
                 [_table(size=(0.6, 0.5, 0.02)), box], fingers, keys,
                 Held("Box", rise=0.10, max_slip=0.0025, grasp_frame=25, max_tilt_deg=2.0))


SCENES = {f.__name__: f for f in (pinch_and_lift, key_pinch, tripod_pencil, weak_grip_slide, can_power, mug_hook,
                                  tray_two_hands, two_people_box)}


# Area contacts (docs/physics.md "Area contacts"): a palm and finger pads are convex fingers.

PLATE = dict(size=(0.20, 0.20, 0.01), mass=0.4)
PALM = (0.09, 0.08, 0.02)


def plate_palm() -> Scene:
    # A 0.4 kg plate (20 x 20 x 1 cm) across two rails; a flat palm (a convex finger, 9 x 8 x
    # 2 cm, 1000 N/m at each of its corners) comes up between them, lifts the plate 10 cm and
    # carries it 10 cm sideways. On one point it would be an inverted pendulum and tip over; on
    # the palm's area the pressure centroid stays under the centre of mass and it stays level.
    sx, sy, sz = PLATE["size"]
    plate = Body("Plate", Box(PLATE["size"]), (0.0, 0.0, sz / 2), mass=PLATE["mass"], mu=(0.6, 0.5))
    rail = Box((0.26, 0.025, 0.02))
    rails = [Body(f"Rail {s}", rail, (0.0, sgn * (sy / 2 - 0.0125), -0.01), static=True)
             for s, sgn in (("-y", -1), ("+y", 1))]
    k = 1000.0
    sink = PLATE["mass"] * G / (4 * k)              # the plate on four corners: it stays where it lay
    palm = Finger("Palm", (0.0, 0.0, -PALM[2] / 2 + sink), (0.0, 0.0, -1.0), radius=0.0, stiffness=k,
                  shape=Box(PALM))
    return Scene("plate_palm", "Area contact: a flat palm lifts a 0.4 kg plate off two rails and carries it "
                 "sideways; the plate stays level on it",
                 rails + [plate], [palm], _lift_keys(0.10, 0.015, carry=(0.10, 0.0, 0.0)),
                 Held("Plate", rise=0.10, max_slip=0.005, grasp_frame=25, max_tilt_deg=2.0),
                 view=(0.17, -0.455, 0.04))              # lower: the palm under the plate in sight


PHONE = dict(size=(0.072, 0.150, 0.008), mass=0.18)


def phone_thumb() -> Scene:
    # Texting (the chapter's Fig. 2.4): a 180 g phone (72 x 150 x 8 mm) lies across four
    # fingers (convex pads 60 x 16 x 14 mm under its back) and the thumb presses on its screen
    # (3 mm: 3 N). The hand lifts it 8 cm from its stand; then the thumb strokes 3 cm across the
    # screen: it slides over the glass (3 N of press cannot hold 3 cm of stroke) while the
    # phone stays in the fingers, whose friction has the thumb's press and the weight behind it.
    sx, sy, sz = PHONE["size"]
    phone = Body("Phone", Box(PHONE["size"]), (0.0, 0.0, sz / 2), mass=PHONE["mass"], mu=(0.6, 0.5))
    rail = Box((0.10, 0.015, 0.02))
    rails = [Body(f"Stand {s}", rail, (0.0, sgn * (sy / 2 - 0.0025), -0.01), static=True)
             for s, sgn in (("-y", -1), ("+y", 1))]
    k, pad = 1000.0, (0.06, 0.016, 0.014)
    sink = 0.0003
    fingers = [Finger(name, (0.005, y, -pad[2] / 2 + sink), (0.0, 0.0, -1.0), radius=0.0, stiffness=k,
                      shape=Box(pad))
               for name, y in (("Index", 0.045), ("Middle", 0.015), ("Ring", -0.015), ("Little", -0.045))]
    r_t, d_t = 0.010, 0.003
    fingers.append(Finger("Thumb", (-0.015, 0.0, sz + r_t - d_t), (0.0, 0.0, 1.0), radius=r_t, stiffness=k))
    up = (0.0, 0.0, 0.08)
    stroke = {"Thumb": (0.03, 0.0, 0.0)}            # along the pads
    keys = [Key(1, "rest", 0.015), Key(7, "close", 0.015), Key(19, "squeeze", 0.0), Key(25, "lift", 0.0),
            Key(49, "hold", 0.0, up), Key(73, "stroke", 0.0, up),
            # the thumb arrives at 97 still sliding; it sticks again a frame later
            Key(97, "stop", 0.0, up, stroke), Key(99, "hold", 0.0, up, stroke), Key(121, "end", 0.0, up, stroke)]
    return Scene("phone_thumb", "Texting grasp: a phone lies across four finger pads, the thumb pressing on "
                 "it; lifted, the thumb strokes the screen and the phone stays in the fingers",
                 rails + [phone], fingers, keys,
                 Held("Phone", rise=0.08, max_slip=0.001, grasp_frame=25, max_tilt_deg=1.0), shown="stroke")


SCENES.update((f.__name__, f) for f in (plate_palm, phone_thumb))


# Soft fingertips (docs/physics.md "Soft fingertips"): torsional friction about the contact normal.

SOFT_BAR = dict(size=(0.20, 0.02, 0.02), mass=0.1, offset=0.05)     # the pinch 5 cm from the centre of mass
SOFT_TIP = dict(radius=0.008, stiffness=3000.0, squeeze=0.003, torsion=0.01)


def soft_pinch_bar() -> Scene:
    # A 0.1 kg bar (20 x 2 x 2 cm) lying on the table, pinched across its width 5 cm from its
    # centre of mass and lifted 8 cm: its weight twists it about the pinch axis with m g d =
    # 0.049 N m. Point contacts leave that turn free; soft fingertips (Soft Tip Radius 1 cm, 9 N
    # each: up to 2 mu_s F_n rho = 0.144 N m) hold it where their twist springs carry the
    # moment, 2 k rho^2 theta = m g d cos theta: 4.67 degrees.
    _, sy, sz = SOFT_BAR["size"]
    bar = Body("Bar", Box(SOFT_BAR["size"]), (SOFT_BAR["offset"], 0.0, sz / 2), mass=SOFT_BAR["mass"], mu=(0.8, 0.6))
    t = SOFT_TIP
    fingers = [Finger(name, (0.0, s * (sy / 2 + t["radius"] - t["squeeze"]), sz / 2), (0.0, s, 0.0),
                      radius=t["radius"], stiffness=t["stiffness"], torsion=t["torsion"])
               for name, s in (("Thumb", -1.0), ("Index", 1.0))]
    return Scene("soft_pinch_bar", "Soft fingertips: two fingertips pinch a bar 5 cm from its centre of mass "
                 "and lift it; their torsional friction holds it against its weight's twist",
                 [_table(), bar], fingers, _lift_keys(0.08, 0.012),
                 Held("Bar", rise=0.08, max_slip=0.006, grasp_frame=25, max_tilt_deg=10.0))


SCENES.update((f.__name__, f) for f in (soft_pinch_bar,))


# --------------------------------------------------------------------------- scenes with the hand
# Add Hand's hand (docs/hands.md, "Add Hand, Rigify, BVH") grasps: its bones are the fingers (capsules along the
# phalanges, the palm's metacarpals), and the scene runs from the armature's pose. The tips of the
# grasping fingers are IK targets keyed like fingertips (``Finger``: the distal capsule's end-cap
# centre when closed, and the direction it opens along); the other fingers curl out of the way; the
# armature (the wrist) is keyed where the hand carries it. The hand is placed where its relaxed
# fingertips best fit the closed tips, the wrist toward ``wrist_toward``.

@dataclass
class Hand:
    side: str
    tips: dict                              # finger ("thumb", "index", ...) -> Finger
    wrist_toward: tuple                     # from the tips' centroid toward the wrist
    touching: tuple                         # bones (without the side suffix) that touch the held body
    curl: tuple = (75.0, 90.0, 60.0)        # the other fingers' MCP, PIP, DIP flexion, degrees
    stiffness: float = 1000.0
    thumb_weight: float = 1.0               # the thumb's weight in the fit (it reaches least far)
    ready: tuple = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))   # flexion beyond rest (fingers, thumb) fitted
    placement: tuple = None                 # (rotation rows, wrist): given, instead of the fit
    approach: tuple = (0.0, 0.0, 0.0)       # the wrist backs off along this as the hand opens


def _hand_rig():
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)
    from addon.engine import hand_rig
    return hand_rig


def hand_placement(hand: Hand):
    """(rotation 3x3, wrist position) of the hand whose fingertips flexed ``ready`` (and wrist, toward
    ``wrist_toward`` at their distance) best fit the closed tips: Kabsch's weighted least squares."""
    import numpy as np
    if hand.placement is not None:
        return np.array(hand.placement[0], dtype=float), np.array(hand.placement[1], dtype=float)
    ready = _hand_rig().fingertips(hand.side, *hand.ready)
    p = np.array([ready[f] for f in hand.tips])
    q = np.array([f.closed for f in hand.tips.values()])
    p_c, q_c = p.mean(axis=0), q.mean(axis=0)
    reach = float(np.linalg.norm(p_c))                      # the wrist is the hand frame's origin
    p = np.vstack([p, np.zeros(3)])
    q = np.vstack([q, q_c + reach * np.array(_unit(hand.wrist_toward))])
    w = np.array([hand.thumb_weight if f == "thumb" else 1.0 for f in hand.tips] + [1.0])[:, None]
    p_c, q_c = (w * p).sum(axis=0) / w.sum(), (w * q).sum(axis=0) / w.sum()
    u, _, vt = np.linalg.svd((w * (p - p_c)).T @ (q - q_c))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rot, q_c - rot @ p_c


def _hand_points(sc: Scene):
    """The hand's tips and wrist at every key (what the camera must see)."""
    import numpy as np
    rot, wrist = hand_placement(sc.hand)
    pts = [finger_position(f, k) for f in sc.hand.tips.values() for k in sc.keys]
    pts += [_wrist_at(sc.hand, wrist, k) for k in sc.keys]
    return pts


def _wrist_at(hand: Hand, wrist, key: Key) -> tuple:
    """Where the armature (the wrist) is at a key: carried, and backed off as the hand opens."""
    back = _unit(hand.approach) if any(hand.approach) else (0.0, 0.0, 0.0)
    return tuple(w + o + key.opening * b for w, o, b in zip(wrist, key.offset, back))


def _add_hand(bpy, sc: Scene):
    from mathutils import Matrix
    h = sc.hand
    rig = _hand_rig()
    hand_add = _extension_module(bpy, "hand_add")
    rot, wrist = hand_placement(h)
    arm, mesh, _ = hand_add.build_hand(bpy.context, h.side, tuple(wrist), tip_targets=True, stiffness=h.stiffness)
    arm.rotation_euler = Matrix(rot.tolist()).to_euler("XYZ")
    suffix = rig.SUFFIX[h.side]
    for finger, bone in rig.tip_bones(h.side).items():
        empty = bpy.data.objects[f"{hand_add.TIP_EMPTY_PREFIX}{finger}{suffix}"]
        if finger in h.tips:
            empty.grasp_lab.role = "NONE"           # an IK target: the bones are the fingers
            for key in sc.keys:
                empty.location = finger_position(h.tips[finger], key)
                empty.keyframe_insert("location", frame=key.frame)
            _set_interpolation(bpy, empty, sc.interpolation)
        else:                                       # curled out of the way
            arm.pose.bones[bone].constraints.remove(arm.pose.bones[bone].constraints["Reach Tip"])
            bpy.data.objects.remove(empty)
            chain = [bone[:-len(suffix) - 1] + f"{k}{suffix}" for k in (1, 2, 3)]
            for name, deg in zip(chain, h.curl):
                arm.pose.bones[name].rotation_euler.x = math.radians(deg)
    for key in sc.keys:
        arm.location = _wrist_at(h, wrist, key)
        arm.keyframe_insert("location", frame=key.frame)
    _set_interpolation(bpy, arm, sc.interpolation)
    return arm


def _extension_module(bpy, name):
    import importlib
    for mod in bpy.context.preferences.addons.keys():
        if mod.endswith(".grasp_lab"):
            return importlib.import_module(f"{mod}.{name}")
    raise RuntimeError("the grasp_lab extension is not enabled")


def _tip(finger, surface_point, outward, squeeze, side="RIGHT"):
    """A grasping fingertip: its distal capsule's end cap ``squeeze`` into the surface at
    ``surface_point`` whose outward normal is ``outward``."""
    r = _hand_rig().RADII[finger][2]
    n = _unit(outward)
    return Finger(finger, tuple(p + (r - squeeze) * c for p, c in zip(surface_point, n)), n, radius=r)


def hand_pinch() -> Scene:
    # A 4 cm, 50 g cube on the table, pinched between the pads of the thumb and the index of the
    # right hand (the hand's capsules, 2 mm deep: 2 N each against 0.25 N of weight each), lifted
    # 8 cm and held.
    size, squeeze = 0.04, 0.002
    cube = Body("Cube", Box((size,) * 3), (0.0, 0.0, size / 2), mass=0.05, mu=(0.8, 0.6))
    z = size / 2
    tips = {"thumb": _tip("thumb", (0.0, -size / 2, z), (0.0, -1.0, 0.0), squeeze),
            "index": _tip("index", (0.0, size / 2, z), (0.0, 1.0, 0.0), squeeze)}
    hand = Hand("RIGHT", tips, wrist_toward=(0.0, -0.7, 0.7), touching=("thumb.03", "f_index.03"))
    return Scene("hand_pinch", "The hand: the pads of the thumb and the index pinch a 50 g cube off the "
                 "table and lift it", [_table(), cube], [], _lift_keys(0.08, 0.012),
                 Held("Cube", rise=0.08, max_slip=0.002, grasp_frame=25, max_tilt_deg=3.0), hand=hand)


def hand_tripod_pencil() -> Scene:
    # tripod_pencil's pencil (10 g, hexagonal, 7 mm across flats, 175 mm, on end) in the hand: the
    # thumb on the flat toward the wrist, the index and middle fingertips on the flats 120 degrees
    # either side, 3 cm below its top, 1.5 mm deep, the hand coming from the side (the pencil passes
    # in front of the knuckles); lifted 8 cm and carried 10 cm sideways.
    flats, length, squeeze = 0.007, 0.175, 0.0015
    pencil = Body("Pencil", Prism(flats / math.sqrt(3.0), length, 6), (0.0, 0.0, length / 2), mass=0.010,
                  mu=(0.7, 0.5))
    z = length - 0.03
    tips = {}
    for finger, deg in (("thumb", 270.0), ("index", 150.0), ("middle", 30.0)):
        n = (math.cos(math.radians(deg)), math.sin(math.radians(deg)), 0.0)
        tips[finger] = _tip(finger, (n[0] * flats / 2, n[1] * flats / 2, z), n, squeeze)
    hand = Hand("RIGHT", tips, wrist_toward=(0.0, -1.0, 0.25), touching=("thumb.03", "f_index.03", "f_middle.03"),
                ready=((30.0, 40.0, 20.0), (20.0, 30.0, 20.0)))
    return Scene("hand_tripod_pencil", "The hand: a tripod of the thumb, index and middle fingertips lifts a "
                 "10 g pencil and carries it", [_table(), pencil], [], _lift_keys(0.08, 0.01, carry=(0.10, 0.0, 0.0)),
                 Held("Pencil", rise=0.08, max_slip=0.0015, grasp_frame=25, max_tilt_deg=3.0), hand=hand)


def hand_can_power() -> Scene:
    # can_power's can (66 x 115 mm, 350 g) in a power grasp of the hand: the can's axis along the
    # knuckle line under the palm, the index on top, the palm's deepest metacarpal placed 8 mm into
    # it; every fingertip (flexed as round a 42 mm radius) reaches by IK for the can's surface 3 mm
    # deep, the thumb across. The hand comes in from the side (-x), closes and lifts it 10 cm. The
    # thumb's and little finger's proximal bones, which IK drives through the can's inside, push it
    # toward the fingers: placed less deep, the palm ends up off the can.
    import numpy as np
    rig = _hand_rig()
    rad, h, squeeze, palm_squeeze = 0.033, 0.115, 0.003, 0.008
    can = Body("Can", Prism(rad, h, 32, angle=math.pi / 32), (0.0, 0.0, h / 2), mass=0.35, mu=(0.6, 0.5))
    axis_y = 0.065                               # hand frame: under the palm, toward the knuckles
    bones = {b.name: b for b in rig.hand_bones("RIGHT")}

    def depth(axis_z, b):                        # of a metacarpal capsule in the can (hand frame)
        a, c = np.array(b.head)[1:], np.array(b.tail)[1:]
        t = np.clip(np.dot((axis_y, axis_z) - a, c - a) / np.dot(c - a, c - a), 0.0, 1.0)
        return rad + b.radius - float(np.linalg.norm(a + t * (c - a) - (axis_y, axis_z)))
    palms = [bones[f"palm.0{k}.R"] for k in (1, 2, 3, 4)]
    axis_z = -(rig.PALM_RADIUS + rad)
    axis_z -= max(depth(axis_z, b) for b in palms) - palm_squeeze
    # hand x (index to little) -> world -z, hand y (fingers) -> world -y, palmar (-z) -> world +x
    rot = np.array([[0.0, 0.0, -1.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0]])
    wrist = np.array((0.0, 0.0, h / 2)) - rot @ np.array((0.0, axis_y, axis_z))
    tips = {}
    for finger, p in rig.fingertips("RIGHT", (25.0, 35.0, 20.0), (20.0, 30.0, 20.0)).items():
        v = np.array((0.0, p[1] - axis_y, p[2] - axis_z))   # the tip moved radially onto the surface
        v /= np.linalg.norm(v)
        surface = rot @ (np.array((p[0], axis_y, axis_z)) + rad * v) + wrist
        tips[finger] = _tip(finger, tuple(surface), tuple(rot @ v), squeeze)
    hand = Hand("RIGHT", tips, wrist_toward=(-1.0, 0.0, 0.0), placement=(rot.tolist(), tuple(wrist)),
                approach=(-1.0, 0.0, 0.0),
                touching=("palm.01", "f_index.03", "f_middle.03", "f_ring.03", "f_pinky.03", "thumb.03"))
    return Scene("hand_can_power", "The hand: a power grasp, the palm and the phalanges of the four fingers and "
                 "the thumb round a full 350 g can, lifts it off the table", [_table(), can], [], _lift_keys(0.10, 0.015),
                 Held("Can", rise=0.10, max_slip=0.003, grasp_frame=25, max_tilt_deg=5.0), hand=hand)


def hand_mug_handle() -> Scene:
    # mug_hook's full mug (350 g, its ring handle on its +x side, Collision Shape Automatic) lifted
    # by the hand's index hooked through the handle: the palm up, the index reaching in along -y
    # (its tip in the handle's hole near its outer side, as mug_hook's fingertip), the other
    # fingers and the thumb curled; the hand lifts 12 cm and the mug hangs from the index. The
    # mug stands on a coaster, so that the back of the hand passes below its top.
    import numpy as np
    rad, h = 0.04, 0.09
    ring = Ring(major=0.024, minor=0.006)
    ring_x, ring_z = rad + 0.010, h / 2 - 0.030
    mug = Body("Mug", Union(((Prism(rad, h, 32), (0.0, 0.0, 0.0)), (ring, (ring_x, 0.0, ring_z)))),
               (0.0, 0.0, h / 2), mass=0.35, mu=(0.6, 0.5), collision="AUTO")
    r = _hand_rig().RADII["index"][2]
    inside = (ring_x + 0.006, 0.0, h / 2 + ring_z)
    tips = {"index": Finger("index", inside, (0.0, 1.0, 0.0), radius=r, stiffness=1500.0, damping=3.0)}
    rot = np.diag([1.0, -1.0, -1.0])             # palm up, the fingers along -y
    ready = _hand_rig().fingertips("RIGHT", (-20.0, -15.0, -10.0))["index"]      # straight, level with the palm
    wrist = np.array(inside) - rot @ np.array(ready)
    hand = Hand("RIGHT", tips, wrist_toward=(0.0, 1.0, 0.0), placement=(rot.tolist(), tuple(wrist)),
                touching=("f_index.03",), stiffness=1500.0)
    keys = [Key(1, "rest", 0.04), Key(7, "reach in", 0.04), Key(25, "lift", 0.0),
            Key(73, "hold", 0.0, (0.0, 0.0, 0.12)), Key(145, "end", 0.0, (0.0, 0.0, 0.12))]
    stand = _table(size=(0.10, 0.10, 0.02), name="Stand")     # a coaster: the hand below its edge
    return Scene("hand_mug_handle", "The hand: the index hooked through a full mug's handle lifts it; the mug "
                 "hangs from the finger", [stand, mug], [], keys,
                 Hangs("Mug", "f_index.03", rise=0.05, max_offset=0.003), hand=hand)


HAND_SCENES = {f.__name__: f for f in (hand_pinch, hand_tripod_pencil, hand_can_power, hand_mug_handle)}


def all_scenes() -> dict:
    """Every scene: the fingertip scenes, then the hand's."""
    return {**SCENES, **HAND_SCENES}


def scene(name) -> Scene:
    scenes = all_scenes()
    if name not in scenes:
        raise KeyError(f"no scene {name!r} in the library (have {', '.join(scenes)})")
    return scenes[name]()


# --------------------------------------------------------------------------- devices

# Scenes that several devices drive, each one person's (or one hand's) fingers: the Finger
# groups, a device each. ``build`` declares them in the scene's device list without a port (a
# port is the machine's, not the file's); ``grasp-lab run --device`` and Find Devices' + give them
# theirs, and meanwhile their fingers follow the animation. Each device's workspace frame is the
# world's, so an emulator playing its group's fingertips of the file
# (``grasp-lab emulate --pty --from SCENE.blend --first K --fingers N``) drives them as animated.
DEVICES = {"two_people_box": ("A", "B")}


def device_fingers(sc: Scene, group: str) -> tuple:
    """(first channel, count) of a group's fingers: consecutive channels, as a device drives them."""
    channels = [i for i, f in enumerate(sc.fingers) if f.group == group]
    if not channels or channels != list(range(channels[0], channels[0] + len(channels))):
        raise ValueError(f"{sc.name}: the fingers of {group!r} must be consecutive, got channels {channels}")
    return channels[0], len(channels)


def _add_devices(bpy, sc: Scene) -> None:
    bscene = bpy.context.scene
    for group in DEVICES.get(sc.name, ()):
        first, count = device_fingers(sc, group)
        frame = bpy.data.objects.new(f"Device {group} frame", None)
        frame.empty_display_type = "ARROWS"
        frame.empty_display_size = 0.05
        bscene.collection.objects.link(frame)
        entry = bscene.grasp_lab_devices.add()
        entry.kind, entry.port = "SERIAL", ""
        entry.finger_offset, entry.num_fingers, entry.frame = first, count, frame


# --------------------------------------------------------------------------- meshes

def _shape_geometry(shape):
    """(vertices, faces) of a closed outward-facing mesh, faces as index tuples."""
    if isinstance(shape, Box):
        sx, sy, sz = (s / 2 for s in shape.size)
        verts = [(x, y, z) for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)]
        faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
        return verts, faces
    if isinstance(shape, Prism):
        n, r, hz = shape.sides, shape.radius, shape.height / 2
        ring = [(r * math.cos(shape.angle + 2 * math.pi * i / n), r * math.sin(shape.angle + 2 * math.pi * i / n))
                for i in range(n)]
        verts = [(x, y, -hz) for x, y in ring] + [(x, y, hz) for x, y in ring]
        faces = [tuple(range(n - 1, -1, -1)), tuple(range(n, 2 * n))]
        faces += [(i, (i + 1) % n, n + (i + 1) % n, n + i) for i in range(n)]
        return verts, faces
    if isinstance(shape, Ring):
        n, m, big, small = shape.segments, shape.tube_segments, shape.major, shape.minor
        verts = []
        for i in range(n):
            u = 2 * math.pi * i / n
            for j in range(m):
                v = 2 * math.pi * j / m
                rr = big + small * math.cos(v)
                verts.append((rr * math.cos(u), small * math.sin(v), rr * math.sin(u)))
        faces = []
        for i in range(n):
            for j in range(m):
                a, b = i * m + j, ((i + 1) % n) * m + j
                c, d = ((i + 1) % n) * m + (j + 1) % m, i * m + (j + 1) % m
                faces.append((a, d, c, b))
        return verts, faces
    if isinstance(shape, Union):
        verts, faces = [], []
        for sub, (dx, dy, dz) in shape.shapes:
            v, f = _shape_geometry(sub)
            base = len(verts)
            verts += [(x + dx, y + dy, z + dz) for x, y, z in v]
            faces += [tuple(base + i for i in face) for face in f]
        return verts, faces
    raise TypeError(f"unknown shape {shape!r}")


def _mesh(bpy, name, shape):
    me = bpy.data.meshes.new(name)
    verts, faces = _shape_geometry(shape)
    me.from_pydata(verts, [], faces)
    me.update()
    return me


# --------------------------------------------------------------------------- building

def finger_position(finger: Finger, key: Key):
    """The finger's HIP at a key: closed, opened along its outward direction, carried, and moved
    on its own (``key.moves``)."""
    own = key.moves.get(finger.name, (0.0, 0.0, 0.0))
    return tuple(c + key.opening * o + d + m
                 for c, o, d, m in zip(finger.closed, _unit(finger.outward), key.offset, own))


def build(bpy, name):
    """Create scene ``name`` in the current (empty) file. Returns the Scene description."""
    sc = scene(name)
    bscene = bpy.context.scene
    bscene[DESCRIPTION_KEY] = sc.description
    bscene.render.fps, bscene.render.fps_base = FPS, 1.0
    bscene.frame_start, bscene.frame_end = sc.keys[0].frame, sc.frame_end
    bscene.unit_settings.system = "METRIC"
    s = bscene.grasp_lab
    s.gravity = (0.0, 0.0, -G)
    s.haptic_rate = 1000.0
    s.duration = 0.0
    bscene.frame_set(bscene.frame_start)
    for b in sc.bodies:
        obj = bpy.data.objects.new(b.name, _mesh(bpy, b.name, b.shape))
        obj.location = b.location
        bscene.collection.objects.link(obj)
        gl = obj.grasp_lab
        gl.role = "STATIC" if b.static else "DYNAMIC"
        gl.mu_s, gl.mu_d = b.mu
        if not b.static:
            gl.mass_mode = "MASS"
            gl.mass = b.mass
        gl.shape = b.collision
    for channel, f in enumerate(sc.fingers):
        if f.shape is None:                 # a fingertip sphere of Radius
            obj = bpy.data.objects.new(f.name, None)
            obj.empty_display_type = "SPHERE"
            obj.empty_display_size = f.radius
        else:                               # a convex finger of the mesh's hull (area contacts)
            obj = bpy.data.objects.new(f.name, _mesh(bpy, f.name, f.shape))
        bscene.collection.objects.link(obj)
        obj["grasp_lab_group"] = f.group
        gl = obj.grasp_lab
        gl.role = "FINGER"
        gl.radius, gl.stiffness, gl.damping, gl.channel = f.radius, f.stiffness, f.damping, channel
        gl.torsion = f.torsion
        for key in sc.keys:
            obj.location = finger_position(f, key)
            obj.keyframe_insert("location", frame=key.frame)
        _set_interpolation(bpy, obj, sc.interpolation)
    if sc.hand is not None:
        _add_hand(bpy, sc)
    _add_devices(bpy, sc)
    _add_view(bpy, sc)
    bscene.frame_set(bscene.frame_start)
    return sc


def extent(sc: Scene):
    """(centre, radius) of what the scene is about: its moving bodies where they start and where
    the hand carries them, and the fingertips at every key (the tables left out)."""
    import numpy as np
    pts = [finger_position(f, k) for f in sc.fingers for k in sc.keys]
    if sc.hand is not None:
        pts += _hand_points(sc)
    for f in sc.fingers:                    # a palm's or a pad's corners too
        if f.shape is not None:
            for k in sc.keys:
                pts.extend(np.array(_shape_geometry(f.shape)[0]) + np.array(finger_position(f, k)))
    carried = np.array([k.offset for k in sc.keys])
    for b in sc.bodies:
        if not b.static:
            verts = np.array(_shape_geometry(b.shape)[0]) + np.array(b.location)
            pts.extend((verts[None, :, :] + carried[:, None, :]).reshape(-1, 3))
    pts = np.array(pts)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2


VIEW_DIRECTION = (0.17, -0.455, 0.105)      # from what is shown toward the camera (the demo's)
CAMERA_LENS = 60.0


def _add_view(bpy, sc: Scene):
    """A camera (aimed by a TRACK_TO at "Camera Target") and a sun, hidden in the viewports (they
    would cross the grasp), and, when building files (in the background), every 3D viewport of
    the file framed on the scene with clipping for millimetre objects; a Blender with a window
    keeps the view its user has."""
    from mathutils import Vector
    bscene = bpy.context.scene
    centre, radius = extent(sc)
    bscene.render.resolution_x, bscene.render.resolution_y = 960, 600
    half_fov = math.atan(18.0 * 600 / 960 / CAMERA_LENS)   # vertical, 36 mm sensor across
    distance = 1.1 * radius / math.sin(half_fov)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = CAMERA_LENS
    cam.location = Vector(centre) + Vector(sc.view or VIEW_DIRECTION).normalized() * distance
    target = bpy.data.objects.new("Camera Target", None)
    target.location = centre
    for obj in (cam, target):
        bscene.collection.objects.link(obj)
    cam.constraints.new("TRACK_TO").target = target
    bscene.camera = cam
    light = bpy.data.objects.new("Light", bpy.data.lights.new("Light", "SUN"))
    light.rotation_euler = (math.radians(40), math.radians(10), math.radians(30))
    bscene.collection.objects.link(light)
    target.empty_display_size = radius / 10
    for obj in (cam, target, light):
        obj.hide_viewport = True
    if not bpy.app.background:
        return
    for screen in bpy.data.screens:
        for area in screen.areas:
            if area.type == "VIEW_3D":
                space = area.spaces[0]
                space.clip_start, space.clip_end = distance / 1000, distance * 100
                space.region_3d.view_location = centre
                space.region_3d.view_distance = distance


def _set_interpolation(bpy, obj, interpolation):
    """LINEAR, or BEZIER with flat (auto-clamped) handles: ease in and out of every key, no
    overshoot."""
    ad = obj.animation_data
    if bpy.app.version >= (4, 4, 0):
        from bpy_extras import anim_utils
        fcurves = anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot).fcurves
    else:
        fcurves = ad.action.fcurves
    for fc in fcurves:
        for kp in fc.keyframe_points:
            kp.interpolation = interpolation
            if interpolation == "BEZIER":
                kp.handle_left_type = kp.handle_right_type = "AUTO_CLAMPED"
        fc.update()


# --------------------------------------------------------------------------- running

@dataclass
class Result:
    """Per frame (from the start frame): the session's snapshots, stacked."""
    frames: object
    body_names: list
    finger_names: list
    poses: object               # (n_frames, n_bodies, 7)
    com: object                 # (n_frames, n_bodies, 3)
    hips: object                # (n_frames, n_fingers, 3)
    god_objects: object
    finger_forces: object       # rendered to the device
    states: object              # 0 free, 1 stick, 2 slip
    contacts: object            # body index, -1 none
    stats: dict = field(default_factory=dict)

    def body(self, name):
        return self.body_names.index(name)


def _session_module(bpy):
    import importlib
    for mod in bpy.context.preferences.addons.keys():
        if mod.endswith(".grasp_lab"):
            return importlib.import_module(f"{mod}.session")
    raise RuntimeError("the grasp_lab extension is not enabled")


def run(bpy, display_objects=False):
    """Run the current scene (built by ``build``) headless, frame by frame; returns a Result.
    ``display_objects``: god-objects and force/torque arrows in the scene too (the demo's);
    recording and baking follow the scene's settings."""
    import numpy as np
    session = _session_module(bpy)
    bpy.context.scene.grasp_lab.display_objects = display_objects
    s = session.BlenderSession(bpy.context, live=False)
    snaps = [s.snapshot]
    frames = [s.frame_start]
    try:
        for k in range(1, s.n_frames + 1):
            s.advance_frame(s.frame_start + k)
            snaps.append(s.snapshot)
            frames.append(s.frame_start + k)
    finally:
        res = s.finish()
    stack = lambda attr: np.array([getattr(p, attr) for p in snaps])   # noqa: E731
    return Result(np.array(frames), list(res.body_names), list(res.finger_names), stack("poses"),
                  stack("com"), stack("hips"), stack("god_objects"), stack("finger_forces"),
                  stack("finger_states"), stack("contacts"), dict(res.stats))


# --------------------------------------------------------------------------- measuring

def _angle_deg(q0, q1):
    import numpy as np
    d = abs(float(np.dot(q0, q1))) / (np.linalg.norm(q0) * np.linalg.norm(q1))
    return math.degrees(2.0 * math.acos(min(1.0, d)))


def measure(sc: Scene, r: Result) -> dict:
    """The numbers the scene's claim is about, from a simulated Result."""
    import numpy as np
    c = sc.claim
    fr = list(r.frames)
    out = {}
    if isinstance(c, (Held, Carried)):
        i = r.body(c.body)
        g = fr.index(c.grasp_frame)
        centroid = r.hips[:, _with_the_hand(sc, r)].mean(axis=1)
        rel = (r.com[:, i] - centroid) - (r.com[g, i] - centroid[g])
        lifted = fr.index(sc.frames_of("hold")[0])         # the first hold: lifted
        out["rise"] = float(r.com[lifted, i, 2] - r.com[0, i, 2])
        out["slip"] = float(np.linalg.norm(rel[g:], axis=1).max())
        out["tilt_deg"] = max(_angle_deg(r.poses[g, i, 3:], q) for q in r.poses[g:, i, 3:])
        hold = [fr.index(f) for f in sc.frames_of("hold")]
        touching = r.contacts[g] == i
        out["fingers_touching"] = int(touching.sum())
        # what the finger springs alone give under the load (all in parallel): part of "slip"
        load = sum(sc.body(n).mass for n in (c.body,) + tuple(getattr(c, "riders", ()))) * G
        if sc.hand is not None:                 # the bones that must touch it
            out["not_touching"] = [b for b in _hand_bone_fingers(sc, r, sc.hand.touching) if not touching[b]]
        elif not any(f.shape is not None for f in sc.fingers):  # a palm's stiffness is per point of contact
            out["spring_give"] = load / sum(f.stiffness for f, t in zip(sc.fingers, touching) if t)
        out["slipping_frames"] = int((r.states[hold][:, touching] == 2).any(axis=1).sum())
        if isinstance(c, Carried):
            shifts = []
            for name in c.riders:
                j = r.body(name)
                shifts.append(float(np.linalg.norm(_in_frame(r.poses[:, i], r.com[:, j])
                                                   - _in_frame(r.poses[:1, i], r.com[:1, j]), axis=1).max()))
            out["rider_shift"] = max(shifts)
            weight = G * sum(sc.body(n).mass for n in (c.body,) + tuple(c.riders))
            up = -r.finger_forces[hold][:, :, 2].sum(axis=1)     # the device's force is the reaction
            out["felt_load"] = float(up.mean())
            out["weight"] = weight
    elif isinstance(c, Slides):
        i = r.body(c.body)
        centroid = r.hips.mean(axis=1)
        rel_z = r.com[:, i, 2] - centroid[:, 2]
        held = fr.index(sc.frames_of("ease off")[0])
        out["drop"] = float(rel_z[held] - rel_z.min())
        out["end_z"] = float(r.com[-1, i, 2])
        out["rest_z"] = float(r.com[0, i, 2])
        # slip onset: the first frame after the hold where a finger slips (the core's state);
        # the grip per finger just before it
        moved = np.nonzero((r.states[held:] == 2).any(axis=1))[0]
        if len(moved):
            onset = held + int(moved[0])
            grip = np.abs(r.finger_forces[:, :, 0]).mean(axis=1)
            body = sc.body(c.body)
            n_f = len(sc.fingers)
            out["onset_frame"] = int(fr[onset])
            out["grip_before"] = float(grip[onset - 1])
            out["grip_at_onset"] = float(grip[onset])
            out["just_enough"] = body.mass * G / (n_f * body.mu[0])
    elif isinstance(c, Hangs):
        i = r.body(c.body)
        f = _hand_bone_fingers(sc, r, [c.finger])[0] if sc.hand is not None else r.finger_names.index(c.finger)
        out["rise"] = float(r.com[-1, i, 2] - r.com[0, i, 2])
        d = r.com[-c.window:, i, :2] - r.god_objects[-c.window:, f, :2]
        out["com_offset"] = float(np.linalg.norm(d.mean(axis=0)))
        out["swing"] = float(np.linalg.norm(d, axis=1).max())
        out["touching"] = bool((r.contacts[-c.window:, f] == i).all())
        out["tilt_deg"] = float(np.mean([_angle_deg(r.poses[0, i, 3:], q) for q in r.poses[-c.window:, i, 3:]]))
    return out


def _with_the_hand(sc: Scene, r: Result) -> list:
    """Indices of the fingers that only move with the hand (none of the keys moves them on
    their own): what a held body's motion in the hand is measured against. The hand's bones
    all do (its tips hold still in it from the squeeze on)."""
    if sc.hand is not None:
        return list(range(len(r.finger_names)))
    return [i for i, f in enumerate(sc.fingers) if not any(f.name in k.moves for k in sc.keys)]


def hand_armature_name(sc: Scene) -> str:
    return "Hand" + _hand_rig().SUFFIX[sc.hand.side]


def _hand_bone_fingers(sc: Scene, r: Result, bones) -> list:
    """The fingers (indices in the result) of the hand's bones named without their side suffix."""
    arm, suffix = hand_armature_name(sc), _hand_rig().SUFFIX[sc.hand.side]
    return [r.finger_names.index(f"{arm}:{b}{suffix}") for b in bones]


def _in_frame(pose, points):
    """World points in a body's frame: pose (n, 7), points (n, 3)."""
    import numpy as np
    q = pose[:, 3:].copy()
    q[:, 1:] *= -1.0                         # inverse rotation
    v = points - pose[:, :3]
    w, u = q[:, :1], q[:, 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def verdict(sc: Scene, m: dict) -> list:
    """What breaks the scene's claim, as text (empty: it does what it shows)."""
    c = sc.claim
    bad = []
    if isinstance(c, (Held, Carried)):
        if m["rise"] < c.rise - 0.005:
            bad.append(f"rose {m['rise'] * 1e3:.1f} mm, not {c.rise * 1e3:.0f}")
        if isinstance(c, Held) and m["slip"] > c.max_slip:
            bad.append(f"moved {m['slip'] * 1e3:.2f} mm in the fingers (at most {c.max_slip * 1e3:.2f})")
        if isinstance(c, Held) and m["tilt_deg"] > c.max_tilt_deg:
            bad.append(f"turned {m['tilt_deg']:.2f} deg (at most {c.max_tilt_deg})")
        if m["slipping_frames"]:
            bad.append(f"a finger slipped in {m['slipping_frames']} hold frames")
        if sc.hand is not None:
            if m["not_touching"]:
                bad.append(f"{len(m['not_touching'])} of {len(sc.hand.touching)} bones that hold it do not touch it")
        elif m["fingers_touching"] != len(sc.fingers):
            bad.append(f"{m['fingers_touching']} of {len(sc.fingers)} fingers touch it")
        if isinstance(c, Carried):
            if m["rider_shift"] > c.max_shift:
                bad.append(f"a rider shifted {m['rider_shift'] * 1e3:.2f} mm on it")
            if abs(m["felt_load"] - m["weight"]) > c.load_tolerance * m["weight"]:
                bad.append(f"fingers felt {m['felt_load']:.3f} N, the load is {m['weight']:.3f} N")
    elif isinstance(c, Slides):
        if m["drop"] < c.min_drop:
            bad.append(f"dropped {m['drop'] * 1e3:.1f} mm in the fingers, not {c.min_drop * 1e3:.0f}")
        if abs(m["end_z"] - m["rest_z"]) > 0.001:
            bad.append(f"ended at z {m['end_z'] * 1e3:.1f} mm, not back on the table")
        if "onset_frame" not in m:
            bad.append("never slipped")
        elif not (m["grip_at_onset"] * (1 - c.onset_tolerance) <= m["just_enough"]
                  <= m["grip_before"] * (1 + c.onset_tolerance)):
            bad.append(f"slipped between {m['grip_before']:.3f} and {m['grip_at_onset']:.3f} N per "
                       f"finger, just enough is {m['just_enough']:.3f} N")
    elif isinstance(c, Hangs):
        if m["rise"] < c.rise:
            bad.append(f"rose {m['rise'] * 1e3:.1f} mm (at least {c.rise * 1e3:.0f})")
        if not m["touching"]:
            bad.append("the finger lost the handle")
        if m["com_offset"] > c.max_offset:
            bad.append(f"centre of mass {m['com_offset'] * 1e3:.1f} mm off the finger's vertical")
    return bad


# --------------------------------------------------------------------------- command line

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "build", "scenes"), help="where the .blend files go")
    ap.add_argument("--only", nargs="+", choices=sorted(all_scenes()), help="these scenes only")
    ap.add_argument("--run", action="store_true", help="also run each scene and print its outcome")
    ap.add_argument("--no-save", action="store_true", help="do not write .blend files")
    ap.add_argument("--zip", help="install the extension from this built zip (default: $GRASP_LAB_ZIP, "
                                  "else a development repository of addon/)")
    args = ap.parse_args(argv)
    sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
    import grasp_env                 # isolates Blender's user resources, then loads the add-on
    grasp_env.isolate()
    import bpy
    grasp_env.enable(args.zip)
    failed = 0
    for name in args.only or all_scenes():
        bpy.ops.wm.read_homefile(use_empty=True)
        sc = build(bpy, name)
        if not args.no_save:
            os.makedirs(args.out, exist_ok=True)
            path = os.path.abspath(os.path.join(args.out, f"{name}.blend"))
            if os.path.exists(path):
                os.remove(path)              # written anew, not kept as a .blend1 backup
            bpy.ops.wm.save_as_mainfile(filepath=path, compress=True)
            print(f"{path} ({os.path.getsize(path) / 1024:.0f} kB): {sc.description}")
        if args.run:
            m = measure(sc, run(bpy))
            bad = verdict(sc, m)
            failed += bool(bad)
            print(f"  {name}: " + ", ".join(f"{k} {v:.6g}" if isinstance(v, float) else f"{k} {v}"
                                            for k, v in m.items()))
            print(f"  {name}: " + ("OK" if not bad else "FAILS: " + "; ".join(bad)))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
