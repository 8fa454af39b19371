"""`blender -c grasp_lab ...` in a real Blender (Debian 13's 4.3 with its Python 3.13, the
extension from the zip with its cp313 wheels): every command runs, exit codes are right, and a
recording made there replays bit for bit in the venv's bpy 4.5 / Python 3.11, and back."""
import os
import subprocess

import pytest

import gui_run

ROOT = gui_run.ROOT
VENV_PY = os.path.join(ROOT, ".venv", "bin", "python")
LAUNCHER = os.path.join(ROOT, ".venv", "bin", "grasp-lab")


@pytest.fixture(scope="module")
def blender(tmp_path_factory):
    env = gui_run.environment(str(tmp_path_factory.mktemp("blender_user")), "needs a Blender executable")

    def grasp_lab(*args):
        return subprocess.run([gui_run.SCRIPT, "blender", "-c", "grasp_lab", *map(str, args)], env=env,
                              capture_output=True, text=True, timeout=240)
    return grasp_lab


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    # Under /tmp: the chroot sees the host's /tmp at the same path.
    path = tmp_path_factory.mktemp("cli_scene") / "pinch.blend"
    r = subprocess.run([VENV_PY, os.path.join(ROOT, "sample_scenes", "build_pinch_and_lift.py"), "--save", str(path)],
                       capture_output=True, text=True, timeout=240)
    assert r.returncode == 0 and path.exists(), r.stderr
    return path


def test_every_command_in_blender(blender, scene, tmp_path):
    rec, saved, baked = tmp_path / "b.mcap", tmp_path / "after.blend", tmp_path / "baked.blend"
    r = blender("run", scene, "--record", rec, "--save", saved)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "6000 ticks at 1000 Hz (EXEC)" in r.stdout and saved.exists()
    r = blender("info", rec)
    assert r.returncode == 0 and "haptic ticks 6001" in r.stdout and "blender 4." in r.stdout, r.stdout
    r = blender("resim", rec)
    assert r.returncode == 0 and "identical" in r.stdout.splitlines(), r.stdout + r.stderr
    r = blender("export", rec, "--csv", tmp_path / "csv", "--every", "100")
    assert r.returncode == 0 and (tmp_path / "csv" / "bodies.csv").exists()
    r = blender("bake", rec, scene, "--save", baked)
    assert r.returncode == 0 and "baked" in r.stdout and baked.exists(), r.stdout + r.stderr
    # The same recording, re-simulated by the venv's core (bpy 4.5, Python 3.11): bit for bit.
    r = subprocess.run([LAUNCHER, "resim", str(rec)], capture_output=True, text=True, timeout=240)
    assert r.returncode == 0 and r.stdout.strip() == "identical", r.stdout + r.stderr


def test_exit_codes_in_blender(blender, tmp_path):
    r = blender("info")
    assert r.returncode == 2 and "usage:" in r.stderr
    r = blender("info", tmp_path / "missing.mcap")
    assert r.returncode == 1 and "missing.mcap: no such file" in r.stderr
    r = blender("run", tmp_path / "missing.blend", "--device", "frob:1")
    assert r.returncode == 1 and "device backend 'frob' is not available" in r.stderr
    r = blender("--help")
    assert r.returncode == 0 and "usage: blender -c grasp_lab" in r.stdout
