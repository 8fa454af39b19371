"""Headless sessions (EXEC): the scripted pinch-and-lift gives the same box trajectory
as driving graspcore directly with the same HIPs."""
import os

import numpy as np
import pytest

import grasp_env
from waiting import wait_until


def _f32(v):
    """Blender stores locations and mesh coordinates as float32."""
    return np.asarray(v, dtype=np.float32).astype(np.float64)


def _direct_trajectory(core, sample, n_frames, fps=24, rate=1000.0):
    """Box poses at every frame, driving the core directly: the table and the box as the
    scene has them (float32 coordinates), the analytic HIPs."""
    import trimesh

    def corners(size):
        return _f32([(x, y, z) for x in (-size[0] / 2, size[0] / 2) for y in (-size[1] / 2, size[1] / 2)
                     for z in (-size[2] / 2, size[2] / 2)])

    ref = trimesh.creation.box((sample.BOX_SIZE,) * 3)
    ref.density = sample.BOX_MASS / ref.volume
    w = core.World(gravity=(0, 0, -9.81))
    # Bodies in name order, as the extension adds them: Box, then Table.
    b = w.add_body(corners((sample.BOX_SIZE,) * 3), mass=sample.BOX_MASS, inertia=ref.moment_inertia,
                   center_of_mass=(0, 0, 0), position=tuple(_f32((0, 0, sample.BOX_Z))),
                   mu_s=sample.BOX_MU[0], mu_d=sample.BOX_MU[1])
    w.add_body(corners(sample.TABLE_SIZE), static=True, position=tuple(_f32(sample.TABLE_CENTER)),
               mu_s=sample.TABLE_MU[0], mu_d=sample.TABLE_MU[1])
    for p in sample.hip_positions(0.0):
        w.add_finger(radius=sample.FINGER_RADIUS, stiffness=sample.STIFFNESS, damping=sample.DAMPING,
                     position=tuple(p))
    dt = 1.0 / rate
    poses = [np.concatenate(w.body_pose(b))]
    step = 0
    for k in range(1, n_frames + 1):
        target = int(np.floor(k / fps / dt + 1e-9))
        while step < target:
            step += 1
            w.set_hips(sample.hip_positions(step * dt))
            w.step(dt)
        poses.append(np.concatenate(w.body_pose(b)))
    return np.array(poses)


@pytest.mark.multiversion
def test_exec_pinch_and_lift_matches_core(bpy, sample, core):
    box = sample.build(bpy)
    assert bpy.ops.grasp_lab.session() == {"FINISHED"}
    res = grasp_env.submodule("session").last_result
    assert res.body_names == ["Box", "Table"]
    traj = res.trajectory("Box")
    n_frames = bpy.context.scene.frame_end - bpy.context.scene.frame_start
    assert len(traj) == n_frames + 1
    assert res.stats["steps"] == int(round(n_frames / 24 * 1000))
    direct = _direct_trajectory(core, sample, n_frames)
    # Blender stores locations as float32: HIPs differ from the analytic ones by ~1e-9 m.
    np.testing.assert_allclose(traj[:, :3], direct[:, :3], atol=2e-6)
    np.testing.assert_allclose(np.abs(np.sum(traj[:, 3:] * direct[:, 3:], axis=1)), 1.0, atol=1e-6)
    frame = np.array(res.frames)
    z = traj[:, 2]
    # Resting on the table until the fingers close, then lifted 10 cm (sagging m g / 2k below
    # the HIPs), carried 10 cm sideways, put down and left on the table.
    sag = sample.BOX_MASS * 9.81 / (2 * sample.STIFFNESS)
    np.testing.assert_allclose(z[frame <= 31], sample.BOX_Z, atol=1e-5)
    held = (frame >= 57) & (frame <= 61)
    np.testing.assert_allclose(z[held], sample.BOX_Z + sample.LIFT - sag, atol=1e-4)
    assert traj[-1, 1] == pytest.approx(sample.CARRY, abs=1e-3)
    assert traj[-1, 2] == pytest.approx(sample.BOX_Z, abs=1e-5)
    assert box.matrix_world.translation.z == pytest.approx(traj[-1, 2], abs=1e-6)
    assert bpy.context.scene.frame_current == bpy.context.scene.frame_end
    assert res.final.n_contacts == 0                        # released
    assert all(s == 0 for s in res.final.finger_states)     # both free


@pytest.mark.multiversion
def test_fingers_stick_while_holding(bpy, sample, core):
    sample.build(bpy)
    bpy.ops.grasp_lab.session(duration=2.5)                 # frame 61: lifted and held
    res = grasp_env.submodule("session").last_result
    assert res.final.n_contacts == 2
    assert list(res.final.contacts) == [0, 0]               # both on the box
    assert all(s == 1 for s in res.final.finger_states)     # both sticking
    assert res.trajectory("Box")[-1, 2] > sample.BOX_Z + sample.LIFT - 0.001


def test_each_frame_analysed_and_god_objects_coloured_by_friction_use(bpy, sample, core):
    """Frame by frame the session analyses the grasp. Mid-lift (constant speed: no
    acceleration) the two fingertips hold the box: two point contacts, which no friction puts
    in force closure (nothing resists a twist about the line between them), a load of its
    weight, a grip of the two normal forces; each god-object's material has the colour of its
    finger's friction use."""
    sample.build(bpy)
    bpy.ops.grasp_lab.session(duration=(sample.MID_LIFT_FRAME - 1) / sample.FPS)
    session = grasp_env.submodule("session")
    gd = grasp_env.submodule("engine.grasp_display")
    res = session.last_result
    assert len(res.grasps) == len(res.frames)
    assert res.grasps[0] == [] and res.frames[0] == 1                  # open hand: nothing held
    (g,) = res.grasps[-1]
    assert res.body_names[g.body] == "Box" and sorted(c.finger for c in g.contacts) == [0, 1]
    assert not g.force_closure and g.epsilon == 0.0 and not any(g.weakest)
    assert g.load_force == pytest.approx(sample.BOX_MASS * 9.81, rel=0.05)
    assert g.grip_force == pytest.approx(sum(c.fn for c in g.contacts)) and g.grip_force > 2 * g.load_force
    for c in g.contacts:
        assert 0.0 < c.friction_use < 1.0 and c.state == 1
        mat = bpy.data.objects[f"GL God-object Finger {c.finger}"].material_slots[0].material
        np.testing.assert_allclose(mat.diffuse_color, gd.friction_color(c.friction_use), atol=1e-6)
        assert mat.diffuse_color[1] > mat.diffuse_color[2]              # on the green-yellow-red scale


@pytest.mark.multiversion
def test_display_objects_and_bake(bpy, sample, core):
    sample.build(bpy)
    bpy.context.scene.grasp_lab.bake = True
    bpy.ops.grasp_lab.session(duration=1.25)             # frames 1-31: closed on the box
    coll = bpy.data.collections["Grasp Lab"]
    names = sorted(o.name for o in coll.objects)
    assert names == ["GL Force Box", "GL God-object Finger 0", "GL God-object Finger 1",
                     "GL Torque Box"]
    res = grasp_env.submodule("session").last_result
    go = bpy.data.objects["GL God-object Finger 0"].matrix_world.translation
    np.testing.assert_allclose(tuple(go), res.final.god_objects[0], atol=1e-6)
    # Fingers in contact: god-objects sit on the box surface, the HIPs are inside.
    assert abs(go.x) == pytest.approx(sample.BOX_SIZE / 2 + sample.FINGER_RADIUS, abs=1e-3)
    # Keyframes on the box: one per frame, matching the session (5.0: channelbags).
    box = bpy.data.objects["Box"]
    z_final = box.matrix_world.translation.z
    bpy.context.scene.frame_set(1)
    assert box.matrix_world.translation.z == pytest.approx(res.poses[0][0][2], abs=1e-6)
    bpy.context.scene.frame_set(31)
    assert box.matrix_world.translation.z == pytest.approx(res.trajectory("Box")[-1][2], abs=1e-6)
    assert z_final == pytest.approx(res.trajectory("Box")[-1][2], abs=1e-6)


def test_second_run_resets_and_repeats(bpy, sample, core):
    sample.build(bpy)
    bpy.ops.grasp_lab.session(duration=2.0)
    first = grasp_env.submodule("session").last_result.trajectory("Box")
    assert first[-1, 2] > sample.BOX_Z + 0.05               # lifted
    bpy.ops.grasp_lab.session(duration=2.0)
    second = grasp_env.submodule("session").last_result.trajectory("Box")
    np.testing.assert_array_equal(first, second)
    bpy.ops.grasp_lab.reset()
    assert bpy.data.objects["Box"].matrix_world.translation.z == pytest.approx(sample.BOX_Z, abs=1e-9)


def test_recording_written(bpy, sample, core, tmp_path):
    sample.build(bpy)
    s = bpy.context.scene.grasp_lab
    s.record = True
    s.recording_folder = str(tmp_path)
    bpy.ops.grasp_lab.session(duration=0.25)
    path = s.last_recording
    assert path.endswith(".mcap") and os.path.dirname(path) == str(tmp_path)
    rec = grasp_env.submodule("engine.recording").open_recording(path)
    # Every haptic tick: tick 0 (the start) and the 250 steps of 0.25 s at 1 kHz.
    assert rec.damage == [] and len(rec.ticks) == 251
    assert rec.ticks["pose"].shape == (251, 2, 7) and rec.ticks["hip"].shape == (251, 2, 3)
    assert rec.body_names == ["Box", "Table"]
    res = grasp_env.submodule("session").last_result
    np.testing.assert_array_equal(rec.ticks["pose"][-1], res.final.poses)


def test_invoke_headless_runs_exec(bpy, sample, core):
    sample.build(bpy)
    assert bpy.ops.grasp_lab.session("INVOKE_DEFAULT", duration=0.25) == {"FINISHED"}
    assert grasp_env.submodule("session").active_session() is None


def test_parented_body_writes_back_world_pose(bpy, sample, core):
    box = sample.build(bpy)
    holder = bpy.data.objects.new("Holder", None)
    bpy.context.scene.collection.objects.link(holder)
    holder.location = (0.0, 0.0, 0.0)
    holder.scale = (2.0, 2.0, 2.0)
    box.parent = holder
    box.scale = (0.5, 0.5, 0.5)     # world size unchanged
    box.location = (0.0, 0.0, sample.BOX_Z / 2)   # world position unchanged: on the table
    bpy.context.view_layer.update()
    bpy.ops.grasp_lab.session()
    res = grasp_env.submodule("session").last_result
    np.testing.assert_allclose(tuple(box.matrix_world.translation), res.final.poses[0][:3], atol=1e-6)
    np.testing.assert_allclose(box.matrix_world.to_scale(), (1, 1, 1), atol=1e-6)


def test_empty_scene_reports(bpy, core):
    with pytest.raises(RuntimeError, match="nothing to simulate"):
        bpy.ops.grasp_lab.session()


def test_live_session_ticks_without_timers(bpy, sample, core):
    """The live (modal) path stepping the core directly, driven by hand: bounded work per
    tick, falls behind real time rather than blocking, and draws nothing headless."""
    session = grasp_env.submodule("session")
    display = grasp_env.submodule("display")
    prefs = grasp_env.submodule("prefs").get_prefs(bpy.context)
    sample.build(bpy)
    prefs.use_runtime = False
    try:
        s = session.BlenderSession(bpy.context, live=True, duration=1.25)
    finally:
        prefs.use_runtime = True
    assert not s.runner.threaded
    assert s.tick(0.1) is False
    assert s.runner.time == pytest.approx(0.1)
    s.tick(0.9, budget=0.0)                          # a stall: one batch of 8 steps, no more
    assert s.runner.time == pytest.approx(0.108)
    assert s.runner.lag == pytest.approx(0.792)
    assert "behind real time by 0.79 s" in s.hud_text()
    s.tick(1.0)                                      # catches up when it can
    assert s.runner.time == pytest.approx(1.0) and s.runner.lag == 0.0
    assert bpy.context.scene.frame_current == 1 + round(1.0 * 24)
    assert "real time" in s.hud_text()
    assert s.tick(5.0) is True                       # reached the duration
    hud = s.hud_text().replace("\u00a0", " ").split("\n")   # the grasp first: closed on the box
    assert hud[0].startswith("Box: held") and hud[1].startswith("Box: closure ")     # the words, then the numbers
    assert "Finger 0 stick" in hud[4] and "Finger 1 stick" in hud[4]
    assert hud[5].startswith("t 1.25 / 1.25 s") and len(hud) == 6
    s.finish()
    display.add_overlay()                            # no-op headless
    assert not display.overlay_active()


def test_live_session_on_the_threaded_runtime(bpy, sample, core):
    """With the runtime (the default for live sessions) the haptic loop runs in C threads;
    ticks only push HIPs and read snapshots, and finishing stops the threads."""
    import time as _time
    session = grasp_env.submodule("session")
    box = sample.build(bpy)
    bpy.context.scene.frame_start = 25               # start squeezing, 0.25 s before the lift
    z0 = box.matrix_world.translation.z
    s = session.BlenderSession(bpy.context, live=True, duration=2.0)
    assert s.runner.threaded and s.runner.world.running
    # Ticking as Blender's timer would until the haptic loop, on its own, has both fingertips
    # holding the box (stick) and lifting it (its pose written back from the snapshots).
    wait_until(lambda: s.snapshot is not None and s.snapshot.time > 0.2 and list(s.snapshot.finger_states) == [1, 1]
               and list(s.snapshot.contacts) == [0, 0] and box.matrix_world.translation.z != z0, 60,
               "both fingertips holding the box, lifting it",
               seen=lambda: s.snapshot and (s.snapshot.time, s.snapshot.finger_states, s.snapshot.contacts,
                                            box.matrix_world.translation.z - z0), poll=0.02, each=s.tick)
    stats = s.runner.stats()
    assert stats["runtime_haptic_rate"] > 0
    # The report is the C loop's own: rate, steps and step time are not the display's.
    # (> 250 Hz: the loop runs at its real-time rate's order; the rate itself is benchmarked.)
    assert stats["haptic_rate"] == stats["runtime_haptic_rate"] > 250
    assert stats["steps"] > 200 and stats["step_us"] > 0
    hud = s.hud_text()                               # the grasp, then the C loop's own timing
    lines = hud.split("\n")                          # the verdict in words, then the numbers
    assert lines[0].startswith("Box: held") and " slips first " in lines[0], lines
    assert lines[1].startswith("Box: closure ") and "p99" in hud and "haptic 0 Hz" not in hud
    # no device: the safety counters (the timeline's input trips the watchdog) are not shown
    assert "safety:" not in hud and "forces held at zero" not in hud, hud
    detail = "\n".join(s.loop_lines(detail=True))   # the sidebar's Loop panel: all of it
    assert stats["runtime_priority_note"] in detail and "safety: rejected inputs" in detail
    assert "step 0 µs" not in detail
    s.finish()
    assert not s.runner.world.running


def _tilting_palm(bpy):
    """A palm (Finger-role mesh, 9 x 8 x 2 cm) keyframed level at frame 1 and tilted 10 deg
    about x at frame 25, staying where it is; a 0.4 kg plate resting on it."""
    palm = grasp_env.add_cube(bpy, "Palm", size=2.0, location=(0.0, 0.0, -0.01))
    palm.scale = (0.045, 0.04, 0.01)
    palm.grasp_lab.role = "FINGER"
    palm.rotation_euler = (0.0, 0.0, 0.0)
    palm.keyframe_insert("rotation_euler", frame=1)
    palm.keyframe_insert("location", frame=1)
    palm.rotation_euler = (np.radians(10.0), 0.0, 0.0)
    palm.keyframe_insert("rotation_euler", frame=25)
    plate = grasp_env.add_cube(bpy, "Plate", size=2.0, location=(0.0, 0.0, 0.0055))
    plate.scale = (0.1, 0.1, 0.005)
    plate.grasp_lab.role = "DYNAMIC"
    plate.grasp_lab.mass_mode = "MASS"
    plate.grasp_lab.mass = 0.4
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 48
    scene.render.fps, scene.render.fps_base = 24, 1.0
    return palm, plate


def _tilt_deg(quat):
    from mathutils import Quaternion
    up = np.array(Quaternion(quat).to_matrix())[:, 2]
    return float(np.degrees(np.arccos(min(1.0, up[2]))))


@pytest.mark.parametrize("threaded", [True, False])
def test_animated_palm_rotation_reaches_the_core(bpy, core, threaded):
    """The palm's animated world rotation, frame by frame, is its HIP's orientation: the
    threaded runtime gets it on the track, the synchronous steps through set_finger_pose; the
    palm ends at the last frame's rotation and the plate resting on it tilts with it."""
    import time as _time
    session = grasp_env.submodule("session")
    prefs = grasp_env.submodule("prefs").get_prefs(bpy.context)
    palm, plate = _tilting_palm(bpy)
    bpy.context.scene.frame_set(48)
    q_end = palm.matrix_world.to_quaternion().normalized()
    bpy.context.scene.frame_set(1)
    prefs.use_runtime = threaded
    try:
        s = session.BlenderSession(bpy.context, live=True, duration=1.9)
    finally:
        prefs.use_runtime = True
    assert s.runner.threaded == threaded
    times, _, mask, turns = s.source.script()
    assert list(mask) == [True] and turns.shape == (len(times), 1, 4)
    world, palm_id = s.runner.world, s.handle.finger_ids[0]
    if threaded:
        t0 = _time.perf_counter()
        while s.snapshot is None or s.snapshot.time < 1.6:
            s.tick(_time.perf_counter() - t0)
            _time.sleep(0.02)
            assert _time.perf_counter() - t0 < 60.0
        s.finish()
    else:
        s.tick(1.6)
    got = np.array(world.finger_pose(palm_id)[1])
    np.testing.assert_allclose(np.abs(got), np.abs([q_end.w, q_end.x, q_end.y, q_end.z]), atol=1e-7)
    assert _tilt_deg(got) == pytest.approx(10.0, abs=1e-4)
    assert _tilt_deg(world.body_pose(s.handle.body_ids[0])[1]) == pytest.approx(10.0, abs=0.3)
    if not threaded:
        s.finish()


@pytest.mark.parametrize("threaded", [True, False])
def test_palm_rotated_in_the_viewport_turns_in_the_core(bpy, core, threaded):
    """A live (not animated) palm the user rotates during the session: its rotation is pushed
    with its position at every display tick and the core's palm turns to it."""
    import time as _time
    from mathutils import Euler
    session = grasp_env.submodule("session")
    prefs = grasp_env.submodule("prefs").get_prefs(bpy.context)
    palm = grasp_env.add_cube(bpy, "Palm", size=2.0, location=(0.0, 0.0, -0.01))
    palm.scale = (0.045, 0.04, 0.01)
    palm.grasp_lab.role = "FINGER"
    prefs.use_runtime = threaded
    try:
        s = session.BlenderSession(bpy.context, live=True, duration=10.0)
    finally:
        prefs.use_runtime = True
    assert s.source.interactive and s.source.script() is None
    palm.rotation_euler = Euler((0.0, np.radians(20.0), 0.0))
    bpy.context.view_layer.update()
    want = palm.matrix_world.to_quaternion().normalized()
    world, palm_id = s.runner.world, s.handle.finger_ids[0]
    if threaded:        # until the haptic loop has had 0.5 s of its own time to turn the palm
        wait_until(lambda: s.snapshot is not None and s.snapshot.time >= 0.5, 60, "0.5 s of the haptic loop's time",
                   seen=lambda: s.snapshot and s.snapshot.time, poll=0.02, each=s.tick)
    else:
        for k in range(1, 11):
            s.tick(0.05 * k)
    s.finish()
    got = np.array(world.finger_pose(palm_id)[1])
    np.testing.assert_allclose(np.abs(got), np.abs([want.w, want.x, want.y, want.z]), atol=1e-7)
