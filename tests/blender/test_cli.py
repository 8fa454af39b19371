"""The grasp-lab command line (addon/engine/cli.py): every command end to end on the sample
scene through the venv launcher (a real process: bpy booted, the extension loaded), exit
codes 0 / 1 / 2 with messages naming the file, --help everywhere, a --realtime recording that
resim replays identically, a kill -9 during a --realtime recording then info and bake on what is left, and `blender -c grasp_lab`
registered in Blender."""
import csv
import io
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import grasp_env

sys.path.insert(0, grasp_env.ROOT)
from addon.engine import cli, recording  # noqa: E402

LAUNCHER = os.path.join(grasp_env.ROOT, ".venv", "bin", "grasp-lab")


def grasp_lab(*args, timeout=300):
    """The launcher `make` writes into the venv, as a user runs it."""
    return subprocess.run([LAUNCHER, *map(str, args)], capture_output=True, text=True, timeout=timeout)


def call(*args):
    """cli.main in this process: (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    code = cli.main([str(a) for a in args], out=out, err=err)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture()
def blend(bpy, sample, tmp_path):
    sample.build(bpy)
    path = tmp_path / "pinch.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


@pytest.fixture(scope="module")
def session(ext, tmp_path_factory):
    """`grasp-lab run` on the sample scene: the recording and the saved scene."""
    import bpy
    import recordings
    tmp = tmp_path_factory.mktemp("cli")
    bpy.ops.wm.read_homefile(use_empty=True)
    recordings.sample_module().build(bpy)
    scene = tmp / "pinch.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(scene))
    rec, out = tmp / "run.mcap", tmp / "after.blend"
    r = grasp_lab("run", scene, "--record", rec, "--save", out)
    assert r.returncode == 0, r.stderr
    return {"scene": scene, "recording": rec, "saved": out, "stdout": r.stdout, "tmp": tmp}


def test_launcher_help_everywhere():
    r = grasp_lab("--help")
    assert r.returncode == 0 and "usage: grasp-lab" in r.stdout
    for name in ("run", "info", "bake", "resim", "export", "analyze"):
        code, _, _ = call(name, "--help")
        assert code == 0
    assert set(cli.COMMANDS) >= {"run", "info", "bake", "resim", "export", "analyze", "devices", "emulate"}


@pytest.mark.parametrize("args", [
    (), ("frobnicate",), ("info",), ("export", "x.mcap"), ("export", "x.mcap", "--csv", "d", "--npz", "f"),
    ("export", "x.mcap", "--csv", "d", "--every", "0"), ("export", "x.mcap", "--wav", "a.wav", "--csv", "d"),
    ("resim", "x.mcap", "--set", "Box.mass"),
    ("resim", "x.mcap", "--tolerance", "-1"), ("run", "s.blend", "--set", "gravity=1,2"),
    ("bake", "x.mcap", "s.blend"), ("analyze",), ("analyze", "x.mcap", "--edges", "2"),
    ("analyze", "x.mcap", "--every", "0"),
])
def test_usage_errors_exit_2(args, capsys):
    assert cli.main(list(args)) == 2
    assert "usage:" in capsys.readouterr().err


def test_failures_exit_1_naming_the_file(tmp_path):
    code, _, err = call("info", tmp_path / "missing.mcap")
    assert code == 1 and "missing.mcap: no such file" in err
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not a recording at all" * 50)
    for command in (("info", junk), ("export", junk, "--npz", tmp_path / "x.npz"), ("resim", junk),
                    ("analyze", junk)):
        code, _, err = call(*command)
        assert code == 1 and "junk.mcap" in err and "not a readable Grasp Lab recording" in err


def test_run_records_every_tick_and_saves(session):
    assert "6.000 s simulated, 6000 ticks" in session["stdout"]
    rec = recording.open_recording(session["recording"])
    assert rec.damage == [] and len(rec.ticks) == 6001 and rec.header["source"] == str(session["scene"])
    assert os.path.getsize(session["saved"]) > 0


def test_info(session):
    code, out, _ = call("info", session["recording"])
    assert code == 0
    for text in ("duration    6.000 s", "haptic ticks 6001", "rate 1000 Hz", "Finger 0 (r 0.008 m",
                 "Box (0.1 kg", "Table (static", "contact_begin 2", "damage      none"):
        assert text in out, text


def test_resim_identical_then_diverged(session, tmp_path):
    code, out, _ = call("resim", session["recording"])
    assert code == 0 and out.strip() == "identical"
    new = tmp_path / "heavy.mcap"
    code, out, _ = call("resim", session["recording"], "--set", "Box.mass=0.2", "--record", new,
                        "--tolerance", "1e-4")
    assert code == 0 and out.startswith("diverged") and "first over tolerance: tick" in out
    assert f"new run: {new}" in out and recording.open_recording(new).header["overrides"] == ["Box.mass=0.2"]
    code, _, err = call("resim", session["recording"], "--set", "Mug.mass=1")
    assert code == 1 and "no body or finger named 'Mug'" in err


def test_analyze_through_the_launcher(session, tmp_path):
    """grasp-lab analyze as a user runs it: the sample session's pinch and lift, every 10th tick."""
    r = grasp_lab("analyze", session["recording"], "--csv", tmp_path / "grasp", "--every", "10")
    assert r.returncode == 0, r.stderr
    assert "Box: held" in r.stdout and "in force closure 0.000 s" in r.stdout      # two fingers: never
    assert "closest to slipping: Finger" in r.stdout and "grasp.csv" in r.stdout
    with open(tmp_path / "grasp" / "grasp.csv") as fh:
        rows = list(csv.DictReader(fh))
    carried = next(row for row in rows if float(row["time"]) >= 4.2)
    assert carried["body"] == "Box" and carried["contacts"] == "2" and carried["mu_min"] == "inf"
    assert float(carried["grip_force"]) > float(carried["load_force"]) > 0.9      # the 0.1 kg box, held


def test_export_csv_and_npz(session, tmp_path):
    rec = recording.open_recording(session["recording"])
    code, out, _ = call("export", session["recording"], "--csv", tmp_path / "csv", "--every", "10")
    assert code == 0
    with open(tmp_path / "csv" / "bodies.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == "time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz,fx,fy,fz,tx,ty,tz".split(",")
    assert len(rows) == 1 + 2 * len(rec.ticks[::10])
    k = 4200 // 10               # tick 4200, the box being carried
    row = rows[1 + 2 * k]
    assert row[1] == "Box" and float(row[0]) == rec.ticks["time"][4200]
    np.testing.assert_array_equal([float(v) for v in row[2:9]], rec.ticks["pose"][4200, 0])
    with open(tmp_path / "csv" / "fingers.csv") as fh:
        frows = list(csv.DictReader(fh))
    assert list(frows[0]) == ("time,finger,hip_x,hip_y,hip_z,go_x,go_y,go_z,force_x,force_y,force_z,"
                              "device_fx,device_fy,device_fz,state,contact").split(",")
    held = frows[2 * k]
    assert held["finger"] == "Finger 0" and held["state"] == "stick" and held["contact"] == "Box"
    with open(tmp_path / "csv" / "events.csv") as fh:
        events = list(csv.DictReader(fh))
    assert len(events) == len(rec.events) and events[0]["kind"] == "contact_begin"
    code, _, _ = call("export", session["recording"], "--npz", tmp_path / "r.npz")
    data = np.load(tmp_path / "r.npz")
    np.testing.assert_array_equal(data["pose"], rec.ticks["pose"])
    assert list(data["body_names"]) == ["Box", "Table"] and len(data["event_kind"]) == len(rec.events)


def test_bake_command(session, bpy):
    out = session["tmp"] / "baked.blend"
    r = grasp_lab("bake", session["recording"], session["scene"], "--save", out)
    assert r.returncode == 0, r.stderr
    assert "baked" in r.stdout and os.path.exists(out)
    bpy.ops.wm.open_mainfile(filepath=str(out))
    rec = recording.open_recording(session["recording"])
    box = bpy.data.objects["Box"]
    bpy.context.scene.frame_set(43)
    pose = rec.ticks["pose"][rec.sample([42 / 24])[0], 0]
    np.testing.assert_allclose(tuple(box.matrix_world.translation), pose[:3], atol=1e-6)


def test_run_with_overrides_and_devices(blend, tmp_path):
    rec = tmp_path / "set.mcap"
    r = grasp_lab("run", blend, "--duration", "0.5", "--set", "Box.mass=0.25", "--set", "haptic_rate=500",
                  "--record", rec)
    assert r.returncode == 0, r.stderr
    got = recording.open_recording(rec)
    h = got.header
    assert h["scene"]["bodies"][0]["mass"] == pytest.approx(0.25) and h["rates"]["haptic_hz"] == 500
    params = [(e["subject"], e["name"], e["value"]) for e in got.events if e["kind"] == "parameter"]
    assert params == [("Box", "mass", 0.25), ("scene", "haptic_rate", 500.0)]
    r = grasp_lab("run", blend, "--set", "Mug.mass=1")
    assert r.returncode == 1 and "no Grasp Lab body or finger named 'Mug'" in r.stderr
    r = grasp_lab("run", blend, "--device", "frob:1")
    assert r.returncode == 1 and "device backend 'frob' is not available" in r.stderr
    r = grasp_lab("run", blend, "--device", "serial:/dev/ttyACM0")
    assert r.returncode == 1 and "--device needs --realtime" in r.stderr
    r = grasp_lab("run", blend, "--device", "serial:")
    assert r.returncode == 1 and "serial needs a port" in r.stderr
    r = grasp_lab("run", tmp_path / "nothing.blend")
    assert r.returncode == 1 and "nothing.blend: no such file" in r.stderr


def _chunk_spans(path):
    """(start, end) session times of every complete chunk, read linearly up to any damage."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader
    spans = []
    with open(path, "rb") as fh:
        try:
            for r in StreamReader(fh, emit_chunks=True).records:
                if isinstance(r, Chunk):
                    spans.append((r.message_start_time * 1e-9, r.message_end_time * 1e-9))
        except Exception:
            pass
    return spans


def test_resim_of_a_live_recording_is_identical(blend, tmp_path):
    """`grasp-lab run --realtime` (the threaded runtime, real threads) records its hand-over
    schedule; `grasp-lab resim` replays it and says `identical`."""
    rec = tmp_path / "live.mcap"
    r = grasp_lab("run", blend, "--realtime", "--duration", "2", "--record", rec)
    assert r.returncode == 0, r.stderr
    live = recording.open_recording(rec)
    assert live.header["mode"] == "realtime" and live.header["runtime"]["object_rate"] == 500.0
    assert live.ticks["object_tick"][-1] > 0 and live.ticks["adopted"].max() == 1
    r = grasp_lab("resim", rec)
    assert r.returncode == 0 and r.stdout.strip() == "identical", r.stdout + r.stderr


def test_kill_9_during_a_realtime_recording(blend, tmp_path):
    rec = tmp_path / "killed.mcap"
    proc = subprocess.Popen([LAUNCHER, "run", str(blend), "--realtime", "--duration", "60", "--record", str(rec)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        seen = 0.0
        deadline = time.monotonic() + 120
        copy = tmp_path / "copy.mcap"
        while seen < 1.5:
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline, "the session never recorded 1.5 s"
            time.sleep(0.05)
            partial = tmp_path / "killed.mcap.partial"      # the name it has until it is finished
            if partial.exists():
                shutil.copy(partial, copy)
                try:
                    got = recording.open_recording(copy)
                    seen = float(got.ticks["time"][-1]) if len(got.ticks) else 0.0
                except recording.RecordingError:
                    pass
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert not rec.exists()                    # never under its name before it is finished
    rec = tmp_path / "killed.mcap.partial"      # what the kill left: a readable prefix
    code, out, err = call("info", rec)
    assert code == 0 and "cut short" in err and "cut short" in out
    left = recording.open_recording(rec)
    assert float(left.ticks["time"][-1]) >= seen          # nothing that was on disk is lost
    assert np.all(np.diff(left.ticks["tick"].astype(np.int64)) == 1)
    # Chunks close on the flush timer: none holds more than 100 ms of the session (+ 10 ms for
    # a loaded machine), so a kill loses at most that.
    spans = _chunk_spans(rec)
    assert len(spans) > 10
    assert max(b - a for a, b in spans[1:]) <= 0.11
    assert max(b1 - b0 for (_, b0), (_, b1) in zip(spans[1:], spans[2:])) <= 0.11
    out_blend = tmp_path / "from_killed.blend"
    r = grasp_lab("bake", rec, blend, "--save", out_blend)
    assert r.returncode == 0 and "cut short" in r.stderr and os.path.exists(out_blend)


@pytest.mark.multiversion
def test_blender_cli_command_registered(bpy, sample, core, tmp_path):
    """`blender -c grasp_lab` is registered on this Blender and runs the same commands."""
    sample.build(bpy)
    s = bpy.context.scene.grasp_lab
    s.record, s.recording_folder = True, str(tmp_path)
    assert bpy.ops.grasp_lab.session(duration=0.25) == {"FINISHED"}
    handle = grasp_env.submodule("cli_blender")._handle
    assert handle is not None
    execute = grasp_env.submodule("cli_blender")._execute
    assert execute(["info", s.last_recording]) == 0
    assert execute(["resim", s.last_recording]) == 0
    assert execute(["analyze", s.last_recording, "--csv", str(tmp_path / "grasp"), "--every", "50"]) == 0
    assert (tmp_path / "grasp" / "grasp.csv").exists()
    assert execute(["info"]) == 2


# The command line of a Python where `import bpy` fails: only engine/ is imported.
WITHOUT_BPY = ("import sys; sys.modules['bpy'] = None; sys.path.insert(0, {root!r}); "
               "from addon.engine import cli; code = cli.main(sys.argv[1:]); "
               "above = sorted(m for m in sys.modules if m.startswith('addon.') and not m.startswith('addon.engine')); "
               "print('ABOVE', above, file=sys.stderr); sys.exit(code)")


def test_recording_commands_run_without_bpy(core, tmp_path):
    """info, export, resim, analyze, continuity and sweep of a recording in a Python that has no
    bpy: none imports it, nor any module of the add-on above engine/. run needs Blender and says so."""
    import recordings
    rec = tmp_path / "pinch.mcap"
    recordings.record_exec(rec, core, seconds=1.0)
    prelude = WITHOUT_BPY.format(root=grasp_env.ROOT)
    for args in (["info", rec], ["export", rec, "--npz", tmp_path / "pinch.npz"], ["resim", rec],
                 ["analyze", rec, "--every", "100"], ["continuity", rec],
                 ["sweep", rec, "--samples", "2", "--vary", "Box.mass=0.05:0.2", "--out", tmp_path / "sweep",
                  "--workers", "1", "--no-analysis"]):
        r = subprocess.run([sys.executable, "-c", prelude, *map(str, args)], capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 0, (args[0], r.stderr)
        assert "ABOVE []" in r.stderr, (args[0], r.stderr)
    assert (tmp_path / "pinch.npz").exists() and (tmp_path / "sweep" / "samples.csv").exists()
    r = subprocess.run([sys.executable, "-c", prelude, "run", str(tmp_path / "none.blend")], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 1 and "Blender (the bpy module) with the Grasp Lab extension is needed" in r.stderr, \
        r.stderr
