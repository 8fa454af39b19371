"""The table in docs/devices.md of which device renders which of the library's grasps (`make fit-table`).

Every scene of the library (sample_scenes/library.py) is built, run headless and recorded; each
recording is evaluated against every device profile (engine/fit.py, the same evaluation as
`grasp-lab fit`), and the table between the markers in docs/devices.md is rewritten.

A device with as many end-effectors as the scene has fingers (or more) takes the fingers in order;
a single-effector device with fewer is evaluated as one unit a finger ("3 ×": three Touches side by
side, each finger on its own: their interference with one another is not evaluated, a limit said in
the docs); a rig with several end-effectors but fewer than the fingers fails for want of them.

    python sample_scenes/fit_table.py [--docs docs/devices.md] [--out build/fit] [--only NAME ...]
"""
from __future__ import annotations

import argparse
import os
import re
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
BEGIN, END = "<!-- fit-table: begin (make fit-table) -->", "<!-- fit-table: end -->"


def record_scene(bpy, lib, name, folder) -> str:
    """Build and run one library scene, recorded; returns the recording's path."""
    bpy.ops.wm.read_homefile(use_empty=True)
    lib.build(bpy, name)
    s = bpy.context.scene.grasp_lab
    s.record = True
    s.recording_folder = folder
    s.bake = False
    lib.run(bpy)
    path = os.path.join(folder, f"{name}.mcap")
    if os.path.exists(path):
        os.remove(path)
    os.replace(s.last_recording, path)
    return path


def cell(task, profile, fit) -> str:
    """One table cell: the verdict, and for a failure its first cause and where."""
    n = len(task.finger_names)
    if profile.end_effectors >= n or profile.end_effectors > 1:
        results = [fit.evaluate(task, profile)]
        prefix = ""
    else:
        results = [fit.evaluate(task, profile, [f]) for f in task.finger_names]
        prefix = f"{n} × "
    fingers = [f for r in results for f in r.fingers]
    verdict = max((f.verdict for f in fingers), key=fit.VERDICTS.index)
    if verdict != "fails":
        return prefix + verdict
    first = min((f for f in fingers if f.verdict == "fails"), key=lambda f: (f.first_fail_time, f.finger))
    if first.check == "end_effectors":
        return f"fails: {n} fingers, {profile.end_effectors} end-effectors"
    what = {"workspace": "workspace", "peak": "peak force", "duty": "continuous force", "stiffness": "stiffness",
            "interference": "thimbles touch", "crossing": "crossing"}[first.check]
    return f"{prefix}fails: {what}, {first.finger} at {first.first_fail_time:.2f} s"


def table(rows, profiles) -> str:
    head = "| scene | " + " | ".join(f"`{p.name}`" for p in profiles) + " |"
    lines = [head, "|---" * (len(profiles) + 1) + "|"]
    for name, cells in rows:
        lines.append(f"| `{name}` | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_docs(path, text) -> None:
    with open(path) as f:
        doc = f.read()
    if BEGIN not in doc or END not in doc:
        raise SystemExit(f"{path}: the markers {BEGIN} ... {END} are not there")
    doc = re.sub(re.escape(BEGIN) + r".*?" + re.escape(END), lambda m: f"{BEGIN}\n{text}\n{END}", doc, flags=re.S)
    with open(path + ".partial", "w") as f:
        f.write(doc)
    os.replace(path + ".partial", path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--docs", default=os.path.join(ROOT, "docs", "devices.md"), help="the page whose table is rewritten")
    ap.add_argument("--out", default=os.path.join(ROOT, "build", "fit"), help="where the recordings go")
    ap.add_argument("--only", nargs="+", help="these scenes only (prints the table, leaves the docs)")
    args = ap.parse_args(argv)
    sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
    sys.path.insert(0, HERE)
    sys.path.insert(0, ROOT)
    import grasp_env
    grasp_env.isolate()
    import bpy
    grasp_env.enable()
    import library as lib
    from addon.engine import fit
    from addon.engine.devices import device_profiles
    from addon.engine.recording import open_recording
    profiles = device_profiles.load_all()
    os.makedirs(args.out, exist_ok=True)
    rows = []
    for name in args.only or lib.SCENES:
        path = record_scene(bpy, lib, name, args.out)
        task = fit.task_from_recording(open_recording(path))
        cells = [cell(task, p, fit) for p in profiles]
        rows.append((name, cells))
        print(f"{name} ({len(task.finger_names)} fingers): " + "; ".join(
            f"{p.name} {c}" for p, c in zip(profiles, cells)), flush=True)
    text = table(rows, profiles)
    if args.only:
        print(text)
    else:
        write_docs(args.docs, text)
        print(f"{args.docs}: table of {len(rows)} scenes x {len(profiles)} profiles written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
