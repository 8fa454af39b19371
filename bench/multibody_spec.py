"""Geometry shared by the multi-body benchmark's engines (pure numpy; imported in .venv
by bench/bench_multibody.py and in .venv-bench by bench/multibody_mujoco.py and
bench/scenes_pybullet.py)."""
from __future__ import annotations

import numpy as np


def quat_matrix(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def finger_touch(spec: dict) -> list[tuple[int, np.ndarray]]:
    """(index of the held body, fingertip centre at first touch) per finger. The held body
    is the dynamic box whose face the HIP sits behind (the HIP inside the box grown by the
    tip radius); the touch point is the HIP moved out along that face's normal until the
    sphere just touches the face."""
    out = []
    for f in spec["fingers"]:
        hip, r = np.asarray(f["hip"], float), float(f["radius"])
        best = None
        for i, b in enumerate(spec["bodies"]):
            if b["static"]:
                continue
            R = quat_matrix(b["orientation"])
            local = R.T @ (hip - np.asarray(b["position"], float))
            depth = np.asarray(b["half"], float) + r - np.abs(local)   # > 0 on every axis: inside
            if np.all(depth > 0):
                k = int(np.argmin(depth))
                if best is None or depth[k] < best[0]:
                    n = np.zeros(3)
                    n[k] = np.sign(local[k])
                    best = (depth[k], i, hip + depth[k] * (R @ n))
        if best is None:
            out.append((-1, hip))
        else:
            out.append((best[1], best[2]))
    return out


def held_bodies(spec: dict) -> list[int]:
    """Indices (into spec["bodies"]) of the bodies the fingers hold."""
    return sorted({i for i, _ in finger_touch(spec) if i >= 0})
