"""The session: Blender glue around ``engine.runner.SessionRunner``.

``BlenderSession`` converts the scene, builds the world and the input source, and
after every advance writes body poses back and updates the display. The operator
``grasp_lab.session`` drives it:

* EXEC (scripts, headless): a plain loop over the frames, no timers;
* INVOKE (UI): a modal operator with a window-manager timer at the display rate.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import bpy
import numpy as np
from bpy.props import BoolProperty, FloatProperty

from . import anim, convert, core_loader, display, record
from .engine.inputs import SampledTrajectory
from .engine.runner import SessionRunner
from .engine.scene import SceneError, build_world, prepare
from .prefs import get_prefs


@dataclass
class SessionResult:
    """What the last session did (for scripts and tests): per display frame."""
    frames: list = field(default_factory=list)
    times: list = field(default_factory=list)
    poses: list = field(default_factory=list)       # (n_bodies, 7) per frame
    body_names: list = field(default_factory=list)
    finger_names: list = field(default_factory=list)
    stats: dict = field(default_factory=dict)
    recording: str = ""
    final: object = None                            # last Snapshot

    def trajectory(self, body_name) -> np.ndarray:
        i = self.body_names.index(body_name)
        return np.array([p[i] for p in self.poses])


last_result: SessionResult | None = None
_active = None      # the running live session (BlenderSession), if any


def active_session():
    return _active


class BlenderSession:
    def __init__(self, context, *, live: bool, duration: float | None = None, reset: bool = True,
                 record_path: str | None = None):
        scene = context.scene
        s = scene.grasp_lab
        self.scene = scene
        self.live = live
        self.settings = s
        prefs = get_prefs(context)
        gc = core_loader.load()
        # Sessions start at the first frame: fingertips (and any animated objects) there.
        self.frame_start = scene.frame_start
        scene.frame_set(self.frame_start)
        if reset:
            restore_rest_poses(context)
            context.view_layer.update()
        self.fps = scene.render.fps / scene.render.fps_base
        desc, self.links, finger_objs = convert.scene_description(context)
        if not desc.bodies and not desc.fingers:
            raise SceneError(scene.name, "nothing to simulate: give objects the role Dynamic, "
                                         "Static or Finger in the Grasp tab")
        prepare(desc)
        self.desc = desc
        self.handle = build_world(desc, gc)
        # Input: fingertips animated on the timeline (the scripted device).
        duration = s.duration if duration is None or duration < 0 else duration
        if duration > 0:
            n_frames = int(np.ceil(duration * self.fps - 1e-9))
        else:
            n_frames = max(scene.frame_end - scene.frame_start, 0)
        self.duration = duration if duration > 0 else n_frames / self.fps
        self.n_frames = n_frames
        times, pos = convert.sample_fingers(context, finger_objs, self.frame_start,
                                            min(self.frame_start + n_frames, scene.frame_end))
        self.source = SampledTrajectory(times, pos)
        use_runtime = live and prefs.use_runtime
        self.recorder = record.session_recorder(self, record_path, use_runtime) \
            if (record_path or s.record) else None
        self.runner = SessionRunner(self.handle, self.source, haptic_rate=s.haptic_rate,
                                    use_runtime=use_runtime, recorder=self.recorder)
        store_rest_poses(context, self.links)
        self.objects = [bpy.data.objects[link.name] for link in self.links]
        self.dynamic = [i for i, link in enumerate(self.links) if not link.static]
        self.display = display.DisplayObjects(scene, desc) if s.display_objects else None
        self.bake = s.bake
        self._baked = {}    # object name -> (frames, values)
        self.result = SessionResult(body_names=[b.name for b in desc.bodies],
                                    finger_names=[f.name for f in desc.fingers])
        self.snapshot = None
        self.finished = False
        self.runner.start()
        self.apply(self.runner.snapshot(), self.frame_start)

    # ------------------------------------------------------------- per update
    def apply(self, snap, frame):
        """Write body poses back and update the display objects."""
        self.snapshot = snap
        for i in self.dynamic:
            p = snap.poses[i]
            self.objects[i].matrix_world = self.links[i].matrix_world(p[:3], p[3:])
        if self.display is not None:
            s = self.settings
            self.display.update(snap, s.force_scale, s.torque_scale)
        r = self.result
        r.frames.append(frame)
        r.times.append(snap.time)
        r.poses.append(snap.poses.copy())
        if self.bake:
            objs = [self.objects[i] for i in self.dynamic]
            if self.display is not None:
                objs += self.display.objects
            for obj in objs:
                fr, vals = self._baked.setdefault(obj.name, ([], []))
                fr.append(frame)
                vals.append(anim.read_transform(obj))

    def advance_frame(self, frame):
        """EXEC path: advance to the time of ``frame`` and apply."""
        t = (frame - self.frame_start) / self.fps
        self.runner.advance_to(t)
        self.apply(self.runner.snapshot(), frame)

    def run_to_end(self):
        for k in range(1, self.n_frames + 1):
            self.advance_frame(self.frame_start + k)
        return self.finish()

    def tick(self, wall_elapsed, max_steps):
        """Live path: advance toward real time (bounded work) and apply. True when done."""
        target = min(wall_elapsed - self.runner.dropped_time, self.duration)
        self.runner.advance_to(target, max_steps=max_steps)
        frame = self.frame_start + int(round(self.runner.time * self.fps))
        if frame != self.scene.frame_current:
            self.scene.frame_current = frame
        snap = self.runner.snapshot()
        self.apply(snap, frame)
        if display.overlay_active():
            display.set_overlay(snap, self.hud_text())
        return self.settings.loop and self.runner.time >= self.duration - 1e-9

    def hud_text(self) -> str:
        st = self.runner.stats()
        snap = self.snapshot
        n_c = snap.n_contacts if snap is not None else 0
        mode = "threaded runtime" if st["threaded"] else "main thread"
        text = (f"Grasp Lab  t = {st['time']:.2f} / {self.duration:.2f} s  ({mode})\n"
                f"haptic {st['haptic_rate']:.0f} Hz (target {st['haptic_rate_target']:.0f})   "
                f"display {st['display_rate']:.1f} Hz   jitter {st['jitter_ms']:.1f} ms\n"
                f"contacts {n_c} / {len(self.desc.fingers)}   step {st['step_us']:.0f} µs   "
                f"behind {st['dropped_s']:.2f} s")
        if "runtime_jitter_p99_us" in st:
            # The operator's view of the C haptic loop: its timing, what the OS granted it
            # (SCHED_FIFO or not), and the safety counters that explain lost forces.
            text += (f"\nhaptic loop p99 {st['runtime_jitter_p99_us']:.0f} µs   "
                     f"late {st['runtime_late_periods']}   overruns {st['runtime_overruns']}   "
                     f"rejected inputs {st['runtime_rejected_inputs']}   "
                     f"watchdog {st['runtime_watchdog_trips']}   adopted {st['runtime_adopted_bodies']}\n"
                     f"{st['runtime_priority_note']}")
        return text

    def finish(self):
        """Stop the runner, bake, save the recording; leave the scene in its final state."""
        global last_result
        if self.finished:
            return self.result
        self.finished = True
        self.runner.stop()
        r = self.result
        r.stats = self.runner.stats()
        r.final = self.snapshot
        if self.bake:
            for name, (frames, vals) in self._baked.items():
                obj = bpy.data.objects.get(name)
                if obj is not None:
                    anim.bake(obj, frames, np.array(vals))
        if self.recorder is not None:
            r.recording = self.recorder.writer.path
            self.settings.last_recording = r.recording
        # Final state: the frame the session ended on, bodies where the session left them.
        final_frame = r.frames[-1] if r.frames else self.scene.frame_current
        if self.scene.frame_current != final_frame:
            self.scene.frame_set(final_frame)
        if self.snapshot is not None:
            self.apply_final()
        last_result = r
        return r

    def apply_final(self):
        snap = self.snapshot
        for i in self.dynamic:
            p = snap.poses[i]
            self.objects[i].matrix_world = self.links[i].matrix_world(p[:3], p[3:])

    def summary(self) -> str:
        st = self.result.stats
        return (f"Grasp session: {self.runner.time:.2f} s, {st.get('steps', 0)} steps, "
                f"{len(self.desc.bodies)} bodies, {len(self.desc.fingers)} fingers, "
                f"{st.get('step_us', 0):.0f} µs/step")


# --------------------------------------------------------------------------- rest poses

def store_rest_poses(context, links):
    for link in links:
        obj = bpy.data.objects.get(link.name)
        if obj is not None and not link.static:
            obj.grasp_lab.rest_matrix = [v for row in obj.matrix_world for v in row]
            obj.grasp_lab.has_rest = True


def restore_rest_poses(context) -> int:
    """Put bodies back where the last session started them. Returns how many moved."""
    from mathutils import Matrix
    n = 0
    for obj in context.view_layer.objects:
        gl = obj.grasp_lab
        if gl.has_rest and gl.role == "DYNAMIC":
            v = list(gl.rest_matrix)
            obj.matrix_world = Matrix([v[0:4], v[4:8], v[8:12], v[12:16]])
            n += 1
    return n


# --------------------------------------------------------------------------- operators

class GRASPLAB_OT_session(bpy.types.Operator):
    """Run a grasp session: fingertip HIPs from the input drive the core; bodies, god-objects
    and force/torque arrows follow. Interactive: Esc stops. Scripts/headless: runs to the end"""
    bl_idname = "grasp_lab.session"
    bl_label = "Run Grasp Session"
    bl_options = {"REGISTER", "UNDO"}

    duration: FloatProperty(name="Duration", default=-1.0, min=-1.0,
                            description="Seconds to run (-1: the scene setting; 0: to the end "
                                        "of the animation)")
    reset: BoolProperty(name="Reset Bodies", default=True,
                        description="Start bodies from where the previous session started them")

    _timer = None
    _session = None
    _t0 = 0.0

    @classmethod
    def poll(cls, context):
        return _active is None and context.scene is not None

    def _start(self, context, live):
        try:
            return BlenderSession(context, live=live, duration=self.duration, reset=self.reset)
        except (SceneError, ValueError) as ex:
            self.report({"ERROR"}, f"Grasp Lab: {ex}")
        except ImportError as ex:
            self.report({"ERROR"}, str(ex))
        return None

    def execute(self, context):
        session = self._start(context, live=False)
        if session is None:
            return {"CANCELLED"}
        session.run_to_end()
        self.report({"INFO"}, session.summary())
        return {"FINISHED"}

    def invoke(self, context, event):
        global _active
        if bpy.app.background or context.window is None:
            return self.execute(context)
        session = self._start(context, live=True)
        if session is None:
            return {"CANCELLED"}
        prefs = get_prefs(context)
        self._session = session
        _active = session
        session.operator_stop = False
        s = context.scene.grasp_lab
        wm = context.window_manager
        self._timer = wm.event_timer_add(1.0 / s.display_rate, window=context.window)
        session.timer = self._timer
        session.wm = wm
        display.add_overlay(prefs.show_overlay, prefs.show_hud)
        self._max_steps = max(1, int(prefs.max_step_ms * 1e-3 * s.haptic_rate))
        s.running = True
        self._t0 = time.perf_counter()
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        session = self._session
        if session is None or getattr(session, "operator_stop", False) or session.finished:
            self._cleanup(context)
            return {"FINISHED"}
        if event.type == "ESC" and event.value == "PRESS":
            self._cleanup(context)
            self.report({"INFO"}, session.summary())
            return {"FINISHED"}
        if event.type == "TIMER" and event.timer is self._timer:
            try:
                done = session.tick(time.perf_counter() - self._t0, self._max_steps)
            except Exception as ex:  # keep Blender usable; report what happened
                self._cleanup(context)
                self.report({"ERROR"}, f"Grasp Lab session stopped: {ex}")
                return {"CANCELLED"}
            display.tag_redraw(context)
            if done:
                self._cleanup(context)
                self.report({"INFO"}, session.summary())
                return {"FINISHED"}
        return {"PASS_THROUGH"}

    def cancel(self, context):
        # Blender calls this when it quits or loads a file with the operator running.
        self._cleanup(context)

    def _cleanup(self, context):
        session = self._session
        self._session = None
        if session is not None:
            stop_session(session)
        display.tag_redraw(context)


def stop_session(session):
    """Stop a live session now: timer and draw handlers removed, runner stopped."""
    global _active
    session.operator_stop = True
    timer = getattr(session, "timer", None)
    if timer is not None:
        try:
            session.wm.event_timer_remove(timer)
        except (ReferenceError, RuntimeError, ValueError):
            pass
        session.timer = None
    display.remove_overlay()
    try:
        session.finish()
    except ReferenceError:
        pass
    try:
        session.settings.running = False
    except (ReferenceError, AttributeError):
        pass
    if _active is session:
        _active = None


def stop_active():
    if _active is not None:
        stop_session(_active)
    display.remove_overlay()


class GRASPLAB_OT_stop(bpy.types.Operator):
    """Stop the running grasp session"""
    bl_idname = "grasp_lab.stop_session"
    bl_label = "Stop Grasp Session"

    @classmethod
    def poll(cls, context):
        return _active is not None

    def execute(self, context):
        stop_active()
        return {"FINISHED"}


@bpy.app.handlers.persistent
def _on_load_pre(*_args):
    stop_active()


@bpy.app.handlers.persistent
def _on_load_post(*_args):
    for scene in bpy.data.scenes:
        if scene.grasp_lab.running:
            scene.grasp_lab.running = False


CLASSES = (GRASPLAB_OT_session, GRASPLAB_OT_stop)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.app.handlers.load_pre.append(_on_load_pre)
    bpy.app.handlers.load_post.append(_on_load_post)


def unregister():
    stop_active()
    for lst, fn in ((bpy.app.handlers.load_pre, _on_load_pre),
                    (bpy.app.handlers.load_post, _on_load_post)):
        while fn in lst:
            lst.remove(fn)
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
