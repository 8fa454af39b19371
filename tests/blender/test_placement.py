"""Set-up helpers' placement (addon/engine/placement.py) and recording names and folders
(addon/engine/recording/naming.py), in plain Python."""
import math
import os
import sys
import time

import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from addon.engine import placement  # noqa: E402
from addon.engine.recording import naming  # noqa: E402


def _cube(size, centre=(0.0, 0.0, 0.0)):
    h = size / 2
    return [(centre[0] + sx * h, centre[1] + sy * h, centre[2] + sz * h)
            for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]


def test_support_needed_only_for_dynamic_bodies_with_nothing_static_under_gravity():
    assert placement.needs_support(["DYNAMIC", "FINGER"], (0, 0, -9.81))
    assert not placement.needs_support(["DYNAMIC", "STATIC", "FINGER"], (0, 0, -9.81))
    assert not placement.needs_support(["DYNAMIC"], (0, 0, 0))           # weightless: nothing falls
    assert not placement.needs_support(["FINGER", "NONE"], (0, 0, -9.81))


def test_table_top_touches_the_bottom_of_the_default_cube():
    centre, dims = placement.table_under(_cube(2.0))          # Blender's 2 m cube at the origin
    top = centre[2] + dims[2] / 2
    assert top == pytest.approx(-1.0) and centre[:2] == (0.0, 0.0)
    assert dims == pytest.approx((6.0, 6.0, 0.4))
    # a pencil-sized body still gets a table a hand fits on
    centre, dims = placement.table_under(_cube(0.008, (0.1, 0.2, 0.05)))
    assert dims[0] == pytest.approx(placement.TABLE_MIN_SIDE) and centre[2] + dims[2] / 2 == pytest.approx(0.046)
    assert centre[:2] == pytest.approx((0.1, 0.2))
    with pytest.raises(ValueError, match="corners"):
        placement.table_under([])
    with pytest.raises(ValueError, match="finite"):
        placement.table_under([(0, 0, float("nan"))])


def test_workspace_frame_puts_the_devices_rest_ring_on_the_scenes_fingers():
    # two fingertips beside a 5 cm box: 3.3 cm from its centre, so the 6 cm ring is scaled 0.55
    origin, scale = placement.workspace_frame([(-0.033, 0, 0.025), (0.033, 0, 0.025)], (5, 5, 5))
    assert origin == pytest.approx((0, 0, 0.025)) and scale == pytest.approx(0.033 / 0.06)
    # the emulator's rest ring mapped by that frame lands on the fingertips
    for angle, finger in ((0.0, (0.033, 0, 0.025)), (math.pi, (-0.033, 0, 0.025))):
        ring = (placement.DEVICE_REST_RADIUS * math.cos(angle), placement.DEVICE_REST_RADIUS * math.sin(angle), 0)
        assert [o + scale * r for o, r in zip(origin, ring)] == pytest.approx(finger, abs=1e-12)
    # Blender's 2 m cube with 0.1 m fingertips beside it: scaled up, not a 6 cm ring inside it
    _, scale = placement.workspace_frame([(-1.1, 0, 0), (1.1, 0, 0)], (0, 0, 0))
    assert scale == pytest.approx(1.1 / 0.06)
    # no finger (the cursor), one finger (no spread), a finger at infinity: scale 1 / clamped
    assert placement.workspace_frame([], (5, 5, 5)) == ((5.0, 5.0, 5.0), 1.0)
    assert placement.workspace_frame([(1, 2, 3)], (5, 5, 5)) == ((1.0, 2.0, 3.0), 1.0)
    assert placement.workspace_frame([(0, 0, 0), (1e9, 0, 0)], (0, 0, 0))[1] == placement.FRAME_SCALES[1]
    assert placement.workspace_frame([(0, 0, float("nan"))], (5, 5, 5)) == ((5.0, 5.0, 5.0), 1.0)


def test_recordings_named_after_the_scene_and_the_time(tmp_path):
    when = time.mktime((2026, 12, 2, 2, 17, 45, 0, 0, -1))
    assert naming.recording_name("tripod_pencil", when) == "tripod_pencil_2026-12-02_02-17-45.mcap"
    assert naming.recording_name("My scene/1", when) == "My_scene_1_2026-12-02_02-17-45.mcap"
    assert naming.recording_name("///", when).startswith("recording_2026")
    # two sessions in one second: the second is not written over the first
    (tmp_path / "Scene_2026-12-02_02-17-45.mcap").write_bytes(b"")
    assert naming.recording_name("Scene", when, str(tmp_path)) == "Scene_2026-12-02_02-17-45_2.mcap"
    assert naming.scene_label("/x/tripod_pencil.blend", "Scene") == "tripod_pencil"
    assert naming.scene_label("", "Scene") == "Scene"


def test_an_unsaved_file_records_to_the_user_folder_never_the_working_directory():
    user = "/home/u/.config/blender/4.5/extensions/.user/user_default/grasp_lab/recordings"
    assert naming.recording_folder("//grasp_recordings/", "", user) == user
    assert naming.recording_folder("grasp_recordings", "", user) == user
    assert naming.recording_folder("//grasp_recordings/", "/p/scene.blend", user) == "/p/grasp_recordings"
    assert naming.recording_folder("/data/rec/", "", user) == "/data/rec"          # an absolute folder: as given
    assert naming.recording_folder("/data/rec", "/p/scene.blend", user) == "/data/rec"


def test_sweep_map_bins_adapt_to_the_sample_count():
    from addon.engine import sweep
    assert sweep.bin_count(50, 1) == 12 and sweep.bin_count(50, 2) == 3
    assert sweep.bin_count(400, 2) == 10 and sweep.bin_count(2000, 2) == sweep.MAX_BINS
    assert sweep.bin_count(3, 2) == 2 and sweep.bin_count(0, 1) == 2      # never a single cell
    for n in (50, 400, 2000):                 # about SAMPLES_PER_CELL a cell, or fewer cells
        assert n / sweep.bin_count(n, 2) ** 2 >= sweep.SAMPLES_PER_CELL
