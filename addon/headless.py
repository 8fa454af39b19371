"""The Blender half of ``grasp-lab run`` and ``grasp-lab bake`` (engine/cli.py parses and
dispatches; this runs them in the loaded extension, headless or in a Blender)."""
from __future__ import annotations

import os
import time

import bpy

from . import bake as baking
from .engine.cli import CliError
from .engine.recording import open_recording
from .engine.resim import BODY_KEYS, FINGER_KEYS


def open_blend(path: str) -> None:
    path = os.path.abspath(path)
    if not os.path.isfile(path):
        raise CliError(f"{path}: no such file")
    try:
        bpy.ops.wm.open_mainfile(filepath=path)
    except RuntimeError as ex:
        raise CliError(f"{path}: cannot open as a .blend ({str(ex).strip()})") from None


def save_blend(path: str) -> str:
    path = os.path.abspath(path)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=path)
    return path


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
                gl.mass_mode = "MASS"
            setattr(gl, o.key, o.value)
        done.append(str(o))
    return done


def run(args, out, err) -> int:
    from .session import BlenderSession
    open_blend(args.scene)
    context = bpy.context
    applied = apply_overrides(context, args.set)
    record = os.path.abspath(args.record) if args.record else None
    if args.device:
        from .devices_ui import run_realtime
        if not args.duration:
            raise CliError("--device: give --duration S (a device session has no end of its own)")
        live = run_realtime(context, args.duration, device_specs=args.device, record_path=record)
        return _report(args, live.finish(), live.runner.recording_end, applied, out)
    session = BlenderSession(context, live=args.realtime,
                             duration=args.duration if args.duration else None, record_path=record)
    if session.duration == float("inf"):
        session.finish()
        raise CliError(f"{args.scene}: no fingertip is animated, so a real-time session has no end: "
                       f"give --duration S")
    if session.recorder is not None:
        for o in args.set:          # in the header's scene already; the events say they were set
            session.recorder.parameter_change(0.0, o.obj or "scene", o.key, o.value)
    try:
        if args.realtime:
            period = 1.0 / context.scene.grasp_lab.display_rate
            t0 = time.perf_counter()
            while True:
                wall = time.perf_counter() - t0
                session.tick(wall)
                if session.runner.time >= session.duration - 1e-9:
                    break
                time.sleep(max(0.0, period - (time.perf_counter() - t0 - wall)))
        else:
            session.run_to_end()
    finally:
        result = session.finish()
    return _report(args, result, session.runner.recording_end, applied, out)


def _report(args, result, end, applied, out) -> int:
    st = result.stats
    print(f"{os.path.abspath(args.scene)}: {st['time']:.3f} s simulated, {st.get('runtime_haptic_ticks', st['steps'])} ticks at "
          f"{st['haptic_rate_target']:g} Hz ({'threaded runtime, real time' if st['threaded'] else 'EXEC'}), "
          f"{len(result.body_names)} bodies, {len(result.finger_names)} fingers"
          + (f"; set {', '.join(applied)}" if applied else ""), file=out)
    if result.recording:
        print(f"recording: {result.recording} ({end.get('overflow', 0)} ticks lost to overflow)", file=out)
        if end.get("recorder_error"):
            raise CliError(f"{result.recording}: {end['recorder_error']}")
    if args.save:
        print(f"saved: {save_blend(args.save)}", file=out)
    return 0


def bake(args, out, err) -> int:
    open_blend(args.scene)
    render = bpy.context.scene.render
    rec = open_recording(args.recording, fps=None if args.every_tick else render.fps / render.fps_base,
                         previous=True)
    for w in rec.warnings():
        print(f"warning: {w}", file=err)
    report = baking.bake_recording(bpy.context, rec, every_tick=args.every_tick)
    for name in report.missing:
        print(f"warning: {args.scene}: {name} is not in the scene (renamed or deleted): not baked", file=err)
    print(f"{args.recording}: {report.message()}", file=out)
    print(f"saved: {save_blend(args.save)}", file=out)
    return 0
