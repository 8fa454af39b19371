"""The Blender half of `make demo`: the pinch-and-lift sample scene, headless, through the
extension.

Builds the scene of build_pinch_and_lift.py (table, box, two animated fingertips), runs
the `grasp_lab.session` operator (EXEC) with display objects, keyframe baking and
recording on, and writes to OUT (default build/demo/):

    pinch_and_lift.blend            the scene, keyframed at every frame (box, god-objects,
                                    residual force/torque arrows, finger-force arrows);
                                    opens on the mid-lift frame
    pinch_and_lift.mcap             the session recording: every haptic tick (docs/recording-format.md)
    pinch_and_lift_box.csv          the box per frame, with the finger forces and states
    pinch_and_lift_frame43.png      a Workbench render of frame 43 (mid-lift)

Usage: python sample_scenes/demo_session.py [--out build/demo] [--zip dist/grasp_lab-….zip]
       [--no-render]

``run(bpy, out_dir)`` is importable (the extension must be enabled).
"""
from __future__ import annotations

import argparse
import csv
import importlib
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
FORCE_SCALE = 0.01          # m/N: 3 N of squeeze is a 3 cm arrow
STATE_NAMES = ("free", "stick", "slip")


def _scene_module():
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        "build_pinch_and_lift", os.path.join(HERE, "build_pinch_and_lift.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _session_module(bpy):
    import importlib
    for mod in bpy.context.preferences.addons.keys():
        if mod.endswith(".grasp_lab"):
            return importlib.import_module(f"{mod}.session")
    raise RuntimeError("the grasp_lab extension is not enabled")


def run(bpy, out_dir, render=True, stream=sys.stdout) -> dict:
    """Build, run, bake, save, render; print a summary. Returns what it wrote and measured."""
    import numpy as np
    sample = _scene_module()
    out_dir = os.path.abspath(out_dir)
    os.makedirs(out_dir, exist_ok=True)
    paths = {k: os.path.join(out_dir, f"pinch_and_lift{suffix}") for k, suffix in (
        ("blend", ".blend"), ("recording", ".mcap"), ("csv", "_box.csv"),
        ("png", f"_frame{sample.MID_LIFT_FRAME}.png"))}
    timings = {}

    bpy.ops.wm.read_homefile(use_empty=True)
    sample.build(bpy)
    sample.add_render_setup(bpy)
    scene = bpy.context.scene
    s = scene.grasp_lab
    s.display_objects = True
    s.bake = True
    s.record = True
    s.recording_folder = out_dir
    s.force_scale = FORCE_SCALE

    t0 = time.perf_counter()
    if bpy.ops.grasp_lab.session() != {"FINISHED"}:
        raise RuntimeError("grasp_lab.session did not finish")
    timings["session"] = time.perf_counter() - t0
    res = _session_module(bpy).last_result
    os.replace(res.recording, paths["recording"])
    s.last_recording = paths["recording"]

    recording = importlib.import_module(f"{_session_module(bpy).__package__}.engine.recording")
    frames = np.array(res.frames)
    full = recording.open_recording(paths["recording"])
    rec = full.ticks[full.sample((frames - frames[0]) / sample.FPS)]    # the tick each frame shows
    box = res.trajectory("Box")
    forces = rec["device_force"]                        # rendered to the device, N
    grip = 0.5 * (forces[:, 1, 0] - forces[:, 0, 0])    # squeeze (finger 0 is on the -x side)
    lift = -forces[:, :, 2].sum(axis=1)                 # weight carried by the fingers
    grip, lift = (np.where(np.abs(v) < 5e-7, 0.0, v) for v in (grip, lift))   # no "-0.000"
    states = rec["state"]

    # The device forces as baked arrows too, so the .blend and the render show them.
    t0 = time.perf_counter()
    sample.add_finger_force_arrows(bpy, frames, rec["god_object"], forces, FORCE_SCALE)
    timings["bake"] = time.perf_counter() - t0

    with open(paths["csv"], "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", "t", "phase", "box_x", "box_y", "box_z", "box_qw", "box_qx", "box_qy",
                    "box_qz", "grip_N", "lift_N", "finger0", "finger1"])
        for k, fr in enumerate(frames):
            w.writerow([int(fr), f"{rec['time'][k]:.6f}", sample.phase_at(fr),
                        *(f"{v:.9f}" for v in box[k]), f"{grip[k]:.6f}", f"{lift[k]:.6f}",
                        *(STATE_NAMES[int(v)] for v in states[k])])

    scene.frame_set(sample.MID_LIFT_FRAME)
    bpy.ops.wm.save_as_mainfile(filepath=paths["blend"])
    if render:
        t0 = time.perf_counter()
        sample.render(bpy, paths["png"])
        timings["render"] = time.perf_counter() - t0
    else:
        del paths["png"]

    # ---- summary
    p = lambda *a: print(*a, file=stream)   # noqa: E731
    st = res.stats
    p(f"Blender {bpy.app.version_string} (bpy module, headless), extension "
      f"{_session_module(bpy).__package__.rsplit('.', 1)[0]}: grasp_lab.session (EXEC) on the "
      f"pinch-and-lift sample scene")
    p(f"{st['time']:.2f} s simulated: {st['steps']} core steps at {st['haptic_rate_target']:.0f} Hz, "
      f"{len(frames)} frames at {sample.FPS} fps, in {timings['session']:.2f} s "
      f"({st['step_us']:.0f} us/step)")
    p(f"{'frame':>5} {'t [s]':>6}  {'phase':<9} {'box z [mm]':>10} {'box y [mm]':>10} "
      f"{'grip [N]':>8} {'lift [N]':>8}  fingers")
    for k in range(0, len(frames), sample.FPS // 2):
        p(f"{frames[k]:5d} {rec['time'][k]:6.2f}  {sample.phase_at(frames[k]):<9} "
          f"{box[k, 2] * 1e3:10.3f} {box[k, 1] * 1e3:10.3f} {grip[k]:8.3f} {lift[k]:8.3f}  "
          + " ".join(f"{STATE_NAMES[int(v)]:5}" for v in states[k]))
    z0, z1 = box[0, 2], box[-1, 2]
    top = box[:, 2].max()
    p(f"box: rests at z {z0 * 1e3:.3f} mm, lifted to {top * 1e3:.3f} mm, carried "
      f"{(box[-1, 1] - box[0, 1]) * 1e3:.2f} mm along y, back on the table at z {z1 * 1e3:.3f} mm "
      f"({round((z1 - z0) * 1e6, 2) + 0.0:+.2f} um)")
    p("lift = the weight the fingers carry, as the device renders it (m g = 0.981 N while held "
      "or carried at constant speed)")
    p(f"outputs in {os.path.relpath(out_dir)}/ (session {timings['session']:.2f} s, arrows "
      f"{timings['bake']:.2f} s" + (f", render {timings['render']:.2f} s" if render else "") + "):")
    notes = {"blend": "baked keyframes, opens on the mid-lift frame",
             "recording": f"session recording: {len(full.ticks)} haptic ticks, {len(full.events)} events "
                          f"(grasp-lab info / export / bake / resim)",
             "csv": f"box pose, grip, lift and finger states per frame ({len(frames)} rows)",
             "png": f"Workbench render of frame {sample.MID_LIFT_FRAME}, mid-lift"}
    for key, path in paths.items():
        p(f"  {os.path.basename(path):<28} {notes[key]}")
    return {"paths": paths, "frames": frames, "box": box, "grip": grip, "lift": lift,
            "states": states, "timings": timings, "stats": st}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "build", "demo"))
    ap.add_argument("--zip", help="install the extension from this built zip (default: "
                                  "$GRASP_LAB_ZIP, else a development repository of addon/)")
    ap.add_argument("--no-render", action="store_true")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
    import grasp_env                 # isolates Blender's user resources, then loads the add-on
    grasp_env.isolate()
    import bpy
    grasp_env.enable(args.zip)
    t_load = time.perf_counter() - t0
    run(bpy, args.out, render=not args.no_render)
    print(f"(bpy import and extension install {t_load:.1f} s, total {time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
