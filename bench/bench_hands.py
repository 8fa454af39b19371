"""Two hands (docs/hands.md): 32 phalanx capsules and 2 palms, convex fingers of the core, hold three
boxes (bench/hands_spec.py) and lift them 10 cm.

* The threaded runtime at 1 kHz, the fingers' poses on the core's track (as a session with an
  animated armature gives them): the haptic tick's work time (p50, p99, max, from every tick's
  record) and the period jitter p99 (the runtime's own statistics), over the whole grasp.
* The synchronous step time of the same scene (``World.step``, poses set before each step)
  beside MuJoCo's ``mj_step`` on the same scene (bench/hands_mujoco.py in .venv-bench: capsule
  geoms on free bodies, each driven by a mocap body through a weld), interleaved repeats.
* Both engines: the boxes' lift at the end (the grasp held).
* The rendered hands (engine/hands.py) at every frame of the synchronous run: the deepest input
  and rendered capsule in any box, the largest gap at a joint.

Prints its section of docs/benchmarks.md (run_bench.py includes it).

    .venv/bin/python bench/bench_hands.py [--quick] [--no-mujoco] [--json OUT]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
sys.path.insert(0, ROOT)

import hands_spec  # noqa: E402
from addon.engine import hands as eh  # noqa: E402
from addon.engine import inputs, recording, runner, scene  # noqa: E402

DT = 1e-3
DURATION = 2.2          # s: closed at 0.5 s, lifted from 0.7 s to 1.7 s, then held


def _corners(half):
    return np.array([(x, y, z) for x in (-half[0], half[0]) for y in (-half[1], half[1])
                     for z in (-half[2], half[2])], dtype=np.float64)


def scene_desc(spec) -> scene.SceneDesc:
    desc = scene.SceneDesc(gravity=(0.0, 0.0, -9.81))
    for i, b in enumerate(spec["boxes"]):
        c = _corners(b["half"])
        faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6),
                 (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
        desc.bodies.append(scene.BodyDesc(name=f"Box{i}", static=False, parts=[c],
                                          meshes=[scene.MeshData(c, np.array(faces), f"Box{i}")],
                                          position=np.array(b["position"]), orientation=np.array((1.0, 0, 0, 0)),
                                          mass=spec["box_mass"], mu_s=spec["mu"], mu_d=spec["mu"] * 0.75))
    t = spec["table"]
    desc.bodies.append(scene.BodyDesc(name="Table", static=True, parts=[_corners(t["half"])], meshes=[],
                                      position=np.array(t["position"]), orientation=np.array((1.0, 0, 0, 0)),
                                      mu_s=spec["mu"], mu_d=spec["mu"] * 0.75))
    pos, rot = hands_spec.poses(0.0)
    for f, p, r in zip(spec["fingers"], pos, rot):
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = r, p
        desc.fingers.append(eh.bone_finger_desc(*f["name"].split(":"), m, f["length"], radius=f["radius"],
                                                stiffness=spec["stiffness"], damping=spec["damping"], channel=0))
    return scene.prepare(desc)


def track(n_samples: int):
    times = np.linspace(0.0, DURATION, n_samples)
    pos, quat = [], []
    for t in times:
        p, r = hands_spec.poses(t)
        pos.append(p)
        quat.append([eh.quat_from_matrix(m) for m in r])
    return times, np.array(pos), np.array(quat)


def runtime_ticks(graspcore, desc, times, pos, quat, path):
    """The grasp on the threaded runtime in real time, every tick recorded."""
    handle = scene.build_world(desc, graspcore)
    header = recording.make_header(desc, mode="realtime", haptic_rate=1000.0, fps=60,
                                   runtime={"threaded": True})
    rec = recording.SessionRecorder(recording.RecordingWriter(path, header), handle.world)
    source = inputs.SampledTrajectory(times, pos, quat)
    run = runner.SessionRunner(handle, source, 1000.0, use_runtime=True, recorder=rec)
    run.start()
    t0 = time.monotonic()
    while run.snapshot().time < DURATION:
        run.advance_to(time.monotonic() - t0)
        time.sleep(1 / 60)
        if time.monotonic() - t0 > 60 * DURATION:
            raise RuntimeError("the runtime did not reach the end of the grasp")
    snap = run.snapshot()
    stats = run.stats()
    run.stop()
    ticks = recording.open_recording(path).ticks
    work = np.asarray(ticks["work_us"], dtype=np.float64)[1:]
    return {"ticks": int(len(work)), "work_p50_us": float(np.percentile(work, 50)),
            "work_p99_us": float(np.percentile(work, 99)), "work_max_us": float(work.max()),
            "jitter_p99_us": float(stats["runtime_jitter_p99_us"]), "late_periods": int(stats["runtime_late_periods"]),
            "lift_m": [float(snap.poses[i][2] - desc.bodies[i].position[2]) for i in range(3)]}


def step_times(graspcore, desc, times, pos, quat, repeats: int):
    """Per repeat: the median and mean wall time of World.step over the whole grasp (poses set
    before each step, not timed), and the boxes' lift at the end."""
    source = inputs.SampledTrajectory(times, pos, quat)
    out, lift = [], None
    n = int(round(DURATION / DT))
    for _ in range(repeats):
        handle = scene.build_world(desc, graspcore)
        w = handle.world
        per = np.empty(n)
        for k in range(n):
            t = (k + 1) * DT
            hips = source.hips_at(t)
            for f, (h, q) in enumerate(zip(hips, source.orientations_at(t))):
                w.set_finger_pose(f, tuple(h), tuple(q))
            t0 = time.perf_counter()
            w.step(DT)
            per[k] = time.perf_counter() - t0
        out.append({"median_us": float(np.median(per) * 1e6), "mean_us": float(per.mean() * 1e6)})
        lift = [float(w.body_pose(handle.body_ids[i])[0][2] - desc.bodies[i].position[2]) for i in range(3)]
    return out, lift


def _rigs(spec):
    """Each hand's HandRig: the palm the root, each chain's first bone its child (not connected),
    the others connected; rest = the pose at t = 0 (only the chain structure is used)."""
    rigs = []
    for hand in ("A", "B"):
        idx = [i for i, f in enumerate(spec["fingers"]) if f["hand"] == hand]
        parents, connected, last = [], [], {}
        for k, i in enumerate(idx):
            chain = spec["fingers"][i]["chain"]
            parent = -1 if chain < 0 else last.get(chain, 0)
            parents.append(parent)
            connected.append(chain >= 0 and chain in last)
            if chain >= 0:
                last[chain] = k
        rigs.append((idx, eh.HandRig(armature=hand, bones=[spec["fingers"][i]["name"] for i in idx], parents=parents,
                                     lengths=np.array([spec["fingers"][i]["length"] for i in idx]),
                                     rest=np.array([np.eye(4)] * len(idx)), fingers=list(idx), connected=connected)))
    return rigs


def _box_depth(heads, tails, radius, pose, half) -> float:
    """Deepest point of capsules (segments heads-tails, radius) in a box at ``pose``, m
    (negative: clear); segments sampled 100 times."""
    r = eh.matrix_from_quat(pose[3:])
    t = np.linspace(0, 1, 100)[None, :, None]
    pts = heads[:, None] + t * (tails - heads)[:, None]
    q = np.abs((pts - pose[:3]) @ r) - np.asarray(half)
    d = np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(axis=-1), 0)
    return float(np.max(radius - d.min(axis=1)))


def rendered_depths(graspcore, spec, desc, times, pos, quat, fps=24):
    """The grasp on the synchronous steps; at every frame the rendered hands (engine/hands.py:
    god-poses, chain correction) beside the input: the deepest input and rendered capsule in
    any box, and the largest gap at a connected joint."""
    handle = scene.build_world(desc, graspcore)
    run = runner.SessionRunner(handle, inputs.SampledTrajectory(times, pos, quat), 1000.0)
    rigs = _rigs(spec)
    radius = np.array([f["radius"] for f in spec["fingers"]])
    points = {f: d.points for f, d in enumerate(desc.fingers)}
    radii = {f: d.radius for f, d in enumerate(desc.fingers)}
    worst = {"input": 0.0, "rendered": -1.0, "joint_gap": 0.0}
    cost = []
    for k in range(int(DURATION * fps) + 1):
        run.advance_to(k / fps)
        snap = run.snapshot()
        p, r = hands_spec.poses(snap.time)
        m = np.array([np.eye(4)] * len(p))
        m[:, :3, :3], m[:, :3, 3] = r, p
        solved = []
        t0 = time.perf_counter()
        for idx, rig in rigs:
            gods = eh.god_matrices({f: m[f] for f in idx}, snap, desc.bodies, points, radii)
            solved.append(eh.rendered_matrices(rig, m[idx], gods))
        cost.append(time.perf_counter() - t0)
        for (idx, rig), out in zip(rigs, solved):
            for name, mats in (("input", m[idx]), ("rendered", out)):
                heads, tails = eh.bone_ends(mats, rig.lengths)
                for b in range(3):
                    depth = _box_depth(heads, tails, radius[idx], snap.poses[b], spec["boxes"][b]["half"])
                    worst[name] = max(worst[name], depth)
            heads, tails = eh.bone_ends(out, rig.lengths)
            gaps = [np.linalg.norm(heads[i] - tails[rig.parents[i]]) for i in range(len(idx)) if rig.connected[i]]
            worst["joint_gap"] = max(worst["joint_gap"], max(gaps))
    run.stop()
    worst["update_ms"] = float(np.median(cost) * 1e3)
    worst["update_max_ms"] = float(np.max(cost) * 1e3)
    return worst


def markdown(r: dict) -> str:
    rt = r["runtime"]
    ratio = r.get("ratio")
    lines = [
        "## Hands: two hands holding three boxes", "",
        "`bench/bench_hands.py` (docs/hands.md): two hands of 16 phalanx capsules and a palm each (34 convex "
        "fingers of the core, 6 hull points each), closing 3 mm into the faces of three boxes (50 g) on a table "
        "and lifting them 10 cm in 2.2 s, the poses on the core's track as an animated armature gives them. "
        "MuJoCo: the same capsules on free bodies of 10 g, each driven by a mocap body through a weld with the "
        "fingers' spring and damper, elliptic cones, implicitfast, dt 1 ms (bench/hands_mujoco.py).", "",
        "| measure | value | target |",
        "|---|---|---|",
        f"| haptic tick work, threaded runtime at 1 kHz: p50 / p99 / max | {rt['work_p50_us']:.0f} / "
        f"{rt['work_p99_us']:.0f} / {rt['work_max_us']:.0f} µs | p99 < 300 µs: "
        f"{'met' if rt['work_p99_us'] < 300 else 'MISSED'} |",
        f"| period jitter p99 (the runtime's, {rt['late_periods']} late periods of {rt['ticks']}) | "
        f"{rt['jitter_p99_us']:.0f} µs | (machine load) |",
        f"| step time, synchronous (median) | graspcore {r['graspcore_step_median_us']:.1f} µs"
        + (f", MuJoCo {r['mujoco_step_median_us']:.1f} µs: {ratio:.2f}×" if ratio is not None else ", MuJoCo not run")
        + f" | ≤ 0.5× MuJoCo: {'met' if ratio is not None and ratio <= 0.5 else ('MISSED' if ratio else 'not measured')} |",
        f"| boxes lifted (graspcore runtime; MuJoCo) | {', '.join(f'{1e3 * z:.1f}' for z in rt['lift_m'])} mm"
        + (f"; {', '.join(f'{1e3 * z:.1f}' for z in r['mujoco_lift_m'])} mm" if "mujoco_lift_m" in r else "")
        + " | 100 mm |",
        f"| deepest capsule in a box, input / rendered hand (every frame) | {1e3 * r['depth']['input']:.2f} / "
        f"{1e3 * r['depth']['rendered']:.3f} mm | rendered ≤ 0.5 mm while the input goes 3 mm: "
        f"{'met' if r['depth']['rendered'] <= 5e-4 and r['depth']['input'] >= 0.0029 else 'MISSED'} |",
        f"| largest gap at a joint of the rendered hands | {1e3 * r['depth']['joint_gap']:.2g} mm | ≤ 0.5 mm |",
        f"| the rendered hands' solve per display update (god-poses + chain correction, both hands), median / max | "
        f"{r['depth']['update_ms']:.1f} / {r['depth']['update_max_ms']:.1f} ms | (the display's budget) |",
    ]
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", default="")
    ap.add_argument("--no-mujoco", action="store_true")
    args = ap.parse_args(argv)
    from addon.engine import core_loader
    gc = core_loader.load()
    spec = hands_spec.spec()
    desc = scene_desc(spec)
    times, pos, quat = track(int(DURATION * 100) + 1)       # 100 Hz samples, the core interpolates
    repeats = 1 if args.quick else 3
    result = {"fingers": len(desc.fingers), "bodies": 3}
    mj = None
    if not args.no_mujoco:
        import run_bench
        mj = run_bench.Worker(run_bench.ensure_bench_venv(), "hands_mujoco.py")
    gc_steps, mj_steps = [], []
    try:
        for _ in range(repeats):            # interleaved: both see the same machine load
            g, result["graspcore_lift_m"] = step_times(gc, desc, times, pos, quat, 1)
            gc_steps += g
            if mj is not None:
                reply = mj(cmd="run", duration=DURATION, dt=DT)
                mj_steps.append(reply["step"])
                result["mujoco_lift_m"] = reply["lift_m"]
                result["mujoco_version"] = reply["version"]
    finally:
        if mj is not None:
            mj.close()
    result["graspcore_step_median_us"] = float(np.median([s["median_us"] for s in gc_steps]))
    if mj_steps:
        result["mujoco_step_median_us"] = float(np.median([s["median_us"] for s in mj_steps]))
        result["ratio"] = result["graspcore_step_median_us"] / result["mujoco_step_median_us"]
    with tempfile.TemporaryDirectory() as tmp:
        result["runtime"] = runtime_ticks(gc, desc, times, pos, quat, os.path.join(tmp, "hands.mcap"))
    result["depth"] = rendered_depths(gc, spec, desc, times, pos, quat)
    if args.json:
        with open(args.json, "w") as fh:
            fh.write(json.dumps(result, indent=1) + "\n")
    print(markdown(result))
    return result


if __name__ == "__main__":
    main()
