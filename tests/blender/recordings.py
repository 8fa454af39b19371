"""Recordings for the tests, made in plain Python (no bpy): the pinch-and-lift scene as an
engine SceneDesc (the sample scene's sizes, masses and fingertip path) run by the session
runner with a recorder, as a Blender EXEC session runs it."""
from __future__ import annotations

import importlib.util
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)
from addon.engine import inputs, recording, runner, scene  # noqa: E402


def sample_module():
    spec = importlib.util.spec_from_file_location(
        "build_pinch_and_lift", os.path.join(ROOT, "sample_scenes", "build_pinch_and_lift.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _box(size, name):
    import trimesh
    tm = trimesh.creation.box(size)
    return scene.MeshData(np.array(tm.vertices), np.array(tm.faces), source=name)


def pinch_desc():
    S = sample_module()
    d = scene.SceneDesc()
    box = _box((S.BOX_SIZE,) * 3, "Box")
    d.bodies.append(scene.BodyDesc("Box", False, [box.vertices], [box], np.array([0.0, 0.0, S.BOX_Z]),
                                   np.array([1.0, 0, 0, 0]), mass=S.BOX_MASS, mu_s=S.BOX_MU[0], mu_d=S.BOX_MU[1]))
    table = _box(S.TABLE_SIZE, "Table")
    d.bodies.append(scene.BodyDesc("Table", True, [table.vertices], [table], np.array(S.TABLE_CENTER),
                                   np.array([1.0, 0, 0, 0]), mu_s=S.TABLE_MU[0], mu_d=S.TABLE_MU[1]))
    for i, p in enumerate(S.hip_positions(0.0)):
        d.fingers.append(scene.FingerDesc(f"Finger {i}", p, S.FINGER_RADIUS, S.STIFFNESS, S.DAMPING, i))
    return scene.prepare(d), S


def record_exec(path, graspcore, seconds=6.0, fps=24, compression="lz4", flush_interval=0.1):
    """An EXEC session of the pinch scene recorded to ``path``; returns (runner, world handle)."""
    desc, S = pinch_desc()
    return record_scene(path, graspcore, desc, S.hip_positions, seconds, fps, compression, flush_interval)


def record_scene(path, graspcore, desc, hip_positions, seconds, fps=24, compression="lz4", flush_interval=0.1):
    """An EXEC session of a prepared SceneDesc whose fingers follow ``hip_positions(t)``
    (n_fingers, 3), recorded to ``path``; returns (runner, world handle)."""
    handle = scene.build_world(desc, graspcore)
    header = recording.make_header(desc, mode="exec", haptic_rate=1000.0, fps=fps)
    writer = recording.RecordingWriter(str(path), header, compression=compression,
                                       flush_interval=flush_interval)
    rec = recording.SessionRecorder(writer, handle.world)
    run = runner.SessionRunner(handle, inputs.CallableInput(len(desc.fingers), hip_positions, duration=seconds),
                               1000.0, recorder=rec)
    for k in range(1, int(round(seconds * fps)) + 1):
        run.advance_to(k / fps)
    run.stop()
    return run, handle


def record_realtime(path, graspcore, seconds=2.0, fps=24):
    """A live session of the pinch scene on the threaded runtime (real threads, real time: the
    fingertip path pushed at the display's ``fps`` as fingertips moved by hand are, walked to by
    the haptic loop), recorded to ``path`` with the header a live session writes; returns the
    runner."""
    import time
    desc, S = pinch_desc()
    handle = scene.build_world(desc, graspcore)
    header = recording.make_header(desc, mode="realtime", haptic_rate=1000.0, fps=fps,
                                   runtime={"threaded": True, "watchdog_timeout": 0.05,
                                            **{k: graspcore.RUNTIME_DEFAULTS[k] for k in runner.RUNTIME_PHYSICS}})
    rec = recording.SessionRecorder(recording.RecordingWriter(str(path), header), handle.world)
    run = runner.SessionRunner(handle, inputs.CallableInput(len(desc.fingers), S.hip_positions, duration=seconds),
                               1000.0, use_runtime=True, recorder=rec, runtime_options={"watchdog_timeout": 0.05})
    run.start()
    t0 = time.monotonic()
    while run.snapshot().time < seconds:
        run.advance_to(time.monotonic() - t0)
        time.sleep(1.0 / fps)
    run.stop()
    return run


def three_finger_lift():
    """A 3 s three-finger lift (the sweep's tests and benchmark): the sample scene's box and table,
    two fingertips closing on its +x face at y = +-12 mm and one on its -x face squeezing twice
    as deep (the forces and the torques about z balance), then lifting it 8 cm and holding it.
    Returns (prepared SceneDesc, hip_positions(t) -> (3, 3))."""
    desc, S = pinch_desc()
    del desc.fingers[:]
    half, r = S.BOX_SIZE / 2, S.FINGER_RADIUS

    def hip_positions(t):
        close = float(np.interp(t, [0.3, 0.8], [0.0, 1.0]))
        lift = float(np.interp(t, [1.0, 2.2], [0.0, 0.08]))
        plus = half + r + S.CLEARANCE - close * (S.CLEARANCE + S.SQUEEZE)
        minus = half + r + S.CLEARANCE - close * (S.CLEARANCE + 2 * S.SQUEEZE)
        z = S.BOX_Z + lift
        return np.array([[plus, 0.012, z], [plus, -0.012, z], [-minus, 0.0, z]])
    for i, p in enumerate(hip_positions(0.0)):
        desc.fingers.append(scene.FingerDesc(f"Finger {i}", p, r, S.STIFFNESS, S.DAMPING, i))
    return scene.prepare(desc), hip_positions
