"""The live view's grasp analysis, per display update: 2 boxes each held by 5 fingers (the
5-finger grasp of the held-box benchmark, bench/bench_core_scenes.py).

Two measurements:

1. On the main thread, per display update (the session's `apply`): the snapshot (the work a
   display update did before the analysis existed), `GraspMonitor.update` (accelerations +
   `analysis.analyse` of both bodies), and what the HUD and the overlay derive from it (text,
   colours, weakest-wrench geometry). Target: the analysis under 0.5 ms (issue 14). Then the
   analysis again with the hand carrying both boxes up and down (a new contact set every
   update: what the memo and the core's `reuse` cannot save).
2. The threaded runtime at 1 kHz while the main thread takes snapshots at 60 Hz, with and
   without the analysis (alternating runs): the haptic loop's mean tick and p99 period
   jitter must not change (the analysis never runs on the haptic thread).

3. With ``--gui``: the GUI test's grasp_hud scenario (tests/gui, a three-finger grasp in the GUI
   Blender 4.3 under Xvfb and llvmpipe): the analysis per display update there.

    .venv/bin/python bench/bench_live_grasp.py [--updates 600] [--runs 3] [--seconds 3] [--gui] [--out FILE]
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
sys.path.insert(0, ROOT)

import bench_core_scenes as core  # noqa: E402
from addon.engine import analysis, grasp_display, inputs, runner, scene  # noqa: E402

DISPLAY_RATE = 60.0
TARGET_MS = 0.5         # issue 14: the analysis of 2 bodies x 5 fingers per display update
BODIES_AT = ((0.0, 0.0, 0.0), (0.5, 0.0, 0.0))


def two_held_boxes():
    """Scene description: two 6 cm, 200 g boxes 0.5 m apart, each with the 5-finger grasp."""
    import trimesh
    spec = core.scene_spec(5)
    bodies, fingers = [], []
    m = trimesh.creation.box((2 * core.HALF,) * 3)
    for k, at in enumerate(BODIES_AT):
        at = np.asarray(at, float)
        bodies.append(scene.BodyDesc(f"Box{k}", False, [np.array(m.vertices)],
                                     [scene.MeshData(np.array(m.vertices), np.array(m.faces))], at,
                                     np.array([1.0, 0, 0, 0]), mass=core.MASS, mu_s=core.MU_S, mu_d=core.MU_D))
        for i, h in enumerate(spec["hips"]):
            fingers.append(scene.FingerDesc(f"F{k}{i}", at + np.asarray(h), radius=core.TIP,
                                            stiffness=core.STIFFNESS, damping=core.DAMPING))
    return scene.prepare(scene.SceneDesc(bodies=bodies, fingers=fingers, gravity=core.GRAVITY))


def _stats(xs) -> dict:
    a = np.asarray(xs) * 1e3
    return {"median_ms": float(np.median(a)), "p99_ms": float(np.percentile(a, 99)), "max_ms": float(a.max())}


MOVE_MM, MOVE_HZ = 0.5, 0.5     # the moving hand: all HIPs up and down together, sinusoidally


def hand_input(hips: np.ndarray, moving: bool, seconds: float):
    """A still hand (the contacts settle and then repeat bit for bit, so the live view's memo
    answers them), or one carrying both boxes up and down by MOVE_MM at MOVE_HZ (every display
    update a new contact set: the core's cost every time)."""
    if not moving:
        return inputs.StaticInput(hips)
    t = np.arange(0.0, seconds + 1.0, 0.005)
    lift = 1e-3 * MOVE_MM * np.sin(2 * np.pi * MOVE_HZ * t)
    samples = hips[None] + lift[:, None, None] * np.array([0.0, 0.0, 1.0])
    return inputs.SampledTrajectory(t, samples)


def measure_main_thread(updates: int, moving: bool = False) -> dict:
    import graspcore
    desc = two_held_boxes()
    h = scene.build_world(desc, graspcore)
    hips = np.array([f.position for f in desc.fingers])
    r = runner.SessionRunner(h, hand_input(hips, moving, 0.5 + updates / DISPLAY_RATE))
    r.advance_to(0.5)                                   # settled in the grasp
    monitor = grasp_display.GraspMonitor(analysis.body_models(desc), [f.radius for f in desc.fingers],
                                         gravity=desc.gravity)
    names_b, names_f = [b.name for b in desc.bodies], [f.name for f in desc.fingers]
    t_snap, t_an, t_view, t_quality, t_mu_min = [], [], [], [], []
    grasps, refused, errors = [], 0, set()
    for k in range(updates):
        r.advance_to(0.5 + (k + 1) / DISPLAY_RATE)
        t0 = time.perf_counter()
        snap = r.snapshot()
        t1 = time.perf_counter()
        grasps = monitor.update(snap)
        t2 = time.perf_counter()
        grasp_display.grasp_lines(grasps, names_b, names_f)
        grasp_display.finger_colors(grasps, len(snap.god_objects))
        for g in grasps:
            grasp_display.weakest_geometry(g)
        t3 = time.perf_counter()
        t_snap.append(t1 - t0)
        t_an.append(t2 - t1)
        t_view.append(t3 - t2)
        if monitor.error:
            refused += 1
            errors.add(monitor.error)
        else:
            tq, tm = _core_parts(graspcore, grasps)
            t_quality.append(tq)
            t_mu_min.append(tm)
    held = [(names_b[g.body], len(g.contacts), bool(g.force_closure), float(g.epsilon)) for g in grasps]
    if not moving:
        moving_run = measure_main_thread(updates, moving=True)
    else:
        return {"analysis": _stats(t_an), "quality": _stats(t_quality or [0.0]), "mu_min": _stats(t_mu_min or [0.0]),
                "refused": refused, "updates": updates}
    return {"snapshot": _stats(t_snap), "analysis": _stats(t_an), "view": _stats(t_view), "held": held,
            "quality": _stats(t_quality or [0.0]), "mu_min": _stats(t_mu_min or [0.0]),
            "refused": refused, "errors": sorted(errors), "moving": moving_run,
            "updates": updates, "ratio": float(np.median(t_an) / np.median(t_snap))}


def _core_parts(graspcore, grasps):
    """The core calls the analysis makes for these grasps, timed alone and as new searches
    (reuse=False: what a contact set the core has not seen costs): the closure measures of both
    bodies in one batch, and mu_min (bisection on closure) of each."""
    pts = np.concatenate([[c.point for c in g.contacts] for g in grasps])
    nrm = np.concatenate([[c.normal for c in g.contacts] for g in grasps])
    mu = np.concatenate([[c.mu for c in g.contacts] for g in grasps])
    counts = np.array([len(g.contacts) for g in grasps])
    centers = np.array([g.center for g in grasps])
    radii = np.array([g.radius for g in grasps])
    t0 = time.perf_counter()
    graspcore.grasp_quality_batch(pts, nrm, mu, counts, centers, radii, volume=False, reuse=False)
    t1 = time.perf_counter()
    for g in grasps:
        graspcore.grasp_mu_min(np.array([c.point for c in g.contacts]), np.array([c.normal for c in g.contacts]),
                               g.center, g.radius, mu_max=analysis.MU_MAX)
    return t1 - t0, time.perf_counter() - t1


def measure_haptic_loop(seconds: float, runs: int) -> dict:
    """Realtime runtime; the main thread snapshots at 60 Hz, analysing or not (alternating)."""
    import graspcore
    out = {"plain": [], "analysis": []}
    for _ in range(runs):
        for mode in ("plain", "analysis"):
            desc = two_held_boxes()
            h = scene.build_world(desc, graspcore)
            hips = np.array([f.position for f in desc.fingers])
            src = inputs.TimelineInput(inputs.SampledTrajectory([0.0, 1e3], np.stack([hips, hips])),
                                       np.zeros(len(hips), bool))
            r = runner.SessionRunner(h, src, use_runtime=True)
            monitor = grasp_display.GraspMonitor(analysis.body_models(desc), [f.radius for f in desc.fingers],
                                                 gravity=desc.gravity)
            r.start()
            t0 = time.perf_counter()
            n = 0
            while time.perf_counter() - t0 < seconds:
                r.advance_to(time.perf_counter() - t0)
                snap = r.snapshot()
                if mode == "analysis":
                    monitor.update(snap)
                n += 1
                time.sleep(max(0.0, t0 + n / DISPLAY_RATE - time.perf_counter()))
            st = r.stats()
            r.stop()
            out[mode].append({"tick_mean_us": st["runtime_tick_mean_us"], "p99_us": st["runtime_jitter_p99_us"],
                              "rate_hz": st["runtime_haptic_rate"], "updates": n,
                              "analysis_ms": float(np.median(monitor.costs) * 1e3) if monitor.costs else 0.0})
    return out


def measure_gui() -> dict | None:
    """The grasp_hud GUI scenario once (needs the GUI Blender and dist/'s zip)."""
    import glob
    sys.path.insert(0, os.path.join(ROOT, "tests", "gui"))
    import gui_run
    zips = sorted(glob.glob(os.path.join(ROOT, "dist", "grasp_lab-*-linux_x64.zip")))
    if gui_run.why_not() or not zips:
        return None
    r, console, _ = gui_run.run(gui_run.prepare(zips[-1]), "grasp_hud")
    if not r.get("ok"):
        raise RuntimeError(f"grasp_hud failed: {r.get('error')}\n{console[-2000:]}")
    g = r["grasps"][0]
    return {"analysis": _stats(np.array(r["analysis_ms"]) * 1e-3), "updates": len(r["analysis_ms"]),
            "display_rate": r["display_rate"], "contacts": len(g["contacts"]), "blender": r["blender"]}


def section(main: dict, loop: dict, gui: dict | None = None) -> str:
    f = lambda d: f"{d['median_ms']:.3f} | {d['p99_ms']:.3f} | {d['max_ms']:.3f}"  # noqa: E731
    lines = [
        "## Live grasp analysis per display update (2 bodies x 5 fingers)",
        "",
        f"Measured {_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M UTC} on {platform.node()} "
        f"({platform.processor() or platform.machine()}, {os.cpu_count()} cores, shared), "
        "`.venv/bin/python bench/bench_live_grasp.py`. Two 6 cm, 200 g boxes each held by the 5-finger "
        f"grasp of the held-box scene; {main['updates']} display updates at {DISPLAY_RATE:.0f} Hz of session "
        f"time, main thread. Target: the analysis under {TARGET_MS} ms per update.",
        "",
        "| per display update | median ms | p99 ms | max ms |",
        "| --- | --- | --- | --- |",
        f"| snapshot (`SessionRunner.snapshot`, what an update did before) | {f(main['snapshot'])} |",
        f"| **analysis** (`GraspMonitor.update`: accelerations + `analysis.analyse`, both bodies) | "
        f"{f(main['analysis'])} |",
        f"| HUD text, god-object colours, weakest-wrench geometry | {f(main['view'])} |",
        f"| of the analysis: `grasp_quality_batch` (`volume=False`), both bodies, alone | {f(main['quality'])} |",
        f"| of the analysis: `grasp_mu_min`, both bodies, alone | {f(main['mu_min'])} |",
        f"| **analysis**, the hand moving ({MOVE_MM} mm up and down at {MOVE_HZ} Hz: a new contact set every "
        f"update) | {f(main['moving']['analysis'])} |",
        f"| of it: `grasp_quality_batch`, both bodies, alone | {f(main['moving']['quality'])} |",
        f"| of it: `grasp_mu_min`, both bodies, alone | {f(main['moving']['mu_min'])} |",
        "",
        "The hand still (the rows above the moving ones), the boxes settle and their contact sets then "
        "repeat bit for bit: the live view's memo (`analysis.analyse_arrays(memo=)`) answers them without "
        "the core. The core's rows are the calls the analysis makes, timed alone as new searches "
        "(`reuse=False`); moving, the contacts slide by about 1e-7 m per update, too far for the core's "
        "`reuse`, so the analysis pays them.",
        "",
        f"Updates whose contact set the analysis refused (no grasp lines shown, the message instead): "
        f"{main['refused']} of {main['updates']}" + (f" ({'; '.join(main['errors'])})" if main["errors"] else "")
        + ".",
        "",
        f"Analysis / snapshot (medians): {main['ratio']:.1f}x. Last update: "
        + "; ".join(f"{b}: {n} contacts, closure {'yes' if c else 'no'}, epsilon {e:.4f}"
                    for b, n, c, e in main["held"]) + ".",
        "",
        "The haptic loop (threaded runtime, 1 kHz, real time: the live session's) while the main thread "
        f"snapshots at {DISPLAY_RATE:.0f} Hz without and with the analysis, alternating runs. Here the "
        "still hand's contacts differ in the last bits from update to update (the loop steps between "
        "snapshots), so the memo rarely answers and the core's `reuse` does (the column on the right):",
        "",
        "| main thread | run | haptic rate Hz | mean tick µs | p99 jitter µs | analysis median ms |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for mode in ("plain", "analysis"):
        for k, r in enumerate(loop[mode]):
            lines.append(f"| {'snapshot only' if mode == 'plain' else 'snapshot + analysis'} | {k + 1} | "
                         f"{r['rate_hz']:.0f} | {r['tick_mean_us']:.1f} | {r['p99_us']:.0f} | "
                         f"{r['analysis_ms']:.3f} |")
    mean = {m: float(np.median([r["tick_mean_us"] for r in loop[m]])) for m in loop}
    lines += ["", f"Mean haptic tick with the analysis / without (medians of the runs): "
                  f"{mean['analysis'] / mean['plain']:.2f}x.", ""]
    if gui is not None:
        a = gui["analysis"]
        lines += [f"In the GUI Blender {gui['blender']} (tests/gui scenario grasp_hud: one box, {gui['contacts']} "
                  f"fingers, llvmpipe under Xvfb), {gui['updates']} display updates at {gui['display_rate']:.1f} Hz: "
                  f"the analysis took {a['median_ms']:.3f} ms median, {a['max_ms']:.3f} ms at most.", ""]
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--updates", type=int, default=600)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--gui", action="store_true", help="also the GUI scenario grasp_hud")
    ap.add_argument("--quick", action="store_true", help="100 updates, one run of 1 s each")
    ap.add_argument("--json", help="write the statistics to this file (bench/run_bench.py reads it)")
    ap.add_argument("--out", help="append the section to this file")
    a = ap.parse_args()
    if a.quick:
        a.updates, a.runs, a.seconds = 100, 1, 1.0
    main_thread, loop = measure_main_thread(a.updates), measure_haptic_loop(a.seconds, a.runs)
    text = section(main_thread, loop, measure_gui() if a.gui else None)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"main": main_thread, "loop": loop, "target_ms": TARGET_MS}, fh)
    print(text)
    if a.out:
        with open(a.out, "a") as fh:
            fh.write("\n" + text)


if __name__ == "__main__":
    main()
