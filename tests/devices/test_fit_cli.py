"""``grasp-lab fit`` on real recordings (made by the core, as a session records them): the verdicts in the
terminal, --json in the documented shape, --csv's timeline, --list, and bad input as one line each."""
import csv
import io
import json
import os
import subprocess
import sys

import graspcore
import numpy as np

from addon.engine import cli, fit
from addon.engine.recording import open_recording

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "blender"))
import recordings  # noqa: E402  (tests/blender/recordings.py: sessions recorded in plain Python)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def run(*argv):
    out, err = io.StringIO(), io.StringIO()
    code = cli.main(list(argv), out=out, err=err)
    return code, out.getvalue(), err.getvalue()


def test_fit_on_the_pinch_recording_ranks_devices_and_writes_json_and_csv(tmp_path):
    rec_path = tmp_path / "pinch.mcap"
    recordings.record_exec(rec_path, graspcore, seconds=6.0)
    code, out, err = run("fit", str(rec_path), "--device", "touch", "--device", "chapter_rig:Finger 0,Finger 1",
                         "--device", "omega3:Finger 1", "--json", str(tmp_path / "v.json"), "--csv", str(tmp_path / "m"))
    assert code == 0, err
    doc = json.loads((tmp_path / "v.json").read_text())
    assert set(doc) == {"profiles"}
    assert sorted(p["profile"] for p in doc["profiles"]) == ["chapter_rig", "omega3", "touch"]
    for p in doc["profiles"]:
        for f in p["fingers"]:
            assert set(f) == {"finger", "verdict", "first_fail_time", "cause"}
            assert f["verdict"] in ("fits", "placed", "fails")
            assert (f["first_fail_time"] is None) == (f["verdict"] != "fails")
    # the command says what the engine finds on the same recording
    rec = open_recording(str(rec_path))
    _, results = fit.fit_recording(rec, ["touch", "chapter_rig:Finger 0,Finger 1", "omega3:Finger 1"])
    assert doc == fit.result_json(results)
    by = {p["profile"]: p for p in doc["profiles"]}
    # the Touch takes Finger 0 only: Finger 1 has no end-effector
    assert by["touch"]["fingers"][1] == {"finger": "Finger 1", "verdict": "fails", "first_fail_time": 0.0,
                                         "cause": "no end-effector (the device has 1)"}
    # the pinch (10 cm lift, 10 cm carry) stays in the chapter's rig's workspaces, but its ~3 N squeeze
    # held for seconds is above the Phantoms' 1.4 N continuous rating: both fingers fail on the duty
    assert [f["cause"].split()[0] for f in by["chapter_rig"]["fingers"]] == ["duty", "duty"]
    assert out.splitlines()[0].startswith(f"{rec_path}: 2 fingers (Finger 0, Finger 1), {len(rec.ticks)} ticks")
    rows = list(csv.reader(open(tmp_path / "m" / "margins.csv")))
    assert rows[0] == fit.MARGIN_COLUMNS
    assert len(rows) - 1 == len(rec.ticks) * (1 + 2 + 1)       # touch 1, chapter_rig 2, omega3 1 finger
    # the margins written are the ones that decided: where no finger leaves the workspace, no workspace
    # margin is negative; the duty margin turns negative at the tick the verdict gives
    for p in doc["profiles"]:
        ws = [float(r[3]) for r in rows[1:] if r[0] == p["profile"]]
        assert min(ws) >= -1e-9
    duty = [(float(r[1]), float(r[5])) for r in rows[1:] if r[0] == "chapter_rig" and r[2] == "Finger 0"]
    first_negative = next(t for t, m in duty if m < -1e-9)
    assert first_negative == by["chapter_rig"]["fingers"][0]["first_fail_time"]


def test_a_recorded_free_finger_leaving_the_box_fails_where_its_recorded_path_says(tmp_path):
    # one fingertip in free space rising at 0.1 m/s: the Touch's box (0.12 m high) holds the recorded
    # path until its height range passes 0.12 m, read here from the recording itself
    desc, S = recordings.pinch_desc()
    desc.fingers = desc.fingers[:1]
    start = np.array([0.0, 0.3, 0.3])          # far from the box and the table

    def path(t):
        return (start + [0.0, 0.0, 0.1 * max(t - 0.2, 0.0)])[None, :]
    rec_path = tmp_path / "rise.mcap"
    recordings.record_scene(rec_path, graspcore, desc, path, seconds=2.0)
    rec = open_recording(str(rec_path))
    z = rec.ticks["hip"][:, 0, 2]
    span = np.maximum.accumulate(z) - np.minimum.accumulate(z)
    expected = int(np.nonzero(span > 0.12 + 1e-9)[0][0])
    code, out, err = run("fit", str(rec_path), "--device", "touch", "--json", str(tmp_path / "v.json"))
    assert code == 0, err
    f = json.loads((tmp_path / "v.json").read_text())["profiles"][0]["fingers"][0]
    assert f["verdict"] == "fails" and f["first_fail_time"] == float(rec.ticks["time"][expected])
    assert f["cause"].startswith("leaves the workspace by ")
    assert f"Finger 0: fails at {rec.ticks['time'][expected]:.3f} s (tick {expected})" in out


def test_list_prints_every_profile_name_first():
    code, out, _ = run("fit", "--list")
    assert code == 0
    names = [line.split()[0] for line in out.splitlines()]
    assert {"touch", "touch_x", "falcon", "omega3", "sigma7", "inverse3", "chapter_rig", "three_finger"} <= set(names)


def test_bad_input_is_one_clear_line_each(tmp_path):
    rec_path = tmp_path / "pinch.mcap"
    recordings.record_exec(rec_path, graspcore, seconds=0.5)
    bad = tmp_path / "broken.toml"
    bad.write_text(open(os.path.join(ROOT, "addon/engine/devices/profiles/touch.toml")).read()
                   .replace("peak_force = 3.3", "peak_force = -3.3"))
    missing = tmp_path / "missing.toml"
    missing.write_text(open(os.path.join(ROOT, "addon/engine/devices/profiles/touch.toml")).read()
                       .replace("stable_stiffness = 1020.0", ""))
    cases = [
        (["--device", "phantom9"], "unknown device profile 'phantom9'"),
        (["--device", str(bad)], "field 'peak_force' must be positive, got -3.3"),
        (["--device", str(missing)], "field 'stable_stiffness' is missing"),
        (["--device", "touch:Finger 0,Finger 1"], "touch: 2 fingers given (Finger 0, Finger 1), the device has 1 "
                                                  "end-effector"),
        (["--device", "touch:Thumb"], "no finger 'Thumb' in the recording"),
        (["--frame", "1,2"], "--frame '1,2': expected X,Y,Z"),
        ([], "no device given"),
    ]
    for extra, message in cases:
        code, out, err = run("fit", str(rec_path), *extra)
        assert code == 1, (extra, out, err)
        assert err.count("\n") == 1 and err.startswith("grasp-lab fit: error: ") and message in err, err
    # through the installed command too: the exit code and the one line
    p = subprocess.run([os.path.join(ROOT, ".venv/bin/grasp-lab"), "fit", str(rec_path), "--device", "phantom9"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 1 and p.stderr.count("\n") == 1 and "unknown device profile 'phantom9'" in p.stderr
