"""Baking a recording (addon/bake.py, File > Import > Grasp Lab Recording): the keys equal the
recorded poses, HIPs and god-objects at sampled frames, measures animate as custom
properties, baking again replaces, every tick bakes subframes, renamed objects are reported
and the rest baked, parents are respected, quaternions stay on one side."""
import numpy as np
import pytest

import grasp_env

SAMPLED_FRAMES = (1, 20, 31, 43, 58, 70, 100, 118, 145)


def _fcurves(bpy, obj):
    ad = obj.animation_data
    if bpy.app.version >= (4, 4, 0):
        from bpy_extras import anim_utils
        return anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot).fcurves
    return ad.action.fcurves


@pytest.fixture()
def recorded(bpy, sample, core, tmp_path):
    """A recording of the sample scene, then a fresh copy of the scene to bake it into."""
    sample.build(bpy)
    s = bpy.context.scene.grasp_lab
    s.record, s.recording_folder = True, str(tmp_path)
    assert bpy.ops.grasp_lab.session() == {"FINISHED"}
    path = s.last_recording
    bpy.ops.wm.read_homefile(use_empty=True)
    sample.build(bpy)
    return path, grasp_env.submodule("engine.recording").open_recording(path)


def _at(rec, frame, fps=24):
    return rec.ticks[rec.sample([(frame - 1) / fps])[0]]


def _at_frames(rec, n=145, fps=24):
    return rec.ticks[rec.sample(np.arange(n) / fps)]


@pytest.mark.multiversion
def test_baked_keys_equal_the_recording(bpy, recorded):
    path, rec = recorded
    assert bpy.ops.grasp_lab.import_recording(filepath=path) == {"FINISHED"}
    scene = bpy.context.scene
    box = bpy.data.objects["Box"]
    fingers = [bpy.data.objects[f"Finger {i}"] for i in range(2)]
    go = bpy.data.objects["GL God-object Finger 0"]
    arrow = bpy.data.objects["GL Force Box"]
    for frame in SAMPLED_FRAMES:
        scene.frame_set(frame)
        t = _at(rec, frame)
        np.testing.assert_allclose(tuple(box.matrix_world.translation), t["pose"][0, :3], atol=1e-6)
        q = np.array(box.matrix_world.to_quaternion())
        assert abs(np.dot(q, t["pose"][0, 3:])) == pytest.approx(1.0, abs=1e-6)
        for i, f in enumerate(fingers):
            np.testing.assert_allclose(tuple(f.matrix_world.translation), t["hip"][i], atol=1e-6)
        np.testing.assert_allclose(tuple(go.matrix_world.translation), t["god_object"][0], atol=1e-6)
        assert go["gl_state"] == pytest.approx(float(t["state"][0]))
        assert arrow["gl_force"] == pytest.approx(np.linalg.norm(t["wrench"][0, :3]), rel=1e-5, abs=1e-6)
    # Mid-lift: both fingers stick, each squeezing k * 3 mm = 3 N; friction holds with room to spare.
    scene.frame_set(43)
    assert go["gl_state"] == 1.0
    assert arrow["gl_grip"] == pytest.approx(2 * 1000.0 * 0.003, rel=0.05)
    assert 0.0 < go["gl_friction_use"] < 1.0
    assert go["gl_normal_force"] == pytest.approx(3.0, rel=0.05)
    # A key per frame where the value changes (runs of equal values keep their ends), linear;
    # the scene covers the recording.
    fc = {(f.data_path, f.array_index): f for f in _fcurves(bpy, box)}
    z = fc[("location", 2)].keyframe_points
    frames_z = np.array(_at_frames(rec)["pose"][:, 0, 2], dtype=np.float32)
    changes = 2 + int(np.sum((frames_z[1:-1] != frames_z[:-2]) | (frames_z[1:-1] != frames_z[2:])))
    assert len(z) == changes and changes < 145      # resting at the start and the end
    assert {k.interpolation for k in z} == {"LINEAR"} and scene.frame_end >= 145


@pytest.mark.multiversion
def test_baked_grasp_measures_are_the_analysis(bpy, recorded):
    """The grasp measures plot beside the forces: on "GL Force Box", at every sampled frame,
    the analysis of that frame's tick (as grasp-lab analyze gives it) over the whole recording,
    read again; mid-lift the values a two-finger pinch has by hand."""
    path, _ = recorded
    assert bpy.ops.grasp_lab.import_recording(filepath=path) == {"FINISHED"}
    analysis = grasp_env.submodule("engine.analysis")
    rec = grasp_env.submodule("engine.recording").open_recording(path)      # every tick
    table = analysis.analyse_recording(rec)
    arrow = bpy.data.objects["GL Force Box"]
    scene = bpy.context.scene
    held = 0
    for frame in range(1, 146, 3):
        scene.frame_set(frame)
        tick = rec.sample([(frame - 1) / 24])[0]
        row = np.flatnonzero(table.snapshot == tick)
        if len(row) == 0:
            assert arrow["gl_held"] == 0.0 and arrow["gl_closure"] == 0.0 and arrow["gl_mu_min"] == -1.0
            continue
        held += 1
        (g,) = analysis.body_grasps(table, row)
        assert arrow["gl_held"] == 1.0
        assert arrow["gl_closure"] == float(g.force_closure)
        assert arrow["gl_epsilon"] == pytest.approx(g.epsilon, rel=1e-6, abs=1e-9)
        assert arrow["gl_mu_min"] == (pytest.approx(g.mu_min, rel=1e-6) if np.isfinite(g.mu_min) else -1.0)
        assert arrow["gl_slip_margin"] == pytest.approx(g.min_slip_margin, rel=1e-5, abs=1e-6)
        assert arrow["gl_grip_load"] == pytest.approx(g.grip_ratio, rel=1e-5)
    assert held > 10
    # Mid-lift: 3 N a finger against the 0.1 kg box's weight (it moves slowly); two point
    # contacts are never in force closure, at any friction.
    scene.frame_set(43)
    assert arrow["gl_grip_load"] == pytest.approx(6.0 / (0.1 * 9.81), rel=0.05)
    assert arrow["gl_closure"] == 0.0 and arrow["gl_mu_min"] == -1.0 and arrow["gl_slip_margin"] > 0


@pytest.mark.multiversion
def test_baking_again_replaces(bpy, recorded):
    path, rec = recorded
    bake = grasp_env.submodule("bake")
    bake.bake_recording(bpy.context, rec)

    def animated():             # objects, the god-objects' materials and their shader node trees
        ids = list(bpy.data.objects) + list(bpy.data.materials)
        ids += [m.node_tree for m in bpy.data.materials if m.node_tree is not None]
        return {(type(i).__name__, i.name): [(f.data_path, f.array_index, len(f.keyframe_points))
                                             for f in _fcurves(bpy, i)] for i in ids if i.animation_data}
    before, actions = animated(), len(bpy.data.actions)
    assert any(kind == "Material" for kind, _ in before)
    bake.bake_recording(bpy.context, rec)
    after = animated()
    # (a material and its node tree may share an action: Blender 4.4's slots)
    assert after == before and len(bpy.data.actions) == actions


@pytest.mark.multiversion
def test_god_object_colour_is_keyed_per_frame(bpy, recorded):
    """A god-object's material has the colour of each frame (not the session's last): mid-lift
    the friction-use colour of the finger's contact as the analysis has it at that frame's tick,
    at the end, released, the free blue; the viewport's colour and the shader's alike."""
    path, rec = recorded
    assert bpy.ops.grasp_lab.import_recording(filepath=path) == {"FINISHED"}
    grasp_display = grasp_env.submodule("engine.grasp_display")
    table = grasp_env.submodule("engine.analysis").analyse_recording(rec)
    scene = bpy.context.scene
    go = bpy.data.objects["GL God-object Finger 0"]
    mat = go.material_slots[0].material
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    seen = {}
    for frame in (20, 43, 70, 145):
        scene.frame_set(frame)
        tick = rec.sample([(frame - 1) / 24])[0]
        sets = np.flatnonzero(table.snapshot == tick)
        uses = [table.friction_use[c] for s in sets for c in range(table.first[s], table.first[s] + table.count[s])
                if table.finger[c] == 0]
        want = grasp_display.friction_color(uses[-1]) if uses else grasp_display.FREE_COLOR
        np.testing.assert_allclose(tuple(mat.diffuse_color), want, atol=1e-6, err_msg=f"frame {frame}")
        np.testing.assert_allclose(tuple(bsdf.inputs["Base Color"].default_value), want, atol=1e-6)
        seen[frame] = (bool(uses), tuple(mat.diffuse_color))
    assert seen[43][0] and not seen[145][0]                   # held mid-lift, let go at the end
    assert seen[43][1] != seen[145][1]
    scene.frame_set(43)
    # the colour says what the baked friction use says (green at 0, yellow at 0.5)
    assert 0.0 < go["gl_friction_use"] < 0.5
    np.testing.assert_allclose(tuple(mat.diffuse_color), grasp_display.friction_color(go["gl_friction_use"]),
                               atol=0.02)


def test_every_tick_bakes_subframes(bpy, recorded):
    path, rec = recorded
    report = grasp_env.submodule("bake").bake_recording(bpy.context, rec, every_tick=True)
    assert report.frames == len(rec.ticks)
    fc = {(f.data_path, f.array_index): f for f in _fcurves(bpy, bpy.data.objects["Box"])}[("location", 2)]
    keys = np.empty(2 * len(fc.keyframe_points), dtype=np.float32)
    fc.keyframe_points.foreach_get("co", keys)
    tick_of_key = (keys[0::2].astype(np.float64) - 1) / 24 * 1000
    np.testing.assert_allclose(tick_of_key, np.round(tick_of_key), atol=0.02)     # keys sit on ticks
    # Every tick, subframes included, evaluates to the recorded height (float32).
    for k in range(0, len(rec.ticks), 37):
        assert fc.evaluate(1 + rec.ticks["time"][k] * 24) == pytest.approx(rec.ticks["pose"][k, 0, 2], abs=1e-7)


def test_renamed_and_deleted_objects(bpy, recorded):
    path, rec = recorded
    bpy.data.objects["Box"].name = "Crate"
    bpy.data.objects.remove(bpy.data.objects["Finger 1"])
    report = grasp_env.submodule("bake").bake_recording(bpy.context, rec)
    assert report.missing == ["body Box", "finger Finger 1"]
    assert "Finger 0" in report.baked and "GL Force Box" in report.baked
    assert "renamed or deleted" in report.message() and "body Box" in report.message()
    assert bpy.data.objects["Crate"].animation_data is None
    # The operator says so too, and still finishes.
    assert bpy.ops.grasp_lab.import_recording(filepath=path) == {"FINISHED"}


def test_parented_body(bpy, recorded):
    path, rec = recorded
    box = bpy.data.objects["Box"]
    holder = bpy.data.objects.new("Holder", None)
    bpy.context.scene.collection.objects.link(holder)
    holder.location = (0.01, -0.02, 0.0)
    holder.rotation_euler = (0.0, 0.0, 0.7)
    holder.scale = (2.0, 2.0, 2.0)
    bpy.context.view_layer.update()
    world = box.matrix_world.copy()
    box.parent = holder
    box.matrix_world = world
    bpy.context.view_layer.update()
    grasp_env.submodule("bake").bake_recording(bpy.context, rec)
    for frame in (1, 43, 100):
        bpy.context.scene.frame_set(frame)
        np.testing.assert_allclose(tuple(box.matrix_world.translation), _at(rec, frame)["pose"][0, :3], atol=1e-6)
        np.testing.assert_allclose(tuple(box.matrix_world.to_scale()), (1, 1, 1), atol=1e-6)


def test_quaternions(bpy):
    from mathutils import Quaternion
    bake = grasp_env.submodule("bake")
    rng = np.random.default_rng(3)
    q = rng.normal(size=(200, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    mats = np.array([np.array(Quaternion(v).to_matrix()) for v in q])
    back = bake.quats_from_matrices(mats)
    assert np.all(np.sum(back[1:] * back[:-1], axis=1) >= 0)               # one side, key to key
    np.testing.assert_allclose(np.abs(np.sum(back * q, axis=1)), 1.0, atol=1e-12)
    # A rotation turning past 180 degrees: without continuity the sign flips halfway.
    angles = np.linspace(0, 3 * np.pi, 50)
    spin = np.stack([np.cos(angles / 2), np.zeros(50), np.zeros(50), np.sin(angles / 2)], axis=1)
    flipped = spin * np.where(np.arange(50) % 7 == 3, -1.0, 1.0)[:, None]
    np.testing.assert_allclose(bake.continuous(flipped), spin)


def test_bad_files_are_reported(bpy, tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 100)
    with pytest.raises(RuntimeError, match="junk.mcap: not a readable Grasp Lab recording"):
        bpy.ops.grasp_lab.import_recording(filepath=str(junk))
