"""Device Fit in Blender (addon/device_fit.py, docs/devices.md): a device profile added to the scene gets a
workspace frame; the fingertip animation is checked against its workspace at that frame (what the
viewport colours red and the HUD says), against the animation sampled here independently; moving and
turning the frame changes the answer; *Fit Devices* on the scene's recording writes what
``grasp-lab fit`` finds."""
import math

import numpy as np
import pytest

import grasp_env
from test_scene_library import lib


def _finger_path(bpy):
    """The fingertips' world positions at every frame, read here (not through the add-on)."""
    scene = bpy.context.scene
    tips = sorted((o for o in scene.objects if o.grasp_lab.role == "FINGER"),
                  key=lambda o: (o.grasp_lab.channel, o.name))
    frames = range(scene.frame_start, scene.frame_end + 1)
    pos = []
    for f in frames:
        scene.frame_set(f)
        pos.append([tuple(o.matrix_world.translation) for o in tips])
    scene.frame_set(scene.frame_start)
    fps = scene.render.fps / scene.render.fps_base
    return [o.name for o in tips], (np.array(frames) - scene.frame_start) / fps, np.array(pos)


def test_the_workspace_at_its_frame_says_who_leaves_when_and_a_turned_frame_holds_it(bpy):
    fit_ui = grasp_env.submodule("device_fit")
    lib.build(bpy, "pinch_and_lift")
    scene = bpy.context.scene
    scene.cursor.location = (0.0, 0.0, 0.0)
    scene.grasp_lab_fit_choice = "touch"
    assert bpy.ops.grasp_lab.fit_device_add() == {"FINISHED"}
    entry = scene.grasp_lab_fit_devices[0]
    assert entry.profile == "touch" and entry.frame is not None and entry.frame.type == "EMPTY"
    names, times, pos = _finger_path(bpy)
    # the Touch's box (160 x 70 x 120 mm) about the frame at the origin: the first frame finger 0 is out
    half = np.array([0.08, 0.035, 0.06])
    out = np.any(np.abs(pos[:, 0]) > half + 1e-9, axis=1)
    assert out.any()
    first = int(np.argmax(out))
    assert fit_ui.hud_lines(scene) == [f"touch: {names[0]} leaves its workspace at {times[first]:.2f} s"]
    # put the frame at the middle of finger 0's path, turned a quarter about z: the 10 cm carry along y
    # then runs along the box's 16 cm; the path's extents fit, so nobody leaves
    lo, hi = pos[:, 0].min(axis=0), pos[:, 0].max(axis=0)
    assert hi[1] - lo[1] > 0.07 and hi[0] - lo[0] < 0.07 and hi[1] - lo[1] < 0.16 and hi[2] - lo[2] < 0.12
    entry.frame.location = (lo + hi) / 2
    entry.frame.rotation_euler = (0.0, 0.0, math.pi / 2)
    bpy.context.view_layer.update()
    assert fit_ui.hud_lines(scene) == ["touch: every finger stays in its workspace"]
    # unturned at the same place, the carry leaves the box's 70 mm depth
    entry.frame.rotation_euler = (0.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    line, = fit_ui.hud_lines(scene)
    assert line.startswith(f"touch: {names[0]} leaves its workspace at ")
    # a finger the scene does not have is said, not drawn
    entry.fingers = "Thumb"
    assert "no finger 'Thumb'" in fit_ui.hud_lines(scene)[0]


def test_fit_devices_writes_under_the_button_what_grasp_lab_fit_finds(bpy, core, tmp_path):
    fit_ui = grasp_env.submodule("device_fit")
    fit = grasp_env.submodule("engine.fit")
    recording = grasp_env.submodule("engine.recording")
    lib.build(bpy, "pinch_and_lift")
    scene = bpy.context.scene
    scene.grasp_lab_fit_choice = "omega3"
    bpy.ops.grasp_lab.fit_device_add()
    scene.grasp_lab_fit_choice = "chapter_rig"
    bpy.ops.grasp_lab.fit_device_add()
    # no recording yet: said under the button
    scene.grasp_lab.recording_folder = str(tmp_path / "none")
    with pytest.raises(RuntimeError, match="Fit Devices: no recording yet"):     # its ERROR report, headless
        bpy.ops.grasp_lab.fit_devices()
    assert scene.grasp_lab_fit_report == "Fit Devices: no recording yet: run the scene with Record on first"
    s = scene.grasp_lab
    s.record = True
    s.recording_folder = str(tmp_path)
    lib.run(bpy)
    rec = recording.open_recording(bpy.path.abspath(s.last_recording))
    scene.grasp_lab_fit_devices[0].fingers = rec.finger_names[0]      # the omega.3 takes the first finger
    assert bpy.ops.grasp_lab.fit_devices() == {"FINISHED"}
    lines = scene.grasp_lab_fit_report.split("\n")
    _, results = fit.fit_recording(rec, [f"omega3:{rec.finger_names[0]}", "chapter_rig"])   # frames at the origin
    assert lines[1:] == fit.report_lines(results)
    assert any(line.startswith("chapter_rig: fails") for line in lines)
    # the entries' frames count: the omega.3's frame moved where its best placement is gives "fits"
    omega = next(r for r in results if r.profile.name == "omega3")
    assert omega.verdict == "placed"
    entry = scene.grasp_lab_fit_devices[0]
    entry.frame.location = tuple(omega.placement.translation)
    bpy.context.view_layer.update()
    bpy.ops.grasp_lab.fit_devices()
    assert "omega3: fits" in scene.grasp_lab_fit_report.split("\n")
    assert fit_ui.fit_devices(bpy.context)[1:] == scene.grasp_lab_fit_report.split("\n")[1:]


def test_the_docs_table_row_of_a_library_scene_is_what_make_fit_table_computes(bpy, core, tmp_path):
    """docs/devices.md's table is made by `make fit-table`, not by hand: one scene's row, computed again
    here the same way (the scene run and recorded, each profile evaluated), is the row in the docs."""
    import importlib.util
    import os
    spec = importlib.util.spec_from_file_location("fit_table", os.path.join(grasp_env.ROOT, "sample_scenes",
                                                                           "fit_table.py"))
    fit_table = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fit_table)
    fit = grasp_env.submodule("engine.fit")
    profiles = grasp_env.submodule("engine.devices.device_profiles").load_all()
    recording = grasp_env.submodule("engine.recording")
    path = fit_table.record_scene(bpy, lib, "pinch_and_lift", str(tmp_path))
    task = fit.task_from_recording(recording.open_recording(path))
    row = "| `pinch_and_lift` | " + " | ".join(fit_table.cell(task, p, fit) for p in profiles) + " |"
    with open(os.path.join(grasp_env.ROOT, "docs", "devices.md")) as fh:
        doc = fh.read()
    table = doc[doc.index(fit_table.BEGIN):doc.index(fit_table.END)]
    assert "| scene | " + " | ".join(f"`{p.name}`" for p in profiles) + " |" in table
    assert row in table.splitlines(), (row, table)
