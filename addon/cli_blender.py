"""The command line inside Blender: the Blender commands' work (headless.py) in the command
line's table, and ``blender -c grasp_lab ...`` (Blender 4.2+)."""
from __future__ import annotations

import bpy

from . import headless
from .engine import cli

_handle = None


def _execute(argv):
    return cli.main(list(argv), prog="blender -c grasp_lab")


def register():
    global _handle
    cli.BLENDER_COMMANDS.update(headless.COMMANDS)
    if hasattr(bpy.utils, "register_cli_command"):
        _handle = bpy.utils.register_cli_command("grasp_lab", _execute)


def unregister():
    global _handle
    if _handle is not None:
        bpy.utils.unregister_cli_command(_handle)
        _handle = None
    for name in headless.COMMANDS:
        cli.BLENDER_COMMANDS.pop(name, None)
