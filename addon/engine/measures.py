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


# What each baked property is, with its unit: the tooltip of the property in Blender (the
# Graph Editor's channel and the Object properties' Custom Properties).
DESCRIPTIONS = {
    "gl_state": "Finger state: 0 free, 1 stick, 2 slip",
    "gl_force": "Magnitude of the force, N (on a god-object: rendered to the finger; on a body's "
                "force arrow: the residual force on the body)",
    "gl_normal_force": "Normal force |Fn| of the contact, N",
    "gl_tangential_force": "Tangential (friction) force |Ft| of the contact, N",
    "gl_friction_use": "Friction use |Ft| / (μ |Fn|), a ratio: 0 far from slipping, 1 at slip (-1: not bounded)",
    "gl_grip": "Grip: the sum of the normal forces of the fingers on the body, N",
    "gl_torque": "Magnitude of the residual torque on the body, N·m",
    "gl_held": "1 while a finger touches the body, else 0",
    "gl_closure": "1 while the grasp is in force closure, else 0",
    "gl_epsilon": "Epsilon grasp quality: the smallest wrench the grasp resists per unit of grip, "
                  "a ratio (0 out of closure)",
    "gl_mu_min": "Smallest friction coefficient μ that closes the grasp, a ratio (-1: none does)",
    "gl_slip_margin": "Smallest slip margin over the fingers: μ|Fn| - |Ft|, N",
    "gl_grip_load": "Grip force over load force (weight and inertia), a ratio",
}
