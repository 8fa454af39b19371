"""The Robustness panel (Grasp tab): a sweep (docs/sweeps.md) of the last recording in a background
process, with a progress bar, Cancel, and the map in the sidebar when it is done
(docs/blender.md). The operator starts the sweep and returns; an application timer polls it
(engine/background_sweep.py), so Blender never waits for it."""
from __future__ import annotations

import os
import zlib

import bpy
import bpy.utils.previews
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from . import record, ui
from .engine.background_sweep import BackgroundSweep, panel_varies, sweep_folder
from .engine.background_sweep import recording_verdict as recording_words
from .engine.recording import RecordingError, open_recording
from .engine.sweep import SweepError

POLL_INTERVAL = 0.25        # s between the timer's looks at the sweep

_jobs = {}                  # scene name -> BackgroundSweep (the one running or last run there)
_previews = None            # bpy.utils.previews collection of the maps shown


NEWEST = "NEWEST"           # the recording list's first entry: whichever recording is newest
_verdicts = {}              # recording path -> ((mtime, size), its verdict in words)
_items = []                 # the recording list's items: Blender needs them kept alive


def recording_verdict(path: str) -> str:
    """background_sweep.recording_verdict of a recording file, read once per version of it."""
    try:
        st = os.stat(path)
    except OSError:
        return "missing"
    key = (st.st_mtime_ns, st.st_size)
    cached = _verdicts.get(path)
    if cached is None or cached[0] != key:
        try:
            text = recording_words(open_recording(path))
        except (RecordingError, OSError, ValueError, KeyError) as ex:
            text = f"unreadable: {ex}"
        cached = _verdicts[path] = (key, text)
    return cached[1]


def scene_recordings(scene) -> list:
    """The scene's recordings, newest first: the .mcap files of its recording folder, and the
    last one it made or baked if that is elsewhere."""
    folder = record.folder_of(scene.grasp_lab)
    try:
        found = [os.path.join(folder, f) for f in os.listdir(folder) if f.endswith(".mcap")]
    except OSError:
        found = []
    last = record.latest_recording(scene.grasp_lab)
    if last and last not in found:
        found.append(last)
    return sorted(found, key=lambda p: os.path.getmtime(p) if os.path.exists(p) else 0.0, reverse=True)


def _recording_items(self, context):
    # Each item's number is fixed by its path, so a choice stays on its file as new ones arrive.
    global _items
    scene = context.scene if context is not None else None
    paths = scene_recordings(scene) if scene is not None else []
    # The first item (the default) follows the newest recording; the others stay on their file.
    newest = "Newest recording" if paths else "No recording yet"
    _items = [(NEWEST, newest, "The newest recording of the scene", "TIME", 0)]
    _items += [(p, f"{os.path.basename(p)}: {recording_verdict(p)}", p, "FILE",
                1 + zlib.crc32(p.encode()) % 0x7FFFFFFE) for p in paths]
    return _items


def chosen_recording(scene) -> str:
    """The recording the panel sweeps: the one picked in its list, else the newest."""
    picked = _settings(scene).recording
    if picked != NEWEST and os.path.isfile(picked):
        return picked
    found = scene_recordings(scene)
    return found[0] if found else ""


class GRASPLAB_PG_robustness(bpy.types.PropertyGroup):
    recording: EnumProperty(name="Recording", items=_recording_items,
                            description="The recording to sweep: the scene's recordings, newest first, each "
                                        "with what it holds (only a held body can be swept)")
    vary_friction: BoolProperty(name="Friction", default=True,
                                description="Vary the held body's static friction uniformly in the range")
    friction_min: FloatProperty(name="μs from", default=0.2, min=0.0, soft_max=2.0)
    friction_max: FloatProperty(name="to", default=1.0, min=0.0, soft_max=2.0)
    vary_mass: BoolProperty(name="Mass", default=True,
                            description="Vary the held body's mass uniformly, as factors of its recorded mass")
    mass_min: FloatProperty(name="× from", default=0.5, min=0.01, soft_max=10.0)
    mass_max: FloatProperty(name="to", default=2.0, min=0.01, soft_max=10.0)
    vary_hip_noise: BoolProperty(name="Fingertip noise", default=False,
                                 description="Gaussian noise on every fingertip position, every tick")
    hip_noise: FloatProperty(name="SD", default=0.001, min=0.0, soft_max=0.01, unit="LENGTH", precision=4)
    vary_push: BoolProperty(name="Push", default=False,
                            description="A force pulse (0.05 s) on the held body in a random direction")
    push_min: FloatProperty(name="N from", default=0.0, min=0.0, soft_max=50.0)
    push_max: FloatProperty(name="to", default=5.0, min=0.0, soft_max=50.0)
    push_time: FloatProperty(name="at", default=1.5, min=0.0, unit="TIME_ABSOLUTE")
    samples: IntProperty(name="Samples", default=50, min=1, soft_max=10000)
    seed: IntProperty(name="Seed", default=0, min=0)
    workers: IntProperty(name="Workers", default=0, min=0, soft_max=64,
                         description="Worker processes (0: one per core)")
    # What the last sweep of this scene did (the panel's view of it; not edited by hand).
    progress: FloatProperty(name="Progress", default=0.0, min=0.0, max=1.0, subtype="FACTOR")
    status: StringProperty(name="Status", default="")
    map_path: StringProperty(name="Map", default="", subtype="FILE_PATH")
    axes: StringProperty(name="Axes", default="")


def _settings(scene):
    return scene.grasp_lab_robustness


def _varies(rec, r) -> list:
    return panel_varies(
        rec,
        friction=(r.friction_min, r.friction_max) if r.vary_friction else None,
        mass=(r.mass_min, r.mass_max) if r.vary_mass else None,
        hip_noise=r.hip_noise if r.vary_hip_noise else None,
        push=(r.push_min, r.push_max, r.push_time) if r.vary_push else None)


def running(scene) -> bool:
    job = _jobs.get(scene.name)
    return job is not None and job.running


class GRASPLAB_OT_robustness_sweep(bpy.types.Operator):
    """Re-simulate the last recording many times with the chosen variations, in background
    processes, and map how likely the grasp is to hold"""
    bl_idname = "grasp_lab.robustness_sweep"
    bl_label = "Run Sweep"

    @classmethod
    def poll(cls, context):
        return not running(context.scene)

    def execute(self, context):
        scene = context.scene
        r = _settings(scene)
        path = chosen_recording(scene)
        if not path:
            self.report({"ERROR"}, "Grasp Lab: no recording to sweep: record a session first")
            return {"CANCELLED"}
        try:
            varies = _varies(open_recording(path), r)
        except (RecordingError, SweepError, OSError) as ex:
            self.report({"ERROR"}, f"Grasp Lab: {ex}")
            return {"CANCELLED"}
        folder = sweep_folder(path, varies, r.samples, r.seed)
        job = BackgroundSweep(path, varies, r.samples, r.seed, folder, r.workers or os.cpu_count() or 1)
        try:
            job.start()
        except OSError as ex:
            self.report({"ERROR"}, f"Grasp Lab: could not start the sweep: {ex}")
            return {"CANCELLED"}
        _jobs[scene.name] = job
        r.progress, r.status, r.map_path = 0.0, job.describe(), ""
        r.axes = "   ".join(f"{axis}: {text}" for axis, text in zip(("→", "↑"), varies))
        if not bpy.app.timers.is_registered(sweep_tick):
            bpy.app.timers.register(sweep_tick, first_interval=POLL_INTERVAL)
        self.report({"INFO"}, f"Grasp Lab: sweeping {bpy.path.basename(path)} into {folder}")
        return {"FINISHED"}


class GRASPLAB_OT_robustness_cancel(bpy.types.Operator):
    """Stop the sweep; the samples it finished are kept (Run Sweep again resumes)"""
    bl_idname = "grasp_lab.robustness_cancel"
    bl_label = "Cancel"

    @classmethod
    def poll(cls, context):
        return running(context.scene)

    def execute(self, context):
        job = _jobs.get(context.scene.name)
        if job is not None:
            job.cancel()
            _show(context.scene, job)
        return {"FINISHED"}


def _show(scene, job) -> None:
    """The job's state into the scene's panel properties; the map loaded when there is one."""
    r = _settings(scene)
    r.progress = job.fraction
    r.status = job.describe()
    map_png = next((p for p in job.paths if os.path.basename(p) == "map.png"), "")
    if map_png and r.map_path != map_png:
        r.map_path = map_png
        map_icon(map_png, reload=True)


def map_icon(path: str, reload: bool = False) -> int:
    """The icon id of the map image at ``path`` (0 when it cannot be shown)."""
    global _previews
    if not path or not os.path.isfile(path):
        return 0
    if _previews is None:
        _previews = bpy.utils.previews.new()
    if reload and path in _previews:
        del _previews[path]
    item = _previews.get(path) or _previews.load(path, path, "IMAGE")
    return item.icon_id


def sweep_tick():
    """The application timer: every running sweep's progress into its scene's panel. Returns
    None (unregistered) once none runs."""
    any_running = False
    for name, job in list(_jobs.items()):
        scene = bpy.data.scenes.get(name)
        still = job.poll()
        if scene is not None:
            _show(scene, job)
        elif still:             # its scene is gone (file loaded): nobody to show it to
            job.cancel()
            still = False
        # polled until its process is collected too: no zombie left until Blender exits
        any_running |= still or not job.reap()
    try:
        ui_redraw()
    except (AttributeError, ReferenceError):
        pass
    return POLL_INTERVAL if any_running else None


def ui_redraw() -> None:
    wm = bpy.context.window_manager
    for win in wm.windows:
        for area in win.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


class GRASPLAB_PT_robustness(ui._GraspPanel, bpy.types.Panel):
    bl_label = "Robustness"
    bl_parent_id = "GRASPLAB_PT_main"

    def draw(self, context):
        layout = self.layout
        r = _settings(context.scene)
        path = chosen_recording(context.scene)
        layout.prop(r, "recording", text="")
        if path:
            ui.wrapped_labels(layout, context, [os.path.basename(path), f"  {recording_verdict(path)}"])
        else:
            ui.wrapped_labels(layout, context, ["Record a session first"])
        busy = running(context.scene)
        # The answer first, under the recording it is about; the settings after it.
        if r.status:
            ui.wrapped_labels(layout, context, [r.status])
        icon = map_icon(r.map_path) if not busy else 0
        if icon:
            box = layout.box()
            box.template_icon(icon_value=icon, scale=10.0)
            box.label(text="P(held): red 0, yellow ½, green 1")
            if r.axes:
                ui.wrapped_labels(box, context, [r.axes])
        col = layout.column(align=True)
        for flag, props in (("vary_friction", ("friction_min", "friction_max")),
                            ("vary_mass", ("mass_min", "mass_max")),
                            ("vary_hip_noise", ("hip_noise",)),
                            ("vary_push", ("push_min", "push_max", "push_time"))):
            col.prop(r, flag)
            row = col.row(align=True)
            row.active = getattr(r, flag)
            for p in props:
                row.prop(r, p)
        row = layout.row(align=True)
        row.prop(r, "samples")
        row.prop(r, "seed")
        layout.prop(r, "workers")
        if busy:
            row = layout.row(align=True)
            row.progress(factor=r.progress, type="BAR", text=f"{r.progress * 100:.0f} %")
            row.operator("grasp_lab.robustness_cancel", text="", icon="CANCEL")
        else:
            layout.operator("grasp_lab.robustness_sweep", icon="PLAY")


@bpy.app.handlers.persistent
def _cancel_all(*_args):
    """Another file is loaded (or Blender quits): the sweeps of this one's scenes end, their
    finished samples kept; the timer went with the file."""
    for job in _jobs.values():
        job.cancel()
    _jobs.clear()


CLASSES = (GRASPLAB_PG_robustness, GRASPLAB_OT_robustness_sweep, GRASPLAB_OT_robustness_cancel,
           GRASPLAB_PT_robustness)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Scene.grasp_lab_robustness = PointerProperty(type=GRASPLAB_PG_robustness)
    bpy.app.handlers.load_pre.append(_cancel_all)


def unregister():
    global _previews
    if _cancel_all in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.remove(_cancel_all)
    if bpy.app.timers.is_registered(sweep_tick):
        bpy.app.timers.unregister(sweep_tick)
    _cancel_all()
    if _previews is not None:
        bpy.utils.previews.remove(_previews)
        _previews = None
    del bpy.types.Scene.grasp_lab_robustness
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
