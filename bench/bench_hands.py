"""Two hands (docs/hands.md): 32 phalanx capsules and 2 palms, convex fingers of the core, hold three
boxes (bench/hands_spec.py) and lift them 10 cm.

* The threaded runtime at 1 kHz, the fingers' poses on the core's track (as a session with an
  animated armature gives them): the haptic tick's work time (p50, p99, max, from every tick's
  record) and the period jitter p99 (the runtime's own statistics), over the whole grasp.
* The synchronous step time of the same scene (``World.step``, poses set before each step)
  beside MuJoCo's ``mj_step`` on the same scene (bench/hands_mujoco.py in .venv-bench: capsule
  geoms on free bodies, each driven by a mocap body through a weld), interleaved repeats.
* Both engines: the boxes' lift at the end (the grasp held).

    .venv/bin/python bench/bench_hands.py [--quick] [--json OUT]
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
    text = json.dumps(result, indent=1)
    print(text)
    if args.json:
        with open(args.json, "w") as fh:
            fh.write(text + "\n")
    return result


if __name__ == "__main__":
    main()
