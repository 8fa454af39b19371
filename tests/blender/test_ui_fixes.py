"""What the Grasp tab does for a new user (issue 16, item 4), against a real bpy: baked keys not
left selected and Show Curves selecting what carries the measures; the bake's file browser on
the last recording and its report of a moved end frame; Check's result kept for the panel, with
the fix for a plane; Add Finger beside the selected object, touching it, big enough to see;
a new device driving the fingers left; the bodies a session moved found for Reset Bodies."""
import os

import numpy as np
import pytest

import grasp_env


def _fcurves(bpy, obj):
    ad = obj.animation_data
    if bpy.app.version >= (4, 4, 0):
        from bpy_extras import anim_utils
        return anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot).fcurves
    return ad.action.fcurves


@pytest.fixture()
def baked(bpy, sample, core, tmp_path):
    sample.build(bpy)
    s = bpy.context.scene.grasp_lab
    s.record, s.recording_folder = True, str(tmp_path)
    assert bpy.ops.grasp_lab.session() == {"FINISHED"}
    path = s.last_recording
    assert bpy.ops.grasp_lab.import_recording(filepath=path) == {"FINISHED"}
    return path


def test_baked_keys_are_not_selected(bpy, baked):
    objs = [o for o in bpy.data.objects if o.animation_data and o.animation_data.action]
    assert len(objs) >= 6
    n = 0
    for o in objs:
        for fc in _fcurves(bpy, o):
            for kp in fc.keyframe_points:
                assert not (kp.select_control_point or kp.select_left_handle or kp.select_right_handle)
                n += 1
    assert n > 1000


def test_show_curves_selects_the_measures(bpy, baked):
    ops = grasp_env.submodule("recording_ops")
    for o in bpy.context.selected_objects:
        o.select_set(False)
    assert bpy.ops.grasp_lab.show_curves() == {"FINISHED"}
    selected = sorted(o.name for o in bpy.context.selected_objects)
    # the god-objects (per-finger measures) and the box's force arrow (the grasp measures)
    assert selected == ["GL Force Box", "GL God-object Finger 0", "GL God-object Finger 1"]
    assert sorted(o.name for o in ops.baked_objects(bpy.context)) == selected
    # A Graph Editor showing selected objects only, filtered to the measures
    area = ops._graph_editor(bpy.context)
    if area is not None:
        assert area.type == "GRAPH_EDITOR"
        assert area.spaces.active.dopesheet.show_only_selected
        assert area.spaces.active.dopesheet.filter_text == "gl_"


def test_show_curves_needs_a_bake(bpy, sample):
    sample.build(bpy)
    with pytest.raises(RuntimeError, match="poll"):
        bpy.ops.grasp_lab.show_curves()


def test_bake_browser_opens_on_the_latest_recording(bpy, tmp_path):
    record = grasp_env.submodule("record")
    s = bpy.context.scene.grasp_lab
    s.recording_folder = str(tmp_path)
    s.last_recording = ""
    assert record.latest_recording(s) == ""                     # nothing there yet
    old, new = tmp_path / "a.mcap", tmp_path / "b.mcap"
    for k, p in enumerate((old, new)):
        p.write_bytes(b"x")
        os.utime(p, (1000 + k, 1000 + k))
    (tmp_path / "c.txt").write_bytes(b"x")
    assert record.latest_recording(s) == str(new)               # the newest .mcap
    s.last_recording = str(old)
    assert record.latest_recording(s) == str(old)               # the one just made or baked
    s.last_recording = str(tmp_path / "gone.mcap")
    assert record.latest_recording(s) == str(new)


def test_bake_says_when_it_moves_the_end_frame(bpy, sample, core, tmp_path):
    bake = grasp_env.submodule("bake")
    recording = grasp_env.submodule("engine.recording")
    sample.build(bpy)
    s = bpy.context.scene.grasp_lab
    s.record, s.recording_folder = True, str(tmp_path)
    assert bpy.ops.grasp_lab.session() == {"FINISHED"}
    rec = recording.open_recording(s.last_recording, fps=24)
    scene = bpy.context.scene
    end = scene.frame_end
    report = bake.bake_recording(bpy.context, rec)
    assert report.frame_end_was is None and "end frame" not in report.message()
    scene.frame_end = 100
    report = bake.bake_recording(bpy.context, rec)
    assert (report.frame_end_was, report.frame_end, scene.frame_end) == (100, end, end)
    assert f"the scene's end frame is now {end} (was 100)" in report.message()


def _plane(bpy):
    bpy.ops.mesh.primitive_plane_add(size=0.1)
    obj = bpy.context.active_object
    obj.grasp_lab.role = "DYNAMIC"
    return obj


def test_check_names_the_fix_and_keeps_its_result(bpy):
    ops = grasp_env.submodule("ops")
    _plane(bpy)
    with pytest.raises(RuntimeError, match="give it thickness"):      # from a script: an error
        bpy.ops.grasp_lab.validate_scene()
    ok, text = ops.last_check[bpy.context.scene.name]
    assert not ok and "zero volume" in text and "give it thickness" in text
    bpy.ops.object.delete()
    bpy.ops.mesh.primitive_cube_add(size=0.05)
    bpy.context.active_object.grasp_lab.role = "DYNAMIC"
    assert bpy.ops.grasp_lab.validate_scene() == {"FINISHED"}
    ok, text = ops.last_check[bpy.context.scene.name]
    assert ok and text.startswith("Grasp scene OK: 1 dynamic")


def test_add_finger_beside_the_selected_object(bpy):
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(1.0, 2.0, 3.0))      # a 2 m cube
    cube = bpy.context.active_object
    expected = [((-0.1, 2.0, 3.0), 0), ((2.1, 2.0, 3.0), 0), ((1.0, 0.9, 3.0), 1), ((1.0, 3.1, 3.0), 1),
                ((1.0, 2.0, 4.1), 2)]
    for k, (loc, axis) in enumerate(expected):
        for o in bpy.context.selected_objects:
            o.select_set(False)
        cube.select_set(True)
        bpy.context.view_layer.objects.active = cube
        assert bpy.ops.grasp_lab.add_finger() == {"FINISHED"}
        f = bpy.context.active_object
        assert f.name == f"Finger {k}" and f.grasp_lab.role == "FINGER" and f.grasp_lab.channel == k
        # a twentieth of the cube: 10 cm, shown at its size, touching the side (not inside)
        assert f.grasp_lab.radius == pytest.approx(0.1) and f.empty_display_size == pytest.approx(0.1)
        np.testing.assert_allclose(tuple(f.location), loc, atol=1e-6)
        gap = abs(f.location[axis] - cube.location[axis]) - 1.0
        assert gap == pytest.approx(f.grasp_lab.radius)


def test_add_finger_small_object_and_cursor(bpy):
    prefs_radius = 0.008
    bpy.ops.mesh.primitive_cube_add(size=0.05)
    assert bpy.ops.grasp_lab.add_finger() == {"FINISHED"}
    f = bpy.context.active_object
    assert f.grasp_lab.radius == pytest.approx(prefs_radius)       # the preference: already seen
    np.testing.assert_allclose(tuple(f.location), (-0.025 - prefs_radius, 0, 0), atol=1e-6)
    # the finger it added is now selected: the next goes beside the same cube, on its other side
    bpy.context.scene.cursor.location = (0.3, 0.0, 0.0)
    assert bpy.ops.grasp_lab.add_finger() == {"FINISHED"}
    np.testing.assert_allclose(tuple(bpy.context.active_object.location), (0.025 + prefs_radius, 0, 0), atol=1e-6)
    # nothing selected: at the 3D cursor
    bpy.ops.object.select_all(action="DESELECT")
    assert bpy.ops.grasp_lab.add_finger() == {"FINISHED"}
    np.testing.assert_allclose(tuple(bpy.context.active_object.location), (0.3, 0, 0), atol=1e-6)


def test_add_finger_on_blenders_default_cube_then_a_table_under_it(bpy):
    """The walkthrough from the startup file: the 2 m cube, made dynamic, gets two fingertips
    on opposite sides sized to it, and the offer of a table (it would fall): Add Table puts one
    under it, and the offer goes."""
    ops = grasp_env.submodule("ops")
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube = bpy.context.active_object
    cube.grasp_lab.role = "DYNAMIC"
    assert [o.name for o in ops.support_offer(bpy.context)] == [cube.name]
    bpy.ops.grasp_lab.add_finger()
    bpy.ops.grasp_lab.add_finger()          # the first fingertip is selected now
    fingers = sorted((o for o in bpy.context.scene.objects if o.grasp_lab.role == "FINGER"), key=lambda o: o.name)
    assert [f.grasp_lab.radius for f in fingers] == pytest.approx([0.1, 0.1])       # a twentieth of 2 m
    np.testing.assert_allclose([tuple(f.location) for f in fingers], [(-1.1, 0, 0), (1.1, 0, 0)], atol=1e-6)
    assert bpy.ops.grasp_lab.add_table() == {"FINISHED"}
    table = bpy.context.scene.objects["Table"]
    assert table.grasp_lab.role == "STATIC" and ops.support_offer(bpy.context) == []
    bpy.context.view_layer.update()
    top = max((table.matrix_world @ v.co).z for v in table.data.vertices)
    assert top == pytest.approx(-1.0) and table.dimensions.x == pytest.approx(6.0)
    ok = bpy.ops.grasp_lab.validate_scene()
    assert ok == {"FINISHED"}, ops.last_check        # a closed mesh, outward: the core takes it


def test_new_device_drives_the_fingers_left(bpy):
    for k in range(3):
        bpy.context.scene.cursor.location = (0.1 * k, 0, 0)
        bpy.ops.grasp_lab.add_finger()
    assert bpy.ops.grasp_lab.device_add(port="/dev/pts/9") == {"FINISHED"}
    entries = bpy.context.scene.grasp_lab_devices
    assert (entries[0].finger_offset, entries[0].num_fingers) == (0, 3)
    entries[0].num_fingers = 2
    assert bpy.ops.grasp_lab.device_add(port="/dev/pts/10") == {"FINISHED"}
    assert (entries[1].finger_offset, entries[1].num_fingers) == (2, 1)
    assert bpy.ops.grasp_lab.device_add(kind="OPENGLOVES", port="/dev/pts/11") == {"FINISHED"}
    assert entries[2].num_fingers == 5


def test_bodies_moved_by_a_session_are_offered_a_reset(bpy, sample, core):
    rest_poses = grasp_env.submodule("rest_poses")
    sample.build(bpy)
    assert rest_poses.moved_from_rest(bpy.context) == []
    assert bpy.ops.grasp_lab.session(duration=3.0) == {"FINISHED"}       # the box is up and carried
    assert [o.name for o in rest_poses.moved_from_rest(bpy.context)] == ["Box"]
    assert bpy.ops.grasp_lab.reset() == {"FINISHED"}
    assert rest_poses.moved_from_rest(bpy.context) == []


def test_scrubbing_a_bake_says_in_words_how_the_grasp_is_at_that_frame(bpy, baked):
    """The pinch and lift baked: mid-lift the box is held by both fingers (words from the baked
    properties at that frame); at the first frame no finger touches it yet."""
    ui = grasp_env.submodule("ui")
    scene = bpy.context.scene
    scene.frame_set(43)
    lines = ui.baked_frame_lines(bpy.context)
    assert len(lines) == 1 and lines[0].startswith("Box: held") and "slips first" in lines[0], lines
    force = bpy.data.objects["GL Force Box"]
    assert force["gl_held"] == 1.0
    scene.frame_set(scene.frame_start)
    assert ui.baked_frame_lines(bpy.context) == ["No finger on a body"]
    # the baked measures say what they are, with units (their tooltips)
    assert "N" in force.id_properties_ui("gl_grip").as_dict()["description"]


def test_state_lines_go_on_file_load_and_undo(bpy, sample, core):
    """The last session's summary and Check's result describe the file they were made in:
    another file loaded, or the session undone, and they go."""
    session, ops = grasp_env.submodule("session"), grasp_env.submodule("ops")
    sample.build(bpy)
    assert bpy.ops.grasp_lab.session(duration=0.5) == {"FINISHED"}
    assert session.last_result is not None and session.last_result.verdict
    assert session.last_result.scene_name == bpy.context.scene.name
    session._on_undo_post()                                # what Blender calls after an undo
    assert session.last_result is None
    assert bpy.ops.grasp_lab.session(duration=0.5) == {"FINISHED"}
    bpy.ops.grasp_lab.validate_scene()                     # after the session: kept until...
    assert bpy.context.scene.name in ops.last_check and session.last_result is not None
    bpy.ops.wm.read_homefile(use_empty=True)               # ...another file: the handlers run
    assert session.last_result is None and ops.last_check == {}
