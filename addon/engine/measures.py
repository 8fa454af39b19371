"""Per-finger and per-body measures of a session, from tick records (bpy-free).

Shared by the bake (animated properties for the Graph Editor) and the viewer channels
(plots in Foxglove), so both show the same numbers.
"""
from __future__ import annotations

import numpy as np


def finger_measures(rec, ticks) -> dict:
    """Per finger (n, nf): |F|, |Fn|, |Ft|, friction use |Ft| / (mu_s |Fn|), state."""
    f, n = np.ascontiguousarray(ticks["force"]), np.ascontiguousarray(ticks["normal"])
    fn = np.einsum("ijk,ijk->ij", f, n)
    tangential = f - fn[:, :, None] * n
    ft = np.sqrt(np.einsum("ijk,ijk->ij", tangential, tangential))
    contact = ticks["contact"]
    mu = np.array([b["mu_s"] for b in rec.header["scene"]["bodies"]] + [np.nan])
    mu_c = mu[np.where(contact >= 0, contact, len(mu) - 1)]
    with np.errstate(divide="ignore", invalid="ignore"):
        use = np.where((contact >= 0) & (np.abs(fn) > 1e-12), ft / (mu_c * np.abs(fn)), 0.0)
    return {"gl_state": ticks["state"].astype(np.float64), "gl_force": np.sqrt(np.einsum("ijk,ijk->ij", f, f)),
            "gl_normal_force": np.abs(fn), "gl_tangential_force": ft, "gl_friction_use": use}


def body_grip(contact: np.ndarray, normal_force: np.ndarray, n_bodies: int) -> np.ndarray:
    """Per body (n, nb): the sum of |Fn| of the fingers touching it. ``contact`` and
    ``normal_force`` are (n, nf)."""
    grip = np.zeros((len(contact), n_bodies))
    on = contact >= 0
    rows, fingers = np.nonzero(on)
    np.add.at(grip, (rows, contact[on]), normal_force[rows, fingers])
    return grip
