"""Run the GUI driver (tests/gui/driver.py) in a GUI Blender: shared by tests/gui/test_gui.py
and bench/bench_gui.py."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCRIPT = os.path.join(ROOT, "tests", "gui", "gui_blender.sh")
DRIVER = os.path.join(ROOT, "tests", "gui", "driver.py")
OUT = os.path.join(ROOT, "build", "gui")
HOW = ("make test builds one as root on Debian (tests/gui/gui_blender.sh setup), or set "
       "BLENDER=/path/to/blender with xvfb-run, xdotool and ImageMagick installed")


def why_not() -> str:
    """Empty when a GUI Blender can be run here, else the reason."""
    check = subprocess.run([SCRIPT, "check"], capture_output=True, text=True)
    return "" if check.returncode == 0 else check.stdout.strip() or check.stderr.strip()


def prepare(zip_path: str, user_dir: str | None = None) -> dict:
    """A fresh Blender user folder with the extension installed (tests/gui/prep.py);
    returns the environment to run the GUI Blender with."""
    if not zip_path or not os.path.exists(zip_path):
        raise FileNotFoundError(f"the built extension zip is missing: {zip_path!r} (make extension)")
    env = dict(os.environ, GRASP_LAB_ZIP=os.path.abspath(zip_path),
               BLENDER_USER_RESOURCES=user_dir or tempfile.mkdtemp(prefix="grasp_lab_gui_"))
    prep = subprocess.run([SCRIPT, "blender", "-b", "--python", os.path.join(ROOT, "tests", "gui", "prep.py")],
                          env=env, capture_output=True, text=True, timeout=120)
    if "grasp-lab-gui-prep: ok" not in prep.stdout:
        raise RuntimeError(f"installing the extension into the GUI Blender failed:\n{prep.stdout}{prep.stderr}")
    return env


def environment(user_dir: str, what: str = "GUI tests need a GUI Blender") -> dict:
    """For a pytest fixture: the prepared environment, or a skip saying why and how to get
    one (a failure under CI=true, where there is no excuse)."""
    import pytest
    reason = why_not()
    if reason:
        msg = f"{what}: {reason}; {HOW}"
        if os.environ.get("CI") and not os.environ.get("GRASP_LAB_GUI_OPTIONAL"):
            pytest.fail(msg)
        pytest.skip(msg)
    return prepare(os.environ.get("GRASP_LAB_ZIP", ""), user_dir)


def run(env: dict, scenario: str, timeout: float = 600, background: bool = False):
    """Run one driver scenario; returns (result.json as a dict, console output, exit code)."""
    out = os.path.join(OUT, scenario)
    shutil.rmtree(out, ignore_errors=True)
    args = [SCRIPT, "blender"] + (["-b"] if background else []) + ["--python", DRIVER, "--", scenario, out]
    proc = subprocess.run(args, env=env, capture_output=True, text=True, timeout=timeout)
    console = proc.stdout + proc.stderr
    path = os.path.join(out, "result.json")
    if not os.path.exists(path):
        raise AssertionError(f"{scenario}: no result (exit {proc.returncode})\n{console[-3000:]}")
    with open(path) as fh:
        return json.load(fh), console, proc.returncode
