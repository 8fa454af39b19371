"""Where set-up helpers put things, bpy-free: a table under bodies that would fall, a device's
workspace frame among the fingers it drives. Positions are world metres, z up (Blender's)."""
from __future__ import annotations

import numpy as np

TABLE_SPAN = 3.0        # the table's side, in the bodies' footprint (the larger of x and y)
TABLE_THICKNESS = 0.2   # its thickness, in the same footprint
TABLE_MIN_SIDE = 0.1    # metres: a table for a pencil is still a table a hand can be put on


def needs_support(roles, gravity) -> bool:
    """True when a scene of these object roles (``"DYNAMIC"``, ``"STATIC"``, ...) would drop its
    bodies: a dynamic body, no static one (nothing to rest on) and gravity."""
    roles = list(roles)
    return "DYNAMIC" in roles and "STATIC" not in roles and float(np.linalg.norm(gravity)) > 0.0


def table_under(corners) -> tuple:
    """(centre, dimensions) of a box table whose top touches the bottom of the bodies whose
    world bounding-box corners are ``corners`` (any number of points, (n, 3)): centred under
    them, TABLE_SPAN times their footprint wide (at least TABLE_MIN_SIDE), TABLE_THICKNESS of it
    thick."""
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0 or not np.all(np.isfinite(pts)):
        raise ValueError("table_under: expected the finite corners of at least one body")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    footprint = max(hi[0] - lo[0], hi[1] - lo[1], 1e-6)
    side = max(TABLE_SPAN * footprint, TABLE_MIN_SIDE)
    thick = max(TABLE_THICKNESS * footprint, TABLE_MIN_SIDE * TABLE_THICKNESS)
    centre = ((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2] - thick / 2)
    return tuple(float(c) for c in centre), (float(side), float(side), float(thick))


DEVICE_REST_RADIUS = 0.06   # device metres: the emulator's fingertips at rest, on a ring this far from its origin
FRAME_SCALES = (0.01, 100.0)


def workspace_frame(finger_positions, fallback) -> tuple:
    """(origin, scale) of a new device's workspace frame, so that the device's rest pose (its
    fingertips on a ring DEVICE_REST_RADIUS about its origin, in its xy plane: the emulator's)
    lies on the scene's fingers: the origin at the centre of the fingers it drives, the scale
    their mean distance from it over DEVICE_REST_RADIUS (within FRAME_SCALES; 1 for one finger).
    A motion that closes the ring then closes the fingers on what they surround, whatever its
    size (an 8 mm pencil, Blender's 2 m cube). Without fingers: ``fallback`` (the 3D cursor),
    scale 1."""
    pts = np.asarray(finger_positions, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0 or not np.all(np.isfinite(pts)):
        return tuple(float(c) for c in fallback), 1.0
    centre = pts.mean(axis=0)
    spread = float(np.linalg.norm(pts - centre, axis=1).mean())
    scale = 1.0 if len(pts) < 2 or spread <= 0.0 else float(np.clip(spread / DEVICE_REST_RADIUS, *FRAME_SCALES))
    return tuple(float(c) for c in centre), scale
