"""The real Rerun viewer under Xvfb: a library scene recorded, opened with ``grasp-lab view
--screenshot`` and its picture read (tests/gui/test_rerun_viewer.py; ``make docs-images``
writes docs/images/rerun_*.png with ``python tests/gui/rerun_shots.py --out docs/images``).

Xvfb runs with ``-extension Composite`` (without it the viewer's window reads back black) on a
display it picks itself (``-displayfd``), so parallel runs never share one; the screen is
more than twice the window's size in pixels (the viewer draws at 2 pixels a point here), so
the pointer (at the screen's centre) is not over the window and draws no hover tooltip.
Rerun keeps its settings in XDG folders: each run gets its own.
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)        # addon.engine (bpy-free): the colours the copy is drawn in
SETUP = os.path.join(ROOT, "tests", "gui", "rerun_viewer.sh")
WINDOW = (1600, 900)            # logical points; the picture is 2x that
SCREEN = "7200x4200x24"
HOW = "make test installs them as root on Debian (tests/gui/rerun_viewer.sh setup)"
# The blueprint's layout (engine/rerun_view.blueprint): the 3-D view and the events in the
# left 3/5, the plots in the right 2/5; the top bar and the time panel at the bottom.
THREE_D = (0.0, 0.58, 0.07, 0.58)       # x0, x1, y0, y1 as fractions of the picture
PLOTS = (0.61, 0.93, 0.05, 0.73)        # left of the legends
PLOT_COUNT = 6


def why_not() -> str:
    check = subprocess.run([SETUP, "check"], capture_output=True, text=True)
    return "" if check.returncode == 0 else check.stdout.strip() or check.stderr.strip()


class Xvfb:
    """An X server of our own: ``with Xvfb() as display: ...`` (":N")."""

    def __enter__(self):
        read, write = os.pipe()
        self.proc = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", SCREEN,
                                      "-extension", "Composite", "-nolisten", "tcp"],
                                     pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        os.close(write)
        with os.fdopen(read) as fh:
            number = fh.readline().strip()          # written once the server accepts clients
        if not number:
            self.proc.kill()
            raise RuntimeError(f"Xvfb did not start: {self.proc.stderr.read().decode(errors='replace')[-500:]}")
        self.display = f":{number}"
        return self.display

    def __exit__(self, *exc):
        self.proc.terminate()
        self.proc.wait(timeout=30)


def grasp_lab(*args, env=None, timeout=600) -> subprocess.CompletedProcess:
    """``grasp-lab ARGS`` of this checkout (the launcher make writes), output captured."""
    code = (f"import sys; sys.path.insert(0, {ROOT!r}); from addon.launcher import launch; sys.exit(launch())")
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env,
                          timeout=timeout, cwd=ROOT)


def library_recording(name: str, folder: str) -> str:
    """The library scene ``name`` (sample_scenes/library.py) built and run headless, recorded."""
    build = subprocess.run([sys.executable, os.path.join(ROOT, "sample_scenes", "library.py"), "--out", folder,
                            "--only", name], capture_output=True, text=True, timeout=600, cwd=ROOT)
    blend = os.path.join(folder, f"{name}.blend")
    if not os.path.exists(blend):
        raise RuntimeError(f"building {name} failed:\n{build.stdout[-2000:]}{build.stderr[-2000:]}")
    rec = os.path.join(folder, f"{name}.mcap")
    run = grasp_lab("run", blend, "--record", rec)
    if run.returncode != 0:
        raise RuntimeError(f"grasp-lab run {blend} failed:\n{run.stdout[-2000:]}{run.stderr[-2000:]}")
    return rec


def viewer_env(display: str, home: str) -> dict:
    """The environment the viewer runs in: our display, its own settings folders."""
    env = dict(os.environ, DISPLAY=display)
    for var in ("XDG_DATA_HOME", "XDG_CONFIG_HOME", "XDG_CACHE_HOME", "XDG_RUNTIME_DIR"):
        path = os.path.join(home, var.lower())
        os.makedirs(path, mode=0o700, exist_ok=True)
        env[var] = path
    return env


def screenshot(rec: str, png: str, display: str, home: str) -> subprocess.CompletedProcess:
    return grasp_lab("view", rec, "--screenshot", png, "--size", f"{WINDOW[0]}x{WINDOW[1]}",
                     env=viewer_env(display, home))


def region(image: np.ndarray, box) -> np.ndarray:
    h, w = image.shape[:2]
    x0, x1, y0, y1 = box
    return image[int(y0 * h):int(y1 * h), int(x0 * w):int(x1 * w)]


def body_pixels(image: np.ndarray, rgb) -> np.ndarray:
    """Where a body of colour ``rgb`` (0..1, as logged) is drawn: pixels whose colour is that
    colour under some light (the same proportions of r, g, b within 5 %), not dark."""
    px = image.astype(np.float64)
    b = np.maximum(px[..., 2], 1.0)
    want = np.asarray(rgb[:3], dtype=np.float64) / rgb[2]
    return ((np.abs(px[..., 0] / b - want[0]) < 0.05) & (np.abs(px[..., 1] / b - want[1]) < 0.05)
            & (px[..., 2] > 50))


def series_pixels(image: np.ndarray) -> np.ndarray:
    """Pixels of plotted lines: saturated colours (the UI is grey, the plots' lines are not)."""
    px = image.astype(np.int32)
    return (px.max(axis=2) - px.min(axis=2)) > 80


def main(argv=None) -> int:
    """docs/images/rerun_*.png: the viewer's own pictures of library scenes."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=os.path.join(ROOT, "docs", "images"))
    p.add_argument("--scenes", nargs="+", default=["pinch_and_lift", "tripod_pencil"])
    args = p.parse_args(argv)
    reason = why_not()
    if reason:
        print(f"Rerun viewer pictures: {reason}; {HOW}", file=sys.stderr)
        return 1
    work = tempfile.mkdtemp(prefix="grasp_lab_rerun_docs_")
    try:
        with Xvfb() as display:
            for name in args.scenes:
                rec = library_recording(name, work)
                png = os.path.join(args.out, f"rerun_{name}.png")
                shot = screenshot(rec, png, display, work)
                if shot.returncode != 0:
                    print(shot.stdout + shot.stderr, file=sys.stderr)
                    return 1
                from PIL import Image       # rerun-sdk's dependency
                with Image.open(png) as im:     # the viewer draws at 2x: half is sharp enough for a page
                    small = im.convert("RGB").resize((im.width // 2, im.height // 2), Image.LANCZOS)
                small.save(png, optimize=True)
                print(png)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
