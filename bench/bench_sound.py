"""Hearing the grasp (docs/sound.md): what the sound costs.

1. The sonification (addon/engine/sound.py) of the pinch and lift's recording (6 s, 1 kHz, two
   fingers): the whole recording at once (what `grasp-lab export --wav` and a bake do), and in
   the pieces a 30 Hz and a 5 Hz display update take (the live sound's work per update).
2. The live sound's cost per display update (LiveSound.update on a threaded session, in the bpy
   module: the sequence built, not played) and the drop of the display rate it makes (target: at
   most 5 %).
3. Live in the GUI Blender (tests/gui, scenario ``sound``): the pinch and lift with Sound on and
   off, alternately, twice each; the display rates achieved, the sound's latency, late stretches
   and cost per display update where it can play (Debian's Blender 4.3 has no aud module).

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
        t0 = time.thread_time()
        samples, son = sound.sonify(rec.header["scene"], rec.ticks)
        whole.append(time.thread_time() - t0)
    lines = ["| what | CPU time (this thread: the machine is shared) | × real time |", "|---|---|---|",
             f"| the whole recording ({seconds:.1f} s, {len(rec.ticks)} ticks, {len(samples)} samples at "
             f"{son.rate} Hz) | {min(whole) * 1e3:.0f} ms | {seconds / min(whole):.0f} |"]
    for rate in (30, 5):
        per = int(round(1000 / rate))
        s = sound.Sonifier(rec.header["scene"])
        cost = []
        for i in range(0, len(rec.ticks), per):
            t0 = time.thread_time()
            s.feed(rec.ticks[i:i + per])
            cost.append(time.thread_time() - t0)
        med = statistics.median(cost)
        lines.append(f"| per {rate} Hz display update ({per} ticks): median / max | {med * 1e3:.2f} / "
                     f"{max(cost) * 1e3:.2f} ms | {per / 1000 / med:.0f} |")
    return lines


def placement() -> list:
    """LiveSound.update (sonify + place in the aud.Sequence) at each display update of a live
    session on the threaded runtime, in the bpy module (which has no audio device: the sequence is
    built, not played): its cost per update against the display interval, the drop of the display
    rate it makes."""
    import grasp_env
    grasp_env.isolate()
    sys.stdout.flush()
    saved = os.dup(1)                   # Blender's own lines (installing the extension) stay out of the report
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
    try:
        import bpy  # noqa: F401
        grasp_env.enable()
    finally:
        os.dup2(saved, 1)
    import recordings
    from addon.engine import core_loader, inputs, runner, scene
    from addon.engine.tick_tap import TickTap
    sound_live = grasp_env.submodule("sound_live")
    core = core_loader.load()
    rows = ["| display rate | updates | sound per update (CPU time): median / max | drop of the display rate it makes |",
            "|---|---|---|---|"]
    for rate in (30.0, 5.0):
        desc, S = recordings.pinch_desc()
        handle = scene.build_world(desc, core)
        tap = TickTap(handle.world, core.tick_dtype(len(desc.bodies), len(desc.fingers)), 1000.0)
        run = runner.SessionRunner(handle, inputs.CallableInput(len(desc.fingers), S.hip_positions, duration=6.0),
                                   1000.0, use_runtime=True, tap=tap)
        player = sound_live.LiveSound(desc, display_rate=rate, volume=1.0, device=None)
        cost = []
        run.start()
        t0 = time.monotonic()
        while run.snapshot().time < 6.0:
            run.advance_to(time.monotonic() - t0)
            now = run.snapshot().time           # the session takes it anyway: not the sound's
            c0 = time.thread_time()
            player.update(tap.take(), now)
            cost.append(time.thread_time() - c0)
            time.sleep(max(0.0, 1.0 / rate - cost[-1]))
        run.stop()
        med = statistics.median(cost)
        rows.append(f"| {rate:g} Hz | {len(cost)} | {med * 1e3:.2f} / {max(cost) * 1e3:.2f} ms | "
                    f"{100 * med * rate:.1f} % (the update's {med * 1e3:.2f} ms in its {1e3 / rate:.0f} ms) |")
    return rows


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
    if not r["audio"]:
        why = ("it is built without audaspace's Python module (`import aud` fails)" if not r.get("aud") else
               f"no audio output opened (outputs: {', '.join(r.get('audio_devices', []))})")
        head = (f"Live in the GUI Blender {r['blender']} (Xvfb, llvmpipe): **the sound could not play**: {why}. "
                "Each session with Sound on said so and ran to its end; the display rates below differ by "
                "the shared machine's load only:")
    else:
        head = (f"Live: Blender {r['blender']} under Xvfb (llvmpipe), audio through `{r['audio']}` (a driver that "
                "takes the samples at its own pace, no sound card), the pinch and lift (6 s), Sound on and off "
                "alternately:")
    lines = [head, "", "| run | Sound | display rate achieved | latency | late stretches | clicks | sound per update |",
             "|---|---|---|---|---|---|---|"]
    on, off = [], []
    for k, run in enumerate(r["runs"], 1):
        st = run.get("sound_stats") or {}
        (on if run["sound"] else off).append(run["display_rate"])
        lines.append(f"| {k} | {'on' if run['sound'] else 'off'} | {run['display_rate']:.2f} Hz | "
                     + (f"{st['latency_ms']:.0f} ms | {st['late']} | {st['clicks']} | {st['cost_ms']:.2f} ms |"
                        if "latency_ms" in st else "- | - | - | - |"))
    if r["audio"]:
        ratio = statistics.mean(on) / statistics.mean(off)
        lines += ["", f"Display rate with Sound on / off: **{ratio:.3f}** (target: a drop of at most 5 %)."]
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--no-gui", action="store_true")
    args = ap.parse_args(argv)
    out = ["### Hearing the grasp", "", "`bench/bench_sound.py` (docs/sound.md): the sonification of a recording, "
           "whole and per display update:", ""] + sonification()
    out += ["", "The live sound's work on the display thread (`LiveSound.update`: the interval's ticks sonified and "
                "placed in its `aud.Sequence`) at each display update of a 6 s pinch and lift on the threaded "
                "runtime, in the `bpy` module (no audio device there: the sequence is built, not played); the "
                "display rate drops by the share of each update it takes:", ""] + placement()
    if not args.no_gui:
        out += [""] + live()
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
