"""The two-hand scene of bench/bench_hands.py, as plain data both engines build from (no
graspcore, no mujoco): two hands of 16 phalanx capsules and a palm each, holding three boxes
on a table. Hand A closes its 5 fingers on box 0 (3 on its +x face, 2 on its -x face); hand B,
10 cm away in x, holds boxes 1 and 2 side by side in y (its middle +x finger presses both).
Each finger is a straight chain hanging down from the palm; closing turns it about its first
joint until its tip's capsule is ``SQUEEZE`` inside the box's face, then both hands lift ``LIFT``.
Every phalanx's pose (head position, bone frame with +y from head to tail) is given per time."""
from __future__ import annotations

import math

import numpy as np

RADIUS = 0.008
PALM_RADIUS = 0.01
PALM_Z = 0.10
CLEARANCE = 0.005
SQUEEZE = 0.003
LIFT = 0.10
CLOSE_S, LIFT_START_S, LIFT_END_S = 0.5, 0.7, 1.7
BOX_MASS = 0.05
MU = 0.8
TABLE = {"half": (0.3, 0.3, 0.01), "position": (0.05, 0.0, -0.01)}


def _boxes():
    return [{"half": (0.025, 0.04, 0.02), "position": (0.0, 0.0, 0.02)},
            {"half": (0.025, 0.019, 0.02), "position": (0.10, -0.022, 0.02)},
            {"half": (0.025, 0.019, 0.02), "position": (0.10, 0.022, 0.02)}]


def _chains(x_centre):
    # (side, y, lengths): 4 fingers of 3 phalanges and a thumb of 4 (its metacarpal): 16 a hand
    return [(1, -0.025, (0.03, 0.025, 0.02)), (1, 0.0, (0.03, 0.025, 0.02)), (1, 0.025, (0.03, 0.025, 0.02)),
            (-1, -0.0125, (0.03, 0.025, 0.02)), (-1, 0.0125, (0.015, 0.015, 0.025, 0.02))]


def spec() -> dict:
    """Bodies (boxes, the table) and fingers (name, radius, length, chain, hand)."""
    fingers = []
    for hand, xc in (("A", 0.0), ("B", 0.10)):
        fingers.append({"name": f"{hand}:palm", "radius": PALM_RADIUS, "length": 0.06, "hand": hand, "chain": -1})
        for k, (side, y, lengths) in enumerate(_chains(xc)):
            for j, length in enumerate(lengths):
                fingers.append({"name": f"{hand}:f{k}.{j + 1}", "radius": RADIUS, "length": length, "hand": hand,
                                "chain": k})
    return {"boxes": _boxes(), "box_mass": BOX_MASS, "mu": MU, "table": TABLE, "fingers": fingers,
            "stiffness": 1000.0, "damping": 2.0}


def _smooth(u):
    u = min(max(u, 0.0), 1.0)
    return u * u * (3 - 2 * u)


def poses(t: float) -> tuple:
    """(positions (n, 3), rotation matrices (n, 3, 3)) of every finger at time ``t``, s: the
    bone frames (head, +y along the bone), in spec()'s order."""
    closed, lifted = _smooth(t / CLOSE_S), _smooth((t - LIFT_START_S) / (LIFT_END_S - LIFT_START_S))
    lift = np.array((0.0, 0.0, LIFT * lifted))
    pos, rot = [], []
    palm_r = np.eye(3)                                        # along +y
    for xc in (0.0, 0.10):
        pos.append(np.array((xc, -0.03, PALM_Z)) + lift)
        rot.append(palm_r)
        x0 = 0.025 + RADIUS + CLEARANCE
        for side, y, lengths in _chains(xc):
            theta = side * math.asin((CLEARANCE + SQUEEZE) / sum(lengths)) * closed
            # down (-z) turned about +y by theta: the tip toward the box
            down = np.array((-math.sin(theta), 0.0, -math.cos(theta)))
            x_axis = np.array((1.0, 0.0, 0.0)) * math.cos(theta) + np.array((0.0, 0.0, -1.0)) * math.sin(theta)
            z_axis = np.cross(x_axis, down)
            r = np.column_stack([x_axis, down, z_axis])
            head = np.array((xc + side * x0, y, PALM_Z)) + lift
            for length in lengths:
                pos.append(head.copy())
                rot.append(r)
                head = head + down * length
    return np.array(pos), np.array(rot)
