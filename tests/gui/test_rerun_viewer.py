"""The real Rerun viewer (the binary inside the rerun-sdk wheel) under Xvfb with Mesa's
software Vulkan driver opens the Rerun copy of a library scene (``grasp-lab view --screenshot``)
and its own picture is checked: the moving body drawn in the middle of the 3-D view, the
fingers' god-objects, the plot panels drawn with their lines. ``view`` without
``--screenshot`` starts the viewer and returns at once. Needs Xvfb and mesa-vulkan-drivers
(tests/gui/rerun_viewer.sh setup, run by make test-gui)."""
from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

import rerun_shots as rs


@pytest.fixture(scope="module")
def display():
    reason = rs.why_not()
    if reason:
        msg = f"the Rerun viewer test needs Xvfb and software Vulkan: {reason}; {rs.HOW}"
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)
    with rs.Xvfb() as d:
        yield d


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    return rs.library_recording("pinch_and_lift", str(tmp_path_factory.mktemp("rerun_library")))


def test_viewer_draws_the_grasp_and_its_plots(display, recording, tmp_path):
    from PIL import Image                       # rerun-sdk's dependency
    from addon.engine import viewer
    png = tmp_path / "shot.png"
    shot = rs.screenshot(recording, str(png), display, str(tmp_path))
    assert shot.returncode == 0, shot.stdout + shot.stderr
    assert f"screenshot: {png}" in shot.stdout
    image = np.asarray(Image.open(png).convert("RGB"))
    h, w = image.shape[:2]
    assert (w, h) == (2 * rs.WINDOW[0], 2 * rs.WINDOW[1])
    view = rs.region(image, rs.THREE_D)
    # The file's layout is the one shown: its 3-D view (with the background it sets) where the
    # layout puts it, not a layout the viewer made up.
    from addon.engine import rerun_view
    background = np.all(np.abs(view.astype(int) - rerun_view.BACKGROUND) <= 1, axis=2)
    assert 0.2 < background.mean() < 0.95, background.mean()
    # The 3-D view is not empty: the box (the moving body's colour) fills a good part of its middle.
    box = rs.body_pixels(view, viewer.BODY_COLOR)
    vh, vw = box.shape
    middle = box[vh // 4:3 * vh // 4, vw // 4:3 * vw // 4]
    assert middle.sum() > 0.02 * middle.size, f"box pixels in the middle of the 3-D view: {middle.sum()}"
    ys, xs = np.nonzero(box)
    assert abs(xs.mean() / vw - 0.5) < 0.25 and abs(ys.mean() / vh - 0.5) < 0.25, (xs.mean(), ys.mean())
    # ... the table beside it (the static colour), the god-objects (blue) at the box's sides.
    assert rs.body_pixels(view, viewer.STATIC_BODY_COLOR).sum() > 0.05 * view.shape[0] * view.shape[1]
    go = rs.body_pixels(view, viewer.GO_COLOR)
    assert go.sum() > 200, go.sum()
    # The plot panels are drawn, each with its lines (not only axes): a saturated line in each.
    plots = rs.region(image, rs.PLOTS)
    lines = rs.series_pixels(plots)
    bands = np.array_split(lines, rs.PLOT_COUNT, axis=0)
    counts = [int(b.sum()) for b in bands]
    assert all(c > 300 for c in counts), counts


def test_view_starts_the_viewer_and_returns(display, recording, tmp_path):
    """Without --screenshot the viewer is a separate process: view returns while it runs."""
    env = rs.viewer_env(display, str(tmp_path))
    t0 = time.monotonic()
    done = rs.grasp_lab("view", recording, env=env, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "up to date (cached)" in done.stdout or "converted" in done.stdout
    pid = int(done.stdout.split("(pid ")[1].split(")")[0])
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            cmdline = fh.read().split(b"\0")
        assert cmdline[0].endswith(b"rerun") and cmdline[-2].endswith(b".rrd"), cmdline
        assert time.monotonic() - t0 < 120
    finally:
        os.kill(pid, signal.SIGTERM)
