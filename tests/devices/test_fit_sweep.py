"""``grasp-lab sweep --vary device=...``: each sample's re-simulated task evaluated against its device
(engine/sweep.py device_outcomes, engine/fit.py), a grid axis like any other."""
import csv
import io
import json
import os
import sys

import graspcore

from addon.engine import cli, fit
from addon.engine.recording import open_recording

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "blender"))
import recordings  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_a_sweep_over_devices_says_per_sample_and_per_device_which_renders_it(tmp_path):
    rec_path = tmp_path / "pinch.mcap"
    recordings.record_exec(rec_path, graspcore, seconds=6.0)
    # a rig like the chapter's with motors rated for the pinch's squeeze held for seconds
    strong = tmp_path / "strong_rig.toml"
    strong.write_text(open(os.path.join(ROOT, "addon/engine/devices/profiles/chapter_rig.toml")).read()
                      .replace("continuous_force = 1.4", "continuous_force = 8.0"))
    out, err = io.StringIO(), io.StringIO()
    code = cli.main(["sweep", str(rec_path), "--samples", "1", "--vary", f"device=chapter_rig,{strong}",
                     "--out", str(tmp_path / "sweep"), "--workers", "1", "--no-analysis"], out=out, err=err)
    assert code == 0, err.getvalue()
    rows = list(csv.DictReader(open(tmp_path / "sweep" / "samples.csv")))
    assert [r["device"] for r in rows] == ["0.0", "1.0"]
    # nothing else varied: each sample replays the recording exactly, so its verdict is the recording's
    rec = open_recording(str(rec_path))
    _, (rig,) = fit.fit_recording(rec, ["chapter_rig"])
    assert rig.verdict == "fails"
    assert (rows[0]["device_fits"], float(rows[0]["device_fail_time"])) == \
        ("0", min(f.first_fail_time for f in rig.fingers))
    assert (rows[1]["device_fits"], rows[1]["device_fail_time"]) == ("1", "")
    summary = json.loads((tmp_path / "sweep" / "summary.json").read_text())
    assert summary["devices"] == {"chapter_rig": {"samples": 1, "fits": 0}, str(strong): {"samples": 1, "fits": 1}}
    assert "device chapter_rig       renders 0 of its 1 samples" in out.getvalue()


def test_an_unknown_device_in_a_sweep_is_one_line(tmp_path):
    rec_path = tmp_path / "pinch.mcap"
    recordings.record_exec(rec_path, graspcore, seconds=2.0)
    out, err = io.StringIO(), io.StringIO()
    code = cli.main(["sweep", str(rec_path), "--samples", "1", "--vary", "device=touch,phantom9",
                     "--out", str(tmp_path / "sweep"), "--workers", "1"], out=out, err=err)
    assert code == 1
    assert err.getvalue().count("\n") == 1 and "unknown device profile 'phantom9'" in err.getvalue(), err.getvalue()
