"""Body and finger defaults: the core's own (``gc_default_body_def`` /
``gc_default_finger_def``, exposed as ``graspcore.BODY_DEFAULTS`` / ``FINGER_DEFAULTS``),
read from the core rather than written again here."""
from __future__ import annotations

from .core_loader import load


def body(name: str) -> float:
    return float(load().BODY_DEFAULTS[name])


def finger(name: str) -> float:
    return float(load().FINGER_DEFAULTS[name])


def renderer() -> str:
    """The default finger renderer: ``"xfca"`` (``"cursor"``: the light-mass cursor)."""
    return str(load().FINGER_DEFAULTS["renderer"])
