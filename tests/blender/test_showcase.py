"""`make demo`, showcase part (sample_scenes/showcase.py) on four scenes, in a temporary
directory: every file the index page names exists, the table says what physics says, the
baked files reopen with their curves and their sound, the pinch and lift's video carries its sound."""
import csv
import importlib.util
import io
import os
import re

import numpy as np
import pytest

import grasp_env
import media

SCENES = ["pinch_and_lift", "tripod_pencil", "weak_grip_slide", "plate_palm"]


def _showcase():
    path = os.path.join(grasp_env.ROOT, "sample_scenes", "showcase.py")
    spec = importlib.util.spec_from_file_location("showcase_under_test", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _png_size(path):
    with open(path, "rb") as fh:
        head = fh.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n", path
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def _fcurves(bpy, obj):
    ad = obj.animation_data
    if bpy.app.version >= (4, 4, 0):
        from bpy_extras import anim_utils
        return anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot).fcurves
    return ad.action.fcurves


@pytest.fixture(scope="module")
def demo(tmp_path_factory, ext):
    import bpy
    out = tmp_path_factory.mktemp("demo")
    stream = io.StringIO()
    res = _showcase().run(bpy, out, SCENES, stream=stream)
    return out, res, stream.getvalue()


def test_index_names_only_files_that_exist(demo):
    out, res, text = demo
    page = (out / "index.html").read_text()
    links = re.findall(r"(?:src|href)='([^']+)'", page)
    assert "contact_sheet.png" in links
    for name in SCENES:
        for f in (f"scenes/{name}.blend", f"scenes/{name}.png", f"recordings/{name}.mcap",
                  f"plots/{name}.png", f"analysis/{name}/grasp.csv", f"analysis/{name}/contacts.csv"):
            assert f in links, f
    for link in links:
        assert (out / link).is_file() and (out / link).stat().st_size > 0, link
    # Progress per scene, then the table, as printed
    for k, name in enumerate(SCENES, 1):
        assert f"[{k}/{len(SCENES)}] {name}:" in text
    assert (out / "summary.txt").read_text().splitlines()[0].split()[:2] == ["scene", "outcome"]


def test_pictures(demo, bpy):
    out, res, _ = demo
    assert _png_size(out / "contact_sheet.png") == (4 * 480, 336)      # one row of four
    for name in SCENES:
        path = str(out / "scenes" / f"{name}.png")
        assert _png_size(path) == (480, 300)
        img = bpy.data.images.load(path)
        px = np.empty(480 * 300 * 4, dtype=np.float32)
        img.pixels.foreach_get(px)
        rgb = px.reshape(-1, 4)[:, :3]
        assert rgb.std() > 0.05
        # the finger-force arrows' orange is in the picture, lit or in a body's shadow (the
        # plate's over the palm's arrow): its hue, g 0.6-0.8 of r and b below 0.3 of r (not the
        # skin of a palm, not a yellow god-object)
        r, g, b = rgb.T
        assert ((r > 0.3) & (b < 0.3 * r) & (g > 0.6 * r) & (g < 0.8 * r)).sum() > 20, name
        w, h = _png_size(out / "plots" / f"{name}.png")
        assert w >= 600 and h >= 300


def test_table_says_what_physics_says(demo):
    out, res, _ = demo
    rows = {r[0]: r for r in res["rows"]}
    entries = {e["name"]: e for e in res["entries"]}
    assert all(not e["failures"] for e in entries.values())
    assert rows["pinch_and_lift"][1] == "held" and rows["weak_grip_slide"][1] == "slides out"
    # The plate on the palm (an area contact) stays where it lies on it.
    assert rows["plate_palm"][1] == "held" and float(rows["plate_palm"][2].split()[0]) < 5.0
    # Two point contacts never close a grasp (nothing resists turning about the line through
    # them); three fingertips round the pencil do, all the time they hold it.
    assert rows["pinch_and_lift"][4] == "0 % of held" and rows["pinch_and_lift"][5] == "0"
    assert rows["tripod_pencil"][4] == "100 % of held"
    assert float(rows["tripod_pencil"][5].split()[0]) > 0
    # A sticking grip slides no god-object over the surface; the weak grip lets the box slide
    # out: its god-objects slide along it by centimetres.
    slip = {n: float(rows[n][3].split()[0]) for n in SCENES}
    assert slip["tripod_pencil"] < 0.05 and slip["pinch_and_lift"] < 0.5
    assert slip["weak_grip_slide"] > 10.0
    # The plotted load, from grasp-lab analyze: held still mid-hold, the pencil's weight
    # (10 g), and the grip the sum of the normal forces of contacts.csv at those ticks.
    e = entries["tripod_pencil"]
    g = e["grasp"]
    sc = e["scene"]
    hold = sc.frames_of("hold")
    t0, t1 = (hold[0] + 6 - 1) / 24, (hold[len(hold) // 2] - 1) / 24
    mid = (g["time"] > t0) & (g["time"] < t1)
    assert mid.sum() > 20
    assert np.median(g["load_force"][mid]) == pytest.approx(0.010 * 9.81, rel=0.02)
    with open(os.path.join(e["paths"]["analysis"], "contacts.csv")) as fh:
        fn = {}
        for row in csv.DictReader(fh):
            fn[float(row["time"])] = fn.get(float(row["time"]), 0.0) + float(row["fn"])
    for t, grip in zip(g["time"][mid], g["grip_force"][mid]):
        assert grip == pytest.approx(fn[t], rel=1e-9)
    # Rates: the target, and steps per wall second above it (EXEC runs faster than real time)
    assert rows["tripod_pencil"][7] == "1000 Hz" and float(rows["tripod_pencil"][8]) > 1000


def test_baked_file_reopens_with_its_curves(demo, bpy):
    out, res, _ = demo
    e = next(x for x in res["entries"] if x["name"] == "tripod_pencil")
    bpy.ops.wm.open_mainfile(filepath=str(out / "scenes" / "tripod_pencil.blend"))
    scene = bpy.context.scene
    assert scene.frame_current == e["frame"]
    n = e["scene"].frame_end - e["scene"].keys[0].frame + 1
    curves = {f.data_path for f in _fcurves(bpy, bpy.data.objects["GL Force Pencil"])}
    for prop in ("gl_closure", "gl_epsilon", "gl_grip", "gl_held"):
        assert f'["{prop}"]' in curves
    for j in range(3):
        assert len(_fcurves(bpy, bpy.data.objects[f"Finger Force {j}"])[0].keyframe_points) == n
    scene.frame_set(e["frame"])
    assert bpy.data.objects["GL Force Pencil"]["gl_closure"] == pytest.approx(1.0)
    # The rendered frame's god-objects have that frame's friction-use colour, not the blue of
    # a finger touching nothing (the session's end).
    grasp_display = grasp_env.submodule("engine.grasp_display")
    for j in range(3):
        go = bpy.data.objects[f"GL God-object {e['scene'].fingers[j].name}"]
        colour = tuple(go.material_slots[0].material.diffuse_color)
        assert colour != pytest.approx(grasp_display.FREE_COLOR)
        np.testing.assert_allclose(colour, grasp_display.friction_color(go["gl_friction_use"]), atol=0.02)


def test_every_scene_has_its_sound_and_the_pinch_video_carries_it(demo):
    out, res, _ = demo
    sound = grasp_env.submodule("engine.sound")
    for name in SCENES:
        samples, rate = sound.read_wav((out / "scenes" / f"{name}.wav").read_bytes())
        assert np.abs(samples).max() > 0.05, name      # every scene touches: clicks and tones
    page = (out / "index.html").read_text()
    assert "src='scenes/pinch_and_lift.mp4'" in page
    track = media.sound_track((out / "scenes" / "pinch_and_lift.mp4").read_bytes())
    entry = next(e for e in res["entries"] if e["name"] == "pinch_and_lift")
    expected = entry["video_frames"] * 48000 // 24
    assert entry["video_frames"] >= 140                 # the whole pinch and lift (6 s at 24 fps)
    assert track["codec"] == b"mp4a" and track["rate"] == 48000
    assert expected <= track["duration"] < expected + 8192      # AAC in Blender's blocks of 8192 samples
