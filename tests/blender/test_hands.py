"""Hands (docs/hands.md): Finger bones as capsule fingers, the rendered armature, its bake.

The engine's geometry against closed forms (no bpy), then a keyed armature (a palm and 5 chains
of 3 bones) that squeezes 3 mm into a box and lifts it 10 cm, run and baked in bpy: the box is
lifted, the baked ``Hand Rendered`` armature's capsules stay on the box's surface (never more
than 0.5 mm inside, within 0.5 mm of it where the input goes in) with its joints connected, the
input armature untouched; a recording of it re-simulates identically; bad input is refused
naming the bone."""

import numpy as np
import pytest

import grasp_env
import hand_scene
from addon.engine import hands as eh
from addon.engine.scene import SceneError, check_hull_points


# --------------------------------------------------------------------------- engine, no bpy

def test_capsule_hull_is_legal_and_holds_the_capsule_within_two_percent():
    length, r = 0.03, 0.008
    pts = eh.capsule_points(length, r)
    check_hull_points("bone", pts)          # >= 4 points spanning a volume
    assert len(pts) == 6 <= 32
    # The segment head-tail is inside the hull (its rings are centred on it) and every hull
    # point is within CAPSULE_CORE_FRACTION r of the segment: the inflated hull is the capsule
    # to within 2 % of the radius, and contains it.
    assert np.all(np.abs(pts[:, 1] - np.clip(pts[:, 1], 0, length)) == 0)
    off_axis = np.linalg.norm(pts[:, [0, 2]], axis=1)
    np.testing.assert_allclose(off_axis, eh.CAPSULE_CORE_FRACTION * r)
    np.testing.assert_allclose(pts[:3].mean(axis=0), (0, 0, 0), atol=1e-15)
    np.testing.assert_allclose(pts[3:].mean(axis=0), (0, length, 0), atol=1e-15)


def _bone_matrix(scale=(1, 1, 1)):
    m = np.eye(4)
    m[:3, :3] = np.diag(scale)
    m[:3, 3] = (0.1, 0.2, 0.3)
    return m


@pytest.mark.parametrize("kw, words", [
    (dict(length=0.0), ["zero length"]),
    (dict(radius=0.0), ["zero radius"]),
    (dict(matrix=_bone_matrix((2, 2, 2))), ["scale of 2", "apply"]),
    (dict(matrix=_bone_matrix((1, 1, 1.5))), ["non-uniform scale"]),
    (dict(rendered_of="Hand"), ["rendered armature", "output only"]),
])
def test_bad_bones_are_refused_naming_the_bone(kw, words):
    args = dict(matrix=_bone_matrix(), length=0.03, radius=0.008, rendered_of="")
    args.update(kw)
    with pytest.raises(SceneError) as ex:
        eh.bone_finger_desc("Hand", "f0.3", args["matrix"], args["length"], radius=args["radius"],
                            stiffness=1000.0, damping=0.0, channel=0, rendered_of=args["rendered_of"])
    assert ex.value.obj_name == "Hand:f0.3"
    for w in words:
        assert w in str(ex.value)


def test_god_pose_lies_on_the_supporting_plane():
    """A bone lying along z = 0.004 (radius 8 mm) over the face z = 0 of a cube: 4 mm inside;
    moved out by exactly 4 mm + the hull's ring offset along the normal, and not at all when
    it is clear."""
    r = 0.008
    pts = eh.capsule_points(0.03, r)
    q = eh.quat_from_matrix(np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1]]).T)   # bone +Y along world +X
    cube = [np.array([(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * 0.05]
    pose = np.array([0, 0, -0.05, 1, 0, 0, 0.0])
    support = eh.body_support(cube, pose, np.array((0, 0, 1.0)))
    assert support == pytest.approx(0.0)
    pos, moved = eh.god_pose((0, 0, 0.004), q, pts, r, (0, 0, 1.0), support)
    ring = eh.CAPSULE_CORE_FRACTION * r * np.sin(np.pi / 3)     # the rings' lowest point below the axis
    assert moved == pytest.approx(0.004 + ring, abs=1e-12)
    np.testing.assert_allclose(pos, (0, 0, 0.008 + ring), atol=1e-12)
    pos, moved = eh.god_pose((0, 0, 0.009), q, pts, r, (0, 0, 1.0), support)
    assert moved == 0.0 and tuple(pos) == (0, 0, 0.009)


def _chain_rig():
    rest = np.array([np.eye(4)] * 3)
    for i in range(3):
        rest[i][1, 3] = 0.03 * i
    return eh.HandRig("A", ["a", "b", "c"], [-1, 0, 1], np.array([0.03, 0.03, 0.03]), rest, [0, 1, 2],
                      [False, True, True])


def test_chain_correction_keeps_joints_and_lengths_and_puts_the_tip_at_its_god_pose():
    rig = _chain_rig()
    inputs = rig.rest.copy()
    gods = {0: inputs[0].copy(), 1: inputs[1].copy(), 2: inputs[2].copy()}
    gods[2][:3, 3] += (0.003, -0.002, 0)        # the fingertip pushed out 3 mm, its joint not
    out = eh.rendered_matrices(rig, inputs, gods)
    heads, tails = eh.bone_ends(out, rig.lengths)
    np.testing.assert_allclose(out[0], gods[0])                          # the root at its god-pose
    np.testing.assert_allclose(heads[1:], tails[:-1], atol=1e-15)        # connected
    np.testing.assert_allclose(np.linalg.norm(tails - heads, axis=1), rig.lengths, rtol=1e-12)
    np.testing.assert_allclose(tails[2], (0.003, 0.088, 0), atol=eh.CHAIN_TOLERANCE)    # reachable: reached
    for m in out:
        np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)
    corr = eh.corrections(inputs, out, rig.lengths)
    assert corr[0] == 0
    assert corr[2] == pytest.approx(max(np.linalg.norm(tails[2] - (0, 0.09, 0)), np.linalg.norm(heads[2] - (0, 0.06, 0))))
    # Out of reach (the chain is straight and the tip 3 mm aside): stretched straight toward it,
    # short by the distance's excess over the chain's length, joints still exact.
    gods[2] = inputs[2].copy()
    gods[2][:3, 3] += (0.003, 0, 0)
    out = eh.rendered_matrices(rig, inputs, gods)
    heads, tails = eh.bone_ends(out, rig.lengths)
    target = np.array((0.003, 0.09, 0))
    np.testing.assert_allclose(heads[1:], tails[:-1], atol=1e-15)
    shortfall = np.linalg.norm(target - heads[1]) - 0.06
    assert np.linalg.norm(tails[2] - target) == pytest.approx(shortfall, rel=1e-6)
    # Non-Finger bones follow the input relative to their rendered parent.
    rig.fingers = [0, 1, -1]
    out = eh.rendered_matrices(rig, inputs, gods)
    np.testing.assert_allclose(out[2], inputs[2], atol=1e-15)


def test_local_bases_invert_the_pose():
    """Bases that Blender would chain (parent pose @ rest offset @ basis) back to the matrices."""
    rig = _chain_rig()
    rng = np.random.default_rng(3)
    arm = eh.pose_matrix((0.1, 0, 0.2), (0.9, 0.1, 0.3, 0.2))
    world = np.array([arm @ eh.pose_matrix(rng.normal(size=3) * 0.01, rng.normal(size=4)) for _ in range(3)])
    bases = eh.local_bases(rig, arm, world)
    pose = np.empty_like(bases)
    for i, p in enumerate(rig.parents):
        pose[i] = (rig.rest[i] if p < 0 else pose[p] @ np.linalg.inv(rig.rest[p]) @ rig.rest[i]) @ bases[i]
    np.testing.assert_allclose(arm @ pose, world, atol=1e-12)


# --------------------------------------------------------------------------- in Blender

def _box_distance(head, tail, box_matrix, half, samples=200):
    """Signed distance (m, negative inside) from the box to the nearest of ``samples`` points of
    the segment head-tail (a convex function along it: sampled to well under a micrometre)."""
    t = np.linspace(0.0, 1.0, samples)[:, None]
    pts = head + t * (tail - head)
    local = (pts - box_matrix[:3, 3]) @ box_matrix[:3, :3]
    q = np.abs(local) - np.asarray(half)
    return float(np.min(np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(np.max(q, axis=1), 0.0)))


def _bones(obj, names):
    mw = np.array(obj.matrix_world)
    heads = np.array([mw @ np.append(obj.pose.bones[n].head, 1.0) for n in names])[:, :3]
    tails = np.array([mw @ np.append(obj.pose.bones[n].tail, 1.0) for n in names])[:, :3]
    return heads, tails


def _keys(obj):
    anim = grasp_env.submodule("anim")
    fc = anim._fcurves(obj)
    return {(f.data_path, f.array_index): [tuple(k.co) for k in f.keyframe_points] for f in fc}


@pytest.fixture()
def baked(bpy, core, tmp_path):
    arm, box = hand_scene.build(bpy)
    input_keys = _keys(arm)
    s = bpy.context.scene.grasp_lab
    s.bake = True
    s.record = True
    s.recording_folder = str(tmp_path)
    assert bpy.ops.grasp_lab.session() == {"FINISHED"}
    return arm, box, input_keys


def test_keyed_hand_squeezes_lifts_and_the_rendered_hand_stays_on_the_box(bpy, baked):
    arm, box, input_keys = baked
    scene = bpy.context.scene
    res = grasp_env.submodule("session").last_result
    # 16 Finger bones, in armature order (channel 0 each, then by name).
    assert len(res.finger_names) == 16 and res.finger_names[0].startswith("Hand:")
    z = res.trajectory("Box")[:, 2]
    frames = np.array(res.frames)
    assert z[0] == pytest.approx(hand_scene.BOX_HALF[2], abs=1e-6)
    assert z[frames == hand_scene.FRAMES["end"]][0] - z[0] == pytest.approx(hand_scene.LIFT, abs=1e-3)   # lifted
    rendered = bpy.data.objects["Hand Rendered"]
    assert rendered.get("grasp_lab_rendered_of") == "Hand" and rendered.type == "ARMATURE"
    assert all(pb.grasp_lab.role == "NONE" for pb in rendered.pose.bones)
    names = [b.name for b in arm.data.bones]
    finger_bones = [n for n in names if n != "palm"]
    radius = {n: arm.pose.bones[n].grasp_lab.radius for n in names}
    input_depth, rendered_depth, touching, gaps = [], [], [], []
    for frame in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(frame)
        bm = np.array(box.matrix_world)
        hi, ti = _bones(arm, names)
        hr, tr = _bones(rendered, names)
        d_in = np.array([_box_distance(h, t, bm, hand_scene.BOX_HALF) - radius[n] for n, h, t in zip(names, hi, ti)])
        d_r = np.array([_box_distance(h, t, bm, hand_scene.BOX_HALF) - radius[n] for n, h, t in zip(names, hr, tr)])
        input_depth.append(-d_in.min())
        rendered_depth.append(-d_r.min())
        # Where the input goes in, the rendered bone touches: within 0.5 mm of the surface.
        touching += list(np.abs(d_r[d_in < 0]))
        for n in finger_bones:
            parent = arm.data.bones[n].parent.name
            if arm.data.bones[n].use_connect:
                gaps.append(np.linalg.norm(hr[names.index(n)] - tr[names.index(parent)]))
        # The baked correction channel: the input-to-rendered distance of each bone, mm.
        for n, h0, t0, h1, t1 in zip(names, hi, ti, hr, tr):
            want = 1e3 * max(np.linalg.norm(h0 - h1), np.linalg.norm(t0 - t1))
            assert rendered.pose.bones[n]["gl_correction_mm"] == pytest.approx(want, abs=0.01)
    input_depth, rendered_depth = np.array(input_depth), np.array(rendered_depth)
    print(f"input depth max {1e3 * input_depth.max():.2f} mm, rendered depth max {1e3 * rendered_depth.max():.3f} mm, "
          f"touching |d| max {1e3 * max(touching):.3f} mm, joint gap max {1e3 * max(gaps):.4f} mm")
    assert input_depth.max() >= hand_scene.SQUEEZE - 1e-4                       # the input goes 3 mm in
    assert rendered_depth.max() <= 0.5e-3                                       # the rendered hand never 0.5 mm
    assert len(touching) > 100 and max(touching) <= 0.5e-3
    assert len(gaps) == 10 * (scene.frame_end - scene.frame_start + 1) and max(gaps) <= 0.5e-3
    # The input armature is untouched: its keys as they were, no new ones.
    assert _keys(arm) == input_keys
    # The skinned mesh has a rendered copy on the rendered armature, deformed with it: each
    # vertex (wholly in its bone's group) moved by its bone's pose from its rest.
    skin, copy = bpy.data.objects["Hand Skin"], bpy.data.objects["Hand Skin Rendered"]
    assert copy.data == skin.data and copy.modifiers["Armature"].object == rendered and copy.parent == rendered
    scene.frame_set(hand_scene.FRAMES["lifted"])
    dg = bpy.context.evaluated_depsgraph_get()
    group_bone = {g.index: g.name for g in skin.vertex_groups}
    bone_of = [group_bone[v.groups[0].group] for v in skin.data.vertices]
    for obj, rig in ((skin, arm), (copy, rendered)):
        ev = obj.evaluated_get(dg)
        got = np.array([np.array(ev.matrix_world) @ np.append(v.co, 1) for v in ev.data.vertices])[:, :3]
        rig_w = np.array(rig.matrix_world)
        moves = {b.name: rig_w @ np.array(rig.pose.bones[b.name].matrix) @ np.linalg.inv(np.array(b.matrix_local))
                 @ np.linalg.inv(rig_w) @ np.array(obj.matrix_world) for b in arm.data.bones}
        want = np.array([moves[b] @ np.append(v.co, 1) for b, v in zip(bone_of, skin.data.vertices)])[:, :3]
        np.testing.assert_allclose(got, want, atol=1e-6)


def test_a_hand_recording_resimulates_identically(bpy, baked):
    s = bpy.context.scene.grasp_lab
    rec = grasp_env.submodule("engine.recording").open_recording(s.last_recording)
    assert len(rec.finger_names) == 16 and rec.ticks["orientation"].shape[1] == 16
    result = grasp_env.submodule("engine.resim").resimulate(rec, grasp_env.graspcore())
    assert result.divergence.report() == "identical"


def test_a_live_hand_recording_of_the_threaded_runtime_resimulates_identically(bpy, core, tmp_path):
    """The animated hand live on the threaded runtime (its poses on the core's track), recorded:
    re-simulated on its hand-over schedule it is identical too."""
    import time as _time
    hand_scene.build(bpy, skinned=False)
    session = grasp_env.submodule("session")
    path = str(tmp_path / "live_hand.mcap")
    s = session.BlenderSession(bpy.context, live=True, duration=1.0, record_path=path)
    assert s.runner.threaded
    t0 = _time.perf_counter()
    while not s.tick(_time.perf_counter() - t0):
        _time.sleep(0.03)
        assert _time.perf_counter() - t0 < 120.0, "the live session never reached its end"
    s.finish()
    rec = grasp_env.submodule("engine.recording").open_recording(path)
    assert rec.header["runtime"]["threaded"] and len(rec.finger_names) == 16
    result = grasp_env.submodule("engine.resim").resimulate(rec, core)
    assert result.divergence.report() == "identical"


def test_baking_the_recording_keys_the_rendered_hand_as_the_session_did(bpy, baked):
    """Bake Recording of the hand's recording, its rendered armature deleted first: made again
    and keyed with the poses and corrections the session's own bake had (float32 keys)."""
    arm = baked[0]
    scene = bpy.context.scene
    names = [b.name for b in arm.data.bones]
    frames = (5, 13, 30, 45)
    before = {}
    rendered = bpy.data.objects["Hand Rendered"]
    for frame in frames:
        scene.frame_set(frame)
        before[frame] = (_bones(rendered, names), [rendered.pose.bones[n]["gl_correction_mm"] for n in names])
    bpy.data.objects.remove(rendered)
    rec = grasp_env.submodule("engine.recording").open_recording(scene.grasp_lab.last_recording)
    report = grasp_env.submodule("bake").bake_recording(bpy.context, rec)
    assert "Hand Rendered" in report.baked and report.missing == [], report.message()
    rendered = bpy.data.objects["Hand Rendered"]
    assert bpy.data.objects["Hand Skin Rendered"].modifiers["Armature"].object == rendered
    for frame in frames:
        scene.frame_set(frame)
        (h0, t0), c0 = before[frame]
        h1, t1 = _bones(rendered, names)
        np.testing.assert_allclose(h1, h0, atol=2e-6)
        np.testing.assert_allclose(t1, t0, atol=2e-6)
        np.testing.assert_allclose([rendered.pose.bones[n]["gl_correction_mm"] for n in names], c0, atol=1e-3)


def test_a_sweep_sample_of_a_hand_recording_with_nothing_varied_is_the_recording(bpy, baked):
    """A sweep replays the bones' recorded orientations too (resim.recorded_turns): with nothing
    varied its traces are the recording's, and the box is held."""
    rec_mod = grasp_env.submodule("engine.recording")
    sweep = grasp_env.submodule("engine.sweep")
    rec = rec_mod.open_recording(bpy.context.scene.grasp_lab.last_recording)
    core = grasp_env.graspcore()
    job = sweep.make_job(rec, [], 0, analysis=False)
    # The 15 phalanges turn (the chains close), the palm only rises: NaN, left alone.
    palm = rec.finger_names.index("Hand:palm")
    assert np.isnan(job.turns[:, palm]).all() and not np.isnan(np.delete(job.turns, palm, axis=1)).any()
    desc = rec_mod.scene_from_dict(rec.header["scene"])
    handle = grasp_env.submodule("engine.scene").build_world(desc, core, exact=True)
    traces = sweep.replay_trace(handle.world, job.hips, 1.0 / job.rate, job.has_start, turns=job.turns)
    np.testing.assert_array_equal(traces["pose"], rec.ticks["pose"])
    np.testing.assert_array_equal(traces["god_object"], rec.ticks["god_object"])
    row = sweep.run_sample(job, 0, core)
    assert row["held"] == 1 and row["drop_time"] is None


def test_a_hand_posed_live_is_pushed_to_the_haptic_loop_and_rendered(bpy, core):
    """Not animated: the armature as it is posed at each display update (by a mocap add-on, or
    a person) goes to the threaded runtime with its time stamp. Closed on the box, the five
    fingertips hold it and the rendered fingertips are on its surface; opened, they let go."""
    import time as _time
    session = grasp_env.submodule("session")
    arm, box = hand_scene.build(bpy, skinned=False)
    arm.animation_data_clear()
    hand_scene.pose(arm, closed=1.0, lifted=0.0)
    bpy.context.view_layer.update()
    s = session.BlenderSession(bpy.context, live=True, duration=60.0)
    assert s.runner.threaded and s.source.interactive
    tips = [s.result.finger_names.index(f"Hand:f{k}.3") for k in range(5)]
    t0 = _time.perf_counter()

    def run_until(cond, what):
        while not cond():
            s.tick(_time.perf_counter() - t0)
            _time.sleep(0.02)
            assert _time.perf_counter() - t0 < 60.0, f"waiting for {what}"

    run_until(lambda: s.snapshot.time > 0.3 and all(s.snapshot.contacts[tips] == 0)
              and np.allclose(s.snapshot.hips[tips[0]], s.finger_objects[tips[0]].matrix_world.translation, atol=1e-6),
              "the fingertips on the box")
    rendered = bpy.data.objects["Hand Rendered"]
    bpy.context.view_layer.update()                 # the pose set at the last update, evaluated
    bm = np.array(box.matrix_world)
    names = [f"f{k}.3" for k in range(5)]
    depths_in = [hand_scene.RADIUS - _box_distance(h, t, bm, hand_scene.BOX_HALF) for h, t in zip(*_bones(arm, names))]
    depths = [hand_scene.RADIUS - _box_distance(h, t, bm, hand_scene.BOX_HALF) for h, t in zip(*_bones(rendered, names))]
    assert min(depths_in) > 0.002 and max(depths) <= 0.5e-3 and min(depths) >= -0.5e-3, (depths_in, depths)
    hand_scene.pose(arm, closed=0.0, lifted=0.0)     # opened, as an add-on would pose it
    bpy.context.view_layer.update()
    run_until(lambda: all(s.snapshot.contacts[tips] < 0), "the fingertips to let go")
    s.finish()
    assert not s.runner.world.running


def test_a_mesh_parented_to_a_bone_is_a_pad_that_follows_it(bpy, core):
    """A Finger-role mesh parented to a bone (parent type Bone) is a convex finger of its own
    mesh, its pose sampled from the animated bone at every frame."""
    arm, box = hand_scene.build(bpy, skinned=False)
    for pb in arm.pose.bones:
        pb.grasp_lab.role = "NONE"
    pad = grasp_env.add_cube(bpy, "Pad", size=0.01, location=(0, 0, 0))
    pad.grasp_lab.role = "FINGER"
    pad.parent, pad.parent_type, pad.parent_bone = arm, "BONE", "f0.3"
    pad.matrix_parent_inverse.identity()
    session = grasp_env.submodule("session")
    s = session.BlenderSession(bpy.context, live=False)
    assert s.result.finger_names == ["Pad"] and s.desc.fingers[0].points is not None
    times, pos, _, quats = s.source.track.times, s.source.track.positions, None, s.source.track.orientations
    scene = bpy.context.scene
    for frame in (hand_scene.FRAMES["open"], hand_scene.FRAMES["closed"], hand_scene.FRAMES["lifted"]):
        scene.frame_set(frame)
        k = frame - scene.frame_start
        np.testing.assert_allclose(pos[k, 0], np.array(pad.matrix_world.translation), atol=1e-6)
    assert quats is not None            # the pad turns with the closing finger
    s.finish()


@pytest.mark.parametrize("case, words", [
    ("zero_length", ["Hand:f1.2", "zero length"]),
    ("zero_radius", ["Hand:f1.2", "zero radius"]),
    ("scale", ["Hand:", "scale of 1.1"]),
    ("non_uniform", ["Hand:", "non-uniform scale"]),
    ("rendered_input", ["Hand Rendered:f1.2", "output only"]),
])
def test_bad_hand_input_is_refused_naming_the_bone_and_nothing_runs(bpy, core, case, words):
    arm, _ = hand_scene.build(bpy, skinned=False)
    if case == "zero_length":
        # A scale of 0 along the bone in the pose: zero length (and non-uniform: length first).
        arm.pose.bones["f1.2"].scale = (1.0, 1e-9, 1.0)
    elif case == "zero_radius":
        arm.pose.bones["f1.2"].grasp_lab.radius = 0.0
    elif case == "scale":
        arm.scale = (1.1, 1.1, 1.1)
    elif case == "non_uniform":
        arm.scale = (1.0, 1.0, 1.2)
    elif case == "rendered_input":
        hands = grasp_env.submodule("hands")
        rendered = hands.ensure_rendered(arm)
        rendered.pose.bones["f1.2"].grasp_lab.role = "FINGER"
    session = grasp_env.submodule("session")
    session.last_result = None
    with pytest.raises(RuntimeError) as ex:
        bpy.ops.grasp_lab.session()
    for w in words:
        assert w in str(ex.value)
    assert session.last_result is None
    if case != "rendered_input":
        assert "Hand Rendered" not in bpy.data.objects
