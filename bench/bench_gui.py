"""Live sessions in a real GUI Blender (tests/gui/gui_blender.sh); prints a Markdown section.

1. Live versus headless: the pinch-and-lift scene run live at display rates of 5, 10, 30 and
   60 Hz, and headless (blender -b, EXEC): where the box ends. Target: within 1 mm.
2. Esc: key sent to session stopped. Target: within one display frame.
3. The viewport's draw cost for 10 fingers + 20 bodies (ms per redraw of the viewport, and
   of the whole window with its swap), without and with a live session; the session's
   display rate and main-thread time per display update, on this machine's CPU renderer.
4. The GUI test suite's wall time (pytest tests/gui), and the GUI Blender's set-up time.

Usage: .venv/bin/python bench/bench_gui.py [--zip dist/...zip] [--no-suite]
"""
from __future__ import annotations

import argparse
import glob
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests", "gui"))
import gui_run  # noqa: E402


def _zip():
    zips = sorted(glob.glob(os.path.join(ROOT, "dist", "grasp_lab-*-linux_x64.zip")))
    return zips[-1] if zips else ""


def _setup_seconds():
    root = os.environ.get("GRASP_LAB_GUI_ROOT") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "grasp-lab", "gui-blender-trixie")
    try:
        with open(os.path.join(root, "setup-seconds")) as fh:
            return int(fh.read().strip())
    except (OSError, ValueError):
        return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--zip", default=_zip())
    ap.add_argument("--no-suite", action="store_true", help="do not time the GUI test suite")
    args = ap.parse_args(argv)
    print("### Live sessions in a GUI Blender\n")
    reason = gui_run.why_not()
    if reason:
        print(f"Not measured: {reason}.")
        return 0
    env = gui_run.prepare(args.zip)
    ref, _, _ = gui_run.run(env, "exec_headless", background=True)
    rates, _, _ = gui_run.run(env, "display_rates", timeout=400)
    esc, _, _ = gui_run.run(env, "start_esc_stop")
    draw, _, _ = gui_run.run(env, "draw_cost")
    for r in (ref, rates, esc, draw):
        if not r.get("ok"):
            print(f"A scenario failed: {r.get('scenario')}\n\n```\n{r.get('error')}\n```")
            return 1
    print(f"Blender {draw['blender']} with Python {draw['python']} (the core `{draw['graspcore']}`), "
          f"under Xvfb with Mesa llvmpipe (software OpenGL), 1600 x 900, on the machine above.\n")
    head = ref["exec_box"]
    print("| display rate asked | achieved | box at the end, x / y / z (mm) | off the headless run | "
          "haptic ticks | target | met |")
    print("|---|---|---|---|---|---|---|")
    print(f"| headless (`blender -b`, EXEC) | - | {head[0]*1e3:.3f} / {head[1]*1e3:.3f} / {head[2]*1e3:.3f} "
          f"| - | {ref['exec_steps']} steps | | |")
    for rate, run in rates["runs"].items():
        off = max(abs(a - b) for a, b in zip(run["box"], head))
        print(f"| {rate} Hz | {run['achieved_display_rate']:.1f} Hz | "
              f"{run['box'][0]*1e3:.3f} / {run['box'][1]*1e3:.3f} / {run['box'][2]*1e3:.3f} | "
              f"{off*1e3:.3f} mm | {run['steps']} at {run['haptic_rate']:.0f} Hz | <= 1 mm | "
              f"{'yes' if off <= 1e-3 else 'no'} |")
    frame = max(esc["frame_max_s"], esc["interval"])
    print()
    print("| measurement | value | target | met |")
    print("|---|---|---|---|")
    print(f"| Esc: key sent to session stopped | {esc['esc_latency_s']*1e3:.0f} ms | within one display frame "
          f"(the longest of the last display updates: {frame*1e3:.0f} ms) | "
          f"{'yes' if esc['esc_latency_s'] <= frame else 'no'} |")
    print(f"| core threads after Esc / Stop | {esc['threads_after']['esc']} / {esc['threads_after']['stop_button']} "
          f"| none | {'yes' if not any(esc['threads_after'].values()) else 'no'} |")
    vp = draw["viewport_px"]
    print(f"| viewport redraw ({vp[0]} x {vp[1]}), 10 fingers + 20 bodies, no session | "
          f"{draw['draw_ms_idle']:.1f} ms | | |")
    print(f"| the same during a live session ({draw['display_objects']} display objects, overlay, HUD) | "
          f"{draw['draw_ms_session']:.1f} ms | | |")
    print(f"| whole window + swap, no session / session | {draw['window_ms_idle']:.1f} / "
          f"{draw['window_ms_session']:.1f} ms | | |")
    print(f"| session display rate (30 Hz asked) | {draw['display_rate_session']:.1f} Hz | | |")
    print(f"| main-thread time per display update (snapshot, 20 bodies and {draw['display_objects']} "
          f"display objects written, HUD) | {draw['tick_ms_median']:.2f} ms | | |")
    setup = _setup_seconds()
    print(f"| GUI Blender set-up (debootstrap + packages, once) | "
          f"{f'{setup} s' if setup is not None else 'cached before this run'} | | |")
    if not args.no_suite:
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "pytest", "-q", os.path.join(ROOT, "tests", "gui")],
                              env=dict(os.environ, GRASP_LAB_ZIP=args.zip), capture_output=True, text=True)
        wall = time.perf_counter() - t0
        tail = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else "no output"
        print(f"| GUI test suite (`pytest tests/gui`: {tail}) | {wall:.0f} s | < 300 s | "
              f"{'yes' if wall < 300 and proc.returncode == 0 else 'no'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
