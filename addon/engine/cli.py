"""The ``grasp-lab`` command line (docs/cli.md).

One implementation, two entry points: ``grasp-lab`` in the development venv (``launcher.py``,
which the launcher ``make`` writes calls) and ``blender -c grasp_lab ...`` inside Blender 4.2+
(``cli_blender.py`` registers ``main`` with ``bpy.utils.register_cli_command``). No bpy here.

Commands live in ``COMMANDS`` (``register_command``). The commands that need Blender (``run``,
``bake``) are checked here and carried out through ``BLENDER_COMMANDS``, which the extension's
bpy side fills when it registers; outside Blender the launcher loads the extension into the
``bpy`` module first and hands the command line to the extension's own copy of this module.
The device work registers ``devices``, ``emulate`` and the ``--device`` kinds
(``register_device_backend``).
"""
from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import traceback
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from . import limits, outputs
from .devices import cli_commands as device_commands

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2
EXIT_DEVICE_LOST = 3    # run: the session ran and was saved, but a device was lost during it
PROG = "grasp-lab"


class CliError(Exception):
    """A command that failed; the message names the file and what is wrong (exit 1)."""


@dataclass
class Command:
    name: str
    help: str
    configure: Callable      # (argparse.ArgumentParser) -> None
    run: Callable            # (args, out) -> int | None
    needs_blender: bool | Callable = False      # or (args) -> bool: whether these arguments need it


COMMANDS: dict[str, Command] = {}
# The work of the commands that need Blender (``needs_blender``: run, bake, emulate --from), by name: the bpy side
# fills this table when the extension registers (cli_blender.py); their checks run here first.
# Outside Blender the launcher (launcher.py) sets ``load_extension``: it loads the extension into
# the bpy module and returns the extension's own ``main``, which such a command is handed to.
BLENDER_COMMANDS: dict[str, Callable] = {}
load_extension: Callable | None = None
# Device backends by SPEC kind ("serial", "spacemouse", "opengloves"): kind -> factory(spec, n_fingers).
DEVICE_BACKENDS: dict[str, Callable] = {}


def register_command(name, help, configure, run, needs_blender=False) -> None:
    COMMANDS[name] = Command(name, help, configure, run, needs_blender)


def register_device_backend(kind: str, factory: Callable) -> None:
    DEVICE_BACKENDS[kind] = factory


def check_device(spec: str):
    """A --device SPEC read by its backend, or CliError saying what is wrong or missing."""
    kind = spec.split(":", 1)[0]
    if kind not in DEVICE_BACKENDS:
        known = ", ".join(sorted(DEVICE_BACKENDS)) or "none yet"
        raise CliError(f"--device {spec}: device backend {kind!r} is not available "
                       f"(registered backends: {known}); run without --device to use the "
                       f"scene's animated fingertips")
    try:
        return DEVICE_BACKENDS[kind](spec)
    except ValueError as ex:
        raise CliError(str(ex)) from None


# ------------------------------------------------------------------------ arguments

def _override(text):
    from .resim import OverrideError, parse_override
    try:
        return parse_override(text)
    except OverrideError as ex:
        raise argparse.ArgumentTypeError(str(ex)) from None


def _positive_int(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if not 1 <= v <= limits.MAX_EVERY:
        raise argparse.ArgumentTypeError(f"must be in 1 .. {limits.MAX_EVERY}, got {v}")
    return v


def _positive_float(high):
    """A number in (0, high]: the range is in the message of a value outside it."""
    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not 0 < v <= high:
            raise argparse.ArgumentTypeError(f"must be in (0, {high:g}], got {text}")
        return v
    return parse


def _size(text):
    try:
        return limits.parse_size(text)
    except ValueError as ex:
        raise argparse.ArgumentTypeError(str(ex)) from None


MAX_SIZE_HELP = (f"refuse a recording that could take more than this (500M, 2G; default "
                 f"{limits.DEFAULT_MAX_SIZE / 1e9:g}G), or more than the free space")
SET_HELP = ("OBJECT.PROPERTY=VALUE (mass, mu_s, mu_d, viscosity, radius, stiffness, damping, cursor_mass, "
            "renderer=xfca|cursor, torsion: a fingertip's Soft Tip Radius) or a "
            "scene setting: haptic_rate=HZ, gravity=X,Y,Z, gyroscopic=0|1; repeatable")


def _configure_run(p):
    p.add_argument("scene", metavar="SCENE.blend", help="the .blend to simulate")
    p.add_argument("--duration", type=_positive_float(limits.MAX_DURATION), metavar="S",
                   help=f"seconds to run, up to {limits.MAX_DURATION:g} (default: the scene's duration, "
                        f"else its animation)")
    p.add_argument("--realtime", action="store_true",
                   help="the threaded runtime at wall-clock speed, as a live session "
                        "(default: stepped as fast as it goes, deterministic)")
    p.add_argument("--device", action="append", default=[], metavar="SPEC",
                   help="an input device: serial:PORT, spacemouse, opengloves:PORT (repeatable)")
    p.add_argument("--forces", choices=("on", "off"), default="off",
                   help="device forces (default off, as in the UI): on turns them on at the start, ramping "
                        "in, with the same safety as the sidebar's Forces On")
    p.add_argument("--record", metavar="OUT.mcap", help="record every haptic tick to this file")
    p.add_argument("--sound", action="store_true",
                   help="with --realtime: play the grasp's sound through Blender's audio (docs/sound.md); "
                        "headless Blender has no audio device, and says so")
    p.add_argument("--max-size", type=_size, default=limits.DEFAULT_MAX_SIZE, metavar="BYTES", help=MAX_SIZE_HELP)
    p.add_argument("--save", metavar="OUT.blend", help="save the scene after the session")
    p.add_argument("--set", action="append", default=[], type=_override, metavar="KEY=VALUE", help=SET_HELP)
    p.add_argument("--live-view", nargs="?", const=8765, type=_live_view, metavar="PORT|rerun",
                   help="with --realtime: serve the session to Foxglove over WebSocket, watching only "
                        "(default port 8765; 0: any free port); rerun, rerun:PORT or rerun:HOST:PORT: stream "
                        "it to a Rerun viewer (default 127.0.0.1:9876, the viewer's own)")
    p.add_argument("--live-view-bind", default="127.0.0.1", metavar="ADDR",
                   help="the address the live view listens on (default 127.0.0.1: this machine only)")


def _live_view(text):
    """--live-view's value: a port (Foxglove) or a Rerun viewer's address (rerun[:[HOST:]PORT])."""
    if text.split(":", 1)[0] == "rerun":
        from .rerun_view import live_url
        try:
            live_url(text)
        except ValueError as ex:
            raise argparse.ArgumentTypeError(str(ex)) from None
        return text
    return _port(text)


def _port(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number, got {text!r}") from None
    if not 0 <= v <= 65535:
        raise argparse.ArgumentTypeError(f"a port is 0..65535, got {v}")
    return v


def _configure_info(p):
    p.add_argument("recording", metavar="REC.mcap")


def _configure_continuity(p):
    p.add_argument("recording", metavar="REC.mcap")
    p.add_argument("--threshold", type=_positive_float(limits.MAX_CONTINUITY_THRESHOLD), default=None,
                   metavar="N", help="per-tick force change listed with its cause (default 0.25 N)")
    p.add_argument("--field", choices=("device_force", "force"), default="device_force",
                   help="the force measured: what the device got (default) or the coupling force")
    p.add_argument("--max-jumps", type=_positive_int, default=20, metavar="N",
                   help="list at most N changes per finger (default 20)")
    p.add_argument("--strict", action="store_true", help="exit 1 when a change above the threshold has no cause")


def _configure_bake(p):
    p.add_argument("recording", metavar="REC.mcap")
    p.add_argument("scene", metavar="SCENE.blend", help="the scene the recording was made in")
    p.add_argument("--save", metavar="OUT.blend", required=True, help="where to save the baked scene")
    p.add_argument("--every-tick", action="store_true",
                   help="a key at every haptic tick (subframes) instead of every frame")
    p.add_argument("--force", action="store_true",
                   help="bake even when some of the recording's bodies and fingers are not in the scene")


def _configure_resim(p):
    p.add_argument("recording", metavar="REC.mcap")
    p.add_argument("--set", action="append", default=[], type=_override, metavar="KEY=VALUE", help=SET_HELP)
    p.add_argument("--record", metavar="OUT.mcap", help="write the new run as a recording")
    p.add_argument("--max-size", type=_size, default=limits.DEFAULT_MAX_SIZE, metavar="BYTES", help=MAX_SIZE_HELP)
    p.add_argument("--tolerance", type=_positive_float(limits.MAX_TOLERANCE), default=1e-6, metavar="METRES",
                   help="distance at which a body or god-object counts as diverged (default 1e-6)")


def _configure_export(p):
    p.add_argument("recording", metavar="REC.mcap")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--csv", metavar="DIR", help="write DIR/bodies.csv, fingers.csv, events.csv")
    g.add_argument("--npz", metavar="FILE", help="write one .npz with every field")
    g.add_argument("--foxglove", metavar="OUT.mcap", help="a copy Foxglove shows: 3-D scene, transforms, "
                                                          "plot channels, events, at the display rate")
    g.add_argument("--wav", metavar="OUT.wav", help="the grasp as sound: contact clicks, a tone whose pitch "
                                                    "follows the normal force, slip scrapes, slip-margin "
                                                    "warnings (docs/sound.md)")
    g.add_argument("--rerun", metavar="OUT.rrd", help="a Rerun recording: 3-D scene, plots, events and a layout, "
                                                      "at the display rate (needs rerun-sdk)")
    p.add_argument("--every", type=_positive_int, default=1, metavar="N", help="every N-th tick (default 1)")
    p.add_argument("--every-tick", action="store_true",
                   help="with --rerun: a frame for every recorded haptic tick instead of the display rate")
    p.add_argument("--sound-map", action="append", default=[], metavar="KEY=VALUE",
                   help="with --wav: a setting of the sound's mapping, e.g. pitch_low=200, pitch_high=1200, "
                        "force_full=5, curve=1, volume=0.8 (docs/sound.md lists them)")


def _edges(text):
    v = _positive_int(text)
    if v < 3:
        raise argparse.ArgumentTypeError(f"a friction cone needs at least 3 edges, got {v}")
    return v


def _configure_analyze(p):
    p.add_argument("recording", metavar="REC.mcap")
    p.add_argument("--csv", metavar="DIR", help="write DIR/grasp.csv (per analysed tick and held body) and "
                                                "DIR/contacts.csv (the finger contacts it used)")
    p.add_argument("--every", type=_positive_int, default=1, metavar="N",
                   help="analyse every N-th haptic tick (default 1: all)")
    p.add_argument("--edges", type=_edges, default=8, metavar="K",
                   help="edges of each linearised friction cone (>= 3, default 8)")


# ------------------------------------------------------------------------ commands

def _warn(rec_or_summary, err):
    damage = rec_or_summary.damage if hasattr(rec_or_summary, "damage") else rec_or_summary["damage"]
    path = rec_or_summary.path if hasattr(rec_or_summary, "path") else rec_or_summary["path"]
    writer = outputs.writer_of(path) if damage else ""
    for d in damage:
        if writer and "cut short" in d:     # not cut short: its session is still going
            d = (f"still being written ({writer} is recording it): what it holds so far was read, "
                 f"up to its last flush")
        print(f"{PROG}: warning: {path}: {d}", file=err)


def _open(path, err):
    from .recording import open_recording
    rec = open_recording(path)
    _warn(rec, err)
    if len(rec.ticks) == 0:
        raise CliError(f"{path}: no tick was recorded")
    return rec


def _run_info(args, out, err):
    from .recording import summarize
    s = summarize(args.recording)
    _warn(s, err)
    p = lambda *a: print(*a, file=out)  # noqa: E731
    p(f"{s['path']}: Grasp Lab recording, format {s['format_version']}, {s['size'] / 1e6:.2f} MB"
      + (f", {s['chunks']} chunks" if s["chunks"] else ""))
    p(f"mode        {s['mode']}   created {s['created']}   source {s['source'] or '-'}")
    p(f"duration    {s['duration']:.3f} s   haptic ticks {s['ticks']}   rate {s['haptic_rate']:g} Hz"
      + (f"   scene fps {s['rates']['fps']:g}" if s["rates"].get("fps") else ""))
    p(f"fingers     {len(s['fingers'])}: " + ", ".join(
        f"{f['name']} (r {f['radius']:g} m, k {f['stiffness']:g} N/m, c {f['damping']:g} N s/m"
        + (f", soft tip {f['torsion']:g} m" if f.get("torsion") else "") + ")"
        for f in s["scene"]["fingers"]))
    p(f"bodies      {len(s['bodies'])}: " + ", ".join(
        f"{b['name']} (" + ("static" if b["static"] else f"{b['mass']:g} kg") +
        f", mu_s {b['mu_s']:g}, mu_d {b['mu_d']:g})" for b in s["scene"]["bodies"]))
    sc = s["scene"]
    p(f"parameters  gravity {tuple(sc['gravity'])} m/s^2, gyroscopic {int(sc['gyroscopic'])}, "
      f"fingerprint {s['fingerprint'][:16]}")
    if s["runtime"]:
        p("runtime     " + ", ".join(f"{k} {v}" for k, v in s["runtime"].items()))
    if s["device"]:
        p("device      " + ", ".join(f"{k} {v}" for k, v in s["device"].items() if k != "drivers"))
    from .devices.live import loss_lines, recorded_device_events
    for line in loss_lines(recorded_device_events(s["event_list"])):
        p("device      " + line)
    p("versions    " + ", ".join(f"{k} {v}" for k, v in (s["versions"] or {}).items()))
    p("events      " + (", ".join(f"{k} {v}" for k, v in sorted(s["events"].items())) or "none"))
    p("continuity  " + _continuity_line(args.recording, s["ticks"]))
    if s["overflow"]:
        p(f"overflow    {s['overflow']} ticks dropped by the recorder (ring full)")
    if s["recorder_error"]:
        p(f"recorder    {s['recorder_error']}")
    if s["ended_by"]:
        p(f"ended       early, by {s['ended_by']} (clean: false)")
    p("damage      " + ("; ".join(s["damage"]) if s["damage"] else "none (summary, footer and data CRC intact)"))
    return EXIT_OK


# info reads every tick for its continuity line up to this many (about a second of reading);
# a longer recording names the command that measures it, so info stays quick.
INFO_CONTINUITY_TICKS = 200_000


def _continuity_line(path, ticks: int) -> str:
    """The force continuity of a recording in one line (reads its ticks)."""
    from .continuity import force_continuity, summary_line
    from .recording import RecordingError, open_recording
    if ticks > INFO_CONTINUITY_TICKS:
        return (f"not measured by info for {ticks} ticks (more than {INFO_CONTINUITY_TICKS}): "
                f"grasp-lab continuity {path}")
    try:
        rec = open_recording(path)
    except (RecordingError, OSError, ValueError) as ex:
        return f"not measured ({ex})"
    if len(rec.ticks) < 2:
        return "not measured (fewer than 2 ticks)"
    return summary_line(force_continuity(rec))


def _run_continuity(args, out, err):
    from .continuity import DEFAULT_THRESHOLD, force_continuity, report, unexplained
    rec = _open(args.recording, err)
    result = force_continuity(rec, threshold=args.threshold or DEFAULT_THRESHOLD, field=args.field)
    print(report(result, max_jumps=args.max_jumps), file=out)
    bad = unexplained(result)
    if args.strict and bad:
        name, j = bad[0]
        raise CliError(f"{args.recording}: {len(bad)} force change(s) above {result['threshold']:g} N with no "
                       f"cause, the first: {name} {j['delta']:.3f} N at tick {j['tick']}")
    return EXIT_OK


def _load_core():
    from . import core_loader
    return core_loader.load()


def _run_resim(args, out, err):
    from .resim import resimulate
    outputs.check_paths({"REC.mcap": args.recording}, {"--record": args.record})
    rec = _open(args.recording, err)
    result = resimulate(rec, _load_core(), overrides=args.set, tolerance=args.tolerance,
                        record_path=args.record, max_size=args.max_size)
    print(result.divergence.report(), file=out)
    if result.path:
        print(f"new run: {result.path} ({len(result.ticks)} ticks)", file=out)
    return EXIT_OK


def _run_export(args, out, err):
    from .export import export_csv, export_npz
    outputs.check_paths({"REC.mcap": args.recording}, {"--csv": args.csv, "--npz": args.npz, "--wav": args.wav,
                                                       "--foxglove": args.foxglove, "--rerun": args.rerun},
                        folders=("--csv",))
    if args.csv:
        for name in ("bodies.csv", "fingers.csv", "events.csv"):
            outputs.check_paths({"REC.mcap": args.recording}, {"--csv": os.path.join(args.csv, name)})
    if args.every_tick and not args.rerun:
        raise CliError("--every-tick goes with --rerun (--csv and --npz take --every N)")
    mapping = None
    if args.sound_map:
        if not args.wav:
            raise CliError("--sound-map goes with --wav")
        from .sound import mapping_from
        try:
            mapping = mapping_from(args.sound_map)
        except ValueError as ex:
            raise CliError(str(ex)) from None
    rec = _open(args.recording, err)
    if args.rerun:
        from .rerun_view import export_rerun
        try:
            done = export_rerun(rec, args.rerun, every_tick=args.every_tick)
        except ImportError as ex:
            raise CliError(str(ex)) from None
        print(f"{args.rerun}: {done['frames']} frames at {done['rate']:g} Hz, {done['events']} events, "
              f"{done['bytes'] / 1e6:.2f} MB", file=out)
    elif args.foxglove:
        from .viewer import export_foxglove
        try:
            done = export_foxglove(rec, args.foxglove)
        except ImportError as ex:
            raise CliError(str(ex)) from None
        print(f"{args.foxglove}: {done['frames']} frames at {done['rate']:g} Hz, {done['events']} events, "
              f"{done['bytes'] / 1e6:.2f} MB; layout {done['layout']}", file=out)
    elif args.wav:
        from .sound import write_wav
        done = write_wav(args.wav, rec.header["scene"], rec.ticks, mapping)
        print(f"{args.wav}: {done['seconds']:.3f} s of sound at {done['rate']} Hz, {done['clicks']} clicks",
              file=out)
    elif args.csv:
        counts = export_csv(rec, args.csv, args.every)
        for name, n in counts.items():
            print(f"{os.path.join(args.csv, name)}: {n} rows", file=out)
    else:
        n = export_npz(rec, args.npz, args.every)
        print(f"{args.npz}: {n} ticks", file=out)
    return EXIT_OK


def _run_analyze(args, out, err):
    from .analysis import analyse_recording, check_recording, point_contacts_note, summary
    from .recording import open_recording
    outputs.check_paths({"REC.mcap": args.recording}, {"--csv": args.csv}, folders=("--csv",))
    if args.csv:
        for name in ("grasp.csv", "contacts.csv"):
            outputs.check_paths({"REC.mcap": args.recording}, {"--csv": os.path.join(args.csv, name)})
    rec = open_recording(args.recording, every=args.every)
    _warn(rec, err)
    if len(rec.ticks) == 0:
        raise CliError(f"{args.recording}: no tick was recorded")
    check_recording(rec)
    table = analyse_recording(rec, every=args.every, edges=args.edges)
    analysed = int(np.count_nonzero(rec.ticks["tick"] % args.every == 0))
    print(f"{args.recording}: {analysed} ticks analysed (every {args.every}), {len(table.body)} held-body "
          f"samples, {len(table.finger)} contacts, cones of {args.edges} edges", file=out)
    times = rec.ticks["time"][table.snapshot]
    for line in summary(table, times, rec.body_names, rec.finger_names, args.every / rec.haptic_rate):
        print(line, file=out)
    note = point_contacts_note(rec)
    if note:
        print(note, file=out)
    if args.csv:
        from .export import export_analysis_csv
        for name, n in export_analysis_csv(rec, table, args.csv).items():
            print(f"{os.path.join(args.csv, name)}: {n} rows", file=out)
    return EXIT_OK


def _run_run(args, out, err):
    outputs.check_paths({"SCENE.blend": args.scene}, {"--record": args.record, "--save": args.save})
    for spec in args.device:
        check_device(spec)
    if args.live_view is not None and not args.realtime:
        raise CliError("--live-view needs --realtime (it serves a live session)")
    if args.sound and not args.realtime:
        raise CliError("--sound needs --realtime (it plays a live session)")
    if args.device and not args.realtime:
        raise CliError("--device needs --realtime (devices drive a live session on the threaded runtime)")
    if args.forces == "on" and not args.device:
        raise CliError("--forces on needs --device (device forces go to the devices of the session)")
    for spec in args.device:
        check_port(spec)
    return BLENDER_COMMANDS["run"](args, out, err)


def check_port(spec: str) -> None:
    """A --device SPEC's serial port opens and is a terminal (can be configured), checked
    before any file is touched."""
    import termios
    kind, _, rest = spec.partition(":")
    port = rest.partition("@")[0] if kind in ("serial", "opengloves") else ""
    if not port:
        return
    try:
        fd = os.open(port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError as ex:
        raise CliError(f"--device {spec}: cannot open {port} ({ex.strerror})") from None
    try:
        termios.tcgetattr(fd)
    except termios.error as ex:
        raise CliError(f"--device {spec}: {port} is not a serial port (cannot be configured: "
                       f"{ex.args[-1]})") from None
    finally:
        os.close(fd)


def _run_bake(args, out, err):
    outputs.check_paths({"REC.mcap": args.recording, "SCENE.blend": args.scene}, {"--save": args.save})
    return BLENDER_COMMANDS["bake"](args, out, err)


register_command("run", "run a scene headless (EXEC, deterministic; --realtime: the threaded runtime)",
                 _configure_run, _run_run, needs_blender=True)
register_command("info", "duration, ticks, rates, fingers, bodies, parameters, events and damage of a "
                         "recording", _configure_info, _run_info)
register_command("continuity", "per-tick change of each finger's force: its distribution and every change "
                               "above a threshold with its cause", _configure_continuity, _run_continuity)
register_command("bake", "bake a recording into a scene as keyframes", _configure_bake, _run_bake,
                 needs_blender=True)
register_command("resim", "re-simulate a recording (with overrides); 'identical' or the divergence report",
                 _configure_resim, _run_resim)
register_command("export", "a recording as CSV tables, one .npz, a viewer's copy (Foxglove, Rerun) or its "
                           "sound (.wav)", _configure_export, _run_export)


def _configure_view(p):
    p.add_argument("recording", metavar="REC.mcap")
    p.add_argument("--screenshot", metavar="PNG", help="write the viewer's picture to PNG and exit (needs a "
                                                       "display: headless, Xvfb)")
    p.add_argument("--size", default="1600x900", metavar="WxH", help="with --screenshot: the window size "
                                                                      "(default 1600x900)")
    p.add_argument("--every-tick", action="store_true", help="a frame for every recorded haptic tick")


def _run_view(args, out, err):
    from .rerun_view import view_recording
    outputs.check_paths({"REC.mcap": args.recording}, {"--screenshot": args.screenshot})
    try:
        done = view_recording(args.recording, screenshot=args.screenshot, size=args.size,
                              every_tick=args.every_tick, warn=lambda line: print(f"{PROG}: warning: {line}",
                                                                                  file=err))
    except ImportError as ex:
        raise CliError(str(ex)) from None
    print(f"{done['rrd']}: " + ("converted" if done["converted"] else "up to date (cached)"), file=out)
    if args.screenshot:
        print(f"screenshot: {args.screenshot}", file=out)
    else:
        print(f"Rerun viewer started (pid {done['pid']})", file=out)
    return EXIT_OK


register_command("view", "open a recording in the Rerun viewer (converted once, cached beside it); "
                         "--screenshot PNG: its picture", _configure_view, _run_view)
register_command("analyze", "grasp analysis of a recording: closure, epsilon, slip margins, grip against load "
                            "(docs/analysis.md)", _configure_analyze, _run_analyze)


# devices, emulate and the --device kinds (engine/devices, docs/devices.md). emulate --from
# SCENE.blend needs Blender to read the .blend: then it is a Blender command (emulate_blend.py).
def _run_emulate(args, out, err):
    if args.from_blend:
        return BLENDER_COMMANDS["emulate"](args, out, err)
    return device_commands.cmd_emulate(args)


def _configure_emulate(p):
    from .devices.emulator import build_parser
    build_parser(p)


register_command("devices", device_commands.DEVICES_HELP, device_commands.configure_devices,
                 lambda args, out, err: device_commands.cmd_devices(args, out))
register_command("emulate", device_commands.EMULATE_HELP, _configure_emulate, _run_emulate,
                 needs_blender=lambda args: bool(args.from_blend))
for _kind in ("serial", "udp", "spacemouse", "opengloves"):
    register_device_backend(_kind, lambda spec, n_fingers=None: device_commands.parse_device_spec(spec))


# sweep (engine/sweep.py, docs/sweeps.md)
SWEEP_HELP = "robustness: re-simulate a recording many times with varied parameters; how likely it holds"


def _vary_arg(text):
    from .sweep import SweepError, parse_vary
    try:
        return parse_vary(text)
    except SweepError as ex:
        raise argparse.ArgumentTypeError(str(ex)) from None


def _ranged_int(low: int, high: int):
    """A whole number in low .. high: the range is in the message of a value outside it."""
    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if not low <= v <= high:
            raise argparse.ArgumentTypeError(f"must be in {low} .. {high:,}, got {v}")
        return v
    return parse


def _configure_sweep(p) -> None:
    from .sweep import ANALYSIS_PERIOD, MAX_SAMPLES
    p.add_argument("recording", metavar="REC.mcap", help="a recording (or SCENE.blend: recorded first)")
    p.add_argument("--samples", type=_ranged_int(1, MAX_SAMPLES), required=True, metavar="N",
                   help=f"samples (per cell of the grid axes, if any), 1 .. {MAX_SAMPLES:,}")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="the sweep's seed (default 0)")
    p.add_argument("--vary", action="append", default=[], type=_vary_arg, metavar="SPEC",
                   help="KEY=LO:HI (uniform), KEY=MEAN~SD (normal), KEY=A,B,C (grid); keys: OBJECT.PROPERTY "
                        "as in --set, gravity, OBJECT.com=SD, hip_noise=SD, hip_offset=SD, push=N@T, "
                        "device=PROFILE,PROFILE (each sample evaluated against its device); repeatable")
    p.add_argument("--out", required=True, metavar="DIR", help="samples.csv, summary.json, map.png, outcomes.png "
                                                              "(a sweep there already is resumed)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_ranged_int(1, os.cpu_count() or 1), default=os.cpu_count() or 1,
                       metavar="K", help=f"local worker processes, 1 .. the core count ({os.cpu_count() or 1}, "
                                         f"the default); more run on a --scheduler")
    where.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="an existing Dask scheduler")
    p.add_argument("--body", metavar="NAME", help="the held body (default: the one the recording holds longest)")
    p.add_argument("--no-analysis", action="store_true",
                   help="skip the grasp measures (time in force closure, smallest epsilon)")
    p.add_argument("--force", action="store_true",
                   help="write into a --out folder that holds files no sweep wrote (a file of a sweep's "
                        "name, map.png, is replaced)")
    p.add_argument("--analysis-period", type=_positive_float, default=ANALYSIS_PERIOD, metavar="S",
                   help=f"the grasp measures every S seconds while held (default {ANALYSIS_PERIOD})")


def _run_sweep(args, out, err) -> int:
    from .recording import open_recording
    from .sweep import PICTURES, RECORDING_FILE, SAMPLES_FILE, SPEC_FILE, SUMMARY_FILE, claim_folder, sweep
    path = args.recording
    if path.endswith(".blend"):
        recorded = os.path.join(args.out, RECORDING_FILE)
        claim_folder(args.out, (RECORDING_FILE, SPEC_FILE, SAMPLES_FILE, SUMMARY_FILE) + PICTURES, args.force)
        if not os.path.exists(recorded):
            if main(["run", path, "--record", recorded], out=err, err=err) != 0:
                raise CliError(f"{path}: could not record the scene to sweep")
        path = recorded
    rec = open_recording(path)
    for d in rec.damage:
        print(f"grasp-lab: warning: {path}: {d}", file=err)
    last = [0.0]

    def progress(done, total, seconds):
        if seconds - last[0] >= 2.0 or done == total:
            last[0] = seconds
            print(f"sweep: {done}/{total} samples, {seconds:.1f} s", file=err, flush=True)
    result = sweep(rec, args.vary, args.samples, args.seed, args.out, workers=args.workers,
                   scheduler=args.scheduler, body=args.body, analysis=not args.no_analysis,
                   analysis_period=args.analysis_period, progress=progress, force=args.force)
    s = result.summary
    print(f"{s['held']} of {s['samples']} samples held {s['body']!r}: p = {s['p_held']:.3f}, "
          f"95 % interval {s['ci95'][0]:.3f} .. {s['ci95'][1]:.3f}", file=out)
    if result.ran:
        print(f"{result.ran} samples re-simulated in {result.seconds:.1f} s "
              f"({result.ran / max(result.seconds, 1e-9):.1f} samples/s)", file=out)
    for name, entry in s["sensitivity"].items():
        c = entry["correlation_with_held"]
        print(f"  {name:<24} correlation with holding {'-' if c is None else f'{c:+.2f}'}", file=out)
    for name, d in s.get("devices", {}).items():
        print(f"  device {name:<17} renders {d['fits']} of its {d['samples']} samples (grasp-lab fit)", file=out)
    for p_ in result.paths:
        print(p_, file=out)
    return 0


register_command("sweep", SWEEP_HELP, _configure_sweep, _run_sweep)



# fit (engine/fit.py, docs/devices.md "Can this device do this task?")
FIT_HELP = "can these devices render this grasp? each finger's verdict against device profiles, with where and why"


def _configure_fit(p) -> None:
    p.add_argument("recording", metavar="REC.mcap", nargs="?", help="the recorded grasp (not with --list)")
    p.add_argument("--device", action="append", default=[], metavar="PROFILE[:FINGERS]",
                   help="a device profile (a name from --list, or a .toml file) and, optionally, the recording's "
                        "fingers it takes, comma-separated, one an end-effector in order; repeatable: several "
                        "devices are ranked")
    p.add_argument("--frame", metavar="X,Y,Z[,YAW]",
                   help="where the device frame is in the scene, metres (and its turn about z, degrees); "
                        "default the scene origin")
    p.add_argument("--csv", metavar="DIR", help="write DIR/margins.csv: every check's margin per tick and finger")
    p.add_argument("--every", type=_positive_int, default=1, metavar="N", help="--csv: every N-th tick (default 1)")
    p.add_argument("--json", metavar="OUT", help="write the verdicts as JSON")
    p.add_argument("--list", action="store_true", help="print the device profiles, one a line, name first")


def _run_fit(args, out, err) -> int:
    from .devices import device_profiles
    from .fit import FitError, fit_recording, parse_frame, report_lines, write_csv, write_json
    try:
        if args.list:
            for profile in device_profiles.load_all():
                print(profile.line(), file=out)
            return EXIT_OK
        if not args.recording:
            raise CliError("a recording is needed (grasp-lab fit REC.mcap --device PROFILE ...), or --list")
        outputs.check_paths({"REC.mcap": args.recording}, {"--json": args.json, "--csv": args.csv},
                            folders=("--csv",))
        frame = parse_frame(args.frame) if args.frame else None
        if not args.device:
            raise CliError("no device given (--device PROFILE[:FINGERS]; grasp-lab fit --list names them)")
        from .fit import parse_spec
        for spec in args.device:
            parse_spec(spec)            # an unknown or bad profile before the recording is read
        rec = _open(args.recording, err)
        task, results = fit_recording(rec, args.device, frame)
    except (FitError, device_profiles.ProfileError) as ex:
        raise CliError(str(ex)) from None
    print(f"{args.recording}: {len(task.finger_names)} fingers ({', '.join(task.finger_names)}), "
          f"{len(task.time)} ticks, {task.time[-1] - task.time[0]:.3f} s; {len(results)} device"
          f"{'s' if len(results) > 1 else ''}, best first", file=out)
    for line in report_lines(results):
        print(line, file=out)
    if args.csv:
        path, rows = write_csv(results, task, args.csv, args.every)
        print(f"{path}: {rows} rows", file=out)
    if args.json:
        print(f"{write_json(results, args.json)}: verdicts", file=out)
    return EXIT_OK


register_command("fit", FIT_HELP, _configure_fit, _run_fit)

# ------------------------------------------------------------------------ dispatch

def build_parser(prog=PROG) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description="Grasp Lab: multi-finger grasp sessions, "
                                                            "recordings, baking and re-simulation.")
    parser.add_argument("--debug", action="store_true", help="a traceback with an error")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for cmd in COMMANDS.values():
        p = sub.add_parser(cmd.name, help=cmd.help, description=cmd.help)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="a traceback with an error")
        cmd.configure(p)
    return parser


def main(argv=None, prog=PROG, out=None, err=None) -> int:
    out = out or sys.stdout
    err = err or sys.stderr
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(prog)
    try:
        args = parser.parse_args(argv)
    except SystemExit as ex:      # --help (0) or a usage error (2): argparse has printed it
        return EXIT_USAGE if ex.code not in (0, None) else EXIT_OK
    cmd = COMMANDS[args.command]
    with _signals_stop(), _warnings_once(prog, cmd.name, err):
        try:
            needs_blender = cmd.needs_blender(args) if callable(cmd.needs_blender) else cmd.needs_blender
            if needs_blender and cmd.name not in BLENDER_COMMANDS:
                try:
                    if load_extension is None:
                        raise RuntimeError("run it with grasp-lab or blender -c grasp_lab")
                    extension_main = _load_unsignalled(load_extension)
                except (ImportError, RuntimeError, OSError) as ex:
                    print(f"{prog} {cmd.name}: error: Blender (the bpy module) with the Grasp Lab extension "
                          f"is needed: {ex}", file=err)
                    return EXIT_FAILED
                return extension_main(argv, prog, out, err)
            return _run_command(cmd, args, prog, out, err)
        except KeyboardInterrupt:       # a signal while Blender was loading
            return _stopped(prog, cmd.name, err)


def _load_unsignalled(load):
    """Blender (bpy and the extension) loaded with the stop signals held back: a signal in
    the middle of Blender's start-up is not a Python exception inside Blender's C code (a
    traceback and a command that ran on, or a crash). One that arrived is taken when the
    load is done: the command stops there, before it has begun (nothing written)."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        loaded = load()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)      # a held signal is handled here
    return loaded


def _run_command(cmd, args, prog, out, err) -> int:
    """The command, its failure as one line (a traceback only with --debug), a signal's stop
    as one line and exit 130 (SIGINT) / 143 (SIGTERM), after what was written is finished."""
    from .recording import RecordingError
    from .scene import SceneError
    try:
        code = int(cmd.run(args, out, err) or EXIT_OK)
    except KeyboardInterrupt:
        return _stopped(prog, cmd.name, err)
    except (CliError, RecordingError, SceneError, ValueError, OSError, MemoryError) as ex:
        if args.debug:
            traceback.print_exc(file=err)
        msg = str(ex) or type(ex).__name__
        if isinstance(ex, OSError) and getattr(ex, "filename", None) and str(ex.filename) not in msg:
            msg = f"{ex.filename}: {msg}"
        if _stop_signal:
            return _stopped(prog, cmd.name, err, msg)
        print(f"{prog} {cmd.name}: error: {msg}", file=err)
        return EXIT_FAILED
    except Exception as ex:  # noqa: BLE001 - one line, not a traceback, unless asked
        if args.debug:
            traceback.print_exc(file=err)
        print(f"{prog} {cmd.name}: error: internal error, {type(ex).__name__}: {ex}"
              + ("" if args.debug else " (--debug shows where)"), file=err)
        return EXIT_FAILED
    finally:
        for partial in outputs.close_unfinished():
            print(f"{prog} {cmd.name}: warning: {partial}: left unfinished (a readable prefix; "
                  f"`grasp-lab info` reads it)", file=err)
    if _stop_signal:        # caught on the way (a live session ends on Ctrl-C) and finished
        return _stopped(prog, cmd.name, err)
    return code


# ------------------------------------------------------------------------ signals, warnings

_stop_signal = 0        # the signal that is stopping this command (0: none)
SIGNAL_NAMES = {1: "SIGHUP (terminal closed)", 2: "SIGINT (Ctrl-C)", 15: "SIGTERM"}
STOP_SIGNALS = (signal.SIGHUP, signal.SIGINT, signal.SIGTERM)


def _on_signal(signum, frame):
    """SIGINT / SIGTERM / SIGHUP: the first one stops the command where it is (KeyboardInterrupt, so
    every ``finally`` finishes what it writes); later ones wait for that to finish."""
    global _stop_signal
    if _stop_signal:
        return
    _stop_signal = signum
    from .recording import set_stop_reason
    set_stop_reason(SIGNAL_NAMES.get(signum, f"signal {signum}"))
    if outputs.defer_stop(SIGNAL_NAMES.get(signum)):
        return          # raised when the write it arrived in is whole (outputs.uninterrupted)
    raise KeyboardInterrupt(SIGNAL_NAMES.get(signum))


def _stopped(prog, name, err, detail="") -> int:
    signum = _stop_signal or signal.SIGINT
    done = outputs.written()
    what = (f"finished {', '.join(done)}" if done else "nothing was written")
    _say(err, f"{prog} {name}: stopped by {SIGNAL_NAMES.get(signum, signum)}; {what}"
         + (f" ({detail})" if detail else ""))
    return 128 + int(signum)


def _say(err, line: str) -> None:
    """A line on standard error that may be gone (SIGHUP: the terminal closed): not an error."""
    try:
        print(line, file=err, flush=True)
    except (OSError, ValueError):
        pass


@contextlib.contextmanager
def _signals_stop():
    """SIGINT, SIGTERM and SIGHUP handled by _on_signal for the command (main thread only)."""
    global _stop_signal
    from .recording import set_stop_reason
    _stop_signal = 0
    set_stop_reason("")
    outputs.forget_written()
    try:
        old = {sig: signal.signal(sig, _on_signal) for sig in STOP_SIGNALS}
    except ValueError:          # not the main thread: signals are the host's business
        old = {}
    try:
        yield
    finally:
        for sig, handler in old.items():
            # None: the host installed its handler in C (Blender's own), which Python cannot
            # put back; the default then (`blender -c` exits after the command).
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        set_stop_reason("")     # a later session in this process (Blender) ends as it ends


@contextlib.contextmanager
def _warnings_once(prog, name, err):
    """Each distinct warning printed once, as one line; repeats counted and said at the end."""
    seen = {}

    def show(message, category, filename, lineno, file=None, line=None):
        text = f"{category.__name__}: {message}"
        seen[text] = seen.get(text, 0) + 1
        if seen[text] == 1:
            print(f"{prog} {name}: warning: {text}", file=err)

    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = show
        try:
            yield
        finally:
            for text, n in seen.items():
                if n > 1:
                    print(f"{prog} {name}: warning: {text} ({n - 1} more times)", file=err)
