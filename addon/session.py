"""The session: Blender glue around ``engine.runner.SessionRunner``.

``BlenderSession`` converts the scene, builds the world and the input source, and
after every advance writes body poses back and updates the display. The operator
``grasp_lab.session`` drives it:

* EXEC (scripts, headless): a plain loop over the frames, no timers;
* INVOKE (UI): a modal operator. The core runs on its own threads at the haptic rate
  (the scripted fingertips handed to it whole, the others pushed as time-stamped
  samples); an application timer at the display rate only pushes the fingertips the
  user moves and shows the latest snapshot, so a slow display changes the picture, not
  the grasp. The modal handler answers Esc and reports how the session ended. Whatever
  ends a session (the end, Esc, Stop, an error, loading a file, undo, disabling the
  extension, quitting) goes through ``stop_session``: threads joined, timers and draw
  handlers removed.
"""
from __future__ import annotations

import time
import traceback
from dataclasses import dataclass, field

import bpy
import numpy as np
from bpy.props import BoolProperty, FloatProperty

from . import anim, convert, display, hands, record, sound_live
from .engine import analysis, core_loader, grasp_display, recording
from .engine.tick_tap import TickTap
from .engine.devices.live import DeviceInput, device_event_detail, device_fingers, without_fingers
from .engine.inputs import SampledTrajectory, TimelineInput, turning_fingers
from .engine.runner import SessionRunner
from .engine.scene import SceneError, build_world, prepare
from .prefs import get_prefs
from .rest_poses import restore_rest_poses, store_rest_poses
from .scene_devices import add_device_specs, connect_scene_devices, entries_in_use, remove_entries, status_lines


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
    grasps: list = field(default_factory=list)      # per display frame: analysis.BodyGrasp list
    scene_name: str = ""
    verdict: list = field(default_factory=list)     # the grasp in words when it ended (grasp_display.verdict_lines)

    def trajectory(self, body_name) -> np.ndarray:
        i = self.body_names.index(body_name)
        return np.array([p[i] for p in self.poses])


last_result: SessionResult | None = None
_active = None      # the running live session (BlenderSession), if any


def active_session():
    return _active


class BlenderSession:
    def __init__(self, context, *, live: bool, duration: float | None = None, reset: bool = True,
                 record_path: str | None = None, sound: bool | None = None):
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
        # Armatures with Finger bones: their rendered armatures, and every bone sampled per frame.
        self.hands = hands.make_hands(finger_objs, desc)
        times, pos, quat = convert.sample_fingers(context, finger_objs, self.frame_start,
                                                  min(self.frame_start + n_frames, scene.frame_end),
                                                  on_frame=lambda: [h.sample() for h in self.hands])
        # Fingertips that move or (a mesh finger: a palm) turn on the timeline are scripted; the
        # others follow the user. Orientations go to the core only when a finger turns, so a
        # scene whose fingers only move runs as before, bit for bit.
        turning = turning_fingers(quat)
        scripted = (np.ptp(pos, axis=0).max(axis=1) > 1e-9) | turning if len(times) > 1 else \
            np.zeros(len(finger_objs), dtype=bool)
        self.source = TimelineInput(SampledTrajectory(times, pos, quat if turning.any() else None), scripted)
        for hand in self.hands:     # animated: the samples; else posed live (a mocap add-on, a person)
            hand.live = not scripted[hand.finger_indices()].any()
        self.finger_objects = finger_objs
        if live and not scripted.any() and not duration > 0:
            self.duration = float("inf")        # nothing scripted, no length asked: until Esc or Stop
        self.threaded = live and prefs.use_runtime
        # Devices drive their fingers from the core's own threads (docs/devices.md), whatever
        # those fingers' animation says; the animation drives the fingers no device drives.
        entries = entries_in_use(scene)
        use_devices = self.threaded and len(entries) > 0
        self.driven_by = np.full(len(finger_objs), -1)      # finger -> index of the device entry
        self.device_labels, self.device_kinds = [], []
        if use_devices:
            # Labelled as their events are (scene_devices.connect_scene_devices): the port, else the kind.
            self.device_labels = [e.port or e.kind.lower() for e in entries]
            self.device_kinds = [e.kind.lower() for e in entries]
            self.driven_by = device_fingers(
                [(label, e.finger_offset, 5 if e.kind == "OPENGLOVES" else e.num_fingers)
                 for label, e in zip(self.device_labels, entries)],
                len(finger_objs), [o.name for o in finger_objs])
            self.source = DeviceInput(len(finger_objs), without_fingers(self.source.script(), self.driven_by >= 0))
            # A device session runs until Esc or Stop unless a duration is set, whatever the
            # other fingers' animation (they hold its last frame after its end).
            self.duration = duration if duration > 0 else float("inf")
        options = {}
        if self.threaded:
            # Fingertips moved in the viewport arrive at the display's rate, which under a
            # software renderer can be 1-2 Hz: that is not stale input, so hip_timeout is long
            # and a mouse-dragged fingertip is walked at a bounded speed. With devices the
            # runtime's own 0.1 s applies (docs/runtime.md): the device threads push at their
            # rate, also while they let a lost device's fingers go.
            options = {"max_hip_speed": 0.0} if use_devices else \
                {"max_hip_speed": prefs.max_hip_speed, "hip_timeout": 2.0}
        self.recorder = record.session_recorder(self, record_path, self.threaded, options) \
            if (record_path or s.record) else None
        # The live sound (docs/sound.md): the Session panel's Sound, off in background mode unless
        # asked for (``sound=True``: grasp-lab run --realtime --sound), which then says there is no
        # audio device there and runs silent.
        self.sound, self.sound_message = None, ""
        if live and (s.sound and not bpy.app.background if sound is None else sound):
            self.sound, self.sound_message = sound_live.open_live_sound(desc, s)
        tap = TickTap(self.handle.world, recording.tick_dtype(len(desc.bodies), len(desc.fingers)),
                      s.haptic_rate) if self.sound is not None else None
        self.runner = SessionRunner(self.handle, self.source, haptic_rate=s.haptic_rate,
                                    use_runtime=self.threaded, recorder=self.recorder,
                                    runtime_options=options, tap=tap)
        store_rest_poses(context, self.links)
        self.objects = [bpy.data.objects[link.name] for link in self.links]
        self.dynamic = [i for i, link in enumerate(self.links) if not link.static]
        self.display = display.DisplayObjects(scene, desc) if s.display_objects else None
        self.monitor = grasp_display.GraspMonitor(analysis.body_models(desc), [f.radius for f in desc.fingers],
                                                  gravity=desc.gravity, torsions=analysis.finger_torsions(desc))
        self.bake = s.bake
        self._baked = {}    # object name -> (frames, values)
        self.result = SessionResult(body_names=[b.name for b in desc.bodies],
                                    finger_names=[f.name for f in desc.fingers])
        self.snapshot = None
        self.live_view = None       # engine.live_view.LiveLoop: display updates served to Foxglove or Rerun
        self.finished = False
        self.error = ""             # why a live session stopped early
        self.ended_by = "Stop"      # how it ended, for the report
        self.stop_at_end = False    # True: the live loop ends at the end whatever the scene's Stop at End
        self.timer = None
        self.runner.start()
        self.devices = None
        if use_devices:
            self.devices = connect_scene_devices(scene, self.handle.world)
            if scene.grasp_lab_device_forces:       # Forces On before the session: it starts with them
                self.devices.enable(True)
        self.apply(self.runner.snapshot(), self.frame_start)

    # ------------------------------------------------------------- per update
    def apply(self, snap, frame):
        """Write body poses back, analyse the grasp, update the display objects."""
        self.snapshot = snap
        for i in self.dynamic:
            p = snap.poses[i]
            self.objects[i].matrix_world = self.links[i].matrix_world(p[:3], p[3:])
        self.follow_devices(snap)
        # The input armature as sampled at the snapshot's frame (animated: the sample the core's
        # track had), or as it is now (posed live, by hand or a mocap add-on).
        for hand in self.hands:
            hand.update(snap, self.desc.bodies, None if hand.live else int(round(snap.time * self.fps)),
                        self.bake, frame)
        grasps = self.monitor.update(snap)
        if self.display is not None:
            s = self.settings
            self.display.update(snap, s.force_scale, s.torque_scale,
                                grasp_display.finger_colors(grasps, len(snap.god_objects)))
        r = self.result
        r.frames.append(frame)
        r.times.append(snap.time)
        r.poses.append(snap.poses.copy())
        r.grasps.append(grasps)
        if self.bake:
            objs = [self.objects[i] for i in self.dynamic]
            if self.display is not None:
                objs += self.display.objects
            for obj in objs:
                fr, vals = self._baked.setdefault(obj.name, ([], []))
                fr.append(frame)
                vals.append(anim.read_transform(obj))

    def follow_devices(self, snap):
        """The Finger objects a device drives go where the device has the fingertip (its HIP),
        turning as they were: the viewport shows the device's hand, not where the fingers stood
        (docs/devices.md, In Blender)."""
        for i in np.flatnonzero(self.driven_by >= 0):
            obj = self.finger_objects[i]
            m = obj.matrix_world.copy()
            m.translation = snap.hips[i]
            obj.matrix_world = m

    def advance_frame(self, frame):
        """EXEC path: advance to the time of ``frame`` and apply."""
        t = (frame - self.frame_start) / self.fps
        self.runner.advance_to(t)
        self.apply(self.runner.snapshot(), frame)

    def run_to_end(self):
        for k in range(1, self.n_frames + 1):
            self.advance_frame(self.frame_start + k)
        return self.finish()

    def tick(self, wall_elapsed, budget=None):
        """Live path: the fingertips the user moved go in, the latest state comes out.
        ``budget``: wall seconds the main-thread fallback may step for. True when done."""
        if self.source.interactive:
            # A mesh finger (a palm) rotated in the viewport turns too; spheres have no rotation.
            turns = [convert.finger_rotation(o) for o in self.finger_objects] \
                if any(o.type in {"MESH", "BONE"} for o in self.finger_objects) else None
            self.source.set_live([tuple(o.matrix_world.translation) for o in self.finger_objects], turns)
        if self.devices is not None:
            self._record_device_events(self.devices.poll())
        self.runner.advance_to(min(wall_elapsed, self.duration), budget=budget)
        snap = self.runner.snapshot()
        frame = self.frame_start + int(round(min(self.runner.time, self.duration) * self.fps)) \
            if self.source.script() is not None else self.scene.frame_current
        if frame != self.scene.frame_current:
            self.scene.frame_current = frame
        self.apply(snap, frame)
        if self.sound is not None:
            self.sound.set_volume(self.settings.sound_volume)
            self.sound.update(self.runner.tap.take(), snap.time)
        if display.overlay_active():
            display.set_overlay(snap, self.hud_text(), self.monitor.grasps)
        if self.live_view is not None:
            # Last: its thread wakes and works while this one waits for the next update,
            # not while the update still needs the interpreter.
            self.live_view.offer(snap, self.monitor.grasps)
        return (self.stop_at_end or self.settings.loop) and self.runner.time >= self.duration - 1e-9

    # ------------------------------------------------------------- the live loop
    def start_live(self, display_rate: float, budget: float | None = None) -> None:
        """The live loop's clock starts now: a display update every 1 / ``display_rate`` s,
        each stepping the main-thread fallback for ``budget`` wall seconds at most."""
        self.interval = 1.0 / max(display_rate, 1.0)
        self.budget = budget
        self.t0 = time.perf_counter()

    def live_update(self) -> float | None:
        """One turn of the live loop, the one loop of every live session (the operator's
        application timer, ``run_live`` without a window): a display update at the wall time
        since ``start_live``. Returns the seconds to wait for the next, None at the end."""
        t = time.perf_counter()
        if self.tick(t - self.t0, budget=self.budget):
            return None
        return max(0.0, self.interval - (time.perf_counter() - t))

    def run_live(self) -> None:
        """A live session without a window (``grasp-lab run --realtime``, with or without
        devices): the live loop until the session's end (always: no one is there to stop it)
        or Ctrl-C, then finished."""
        self.stop_at_end = True
        self.start_live(self.settings.display_rate)
        try:
            while (wait := self.live_update()) is not None:
                time.sleep(wait)
        except KeyboardInterrupt:
            self.ended_by = "Ctrl-C"
        finally:
            self.finish()

    def _record_device_events(self, events) -> None:
        """Device events (connected, lost, enabled, ...) into the recording as they come, at
        the session time the device thread observed them."""
        if self.recorder is None or not events:
            return
        for t, source, event, value in events:
            self.recorder.event(t, f"device_{event}", str(source), device_event_detail(event, value), value=value)

    def input_description(self) -> dict:
        """What drives the fingers, for the recording's header (``grasp-lab info``)."""
        names = [o.name for o in self.finger_objects]
        script = self.source.script()
        scripted = np.zeros(len(names), dtype=bool) if script is None else \
            (np.ones(len(names), dtype=bool) if script[2] is None else np.asarray(script[2], dtype=bool))
        drivers, parts = [], []
        for k, label in enumerate(self.device_labels):
            fingers = [names[i] for i in np.flatnonzero(self.driven_by == k)]
            drivers.append({"device": label, "kind": self.device_kinds[k], "fingers": fingers})
            parts.append(f"{', '.join(fingers)}: {self.device_kinds[k]} device {label}")
        animated = [n for i, n in enumerate(names) if scripted[i] and self.driven_by[i] < 0]
        if animated:
            parts.append(f"{', '.join(animated)}: animated on the timeline")
        rest = [n for i, n in enumerate(names) if not scripted[i] and self.driven_by[i] < 0]
        if rest:
            parts.append(f"{', '.join(rest)}: not animated (where they are; live, moved in the viewport)")
        out = {"kind": "devices" if drivers else self.source.name, "fingers": len(names),
               "detail": "; ".join(parts)}
        if drivers:
            out["drivers"] = drivers
        return out

    def grasp_lines(self) -> list:
        """The grasp as the last display update analysed it (engine.grasp_display)."""
        lines = grasp_display.grasp_lines(self.monitor.grasps, [b.name for b in self.desc.bodies],
                                          [f.name for f in self.desc.fingers])
        if self.monitor.error:
            lines.append(f"analysis: {self.monitor.error}")
        return lines

    def loop_lines(self, detail: bool = False) -> list:
        """The loop's telemetry: what the operator needs to trust the picture. Short (one line,
        and the safety counters only when one is not zero) or in ``detail``."""
        st = self.runner.stats()
        end = "until Esc" if self.duration == float("inf") else f"/ {self.duration:.2f} s"
        cost = f"analysis {1e3 * self.monitor.cost_s:.2f} ms"
        if not (st["threaded"] and "runtime_haptic_rate" in st):
            behind = (f"behind real time by {st['lag_s']:.2f} s (x{st['realtime_factor']:.2f})"
                      if st["lag_s"] > 2.0 / max(self.settings.display_rate, 1.0) else "real time")
            lines = [f"t {st['time']:.2f} {end}   main thread {st['haptic_rate']:.0f} Hz "
                     f"(target {st['haptic_rate_target']:.0f})   display {st['display_rate']:.1f} Hz   {behind}"]
            if detail:
                lines.append(f"step {st['step_us']:.0f} µs   {st['steps']} steps   {cost}")
            return lines
        # Forces reach a hand only through a device: without one, the watchdog and stale-input
        # counters count the timeline's input, not a fault, so they stay out of the way unless
        # something is wrong (a rejected input, a force that was not a number).
        has_device = self.devices is not None
        enabled = [d["enabled"] for d in self.devices.status()] if has_device else None
        forces = f"   {grasp_display.force_output(st['runtime_forces_enabled'], enabled)}" if has_device else ""
        lines = [f"t {st['time']:.2f} {end}   haptic {st['haptic_rate']:.0f} Hz   "
                 f"display {st['display_rate']:.1f} Hz   p99 {st['runtime_jitter_p99_us']:.0f} µs{forces}"]
        safety = {k: st[f"runtime_{k}"] for k in ("rejected_inputs", "watchdog_trips", "stale_inputs",
                                                  "nonfinite_forces")}
        wrong = safety["rejected_inputs"] or safety["nonfinite_forces"]
        if detail or wrong or (has_device and any(safety.values())):
            lines.append(f"safety: rejected inputs {safety['rejected_inputs']}   watchdog {safety['watchdog_trips']}   "
                         f"stale {safety['stale_inputs']}   non-finite {safety['nonfinite_forces']}")
        if detail:
            lines.append(f"haptic target {st['haptic_rate_target']:.0f} Hz   object {st['runtime_object_rate']:.0f} Hz   "
                         f"step {st['step_us']:.0f} µs   {st['steps']} steps   {cost}")
            lines.append(f"late {st['runtime_late_periods']}   overruns {st['runtime_overruns']}   "
                         f"adopted {st['runtime_adopted_bodies']}")
            lines.append(st["runtime_priority_note"])
        if self.devices is not None:
            lines += status_lines(self.devices)
        return lines

    def hud_text(self) -> str:
        """The viewport's HUD: the grasp first, the loop's telemetry second and shorter; the
        weakest wrench's legend while one is drawn."""
        lines = self.grasp_lines() + [h.hud_line() for h in self.hands] + self.loop_lines()
        if any(g.force_closure for g in self.monitor.grasps):
            lines.append(grasp_display.WEAKEST_LEGEND)
        if self.live_view is not None:
            lines.append(self.live_view.status())
        if self.sound is not None:
            lines.append(self.sound.status())
        return "\n".join(lines)

    def finish(self, discard_recording: bool = False):
        """Stop the runner, bake, save the recording; leave the scene in its final state.
        ``discard_recording``: the session failed at its start (a device that did not open):
        its recording is removed, the file it would have replaced left as it was."""
        global last_result
        if self.finished:
            return self.result
        self.finished = True
        if discard_recording and self.recorder is not None:
            self.recorder.discard_on_finish = True
        device_stats = {}
        if self.devices is not None:
            self._record_device_events(self.devices.poll())   # before the runner stops and the file closes
            device_stats = {d.label: d.stats() for d in self.devices.devices}
            self.devices.close()
        self.runner.stop()
        r = self.result
        r.stats = self.runner.stats()
        if self.sound is not None:
            self.sound.close()
            r.stats["sound"] = {"latency_ms": 1e3 * self.sound.latency, "late": self.sound.late,
                                "clicks": self.sound.clicks, "seconds": self.sound.samples / self.sound.rate,
                                "updates": self.sound.updates,
                                "cost_ms": 1e3 * self.sound.cost_s / max(self.sound.updates, 1)}
        elif self.sound_message:
            r.stats["sound"] = {"message": self.sound_message}
        if self.live_view is not None:
            r.stats["live_view"] = self.live_view.close()
        if self.devices is not None:
            r.stats["device_events"] = list(self.devices.events)
            r.stats["device_stats"] = device_stats         # each device's counters when it was closed
            self.runner.events += self.devices.events
        r.final = self.snapshot
        r.scene_name = self.scene.name
        r.verdict = grasp_display.verdict_lines(self.monitor.grasps, r.body_names, r.finger_names)
        if self.bake:
            for name, (frames, vals) in self._baked.items():
                obj = bpy.data.objects.get(name)
                if obj is not None:
                    anim.bake(obj, frames, np.array(vals))
            for hand in self.hands:
                hand.write_bake()
        if self.recorder is not None and not discard_recording:
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
        st = self.result.stats or self.runner.stats()
        mode = "threaded runtime" if st.get("threaded") else "main thread"
        return (f"Grasp session: {self.runner.time:.2f} s, {st.get('steps', 0)} steps at "
                f"{st.get('haptic_rate', 0):.0f} Hz ({mode}), {len(self.desc.bodies)} bodies, "
                f"{len(self.desc.fingers)} fingers, {st.get('step_us', 0):.0f} µs/step")


# --------------------------------------------------------------------------- live view

def start_live_view(session, port=0, bind: str = "127.0.0.1", server=None):
    """Serve a live session to Foxglove (engine/live_view.py; ``port`` a number, ``server`` the
    server bound before the session), or stream it to a Rerun viewer (engine/rerun_view.py;
    ``port`` "rerun", "rerun:PORT" or "rerun:HOST:PORT"): the session panel's Live View and
    ``grasp-lab run --live-view``. ImportError without the viewer's SDK, OSError for an address it
    cannot serve on."""
    from .engine.live_view import LiveView, header_of
    header = header_of(session.desc, session.runner.haptic_rate)
    if isinstance(port, str):
        from .engine.rerun_view import RerunLiveView
        session.live_view = RerunLiveView(header, port)
    else:
        session.live_view = LiveView(header, port=port, bind=bind, bound=server)
    return session.live_view


def live_view_target(settings):
    """The Session panel's live view as start_live_view takes it: Foxglove's port, or the
    Rerun viewer on this machine ("rerun:127.0.0.1:PORT")."""
    if settings.live_view_viewer == "RERUN":
        return f"rerun:127.0.0.1:{settings.live_view_rerun_port}"
    return settings.live_view_port


def live_session(context, device_specs=(), forces: bool = False, **options) -> BlenderSession:
    """A live BlenderSession driven by the devices of the scene's list and of ``device_specs``
    (added for this session only), forces enabled when ``forces``; a device that does not
    open is an error naming it. ``options`` go to BlenderSession (duration, record_path)."""
    added = add_device_specs(context, device_specs)
    try:
        live = BlenderSession(context, live=True, **options)
    finally:
        remove_entries(context, added)
    if live.devices is not None and live.devices.failed:
        live.finish(discard_recording=True)
        raise ConnectionError("; ".join(f"{p}: {e}" for p, e in live.devices.failed.items()))
    if forces and live.devices is not None:
        live.devices.enable(True)
    return live


def run_realtime(context, duration: float, device_specs=(), forces: bool = False, record_path=None):
    """A device session without a window for ``duration`` seconds (``live_session`` and its
    ``run_live``). Returns the finished BlenderSession."""
    live = live_session(context, device_specs, forces, duration=duration, record_path=record_path)
    live.run_live()
    return live


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

    _session = None

    @classmethod
    def poll(cls, context):
        return _active is None and context.scene is not None

    def _start(self, context, live):
        from .ops import last_check
        last_check.pop(context.scene.name, None)        # a session checks the scene again
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
        # An undo step for the scene as it was: Ctrl+Z during the session (which ends it)
        # or after it comes back here.
        bpy.ops.ed.undo_push(message="Before Grasp Session")
        session = self._start(context, live=True)
        if session is None:
            return {"CANCELLED"}
        if session.sound_message:
            self.report({"WARNING"}, f"Grasp Lab: {session.sound_message}")
        try:
            prefs = get_prefs(context)
            s = context.scene.grasp_lab
            if s.live_view:
                try:
                    start_live_view(session, live_view_target(s), s.live_view_bind)
                except (ImportError, OSError) as ex:       # the session runs without it
                    self.report({"WARNING"}, f"Grasp Lab: no live view: {ex}")
            session.start_live(s.display_rate, budget=prefs.max_step_ms * 1e-3)
            session.wm = context.window_manager
            # Wakes this handler to notice an end it did not see (timer, Stop button).
            session.timer = session.wm.event_timer_add(session.interval, window=context.window)
            _active = session
            display.add_overlay(prefs.show_overlay, prefs.show_hud, s.weakest_scale)
            s.running = True
            bpy.app.timers.register(_live_tick, first_interval=0.0)
        except Exception:
            stop_session(session)
            raise
        self._session = session
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        session = self._session
        if session is None:
            return {"CANCELLED"}
        if not session.finished and event.type == "ESC" and event.value == "PRESS":
            session.ended_by = "Esc"
            stop_session(session)
        if not session.finished:
            return {"PASS_THROUGH"}
        self._session = None
        if session.error:
            self.report({"ERROR"}, f"Grasp Lab session stopped: {session.error}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"{session.summary()} (ended by {session.ended_by})")
        return {"FINISHED"}

    def cancel(self, context):
        # Blender calls this when it quits or loads a file with the operator running.
        session, self._session = self._session, None
        if session is not None:
            session.ended_by = "Blender (quit or file load)"
            stop_session(session)


def _live_tick():
    """The application timer of a live session: one display update. Any exception ends
    the session cleanly (never half alive) and is reported by the operator."""
    session = _active
    if session is None or session.finished:
        return None
    try:
        wait = session.live_update()
        display.tag_redraw()
    except Exception as ex:  # noqa: BLE001 - whatever it was, stop and say so
        traceback.print_exc()
        session.error = f"{type(ex).__name__}: {ex}"
        session.ended_by = "an error"
        wait = None
    if wait is None:
        if not session.error:
            session.ended_by = "the end of the animation"
        stop_session(session, from_timer=True)
        return None
    return wait


def stop_session(session, from_timer=False):
    """Stop a live session now: threads joined, timers and draw handlers removed, the
    scene left in the session's final state. Safe to call more than once."""
    global _active
    session.stopped_at = time.perf_counter()
    if not from_timer and bpy.app.timers.is_registered(_live_tick):
        bpy.app.timers.unregister(_live_tick)
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
    except ReferenceError:      # its scene is gone (file loaded): the threads still stop
        session.runner.stop()
        session.finished = True
    except Exception as ex:  # noqa: BLE001 - the session must end whatever happened
        traceback.print_exc()
        session.runner.stop()
        session.finished = True
        session.error = session.error or f"{type(ex).__name__}: {ex}"
    try:
        session.settings.running = False
    except (ReferenceError, AttributeError):
        pass
    if _active is session:
        _active = None
        print(f"{session.summary()} (ended by {session.ended_by})"
              + (f": {session.error}" if session.error else ""), flush=True)
    display.tag_redraw()


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
    if _active is not None:
        _active.ended_by = "loading a file"
    stop_active()


@bpy.app.handlers.persistent
def _on_undo_pre(*_args):
    # Undo replaces the data-blocks a running session writes to: end the session first.
    if _active is not None:
        _active.ended_by = "undo"
    stop_active()


@bpy.app.handlers.persistent
def _on_undo_post(*_args):
    # The last session's summary describes a scene that undo took back: it goes. The undone
    # objects' matrix_world is stale until the depsgraph is evaluated: evaluated now, so the
    # Session panel's "where the session left it" compares the poses undo brought back.
    global last_result
    last_result = None
    try:
        bpy.context.view_layer.update()
    except (AttributeError, RuntimeError):
        pass


@bpy.app.handlers.persistent
def _on_load_post(*_args):
    global last_result
    last_result = None          # another file: nothing of the last one's session stays on screen
    from .ops import last_check
    last_check.clear()
    for scene in bpy.data.scenes:
        if scene.grasp_lab.running:
            scene.grasp_lab.running = False


CLASSES = (GRASPLAB_OT_session, GRASPLAB_OT_stop)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.app.handlers.load_pre.append(_on_load_pre)
    bpy.app.handlers.load_post.append(_on_load_post)
    bpy.app.handlers.undo_pre.append(_on_undo_pre)
    bpy.app.handlers.redo_pre.append(_on_undo_pre)
    bpy.app.handlers.undo_post.append(_on_undo_post)


def unregister():
    stop_active()
    for lst, fn in ((bpy.app.handlers.load_pre, _on_load_pre),
                    (bpy.app.handlers.load_post, _on_load_post),
                    (bpy.app.handlers.undo_pre, _on_undo_pre),
                    (bpy.app.handlers.redo_pre, _on_undo_pre),
                    (bpy.app.handlers.undo_post, _on_undo_post)):
        while fn in lst:
            lst.remove(fn)
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
