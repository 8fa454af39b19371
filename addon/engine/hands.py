"""Hands: armature bones as fingers (bpy-free part; docs/hands.md).

The names shared with the Add Hand builder and the bake: the rendered armature of
input armature ``A`` is the object ``A Rendered`` with the custom property
``grasp_lab_rendered_of = "A"``.
"""
from __future__ import annotations

RENDERED_SUFFIX = " Rendered"
RENDERED_OF_PROPERTY = "grasp_lab_rendered_of"


def rendered_name(armature_name: str) -> str:
    """The object name of the rendered armature of ``armature_name``."""
    return armature_name + RENDERED_SUFFIX
