"""Blender extension benchmarks; prints a Markdown section.

1. Display update: main-thread time per display frame of a live session with 10 fingers
   and 20 bodies (read the core's state, write 20 body matrices, move 10 god-objects
   and 40 force/torque arrows). Target: <= 2 ms. The depsgraph evaluation that follows
   (Blender's own work before the viewport redraws) is reported separately.
2. Scene conversion of a ~100k-triangle object (evaluated mesh, checks, trimesh mass
   properties, core world with its hull). Target: < 1 s.

Usage: .venv/bin/python bench/bench_blender.py [--frames 300] [--zip dist/...zip]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))



def _pct(values, p):
    v = sorted(values)
    return v[min(len(v) - 1, int(round(p / 100 * (len(v) - 1))))]


def bench_display(bpy, grasp_env, frames):
    session_mod = grasp_env.submodule("session")
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 1 + frames
    for i in range(20):
        obj = grasp_env.add_cube(bpy, f"Body {i:02d}", 0.04, ((i % 5) * 0.1, (i // 5) * 0.1, 0.0))
        obj.grasp_lab.role = "DYNAMIC"
        obj.grasp_lab.mass = 0.1
    for j in range(10):
        f = bpy.data.objects.new(f"Finger {j}", None)
        scene.collection.objects.link(f)
        f.location = ((j % 5) * 0.1 - 0.03, (j // 5) * 0.1, 0.0)
        f.grasp_lab.role = "FINGER"
        f.grasp_lab.channel = j
    scene.grasp_lab.gravity = (0.0, 0.0, -9.81)
    s = session_mod.BlenderSession(bpy.context, live=True, duration=frames / 24)
    update, snap_t, evals = [], [], []
    fps = 24.0
    for k in range(1, frames + 1):
        s.runner.advance_to(k / fps)
        t0 = time.perf_counter()
        snap = s.runner.snapshot()
        t1 = time.perf_counter()
        s.apply(snap, 1 + k)
        t2 = time.perf_counter()
        bpy.context.view_layer.update()
        t3 = time.perf_counter()
        snap_t.append(t1 - t0)
        update.append(t2 - t0)
        evals.append(t3 - t2)
    s.finish()
    n_obj = len(s.display.objects) if s.display else 0
    return {
        "frames": frames, "display_objects": n_obj,
        "update_median_ms": 1e3 * statistics.median(update),
        "update_p95_ms": 1e3 * _pct(update, 95),
        "update_max_ms": 1e3 * max(update),
        "snapshot_median_ms": 1e3 * statistics.median(snap_t),
        "eval_median_ms": 1e3 * statistics.median(evals),
        "step_us": s.result.stats.get("step_us", 0.0),
        "threaded": s.runner.threaded,
    }


def bench_conversion(bpy, grasp_env, repeats=3):
    convert = grasp_env.submodule("convert")
    scene_mod = grasp_env.submodule("engine.scene")
    core = grasp_env.graspcore()
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=320, ring_count=160, radius=0.05)
    obj = bpy.context.active_object
    obj.grasp_lab.role = "DYNAMIC"
    obj.scale = (1.0, 0.8, 1.2)
    obj.data.calc_loop_triangles()
    n_tri = len(obj.data.loop_triangles)
    times, t_desc, t_prep, t_world = [], [], [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        desc, _, _ = convert.scene_description(bpy.context)
        t1 = time.perf_counter()
        scene_mod.prepare(desc)
        t2 = time.perf_counter()
        scene_mod.build_world(desc, core)
        t3 = time.perf_counter()
        times.append(t3 - t0)
        t_desc.append(t1 - t0)
        t_prep.append(t2 - t1)
        t_world.append(t3 - t2)
    return {"triangles": n_tri, "total_s": min(times), "read_s": min(t_desc),
            "checks_mass_s": min(t_prep), "world_s": min(t_world)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=240)
    ap.add_argument("--zip", default=None)
    args = ap.parse_args(argv)
    import grasp_env
    grasp_env.isolate()
    import bpy
    grasp_env.enable(args.zip)
    d = bench_display(bpy, grasp_env, args.frames)
    c = bench_conversion(bpy, grasp_env)
    ok_d = "yes" if d["update_p95_ms"] <= 2.0 else "**no**"
    ok_c = "yes" if c["total_s"] < 1.0 else "**no**"
    print("## Blender extension\n")
    print(f"bpy {bpy.app.version_string}, extension from {grasp_env.source()}.\n")
    print("| measurement | value | target | met |")
    print("|---|---|---|---|")
    print(f"| display update per frame, 10 fingers + 20 bodies ({d['display_objects']} display "
          f"objects), median / p95 / max | {d['update_median_ms']:.3f} / {d['update_p95_ms']:.3f} / "
          f"{d['update_max_ms']:.3f} ms | <= 2 ms | {ok_d} |")
    print(f"| of which reading the core state (snapshot), median | {d['snapshot_median_ms']:.3f} ms | | |")
    print(f"| depsgraph evaluation after the update (Blender), median | {d['eval_median_ms']:.3f} ms | | |")
    if d["threaded"]:
        print("| core stepping, 10 fingers + 20 bodies | on the runtime's threads: none on the main thread | | |")
    else:
        print(f"| core step, 10 fingers + 20 bodies (main thread) | {d['step_us']:.1f} µs | | |")
    print(f"| scene conversion, {c['triangles']} triangles (read / checks + mass / world) | "
          f"{c['total_s']:.3f} s ({c['read_s']:.3f} / {c['checks_mass_s']:.3f} / {c['world_s']:.3f}) "
          f"| < 1 s | {ok_c} |")
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
