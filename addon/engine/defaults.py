"""World, body, finger and runtime defaults and the names of the core's enums: the core's own
(``gc_default_world_def`` / ``gc_default_body_def`` / ``gc_default_finger_def`` / ``gc_default_runtime_def``, exposed as
``graspcore.WORLD_DEFAULTS`` / ``BODY_DEFAULTS`` / ``FINGER_DEFAULTS`` / ``RUNTIME_DEFAULTS``; ``graspcore.RENDERERS``),
read from the core rather than written again here."""
from __future__ import annotations

from .core_loader import load


def world(name: str):
    """A world setting's default, of the core's type (``gravity`` a 3-tuple of floats)."""
    return load().WORLD_DEFAULTS[name]


def body(name: str) -> float:
    return float(load().BODY_DEFAULTS[name])


def finger(name: str) -> float:
    return float(load().FINGER_DEFAULTS[name])


def runtime(name: str):
    """A runtime setting's default, of the core's type (``max_adopted_bodies`` is an int)."""
    return load().RUNTIME_DEFAULTS[name]


def renderer() -> str:
    """The default finger renderer: ``"xfca"`` (``"cursor"``: the light-mass cursor)."""
    return str(load().FINGER_DEFAULTS["renderer"])


def renderers() -> tuple[str, ...]:
    """Every finger renderer the core has, by name."""
    return tuple(load().RENDERERS)
