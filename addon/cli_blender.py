"""``blender -c grasp_lab ...``: the grasp-lab command line inside Blender (4.2+)."""
from __future__ import annotations

import bpy

from .engine import cli

_handle = None


def _execute(argv):
    return cli.main(list(argv), prog="blender -c grasp_lab")


def register():
    global _handle
    if hasattr(bpy.utils, "register_cli_command"):
        _handle = bpy.utils.register_cli_command("grasp_lab", _execute)


def unregister():
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None
