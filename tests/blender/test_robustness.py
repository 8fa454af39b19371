"""The Robustness panel's sweep (addon/robustness.py, addon/engine/background_sweep.py) on a real
bpy: the operator starts a sweep of the last recording in a background process and returns at
once; the timer function, driven here by hand as Blender's timers would, shows its progress, and
at the end the summary and the map; Cancel ends the process and keeps the finished samples, and
Run again resumes them. The map drawn without matplotlib (as in Blender) read back pixel by pixel."""
import csv
import os
import time
import types

import numpy as np
import pytest

import grasp_env
import recordings
from addon.engine import recording, sweep
from addon.engine.background_sweep import panel_varies, sweep_folder


@pytest.fixture(scope="module")
def pinch(core, tmp_path_factory):
    path = tmp_path_factory.mktemp("robustness") / "pinch.mcap"
    recordings.record_exec(path, core, seconds=3.0)
    return str(path)


def rows_in(folder):
    with open(os.path.join(folder, "samples.csv"), newline="") as fh:
        return list(csv.DictReader(fh))


def tick_until(module, done, seconds=240.0):
    """Call the timer function as Blender's timer would, until ``done()`` or it unregisters."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        again = module.sweep_tick()
        if done() or again is None:
            return again
        time.sleep(0.05)
    raise AssertionError("the sweep did not get there in time")


def test_panel_keys_become_sweep_specs_on_the_held_body(pinch):
    rec = recording.open_recording(pinch)
    mass = rec.header["scene"]["bodies"][0]["mass"]
    specs = panel_varies(rec, friction=(0.3, 0.9), mass=(0.5, 2.0), hip_noise=0.002, push=(0.0, 4.0, 1.5))
    assert specs == ["Box.mu_s=0.3:0.9", f"Box.mass={mass * 0.5:.6g}:{mass * 2.0:.6g}", "hip_noise=0.002",
                     "push=0:4@1.5"]
    with pytest.raises(sweep.SweepError, match="at least one"):
        panel_varies(rec)
    with pytest.raises(sweep.SweepError, match="mu_s"):
        panel_varies(rec, friction=(0.9, 0.3))
    assert sweep_folder(pinch, specs, 10, 0) == sweep_folder(pinch, list(specs), 10, 0)
    assert sweep_folder(pinch, specs, 10, 0) != sweep_folder(pinch, specs, 10, 1)


def test_the_map_without_matplotlib(tmp_path):
    """Grid axes mu_s (3 values) x mass (2): held only where mu_s > 0.5, one cell never sampled;
    the PNG read back has red, green and grey cells where they belong (y up)."""
    import matplotlib.image
    job = types.SimpleNamespace(varies=[sweep.parse_vary("Box.mu_s=0.2,0.6,1.0"),
                                        sweep.parse_vary("Box.mass=0.1,0.2")])
    cols = [v.column for v in job.varies]
    rows = [{cols[0]: mu, cols[1]: m, "held": mu > 0.5} for mu in (0.2, 0.6, 1.0) for m in (0.1, 0.2)
            if (mu, m) != (1.0, 0.2)] * 2
    rgb = sweep.plain_map(job, rows)
    assert rgb.shape == (64, 96, 3) and rgb.dtype == np.uint8
    path = str(tmp_path / "map.png")
    sweep.write_png(path, rgb)
    back = (matplotlib.image.imread(path)[..., :3] * 255).round().astype(np.uint8)
    np.testing.assert_array_equal(back, rgb)
    cell = lambda x, y: tuple(back[63 - (32 * y + 16), 32 * x + 16])    # noqa: E731 (x right, y up)
    red, green, grey = (215, 48, 39), (26, 152, 80), (128, 128, 128)
    assert cell(0, 0) == cell(0, 1) == red
    assert cell(1, 0) == cell(1, 1) == cell(2, 0) == green
    assert cell(2, 1) == grey


def test_run_sweep_to_the_end(bpy, core, pinch):
    robustness = grasp_env.submodule("robustness")
    scene = bpy.context.scene
    scene.grasp_lab.last_recording = pinch
    r = scene.grasp_lab_robustness
    r.samples, r.seed, r.workers = 6, 3, 2
    started = time.monotonic()
    assert bpy.ops.grasp_lab.robustness_sweep() == {"FINISHED"}
    assert time.monotonic() - started < 5.0             # it returned: the sweep runs elsewhere
    job = robustness._jobs[scene.name]
    assert job.running and not bpy.ops.grasp_lab.robustness_sweep.poll()     # one at a time
    seen = []
    tick_until(robustness, lambda: seen.append(r.progress) or not job.running)
    assert job.finished and not job.error, job.error
    assert r.progress == 1.0 and r.status.startswith("Held ") and " of 6: p = " in r.status
    assert sorted(seen) == seen                          # the bar only goes forwards
    assert os.path.basename(r.map_path) == "map.png" and os.path.isfile(r.map_path)
    assert len(rows_in(job.folder)) == 6
    assert r.axes.startswith("→: Box.mu_s=0.2:1   ↑: Box.mass=")
    assert tick_until(robustness, lambda: False) is None     # its process collected: the timer goes
    assert robustness.map_icon(r.map_path) >= 0          # loads (0 only without a GPU preview)
    # no zombie: the child was collected; only results in the results folder (no engine zip)
    assert job._proc.returncode == 0 and job._scratch is None
    assert not [f for f in os.listdir(job.folder) if f.endswith(".zip")], os.listdir(job.folder)


def test_the_panel_picks_its_recording_from_a_list_with_verdicts(bpy, core, pinch, tmp_path):
    """The scene's recordings, newest first, each with what it holds; a recording that holds
    nothing says so; the one picked is the one swept, and it stays picked as new ones arrive."""
    import shutil
    robustness = grasp_env.submodule("robustness")
    scene = bpy.context.scene
    scene.grasp_lab.recording_folder = str(tmp_path)
    scene.grasp_lab.last_recording = ""
    assert robustness.chosen_recording(scene) == ""
    older = str(tmp_path / "pinch_old.mcap")
    shutil.copy(pinch, older)
    os.utime(older, (time.time() - 60, time.time() - 60))
    newer = str(tmp_path / "pinch_new.mcap")
    shutil.copy(pinch, newer)
    assert robustness.scene_recordings(scene) == [newer, older]
    assert robustness.chosen_recording(scene) == newer                    # nothing picked: the newest
    assert robustness.recording_verdict(newer).startswith("holds Box ")
    items = robustness._recording_items(None, bpy.context)
    assert [i[0] for i in items] == ["NEWEST", newer, older] and items[1][1].startswith("pinch_new.mcap: holds Box ")
    assert items[0][1] == "Newest recording"
    r = scene.grasp_lab_robustness
    r.recording = older
    assert robustness.chosen_recording(scene) == older
    newest = str(tmp_path / "pinch_newest.mcap")
    shutil.copy(pinch, newest)
    robustness._recording_items(None, bpy.context)
    assert r.recording == older and robustness.chosen_recording(scene) == older   # still the one picked
    (tmp_path / "broken.mcap").write_bytes(b"not a recording")
    assert robustness.recording_verdict(str(tmp_path / "broken.mcap")).startswith("unreadable")


def test_cancel_keeps_the_finished_samples_and_run_resumes(bpy, core, pinch):
    robustness = grasp_env.submodule("robustness")
    scene = bpy.context.scene
    scene.grasp_lab.last_recording = pinch
    r = scene.grasp_lab_robustness
    r.samples, r.seed, r.workers = 2000, 5, 1
    r.vary_hip_noise = True
    assert bpy.ops.grasp_lab.robustness_sweep() == {"FINISHED"}
    job = robustness._jobs[scene.name]
    tick_until(robustness, lambda: job.done >= 3)
    assert bpy.ops.grasp_lab.robustness_cancel() == {"FINISHED"}
    assert job._proc.poll() is not None                  # the process is gone
    assert job.cancelled and r.status.startswith(f"Cancelled at {job.done} of 2000")
    assert not bpy.ops.grasp_lab.robustness_cancel.poll() and bpy.ops.grasp_lab.robustness_sweep.poll()
    kept = len(rows_in(job.folder))
    assert job.done <= kept < 2000
    assert robustness.sweep_tick() is None

    assert bpy.ops.grasp_lab.robustness_sweep() == {"FINISHED"}     # the same sweep: resumed
    again = robustness._jobs[scene.name]
    assert again.folder == job.folder
    tick_until(robustness, lambda: again.total > 0)
    assert again.done >= kept                            # the kept samples were not run again
    again.cancel()
    robustness.sweep_tick()


def test_loading_a_file_ends_a_running_sweep(bpy, core, pinch):
    robustness = grasp_env.submodule("robustness")
    scene = bpy.context.scene
    scene.grasp_lab.last_recording = pinch
    r = scene.grasp_lab_robustness
    r.samples, r.seed, r.workers = 2000, 11, 1
    assert bpy.ops.grasp_lab.robustness_sweep() == {"FINISHED"}
    job = robustness._jobs[scene.name]
    bpy.ops.wm.read_homefile(use_empty=True)
    assert job.cancelled and job._proc.poll() is not None and not robustness._jobs
