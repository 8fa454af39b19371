"""`make demo`, Blender part (sample_scenes/demo_session.py), in a temporary directory:
the outputs exist and are sane."""
import csv
import importlib.util
import io
import os

import numpy as np
import pytest

import grasp_env


def _demo_module():
    path = os.path.join(grasp_env.ROOT, "sample_scenes", "demo_session.py")
    spec = importlib.util.spec_from_file_location("demo_session", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _fcurves(bpy, obj):
    ad = obj.animation_data
    if bpy.app.version >= (4, 4, 0):
        from bpy_extras import anim_utils
        return anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot).fcurves
    return ad.action.fcurves


@pytest.mark.multiversion
def test_demo_outputs(bpy, sample, core, tmp_path):
    demo = _demo_module()
    out = io.StringIO()
    result = demo.run(bpy, tmp_path / "demo", stream=out)
    paths = result["paths"]
    assert sorted(paths) == ["blend", "csv", "png", "recording"]
    for p in paths.values():
        assert os.path.dirname(p) == str(tmp_path / "demo") and os.path.getsize(p) > 0
    text = out.getvalue()
    assert "back on the table" in text and "pinch_and_lift.blend" in text
    n = sample.KEYS[-1][0] - sample.KEYS[0][0] + 1          # frames 1..145

    # The CSV: one row per frame; rests on the table, lifted, ends on the table (within 1 mm
    # of where it started, 10 cm further along y).
    with open(paths["csv"]) as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == n and [int(r["frame"]) for r in rows] == list(range(1, n + 1))
    z = np.array([float(r["box_z"]) for r in rows])
    assert z[0] == pytest.approx(sample.BOX_Z, abs=1e-5)
    assert abs(z[-1] - z[0]) < 1e-3
    assert z.max() > sample.BOX_Z + sample.LIFT - 0.001
    assert float(rows[-1]["box_y"]) == pytest.approx(sample.CARRY, abs=1e-3)
    states = [(r["finger0"], r["finger1"]) for r in rows]
    assert states[0] == ("free", "free") and states[-1] == ("free", "free")
    assert states[sample.MID_LIFT_FRAME - 1] == ("stick", "stick")
    assert float(rows[sample.MID_LIFT_FRAME - 1]["grip_N"]) == pytest.approx(
        sample.STIFFNESS * sample.SQUEEZE, rel=0.05)

    # The recording: every haptic tick (tick 0 is the start), both bodies and fingers; the
    # tick each frame shows has the box where the CSV has it.
    recording = grasp_env.submodule("engine.recording")
    rec = recording.open_recording(paths["recording"])
    assert rec.damage == [] and rec.end["overflow"] == 0
    n_ticks = round((n - 1) / sample.FPS * 1000) + 1
    assert len(rec.ticks) == n_ticks
    np.testing.assert_array_equal(rec.ticks["tick"], np.arange(n_ticks))
    assert rec.body_names == ["Box", "Table"] and rec.ticks["pose"].shape == (n_ticks, 2, 7)
    assert rec.ticks["hip"].shape == rec.ticks["god_object"].shape == (n_ticks, 2, 3)
    at_frames = rec.ticks[rec.sample(np.arange(n) / sample.FPS)]
    np.testing.assert_allclose(at_frames["pose"][:, 0, 2], z, atol=1e-9)   # the CSV has 9 decimals
    np.testing.assert_allclose(at_frames["time"], np.floor(np.arange(n) / sample.FPS * 1000 + 1e-9) / 1000,
                               atol=1e-9)

    # The render: a 960 x 600 PNG that is not blank.
    img = bpy.data.images.load(paths["png"])
    assert tuple(img.size) == (960, 600)
    px = np.empty(960 * 600 * 4, dtype=np.float32)
    img.pixels.foreach_get(px)
    assert px.reshape(-1, 4)[:, :3].std() > 0.05

    # The .blend reloads with a keyframe per frame on the box, following the trajectory.
    bpy.ops.wm.open_mainfile(filepath=paths["blend"])
    scene = bpy.context.scene
    assert scene.frame_current == sample.MID_LIFT_FRAME
    box = bpy.data.objects["Box"]
    fc = {(f.data_path, f.array_index): f for f in _fcurves(bpy, box)}
    assert len(fc[("location", 2)].keyframe_points) == n
    for frame in (1, sample.MID_LIFT_FRAME, 100, n):
        scene.frame_set(frame)
        assert box.matrix_world.translation.z == pytest.approx(z[frame - 1], abs=1e-6)
    for name in ("GL God-object Finger 0", "GL Force Box", "Finger Force 1"):
        assert len(_fcurves(bpy, bpy.data.objects[name])[0].keyframe_points) == n
