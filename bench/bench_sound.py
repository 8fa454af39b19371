"""Hearing the grasp (docs/sound.md): what the sound costs.

1. The sonification (addon/engine/sound.py) of the pinch and lift's recording (6 s, 1 kHz, two
   fingers): the whole recording at once (what `grasp-lab export --wav` and a bake do), and in
   the pieces a 30 Hz and a 5 Hz display update take (the live sound's work per update).
2. Live in the GUI Blender (tests/gui, scenario ``sound``): the pinch and lift with Sound on and
   off, alternately, twice each; the display rates achieved, their ratio (the target: a drop of
   at most 5 %), the sound's latency, late stretches and cost per display update.

Prints a Markdown section.   .venv/bin/python bench/bench_sound.py [--no-gui]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
sys.path.insert(0, os.path.join(ROOT, "tests", "gui"))


def sonification() -> list:
    import recordings
    from addon.engine import core_loader, recording, sound
    core = core_loader.load()
    path = os.path.join(tempfile.mkdtemp(prefix="bench_sound_"), "pinch.mcap")
    recordings.record_exec(path, core, seconds=6.0)
    rec = recording.open_recording(path)
    seconds = float(rec.ticks["time"][-1])
    whole = []
    for _ in range(3):
        t0 = time.perf_counter()
        samples, son = sound.sonify(rec.header["scene"], rec.ticks)
        whole.append(time.perf_counter() - t0)
    lines = ["| what | wall time | × real time |", "|---|---|---|",
             f"| the whole recording ({seconds:.1f} s, {len(rec.ticks)} ticks, {len(samples)} samples at "
             f"{son.rate} Hz) | {min(whole) * 1e3:.0f} ms | {seconds / min(whole):.0f} |"]
    for rate in (30, 5):
        per = int(round(1000 / rate))
        s = sound.Sonifier(rec.header["scene"])
        cost = []
        for i in range(0, len(rec.ticks), per):
            t0 = time.perf_counter()
            s.feed(rec.ticks[i:i + per])
            cost.append(time.perf_counter() - t0)
        med = statistics.median(cost)
        lines.append(f"| per {rate} Hz display update ({per} ticks): median / max | {med * 1e3:.2f} / "
                     f"{max(cost) * 1e3:.2f} ms | {per / 1000 / med:.0f} |")
    return lines


def live() -> list:
    import gui_run
    reason = gui_run.why_not()
    if reason:
        return [f"Live in the GUI Blender: not measured ({reason})."]
    import glob
    zips = sorted(glob.glob(os.path.join(ROOT, "dist", "grasp_lab-*-linux_x64.zip")))
    env = gui_run.prepare(os.environ.get("GRASP_LAB_ZIP") or (zips[-1] if zips else ""))
    r, console, _ = gui_run.run(env, "sound", timeout=400)
    if not r.get("ok"):
        return [f"Live in the GUI Blender: the scenario failed:\n\n```\n{r.get('error')}\n```"]
    lines = [f"Live: Blender {r['blender']} under Xvfb (llvmpipe), audio through `{r['audio'] or 'none'}` "
             "(SDL's dummy driver: a device that takes the samples at its own pace, no sound card), the pinch "
             "and lift (6 s) at a display rate asked of 30 Hz, Sound on and off alternately:", "",
             "| run | Sound | display rate achieved | latency | late stretches | clicks | sound per update |",
             "|---|---|---|---|---|---|---|"]
    on, off = [], []
    for k, run in enumerate(r["runs"], 1):
        st = run.get("sound_stats") or {}
        (on if run["sound"] else off).append(run["display_rate"])
        lines.append(f"| {k} | {'on' if run['sound'] else 'off'} | {run['display_rate']:.2f} Hz | "
                     + (f"{st['latency_ms']:.0f} ms | {st['late']} | {st['clicks']} | {st['cost_ms']:.2f} ms |"
                        if "latency_ms" in st else "- | - | - | - |"))
    ratio = statistics.mean(on) / statistics.mean(off)
    lines += ["", f"Display rate with Sound on / off: **{ratio:.3f}** (a drop of {100 * (1 - ratio):.1f} %; "
                  f"target: at most 5 %). The machine is shared: the display rate of llvmpipe varies from run "
                  f"to run by more than the sound costs (its cost per update is the column above)."]
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--no-gui", action="store_true")
    args = ap.parse_args(argv)
    out = ["### Hearing the grasp", "", "`bench/bench_sound.py` (docs/sound.md): the sonification of a recording, "
           "whole and per display update:", ""] + sonification()
    if not args.no_gui:
        out += [""] + live()
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
