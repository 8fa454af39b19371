"""The Blender half of ``grasp-lab run`` and ``grasp-lab bake`` (engine/cli.py parses, checks and
dispatches through its BLENDER_COMMANDS table; this runs them in the loaded extension, headless
or in a Blender)."""
from __future__ import annotations

import os

import bpy

from . import bake as baking
from . import emulate_blend
from .engine import limits
from .engine.cli import CliError
from .engine.outputs import AtomicFile, blend_is_whole
from .engine.recording import open_recording, tick_dtype
from .engine.resim import BODY_KEYS, FINGER_KEYS


def open_blend(path: str) -> None:
    path = os.path.abspath(path)
    if os.path.isdir(path):
        raise CliError(f"{path}: is a folder, not a .blend file")
    if not os.path.isfile(path):
        raise CliError(f"{path}: no such file")
    try:
        bpy.ops.wm.open_mainfile(filepath=path)
    except RuntimeError as ex:
        raise CliError(f"{path}: cannot open as a .blend ({str(ex).strip()})") from None


def claim_blend(path: str) -> AtomicFile:
    """The --save target claimed before the command begins (its partial file locked: a second
    command saving to it is refused now, not after its work); ``save_blend`` writes it."""
    return AtomicFile(path)


def save_blend(out: AtomicFile) -> str:
    """Saved by Blender beside its target (a copy: the open file keeps its name), synced,
    checked whole (its ENDB block: Blender does not notice every failed write on a full disk)
    and renamed into place; anything else leaves the target as it was, naming it."""
    written = out.partial + ".blend"
    try:
        bpy.ops.wm.save_as_mainfile(filepath=written, copy=True)
    except RuntimeError as ex:  # Blender's report (a full disk, ...); the target is as it was
        _remove(written)
        out.discard()
        raise CliError(f"{out.path}: could not save ({str(ex).strip()}); it is as it was") from None
    return out.commit(verify=blend_is_whole, source=written)


def _remove(path: str) -> None:
    for p in (path, path + "@"):        # Blender's own temporary name too
        try:
            os.unlink(p)
        except OSError:
            pass


def check_run_size(context, args) -> None:
    """The session's length, tick count and recording size, before any file is touched."""
    s = context.scene.grasp_lab
    scene = context.scene
    fps = scene.render.fps / scene.render.fps_base
    duration = args.duration or s.duration or (scene.frame_end - scene.frame_start) / fps
    if duration <= 0 and not args.realtime:
        raise CliError(f"{args.scene}: nothing to run: the animation is {scene.frame_end - scene.frame_start} "
                       f"frames long and neither the scene nor --duration gives a duration")
    if not args.record or duration <= 0:
        return
    roles = [o.grasp_lab.role for o in scene.objects]
    n_bodies = len(roles) - roles.count("FINGER") - roles.count("NONE")
    n_fingers = roles.count("FINGER") + sum(pb.grasp_lab.role == "FINGER" for o in scene.objects
                                            if o.type == "ARMATURE" and o.pose is not None for pb in o.pose.bones)
    ticks = duration * s.haptic_rate + 1
    limits.check_recording_size("--record", args.record, ticks, tick_dtype(n_bodies, n_fingers).itemsize,
                                args.max_size)


def check_channels(context) -> None:
    """Fingers a device drives: one a channel (two on one would move together, silently)."""
    by_channel = {}
    for o in sorted(context.scene.objects, key=lambda o: o.name):
        if o.grasp_lab.role == "FINGER":
            other = by_channel.setdefault(o.grasp_lab.channel, o.name)
            if other != o.name:
                raise CliError(f"--device: fingers {other!r} and {o.name!r} are both on device channel "
                               f"{o.grasp_lab.channel}: give each finger its own channel")


def apply_overrides(context, overrides) -> list:
    """--set on the open scene's objects and settings. Returns what was set, as text."""
    s = context.scene.grasp_lab
    done = []
    for o in overrides:
        if not o.obj:
            setattr(s, o.key, o.value)
        else:
            obj = bpy.data.objects.get(o.obj)
            if obj is None or obj.grasp_lab.role == "NONE":
                raise CliError(f"--set {o}: no Grasp Lab body or finger named {o.obj!r} in the scene")
            gl = obj.grasp_lab
            allowed = FINGER_KEYS if gl.role == "FINGER" else BODY_KEYS
            if o.key not in allowed:
                raise CliError(f"--set {o}: {o.obj!r} is a {gl.role.lower()} object; {o.key} is not one "
                               f"of its properties ({', '.join(allowed)})")
            if o.key == "mass":
                if gl.role == "STATIC":
                    raise CliError(f"--set {o}: {o.obj!r} is static (it has no mass to set)")
                gl.mass_mode = "MASS"
            setattr(gl, o.key, o.value.upper() if o.key == "renderer" else o.value)   # the enum's identifiers
        done.append(str(o))
    return done


def run(args, out, err) -> int:
    from .session import BlenderSession, live_session
    open_blend(args.scene)
    context = bpy.context
    applied = apply_overrides(context, args.set)
    check_run_size(context, args)
    if args.device:
        check_channels(context)
    record = os.path.abspath(args.record) if args.record else None
    if isinstance(getattr(args, "live_view", None), str):
        # The Rerun SDK (with pyarrow) takes seconds to import on a busy machine: before the
        # session's clock starts, not out of its duration.
        from .engine.rerun_view import _sdk
        try:
            _sdk()
        except ImportError as ex:
            raise CliError(str(ex)) from None
    if args.device and not args.duration:
        raise CliError("--device: give --duration S (a device session has no end of its own)")
    # Everything that can refuse does so before the recording is opened: the --save target
    # claimed (locked), the live view's address bound.
    saving = claim_blend(args.save) if args.save else None
    live_server = _bind_live(args) if getattr(args, "live_view", None) is not None else None
    try:
        session = _start_session(context, args, record, live_server)
    except BaseException:
        if live_server is not None:
            live_server.close()
        raise
    if session.sound_message:
        print(f"grasp-lab run: {session.sound_message}", file=err, flush=True)
    if getattr(args, "live_view", None) is not None:
        print(f"live view: {session.live_view.address} ({session.live_view.hint})", file=out, flush=True)
    if session.recorder is not None:
        for o in args.set:          # in the header's scene already; the events say they were set
            session.recorder.parameter_change(0.0, o.obj or "scene", o.key, o.value)
    try:
        if args.realtime:
            session.run_live()
        else:
            session.run_to_end()
    finally:
        result = session.finish()
    code = _report(args, result, session.runner.recording_end, applied, saving, out)
    return (_report_devices(session, out, err) or code) if args.device else code


def _start_session(context, args, record, live_server):
    """The session, its devices connected and its live view attached (served to Foxglove,
    engine/live_view.py, or streamed to Rerun, engine/rerun_view.py); a session that fails at
    its start ends with its recording discarded (the file it would replace as it was)."""
    from .session import BlenderSession, live_session, start_live_view
    if args.device:
        session = live_session(context, args.device, args.forces == "on", duration=args.duration,
                               record_path=record, sound=args.sound)
    else:
        session = BlenderSession(context, live=args.realtime,
                                 duration=args.duration if args.duration else None, record_path=record,
                                 sound=args.sound)
        if session.duration == float("inf"):
            session.finish(discard_recording=True)
            raise CliError(f"{args.scene}: a real-time session with no fingertip animated, or driven by the "
                           f"scene's devices, has no end: give --duration S")
    if getattr(args, "live_view", None) is not None:
        try:
            start_live_view(session, args.live_view, args.live_view_bind, server=live_server)
        except (ImportError, OSError) as ex:
            session.finish(discard_recording=True)
            raise CliError(str(ex)) from None
    return session


def _bind_live(args):
    """--live-view PORT: its address bound before the session (and its recording) starts (a
    Rerun live view connects to its viewer instead: nothing to bind)."""
    if isinstance(args.live_view, str):
        return None
    from .engine.live_view import bind_server
    try:
        return bind_server(args.live_view, args.live_view_bind)
    except (ImportError, OSError) as ex:
        raise CliError(f"--live-view {args.live_view_bind}:{args.live_view}: {ex}") from None


def _report(args, result, end, applied, saving, out) -> int:
    st = result.stats
    print(f"{os.path.abspath(args.scene)}: {st['time']:.3f} s simulated, {st.get('runtime_haptic_ticks', st['steps'])} ticks at "
          f"{st['haptic_rate_target']:g} Hz ({'threaded runtime, real time' if st['threaded'] else 'EXEC'}), "
          f"{len(result.body_names)} bodies, {len(result.finger_names)} fingers"
          + (f"; set {', '.join(applied)}" if applied else ""), file=out)
    if st.get("live_view"):
        lv = st["live_view"]
        refused = lv.get("refused") or {}
        print(f"live view: {lv['updates']} updates, {lv['dropped']} skipped"
              + (f", {sum(refused.values())} client requests refused "
                 f"({', '.join(f'{k} {n}' for k, n in sorted(refused.items()))})" if refused else "")
              + (f"; {lv['error']}" if lv["error"] else ""), file=out)
    if result.recording:
        if end.get("recorder_error"):       # said before anything claims it was written
            raise CliError(f"{result.recording}: {end['recorder_error']}")
        print(f"recording: {result.recording} ({end.get('overflow', 0)} ticks lost to overflow)", file=out)
    if saving is not None:
        print(f"saved: {save_blend(saving)}", file=out)
    return 0


def _report_devices(live, out, err) -> int:
    """Which device drove which finger; a device lost during the run is said on standard
    error: EXIT_DEVICE_LOST (docs/cli.md)."""
    from .engine.cli import EXIT_DEVICE_LOST
    from .engine.devices.live import loss_lines
    from .engine.devices.live import summary_line
    print(f"fingers: {live.input_description()['detail']}", file=out)
    for label, st in live.result.stats.get("device_stats", {}).items():
        print(f"device {summary_line(label, st)}", file=out)
    lines = loss_lines(live.result.stats.get("device_events", []))
    for label, st in live.result.stats.get("device_stats", {}).items():
        # A serial or UDP device that answered nothing the session could use drove nothing:
        # an error, not a quiet run of fingers that never moved.
        if "poses" in st and not st["poses"]:
            kinds = ", ".join(f"{k} {v}" for k, v in st.get("frame_errors", {}).items() if v)
            lines.append(f"{label} never sent a valid pose ({st.get('dropped', 0)} frames dropped"
                         + (f": {kinds}" if kinds else "") + "); its fingers did not follow it")
    for line in lines:
        print(f"grasp-lab run: device {line}", file=err)
    return EXIT_DEVICE_LOST if lines else 0


def bake(args, out, err) -> int:
    saving = claim_blend(args.save)     # a second bake to this path is refused now, not after its work
    open_blend(args.scene)
    render = bpy.context.scene.render
    rec = open_recording(args.recording, fps=None if args.every_tick else render.fps / render.fps_base,
                         previous=True)
    for w in rec.warnings():
        print(f"warning: {w}", file=err)
    if len(rec.ticks) == 0:
        raise CliError(f"{args.recording}: no tick was recorded: nothing to bake")
    _check_bake_fits(args, rec)
    report = baking.bake_recording(bpy.context, rec, every_tick=args.every_tick, blend_path=args.save)
    for name in report.missing:
        print(f"warning: {args.scene}: {name} is not in the scene (renamed or deleted): not baked", file=err)
    print(f"{args.recording}: {report.message()}", file=out)
    print(f"saved: {save_blend(saving)}", file=out)
    if report.sound_error:      # after the save: a scene that could not be saved is the one error to tell
        print(f"warning: {args.recording}: no sound baked: {report.sound_error}", file=err)
    return 0


def _check_bake_fits(args, rec) -> None:
    """A recording made in another scene (none of its bodies and fingers here, or some
    missing) is refused, naming them, unless --force: baking it would only move the end frame."""
    scene = rec.header.get("scene", {})
    names = [b["name"] for b in scene.get("bodies", [])] + [f["name"] for f in scene.get("fingers", [])]
    missing = [n for n in names if bpy.data.objects.get(n) is None]
    if missing and not getattr(args, "force", False):
        shown = ", ".join(missing[:8]) + (f" and {len(missing) - 8} more" if len(missing) > 8 else "")
        whose = "none" if len(missing) == len(names) else f"{len(missing)} of {len(names)}"
        raise CliError(f"{args.recording}: {whose} of its bodies and fingers are in {args.scene} "
                       f"(missing: {shown}); is it this scene's recording? --force bakes what is there")


# The Blender commands' work, by name: the command line (engine/cli.py) checks their arguments,
# then dispatches here through its BLENDER_COMMANDS table (cli_blender.py fills it).
COMMANDS = {"run": run, "bake": bake, "emulate": emulate_blend.emulate}
