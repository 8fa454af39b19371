"""Shared scene builders for the core tests (imported as a plain module)."""
import numpy as np


def box_points(hx, hy, hz, center=(0.0, 0.0, 0.0)):
    """The 8 corners of a box with half extents (hx, hy, hz)."""
    c = np.asarray(center, dtype=float)
    return np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)]) + c


def prism_points(radius, half_length, sides=6):
    """A regular prism along x (a pencil)."""
    angles = 2 * np.pi * np.arange(sides) / sides
    ring = np.stack([np.zeros(sides), radius * np.cos(angles), radius * np.sin(angles)], axis=1)
    return np.concatenate([ring + [-half_length, 0, 0], ring + [half_length, 0, 0]])


def quat_to_matrix(q):
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
