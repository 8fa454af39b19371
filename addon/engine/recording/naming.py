"""Where a Blender session's recording goes and what it is called (bpy-free): named after the
scene and the time, in a folder the user can find again. An unsaved .blend has no folder of
its own, so a folder relative to it ("//") would be Blender's working directory: such a
session records to the per-user Grasp Lab folder instead."""
from __future__ import annotations

import os
import re
import time

TIME_FORMAT = "%Y-%m-%d_%H-%M-%S"


def recording_stem(label: str) -> str:
    """A file-name-safe version of a scene's name: letters, digits, '-', '_' and '.' kept,
    anything else (spaces, slashes) an underscore; "recording" when nothing is left."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", label).strip("._")
    return stem or "recording"


def recording_name(label: str, when: float, folder: str = "") -> str:
    """``<label>_<YYYY-MM-DD_HH-MM-SS>.mcap`` (local time ``when``), e.g.
    ``tripod_pencil_2026-12-02_02-17-45.mcap``; with ``_2``, ``_3``... before the extension
    when ``folder`` already holds one of that name (two sessions in one second)."""
    base = f"{recording_stem(label)}_{time.strftime(TIME_FORMAT, time.localtime(when))}"
    name, k = f"{base}.mcap", 1
    while folder and os.path.exists(os.path.join(folder, name)):
        k += 1
        name = f"{base}_{k}.mcap"
    return name


def recording_folder(setting: str, blend_path: str, user_folder: str) -> str:
    """The absolute folder a session records to: ``setting`` (a folder, "//" meaning beside the
    .blend) resolved against ``blend_path``; an unsaved file (``blend_path`` "") with a
    relative setting records to ``user_folder``."""
    relative = setting.startswith("//") or not os.path.isabs(setting or "")
    if relative and not blend_path:
        return os.path.normpath(user_folder)
    if setting.startswith("//"):
        return os.path.normpath(os.path.join(os.path.dirname(blend_path), setting[2:]))
    if not os.path.isabs(setting or ""):
        return os.path.normpath(os.path.join(os.path.dirname(blend_path), setting))
    return os.path.normpath(setting)


def scene_label(blend_path: str, scene_name: str) -> str:
    """What a recording is named after: the .blend's name when it is saved (tripod_pencil),
    else the scene's (Scene)."""
    return os.path.splitext(os.path.basename(blend_path))[0] if blend_path else scene_name
