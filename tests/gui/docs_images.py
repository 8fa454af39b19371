"""`make docs-images`: the README's pictures, made by the project's own GUI Blender
(tests/gui/gui_blender.sh) walking through the README (tests/gui/driver.py, scenarios
``walkthrough``, ``device``, ``device_fit`` and ``first_hour``), and the demo's contact sheet; cropped to what they show,
scaled down and stored as 256-colour PNGs in docs/images/.

    python tests/gui/docs_images.py [--demo build/demo] [--out docs/images]

Needs the built zip in $GRASP_LAB_ZIP and a GUI Blender (docs/gui-tests.md).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import gui_run  # noqa: E402

WIDTH = 960                     # px: the README's pictures
SIDEBAR_WIDTH = 300


def save(src, crop, dst, width):
    """``src`` cropped to ``crop`` (x, y, w, h; None: all), scaled to ``width`` (never up),
    as a 256-colour PNG."""
    from PIL import Image
    img = Image.open(src).convert("RGB")
    if crop is not None:
        x, y, w, h = crop
        img = img.crop((x, y, x + w, y + h))
    if img.width > width:
        img = img.resize((width, round(img.height * width / img.width)), Image.LANCZOS)
    img.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(dst, optimize=True)
    print(f"{dst}: {img.width} x {img.height}, {os.path.getsize(dst) / 1024:.0f} kB")


def run_scenario(env, name, timeout=300, **extra):
    result, console, code = gui_run.run(dict(env, **extra), name, timeout=timeout)
    if not result.get("ok"):
        raise SystemExit(f"the GUI scenario {name} failed:\n{result.get('error')}\n{console[-2000:]}")
    return result


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--demo", default=os.path.join(gui_run.ROOT, "build", "demo"), help="make demo's outputs")
    ap.add_argument("--out", default=os.path.join(gui_run.ROOT, "docs", "images"))
    args = ap.parse_args(argv)
    reason = gui_run.why_not()
    if reason:
        raise SystemExit(f"make docs-images needs a GUI Blender: {reason}; {gui_run.HOW}")
    os.makedirs(args.out, exist_ok=True)
    sheet = os.path.join(args.demo, "contact_sheet.png")
    if not os.path.exists(sheet):
        raise SystemExit(f"{sheet} is missing: run make demo first")
    save(sheet, None, os.path.join(args.out, "demo_contact_sheet.png"), WIDTH)
    env = gui_run.prepare(os.environ.get("GRASP_LAB_ZIP", ""), tempfile.mkdtemp(prefix="grasp_lab_docs_"))
    pictures = dict(run_scenario(env, "walkthrough")["docs_pictures"])
    for scenario in ("device", "first_hour"):       # each with an emulator of its own
        emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--motion", "grip"],
                               cwd=gui_run.ROOT, stdout=subprocess.PIPE, text=True)
        try:
            port = emu.stdout.readline().split()[1]
            pictures.update(run_scenario(env, scenario, timeout=900,
                                         GRASP_LAB_GUI_DEVICE_PORT=port)["docs_pictures"])
        finally:
            emu.terminate()
            emu.wait(timeout=20)
    pictures.update(run_scenario(env, "device_fit")["docs_pictures"])
    save_pictures(pictures, args.out)
    return 0


def save_pictures(pictures, out):
    """A scenario's docs pictures (its result's ``docs_pictures``) as docs/images/gui_<name>.png."""
    for name, pic in pictures.items():
        crop = pic["crop"]
        width = SIDEBAR_WIDTH if crop is not None and crop[2] < 400 else WIDTH
        save(pic["path"], crop, os.path.join(out, f"gui_{name}.png"), width)


if __name__ == "__main__":
    sys.exit(main())
