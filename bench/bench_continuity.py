"""Force continuity over the sample scenes and along the hooked mug's handle (issue 20).

For every scene of sample_scenes/library.py: the scene is built, run headless (EXEC, 1 kHz)
with a recording, and the recording's force continuity is measured
(addon/engine/continuity.py): per finger the per-tick change of the rendered force, its
p99.9 and largest value, and every change above the threshold with its cause. Then the
mug of `mug_hook` held still while a finger pressed 4 N into its handle slides 60 degrees
along the inside of the ring across the seams of its convex parts (tests/core/scenes.py).

    .venv/bin/python bench/bench_continuity.py [--threshold 0.25] [--only mug_hook ...]

prints Markdown tables (docs/benchmarks.md, "Force continuity").
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests", "core"))

from addon.engine.continuity import WINDOW, cause_counts, finger_continuity, force_continuity  # noqa: E402
from addon.engine.recording import open_recording  # noqa: E402


def scene_rows(names, threshold, folder):
    py = sys.executable
    subprocess.run([py, os.path.join(ROOT, "sample_scenes", "library.py"), "--out", folder, "--only", *names],
                   check=True, stdout=subprocess.DEVNULL)
    rows = []
    for name in names:
        rec_path = os.path.join(folder, f"{name}.mcap")
        subprocess.run([os.path.join(ROOT, ".venv", "bin", "grasp-lab"), "run", os.path.join(folder, f"{name}.blend"),
                        "--record", rec_path], check=True, stdout=subprocess.DEVNULL)
        r = force_continuity(open_recording(rec_path), threshold=threshold)
        worst = max(r["fingers"], key=lambda f: f["max"])
        jumps = [j for f in r["fingers"] for j in f["jumps"]]
        counts = {}
        for f in r["fingers"]:
            for c, n in cause_counts(f).items():
                counts[c] = counts.get(c, 0) + n
        biggest = max(jumps, key=lambda j: j["delta"]) if jumps else None
        rows.append({"scene": name, "fingers": len(r["fingers"]),
                     "p999": max(f["p999"] for f in r["fingers"]), "max": worst["max"], "max_finger": worst["name"],
                     "max_time": worst["max_time"], "max_causes": biggest["causes"] if biggest else [],
                     "jumps": len(jumps), "causes": counts,
                     "unexplained": sum(1 for j in jumps if j["causes"] == ["unexplained"])})
    return rows


def mug_slide(threshold, seconds, renderer="xfca"):
    """The handle slide: the largest per-tick change while slipping, without and with the
    ticks of a stick/slip transition (the friction law's own step, (mu_s - mu_d) |Fn|)."""
    import scenes
    w, hips = scenes.mug_handle_slide(seconds=seconds, renderer=renderer)
    ticks = scenes.run_ticks(w, hips)
    k = scenes.MUG_FINGER["stiffness"]
    r = finger_continuity(ticks, 0, k, scenes.MUG_FINGER["damping"], threshold)
    delta, state = r["delta"], ticks["state"][:, 0]
    slide = np.zeros(len(delta), dtype=bool)
    start = 1 + int(0.2 / 1e-3) + int(0.3 / 1e-3)
    slide[start:start + int(seconds / 1e-3)] = True
    transition = np.zeros(len(delta), dtype=bool)
    transition[1:] = state[1:] != state[:-1]
    near = transition.copy()                # the transition and the ticks it can explain
    for lag in range(1, WINDOW + 1):
        near[lag:] |= transition[:-lag]
    force = np.linalg.norm(ticks["force"][:, 0], axis=1)
    parts = ticks["parts"][:, 0]
    part_change = np.zeros(len(delta), dtype=bool)
    part_change[1:] = (parts[1:] != parts[:-1]) & (parts[1:] != 0) & (parts[:-1] != 0)
    return {"max_sliding": float(delta[slide & ~near].max()), "renderer": renderer, "max_with_stick_slip": float(delta[slide].max()),
            "max_at_part_change": float(delta[part_change & slide & ~near].max()) if (part_change & slide & ~near).any() else 0.0,
            "part_changes": int((part_change & slide).sum()), "p999": float(np.percentile(delta[slide], 99.9)),
            "force_min": float(force[slide].min()), "force_max": float(force[slide].max()),
            "jumps": r["jumps"], "max_parts": int(max(bin(int(p)).count("1") for p in parts))}


def _step_times(w, hips, dt=1e-3):
    """Wall time of each w.step (µs), HIPs set outside the timed call."""
    import time
    out = np.empty(len(hips))
    for t, h in enumerate(hips):
        w.set_hips(np.asarray(h, float).reshape(1, 3))
        t0 = time.perf_counter_ns()
        w.step(dt)
        out[t] = (time.perf_counter_ns() - t0) / 1e3
    return out


def _corner_world(renderer):
    """Worst case of the cursor's solve: a fingertip pressed into a corner of a cubic cavity
    whose six walls are six convex parts, sweeping round it (three planes active, six in reach)."""
    import graspcore
    import scenes
    half, t = 0.02, 0.004
    walls = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            c = np.zeros(3)
            c[axis] = sign * (half + t / 2)
            h = [half + t] * 3
            h[axis] = t / 2
            walls.append(scenes.box_points(*h, center=c))
    w = graspcore.World()
    w.add_body(parts=walls, static=True, mu_s=0.6, mu_d=0.5)
    r, d = 0.005, 0.002
    corner = np.array([half - r + d] * 3)
    n = 2000
    a = np.linspace(0.0, 4 * np.pi, n)
    hips = corner + 0.001 * np.stack([np.cos(a), np.sin(a), np.zeros(n)], axis=1)
    w.add_finger(radius=r, stiffness=1000.0, damping=2.0, position=np.zeros(3), renderer=renderer)
    hips = np.concatenate([np.linspace(np.zeros(3), corner, 300), hips])
    return w, hips


def cost(repeats=5):
    """Per tick of one finger (µs, the step's wall time with the Python call): the handle
    slide (0.3 s) and the six-wall corner, xFCA beside the cursor, repeats interleaved."""
    import scenes
    rows = {}
    for _ in range(repeats):
        for scene in ("handle slide", "six-wall corner"):
            for renderer in ("xfca", "cursor"):
                if scene == "handle slide":
                    w, hips = scenes.mug_handle_slide(seconds=0.3, renderer=renderer)
                else:
                    w, hips = _corner_world(renderer)
                rows.setdefault((scene, renderer), []).append(_step_times(w, hips))
    out = {}
    for key, runs in rows.items():
        med = np.median([np.median(r) for r in runs])
        p99 = np.median([np.percentile(r, 99) for r in runs])
        worst = np.median([r.max() for r in runs])
        out[key] = (med, p99, worst)
    return out


def bowl(renderer):
    """The decomposed bowl traced inside at 3 N (tests/core/scenes.py, bowl_trace)."""
    import scenes
    w, hips = scenes.bowl_trace(renderer=renderer)
    ticks = scenes.run_ticks(w, hips)
    r = finger_continuity(ticks, 0, 1000.0, 2.0, 0.1)
    state = ticks["state"][:, 0]
    transition = np.zeros(len(state), dtype=bool)
    transition[1:] = state[1:] != state[:-1]
    near = transition.copy()
    for lag in range(1, WINDOW + 1):
        near[lag:] |= transition[:-lag]
    trace = np.zeros(len(state), dtype=bool)
    trace[401:1901] = True
    force = np.linalg.norm(ticks["force"][:, 0], axis=1)
    return {"max_sliding": float(r["delta"][trace & ~near].max()), "max": float(r["delta"][trace].max()),
            "force_min": float(force[trace].min()), "force_max": float(force[trace].max()),
            "unexplained": sum(1 for j in r["jumps"] if j["causes"] == ["unexplained"])}


SLIDE_SECONDS = (2.0, 0.3)      # 60 degrees of the 13.7 mm arc: 14 and 96 mm/s on average


def main(argv=None):
    from sample_scenes import library
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threshold", type=float, default=0.25, help="N per tick (default 0.25)")
    ap.add_argument("--only", nargs="+", choices=sorted(library.SCENES), help="these scenes only")
    ap.add_argument("--cost", action="store_true", help="also time both renderers per tick")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        rows = scene_rows(args.only or list(library.SCENES), args.threshold, folder)
    print(f"| scene | fingers | p99.9 of per-tick change | largest (finger, time, cause) | changes > {args.threshold:g} N: causes | unexplained |")
    print("| --- | --- | --- | --- | --- | --- |")
    for r in rows:
        causes = ", ".join(f"{c} {n}" for c, n in sorted(r["causes"].items())) or "none"
        cause = ", ".join(r["max_causes"]) if r["max"] > args.threshold else "below the threshold"
        print(f"| {r['scene']} | {r['fingers']} | {r['p999']:.3f} N | {r['max']:.3f} N ({r['max_finger']}, "
              f"{r['max_time']:.3f} s, {cause}) | {r['jumps']}: {causes} | {r['unexplained']} |")
    slides = [mug_slide(args.threshold, seconds, renderer) for renderer in ("xfca", "cursor")
              for seconds in SLIDE_SECONDS]
    print()
    print("| hooked mug's handle, 60 degrees slid at 4 N | " +
          " | ".join(f"{m['renderer']}, {s:g} s" for m, s in zip(slides, SLIDE_SECONDS * 2)) + " |")
    print("| --- | " + " | ".join("---" for _ in slides) + " |")
    rows = (("largest per-tick change while sliding (stick/slip transitions aside)", "max_sliding", "{:.3f} N"),
            ("largest at a change of convex part (stick/slip transitions aside)", "max_at_part_change", "{:.3f} N"),
            ("changes of convex part while sliding", "part_changes", "{}"),
            ("largest with the stick/slip transitions", "max_with_stick_slip", "{:.3f} N"),
            ("p99.9 while sliding", "p999", "{:.3f} N"),
            ("least force while sliding", "force_min", "{:.2f} N"),
            ("largest force while sliding", "force_max", "{:.2f} N"),
            ("most parts touched at once", "max_parts", "{}"))
    for label, key, fmt in rows:
        print(f"| {label} | " + " | ".join(fmt.format(m[key]) for m in slides) + " |")
    bowls = {r: bowl(r) for r in ("xfca", "cursor")}
    print()
    print("| the bowl (20 parts) traced 120 degrees inside at 3 N in 1.5 s | xfca | cursor |")
    print("| --- | --- | --- |")
    for label, key, fmt in (("largest per-tick change (stick/slip transitions aside)", "max_sliding", "{:.3f} N"),
                            ("largest with the stick/slip transitions", "max", "{:.3f} N"),
                            ("changes above 0.1 N with no cause", "unexplained", "{}"),
                            ("least force", "force_min", "{:.2f} N"), ("largest force", "force_max", "{:.2f} N")):
        print(f"| {label} | " + " | ".join(fmt.format(bowls[r][key]) for r in ("xfca", "cursor")) + " |")
    if args.cost:
        c = cost()
        print()
        print("| one finger, per tick (µs: median / p99 / largest) | xFCA | cursor | cursor / xFCA (median) |")
        print("| --- | --- | --- | --- |")
        for scene in ("handle slide", "six-wall corner"):
            x, k = c[(scene, "xfca")], c[(scene, "cursor")]
            print(f"| {scene} | {x[0]:.2f} / {x[1]:.2f} / {x[2]:.1f} | {k[0]:.2f} / {k[1]:.2f} / {k[2]:.1f} | "
                  f"{k[0] / x[0]:.1f}x |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
