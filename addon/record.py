"""Recording a Blender session: where the file goes and what its header says
(the format and the recorder are bpy-free: engine/recording/)."""
from __future__ import annotations

import os
import time

import bpy

from .engine import defaults
from .engine.recording import RecordingWriter, SessionRecorder, make_header, naming
from .engine.runner import RUNTIME_PHYSICS

# The core's runtime defaults (graspcore.RUNTIME_DEFAULTS) that the header records when a
# session's options leave them as they are: the recorder reads clamping and watchdog events
# against them, and a re-simulation replays the object manager with the physics ones.
RECORDED_RUNTIME_DEFAULTS = ("max_force", "ramp_time", "watchdog_timeout", "hip_timeout") + RUNTIME_PHYSICS


def user_folder(create: bool = False) -> str:
    """The per-user Grasp Lab recordings folder, for files not saved yet: the extension's
    own user folder (``<Blender's user extensions>/.user/<repo>/grasp_lab/recordings``), or
    Blender's user data folder when the add-on is not an extension (a development checkout)."""
    try:
        base = bpy.utils.extension_path_user(__package__, create=create)
    except (ValueError, AttributeError, TypeError):
        base = bpy.utils.user_resource("DATAFILES", path="grasp_lab", create=create)
    return os.path.join(base, "recordings")


def folder_of(settings) -> str:
    """The absolute folder this scene's sessions record to (engine.recording.naming)."""
    return naming.recording_folder(settings.recording_folder, bpy.data.filepath, user_folder())


def default_path(settings) -> str:
    folder = folder_of(settings)
    os.makedirs(folder, exist_ok=True)
    label = naming.scene_label(bpy.data.filepath, settings.id_data.name)
    return os.path.join(folder, naming.recording_name(label, time.time(), folder))


def latest_recording(settings) -> str:
    """The recording a bake most likely wants: the last one made (or baked) here, else the
    newest .mcap in the recording folder; "" when there is none."""
    last = bpy.path.abspath(settings.last_recording) if settings.last_recording else ""
    if last and os.path.isfile(last):
        return last
    folder = folder_of(settings)
    try:
        found = [os.path.join(folder, f) for f in os.listdir(folder) if f.endswith(".mcap")]
    except OSError:
        return ""
    return max(found, key=os.path.getmtime) if found else ""


def session_recorder(session, path, threaded: bool, options: dict) -> SessionRecorder:
    """A recorder for a BlenderSession about to start (path None: the scene's recording folder)."""
    s = session.settings
    path = bpy.path.abspath(path) if path else default_path(s)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    recorded = {name: defaults.runtime(name) for name in RECORDED_RUNTIME_DEFAULTS}
    runtime = dict(recorded, **options, threaded=True) if threaded else {"threaded": False}
    header = make_header(
        session.desc, mode="realtime" if threaded else "exec", haptic_rate=s.haptic_rate,
        fps=session.fps, source=bpy.data.filepath,
        device=session.input_description(),
        runtime=runtime,
        extra={"scene_name": session.scene.name, "frame_start": session.frame_start})
    return SessionRecorder(RecordingWriter(path, header), session.handle.world)
