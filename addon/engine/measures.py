"""Per-finger and per-body measures of a session, from tick records (bpy-free).

Shared by the bake (animated properties for the Graph Editor) and the viewer channels
(plots in Foxglove), so both show the same numbers.
"""
from __future__ import annotations

import numpy as np

from . import analysis


def finger_measures(rec, ticks) -> dict:
    """Per finger (n, nf): |F|, |Fn|, |Ft|, friction use |Ft| / (mu |Fn|) with the mu of its
    current cone (mu_s sticking, mu_d slipping: analysis.friction_use; analysis.NONE where
    unbounded, a finger pulling), state."""
    f = np.ascontiguousarray(ticks["force"])
    fn, ft = analysis.contact_forces(f, ticks["normal"])
    contact = ticks["contact"]
    mu = analysis.cone_mu(analysis.body_models(rec.header["scene"]), ticks["state"], contact)
    use = np.where(contact >= 0, analysis.friction_use(ft, mu, fn), 0.0)
    return {"gl_state": ticks["state"].astype(np.float64), "gl_force": np.sqrt(np.einsum("ijk,ijk->ij", f, f)),
            "gl_normal_force": np.abs(fn), "gl_tangential_force": ft,
            "gl_friction_use": np.where(np.isfinite(use), use, analysis.NONE)}


def body_grip(contact: np.ndarray, normal_force: np.ndarray, n_bodies: int) -> np.ndarray:
    """Per body (n, nb): the sum of |Fn| of the fingers touching it. ``contact`` and
    ``normal_force`` are (n, nf)."""
    grip = np.zeros((len(contact), n_bodies))
    on = contact >= 0
    rows, fingers = np.nonzero(on)
    np.add.at(grip, (rows, contact[on]), normal_force[rows, fingers])
    return grip
