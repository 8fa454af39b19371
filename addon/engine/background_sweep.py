"""A sweep (sweep.py) in a background process, for the Robustness panel (docs/blender.md): started,
watched and cancelled without ever blocking the caller. bpy-free.

The sweep runs in a child process of the caller's Python (Blender's own, in Blender) with the
engine as the importable zip Dask workers get (``sweep.engine_zip``): inside Blender the engine
is a module of the extension package, which a plain process cannot import. The child prints one
JSON line per progress report and one at the end; a reader thread queues them, and ``poll()``
takes what has come. Cancelling ends the child (its pool workers follow it, sweep.py); the
samples it finished stay in the sweep's folder, and the same sweep started again resumes there.
"""
from __future__ import annotations

import hashlib
import json
import os
import queue
import shutil
import subprocess
import sys
import tempfile
import threading

from . import core_loader
from . import sweep as _sweep

# The child: the engine from the zip, the sweep, its progress as JSON lines on stdout.
CHILD = r"""
import importlib, json, sys
args = json.loads(sys.argv[1])
sys.path[:0] = args["front"]
sys.path += args["back"]
def say(**kw):
    print(json.dumps(kw), flush=True)
try:
    sweep = importlib.import_module(args["package"] + ".engine.sweep")
    recording = importlib.import_module(args["package"] + ".engine.recording")
    rec = recording.open_recording(args["recording"])
    varies = [sweep.parse_vary(t) for t in args["varies"]]
    say(done=0, total=0, seconds=0.0)
    result = sweep.sweep(rec, varies, args["samples"], args["seed"], args["folder"], workers=args["workers"],
                         progress=lambda done, total, seconds: say(done=done, total=total, seconds=seconds))
    say(finished=True, summary=result.summary, paths=result.paths, ran=result.ran, seconds=result.seconds)
except Exception as ex:
    say(error=f"{type(ex).__name__}: {ex}")
    sys.exit(1)
"""


def panel_varies(rec, friction=None, mass=None, hip_noise=None, push=None) -> list:
    """The panel's keys as ``--vary`` specs on the body the recording holds longest: friction
    (mu_s LO, HI), mass (factors LO, HI of the recorded mass), hip_noise (SD, metres), push
    (N LO, HI, at time T s). Each checked as ``grasp-lab sweep`` checks it (SweepError)."""
    header = rec.header
    body = _sweep.choose_body(header, rec.ticks, None)
    entry = header["scene"]["bodies"][body]
    name = entry["name"]
    specs = []
    if friction is not None:
        specs.append(f"{name}.mu_s={friction[0]:g}:{friction[1]:g}")
    if mass is not None:
        m = float(entry["mass"])
        specs.append(f"{name}.mass={m * mass[0]:.6g}:{m * mass[1]:.6g}")
    if hip_noise is not None:
        specs.append(f"hip_noise={hip_noise:g}")
    if push is not None:
        specs.append(f"push={push[0]:g}:{push[1]:g}@{push[2]:g}")
    for text in specs:
        _sweep.parse_vary(text)
    if not specs:
        raise _sweep.SweepError("choose at least one thing to vary")
    return specs


def held_time(rec) -> tuple:
    """(body name, seconds) of the dynamic body the recording holds longest (held: at least
    sweep.HOLD_FINGERS fingers on it), ("", 0.0) when it never holds one: what the Robustness
    panel's list says of each recording, since only a held body can be swept."""
    scene = rec.header["scene"]
    best, longest = "", 0
    for i, b in enumerate(scene["bodies"]):
        if not b["static"]:
            n = int((_sweep.hold_counts(rec.ticks, i) >= _sweep.HOLD_FINGERS).sum())
            if n > longest:
                best, longest = b["name"], n
    return best, longest / float(rec.haptic_rate)


def recording_verdict(rec) -> str:
    """A recording in a few words for a list: what it holds and how long, or that it holds
    nothing (a sweep of it is refused)."""
    name, seconds = held_time(rec)
    return f"holds {name} {seconds:.1f} s" if name else "holds nothing: cannot be swept"


def sweep_folder(recording: str, varies, samples: int, seed: int) -> str:
    """Where a sweep of ``recording`` goes: beside it, named by what it is, so that the same
    sweep started again (after a Cancel) resumes there and another one never collides."""
    key = json.dumps([os.path.abspath(recording), list(varies), int(samples), int(seed)])
    stem = os.path.splitext(os.path.abspath(recording))[0]
    return f"{stem}_sweep_{hashlib.sha256(key.encode()).hexdigest()[:8]}"


class BackgroundSweep:
    """One sweep in a child process. ``poll()`` from any loop (a Blender timer) returns at once;
    ``done``/``total`` say how far it is, ``finished``, ``error`` or ``cancelled`` how it ended,
    ``summary`` and ``paths`` what it wrote."""

    def __init__(self, recording: str, varies, samples: int, seed: int, folder: str, workers: int):
        self.recording, self.varies = recording, list(varies)
        self.samples, self.seed, self.folder, self.workers = int(samples), int(seed), folder, int(workers)
        self.done = self.total = 0
        self.seconds = 0.0
        self.finished = self.cancelled = False
        self.error = ""
        self.summary, self.paths = None, []
        self._lines = queue.Queue()
        self._stderr = []
        self._proc = None
        self._scratch = None        # the engine zip's folder while the child may need it

    def start(self) -> None:
        os.makedirs(self.folder, exist_ok=True)
        # The engine the child imports goes to a folder of its own, deleted once the child is
        # gone: the results folder holds only results.
        self._scratch = tempfile.mkdtemp(prefix="grasp_lab_sweep_")
        path, package = _sweep.engine_zip(self._scratch)
        # The folder of the core this process runs (a built extension vendors it in engine/graspcore/,
        # which the zip leaves out): last on the child's path, after the caller's (numpy, mcap).
        core_folder = os.path.dirname(os.path.dirname(os.path.abspath(core_loader.load().__file__)))
        args = {"package": package, "recording": self.recording, "varies": self.varies,
                "samples": self.samples, "seed": self.seed, "folder": self.folder, "workers": self.workers,
                "front": [path] + [p for p in sys.path if p], "back": [core_folder]}
        self._proc = subprocess.Popen([sys.executable, "-c", CHILD, json.dumps(args)], stdin=subprocess.DEVNULL,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        threading.Thread(target=self._read, args=(self._proc.stdout, True), daemon=True,
                         name="grasp_lab sweep: progress").start()
        threading.Thread(target=self._read, args=(self._proc.stderr, False), daemon=True,
                         name="grasp_lab sweep: errors").start()

    def _read(self, stream, progress: bool) -> None:
        for line in stream:
            if not progress:
                self._stderr = (self._stderr + [line.rstrip()])[-20:]
                continue
            try:
                self._lines.put(json.loads(line))
            except ValueError:
                self._stderr = (self._stderr + [line.rstrip()])[-20:]

    @property
    def running(self) -> bool:
        return self._proc is not None and not (self.finished or self.cancelled or self.error)

    @property
    def fraction(self) -> float:
        return self.done / self.total if self.total else 0.0

    def poll(self) -> bool:
        """Takes the reports that have come; True while the sweep runs."""
        while True:
            try:
                msg = self._lines.get_nowait()
            except queue.Empty:
                break
            if "error" in msg:
                self.error = msg["error"]
            elif msg.get("finished"):
                self.finished, self.summary, self.paths = True, msg["summary"], msg["paths"]
                self.seconds = msg["seconds"]
                self.done = self.total = msg["summary"]["samples"]
            else:
                self.done, self.total, self.seconds = msg["done"], msg["total"], msg["seconds"]
        if self.running and self._proc.poll() is not None and self._lines.empty():
            # ended without saying so (killed, a crash): what it wrote on stderr says why
            self._proc.wait()
            self.error = self.error or (f"the sweep process ended with status {self._proc.returncode}: "
                                        + (" / ".join(self._stderr[-3:]) or "no message"))
        self.reap()
        return self.running

    def reap(self) -> bool:
        """Collects the child once it has exited (never waits) and deletes the engine zip; True
        when nothing of the sweep is left running (a caller's timer stops polling then, with no
        zombie left behind)."""
        if self._proc is not None and self._proc.poll() is None:
            return False
        if self._scratch is not None:
            shutil.rmtree(self._scratch, ignore_errors=True)
            self._scratch = None
        return True

    def cancel(self, timeout: float = 5.0) -> None:
        """Ends the child now (the samples it finished are kept in the folder)."""
        if self._proc is None or not self.running:
            return
        self.cancelled = True
        self._proc.terminate()
        try:
            self._proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        self.reap()

    def describe(self) -> str:
        """One line for the panel."""
        if self.error:
            return f"Failed: {self.error}"
        if self.cancelled:
            return f"Cancelled at {self.done} of {self.total} samples (kept: Run again resumes)"
        if self.finished:
            s = self.summary
            return (f"Held {s['held']} of {s['samples']}: p = {s['p_held']:.2f} "
                    f"(95 %: {s['ci95'][0]:.2f} .. {s['ci95'][1]:.2f})")
        if not self.total:
            return "Starting..."
        return f"{self.done} of {self.total} samples, {self.seconds:.0f} s"
