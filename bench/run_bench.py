"""`make bench`: graspcore beside MuJoCo and PyBullet on the same scenes, creep, haptic jitter, GJK/EPA, Blender.

Runs in .venv (graspcore built by `make core`). MuJoCo and PyBullet run in their own
environment, .venv-bench, created here from bench/requirements.txt on first use (mujoco
pins its own numpy; bpy in .venv pins numpy < 2), as subprocesses serving
bench/scenes_mujoco.py and bench/scenes_pybullet.py. Timing repeats of the engines are
interleaved so all see the same machine load. The multi-body scenes are run by
bench/bench_multibody.py, the haptic-loop jitter by bench/bench_jitter.py, grasp quality
against scipy by bench/bench_grasp_quality.py, grasp-lab analyze of a 10-minute recording by
bench/bench_analysis.py, grasp-lab sweep by bench/bench_sweep.py, two hands holding three boxes by
bench/bench_hands.py.
Writes docs/benchmarks.md and prints it.

    .venv/bin/python bench/run_bench.py [--quick] [--out docs/benchmarks.md]
"""
from __future__ import annotations

import argparse
import datetime as _dt
import hashlib
import json
import os
import platform
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)

import bench_core_scenes as core  # noqa: E402
import bench_held  # noqa: E402
import bench_multibody as mb  # noqa: E402
import bench_scenes  # noqa: E402

BENCH_VENV = os.path.join(ROOT, ".venv-bench")
BENCH_REQ = os.path.join(HERE, "requirements.txt")
MJ_MAIN = "recommended"                 # the configuration the ratio / target is quoted against
MJ_CONFIGS = ("recommended", "recommended+noslip")


def log(msg: str) -> None:
    print(f"[bench] {msg}", file=sys.stderr, flush=True)


# --- environment ----------------------------------------------------------------------
def _bench_python() -> str:
    return os.path.join(BENCH_VENV, "bin", "python")


def _base_python() -> str:
    for cand in (os.environ.get("PYTHON"), "python3.11"):
        if cand and shutil.which(cand):
            return shutil.which(cand)
    return getattr(sys, "_base_executable", sys.executable)


def ensure_bench_venv() -> str:
    """Create/refresh .venv-bench when bench/requirements.txt changed. Returns its python."""
    with open(BENCH_REQ, "rb") as fh:
        want = hashlib.sha256(fh.read()).hexdigest()
    stamp = os.path.join(BENCH_VENV, ".bench-deps")
    py = _bench_python()
    if os.path.exists(stamp) and open(stamp).read().strip() == want and os.path.exists(py):
        return py
    if not os.path.exists(py):
        log(f"creating {os.path.relpath(BENCH_VENV, ROOT)} with {_base_python()}")
        subprocess.run([_base_python(), "-m", "venv", "--clear", BENCH_VENV], check=True)
    log("installing bench/requirements.txt into .venv-bench")
    pip = [py, "-m", "pip", "--disable-pip-version-check", "-q"]
    subprocess.run(pip + ["install", "--upgrade", "pip"], check=True)
    subprocess.run(pip + ["install", "-r", BENCH_REQ], check=True)
    with open(stamp, "w") as fh:
        fh.write(want + "\n")
    return py


class Worker:
    """An engine worker in .venv-bench (bench/scenes_mujoco.py, bench/scenes_pybullet.py),
    one JSON line each way."""

    def __init__(self, python: str, script: str = "scenes_mujoco.py"):
        self.name = script
        self.proc = subprocess.Popen([python, os.path.join(HERE, script)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                     cwd=ROOT)

    def __call__(self, **req) -> dict:
        self.proc.stdin.write(json.dumps(req) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"{self.name} worker exited")
        reply = json.loads(line)
        if not reply.pop("ok"):
            raise RuntimeError(f"{self.name} worker: {reply['error']}")
        return reply

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait(timeout=30)


MuJoCo = Worker


# --- machine --------------------------------------------------------------------------
def machine_info() -> dict:
    cpu = "unknown"
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    os_name = platform.platform()
    try:
        with open("/etc/os-release") as fh:
            for line in fh:
                if line.startswith("PRETTY_NAME="):
                    os_name = f"{line.split('=', 1)[1].strip().strip(chr(34))}, Linux {platform.release()}"
    except OSError:
        pass
    try:
        from importlib.metadata import version
        gc_version = version("graspcore")
    except Exception:
        gc_version = "unknown"
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "native"], cwd=ROOT,
                               capture_output=True, text=True).stdout.strip()
        if dirty:
            commit += " (native/ has uncommitted changes)"
    except Exception:
        commit = "unknown"
    return {"cpu": cpu, "cores": os.cpu_count(), "os": os_name,
            "python": platform.python_version(), "numpy": np.__version__,
            "graspcore": gc_version, "commit": commit}


def loadavg() -> str:
    try:
        return " ".join(open("/proc/loadavg").read().split()[:3])
    except OSError:
        return "n/a"


# --- measurements ---------------------------------------------------------------------
def stats(samples: list[float]) -> dict:
    q = np.percentile(samples, [25, 50, 75])
    return {"median": float(q[1]), "p25": float(q[0]), "p75": float(q[2]), "min": float(min(samples)),
            "n": len(samples)}


def grasp_timing(mj: MuJoCo | None, fingers: tuple[int, ...], steps: int, repeats: int) -> list[dict]:
    """Per scene: graspcore and each MuJoCo config timed in interleaved repeats."""
    rows = []
    for n in fingers:
        spec = core.scene_spec(n)
        w, b = core.build_world(spec)
        w.step(core.DT, steps=2000)                  # 2 s: settle (and warm up)
        p0 = core.box_position(w, b)
        ours, mjt = [], {c: [] for c in MJ_CONFIGS}
        mj_setup, mj_ncon, mj_moved = {}, {c: [] for c in MJ_CONFIGS}, {c: [] for c in MJ_CONFIGS}
        if mj:
            for c in MJ_CONFIGS:
                mj_setup[c] = mj(cmd="setup", key=f"{n}/{c}", spec=spec, variant=c, warmup_s=2.0)
        for _ in range(repeats):
            ours += core.time_steps(w, steps, 1)
            if mj:
                for c in MJ_CONFIGS:
                    r = mj(cmd="time", key=f"{n}/{c}", steps=steps)
                    mjt[c].append(r["per_step"])
                    mj_ncon[c].append(r["ncon"])
                    mj_moved[c].append(r["moved_m"])
        if mj:
            for c in MJ_CONFIGS:
                mj(cmd="drop", key=f"{n}/{c}")
        row = {"fingers": n, "steps": steps, "repeats": repeats, "ours": stats(ours),
               "ours_drift_m": float(np.linalg.norm(core.box_position(w, b) - p0)),
               "ours_sim_s": steps * repeats * core.DT,
               "ours_states": [w.finger_state(f) for f in range(n)]}
        if mj:
            row["mujoco"] = {c: {**stats(mjt[c]), "ncon_min": min(mj_ncon[c]),
                                 "moved_m": max(mj_moved[c]), "setup": mj_setup[c]} for c in MJ_CONFIGS}
        rows.append(row)
        log(f"{n} fingers: ours {row['ours']['median'] * 1e6:.2f} us/step"
            + (f", MuJoCo {row['mujoco'][MJ_MAIN]['median'] * 1e6:.2f} us/step" if mj else ""))
    return rows


CREEP_SENSITIVITY = [
    # (label, config dict) -- the first two are the measured configurations
    ("solref 0.002, 10 g fingers (recommended)", {"noslip_iterations": 0}),
    ("solref 0.002, 10 g fingers, noslip 10", {"noslip_iterations": 10}),
    ("solref 0.002, 50 g fingers", {"noslip_iterations": 0, "finger_mass": 0.05}),
    ("solref 0.002, 50 g fingers, noslip 10", {"noslip_iterations": 10, "finger_mass": 0.05}),
    ("solref 0.02 (default), 50 g fingers", {"noslip_iterations": 0, "finger_mass": 0.05, "solref": "0.02 1"}),
    ("solref 0.02 (default), 50 g fingers, noslip 10",
     {"noslip_iterations": 10, "finger_mass": 0.05, "solref": "0.02 1"}),
    ("solref 0.02 (default), 10 g fingers", {"noslip_iterations": 0, "solref": "0.02 1"}),
]


def creep_all(mj: MuJoCo | None) -> dict:
    out = {"ours": core.creep(2.0, 10.0)}
    if mj:
        spec = core.scene_spec(2)
        out["mujoco"] = [(label, mj(cmd="creep", spec=spec, variant=cfg, settle_s=2.0, hold_s=10.0))
                         for label, cfg in CREEP_SENSITIVITY]
    return out


def demote_headings(md: str) -> str:
    """Nest another script's Markdown under our section: '#' -> '##' outside code fences."""
    out, fence = [], False
    for line in md.splitlines():
        if line.lstrip().startswith("```"):
            fence = not fence
        out.append("#" + line if (not fence and line.startswith("#")) else line)
    return "\n".join(out)


def run_external(cmd: list[str], timeout: float) -> tuple[bool, str]:
    """Run another engineer's bench script; (ok, its stdout or a note on the failure)."""
    try:
        r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return False, f"`{' '.join(cmd)}` did not finish within {timeout:.0f} s."
    if r.returncode != 0:
        tail = "\n".join((r.stderr or r.stdout).strip().splitlines()[-15:])
        return False, f"`{' '.join(cmd)}` failed (exit {r.returncode}):\n\n```\n{tail}\n```"
    return True, demote_headings(r.stdout.strip())


def grasp_analysis(quick: bool) -> tuple[bool, str, list[str]]:
    """bench/bench_analysis.py: a 10-minute recording through grasp-lab analyze (1 minute with
    --quick); (ok, its Markdown section, target rows for the summary)."""
    venv_py = os.path.join(ROOT, ".venv", "bin", "python")
    cmd = [venv_py if os.path.exists(venv_py) else sys.executable, os.path.join(HERE, "bench_analysis.py")]
    if quick:
        cmd += ["--minutes", "1", "--repeats", "1"]
    try:
        r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=3600)
    except subprocess.TimeoutExpired:
        return False, "## Grasp analysis\n\n`bench/bench_analysis.py` did not finish within 3600 s.", []
    if r.returncode != 0:
        tail = "\n".join((r.stderr or r.stdout).strip().splitlines()[-15:])
        return (False, f"## Grasp analysis\n\n`bench/bench_analysis.py` failed (exit {r.returncode}):\n\n```\n{tail}\n```",
                [])
    found = re.search(r"<!-- target (.*?) -->", r.stdout)
    values = dict(kv.split("=") for kv in found.group(1).split()) if found else {}
    rows = []
    if values:
        total, mu, snap = (float(values[k]) for k in ("analyze_s", "mu_min_s", "snapshot_ms"))
        failed = values.get("failed") == "1"
        rows.append(f"| `grasp-lab analyze` of a {values['minutes']}-minute recording, every display-rate tick, "
                    f"< 10 s | {total:.1f} s (of which `grasp_mu_min` {mu:.1f} s)"
                    + (": the command failed (see \"Grasp analysis\"), its parts timed" if failed else "")
                    + f" | {'**met**' if total < 10 and not failed else '**MISSED**'} |")
        fast = float(values.get("fast_ms", snap))
        rows.append(f"| Grasp analysis of one snapshot, 2 bodies × 5 fingers, < 0.5 ms | {fast:.2f} ms without the "
                    f"volume (the live view's call), {snap:.2f} ms with it | "
                    f"{'**met**' if fast < 0.5 else '**MISSED**'} |")
    return True, r.stdout.strip(), rows


def jitter(seconds: float) -> tuple[bool, str, list[str]]:
    """bench/bench_jitter.py in both modes (SCHED_FIFO and normal priority), each beside the
    bare-loop baseline of the same mode: (ok, its Markdown, target rows for the summary)."""
    script = os.path.join(HERE, "bench_jitter.py")
    if not os.path.exists(script):
        return False, "`bench/bench_jitter.py` does not exist: not measured.", []
    venv_py = os.path.join(ROOT, ".venv", "bin", "python")
    fd, js = tempfile.mkstemp(suffix=".json")
    os.close(fd)
    try:
        # Four runs of `seconds`: bare loop and runtime, SCHED_FIFO then normal priority.
        good, md = run_external([venv_py if os.path.exists(venv_py) else sys.executable, script,
                                 "--seconds", f"{seconds:g}", "--modes", "fifo,normal", "--json", js],
                                timeout=4 * seconds + 120)
        rows = json.load(open(js)) if good else []
    except (OSError, ValueError) as exc:
        good, md, rows = False, f"bench_jitter.py wrote no statistics: {exc}", []
    finally:
        os.unlink(js)
    return good, md, jitter_target_rows(rows)


def jitter_target_rows(rows: list[dict]) -> list[str]:
    """Target rows for the graspcore runs; each says whether the bare loop of the same mode,
    run just before it under the same load, met the same target."""
    targets = []
    for r in rows:
        if r.get("kind", "runtime") != "runtime":
            continue
        mode = "SCHED_FIFO" if r.get("rt_priority") else (
            "normal priority" if not r.get("priority_requested") else "normal priority (SCHED_FIFO refused)")
        bare = next((b for b in rows if b.get("kind") == "baseline"
                     and b.get("priority_requested") == r.get("priority_requested")), None)
        p99, late = r["jitter_p99_us"], r["late_periods"]
        p99_ok, late_ok = p99 < 100, late == 0
        if bare:
            bp99, blate = bare["jitter_p99_us"], bare["late_periods"]
            p99_bare = f"; bare loop, same run: {bp99:.0f} µs"
            late_bare = f"; bare loop, same run: {blate} late"
            p99_why = "" if p99_ok else (" (the bare loop missed it too)" if bp99 >= 100 else
                                         " (the bare loop met it)")
            late_why = "" if late_ok else (" (the bare loop missed it too)" if blate > 0 else
                                           " (the bare loop met it)")
        else:
            p99_bare = late_bare = p99_why = late_why = ""
        targets.append(f"| 1 kHz haptic loop, p99 period error < 100 µs, {r['seconds']:.0f} s under Python load, "
                       f"{mode} | {p99:.0f} µs (max {r['jitter_max_us']:.0f} µs){p99_bare} | "
                       f"{'**met**' if p99_ok else '**MISSED**' + p99_why} |")
        targets.append(f"| 1 kHz haptic loop, no period > 1 ms late in {r['seconds']:.0f} s, {mode} | "
                       f"{late} late, {r['overruns']} overruns{late_bare} | "
                       f"{'**met**' if late_ok else '**MISSED**' + late_why} |")
    return targets


def serial_roundtrip(seconds: float) -> tuple[bool, str, list[str]]:
    """bench/bench_serial.py: pose in to force out over a pty, graspcore beside the bare C echo
    loop in the same run: (ok, its Markdown, target rows for the summary)."""
    script = os.path.join(HERE, "bench_serial.py")
    venv_py = os.path.join(ROOT, ".venv", "bin", "python")
    fd, js = tempfile.mkstemp(suffix=".json")
    os.close(fd)
    try:
        good, md = run_external([venv_py if os.path.exists(venv_py) else sys.executable, script,
                                 "--seconds", f"{seconds:g}", "--rounds", "6" if seconds >= 30 else "2",
                                 "--transport", "both", "--json", js], timeout=4 * seconds + 240)
        rows = json.load(open(js)) if good else []
    except (OSError, ValueError) as exc:
        good, md, rows = False, f"bench_serial.py wrote no statistics: {exc}", []
    finally:
        os.unlink(js)
    return good, md, serial_target_rows(rows, seconds)


def serial_target_rows(rows: list[dict], seconds: float) -> list[str]:
    out = []
    for r in rows:
        if "graspcore" not in r["host"]:
            continue
        link = "UDP (loopback)" if r.get("transport") == "udp" else "a pty"
        bare = next((b for b in rows if "echo" in b["host"] and b.get("transport") == r.get("transport")), None)
        ok = r["p99_us"] < 1000 and r["unacknowledged"] == 0
        why = ""
        if not ok and bare:
            why = (" (the bare echo loop missed it too)" if bare["p99_us"] >= 1000 or bare["unacknowledged"]
                   else " (the bare echo loop met it)")
        bare_txt = (f"; bare C echo loop, same run: {bare['p99_us']:.0f} µs, {bare['unacknowledged']} unanswered"
                    if bare else "")
        out.append(f"| Serial device, pose in to force out over {link} at 1 kHz, {seconds:.0f} s under Python load: "
                   f"p99 < 1 ms, no dropped frames | {r['p99_us']:.0f} µs, {r['unacknowledged']} unanswered, "
                   f"{r['frame_errors']} frame errors{bare_txt} | {'**met**' if ok else '**MISSED**' + why} |")
    return out


def grasp_quality(quick: bool) -> tuple[bool, str, list[str]]:
    """bench/bench_grasp_quality.py: graspcore.grasp_quality beside scipy ConvexHull on the same
    contact sets in the same run: (ok, its Markdown, target rows for the summary)."""
    script = os.path.join(HERE, "bench_grasp_quality.py")
    venv_py = os.path.join(ROOT, ".venv", "bin", "python")
    fd, js = tempfile.mkstemp(suffix=".json")
    os.close(fd)
    try:
        good, md = run_external([venv_py if os.path.exists(venv_py) else sys.executable, script, "--json", js]
                                + (["--quick"] if quick else []), timeout=600)
        data = json.load(open(js)) if good else {}
    except (OSError, ValueError) as exc:
        good, md, data = False, f"bench_grasp_quality.py wrote no statistics: {exc}", {}
    finally:
        os.unlink(js)
    return good, md, grasp_target_rows(data)


def grasp_target_rows(data: dict) -> list[str]:
    target = data.get("target", 100.0)
    rows = [r for r in data.get("rows", []) if r["edges"] == 8]
    if not rows:
        return []
    ratios = " / ".join(f"{r['ratio']:.0f}×" for r in rows)
    times = " / ".join(f"{r['fast_us']:.0f} vs {r['scipy_us']:.0f} µs" for r in rows)
    ok = all(r["ratio"] >= target for r in rows)
    counts = " / ".join(str(r["contacts"]) for r in rows)
    out = [f"| Grasp quality (closure, epsilon, weakest: `volume=False`) ≥ {target:.0f}× faster than scipy "
           f"ConvexHull, {counts} contacts × 8 edges | {ratios} ({times}) | {'**met**' if ok else '**MISSED**'} |"]
    live = data.get("live")
    if live:
        out.append(f"| Grasp analysis core work per display update (2 bodies × 5 contacts: quality and mu_min) "
                   f"< 500 µs | median {live['median_us']:.0f} µs, 99th percentile {live['p99_us']:.0f} µs | "
                   f"{'**met**' if live['p99_us'] < 500 else '**MISSED**'} |")
    return out


def live_grasp(quick: bool) -> tuple[bool, str, list[str]]:
    """bench/bench_live_grasp.py: the live view's grasp analysis per display update (2 bodies x 5
    fingers) and the haptic loop with and without it: (ok, its Markdown, target rows)."""
    script = os.path.join(HERE, "bench_live_grasp.py")
    venv_py = os.path.join(ROOT, ".venv", "bin", "python")
    fd, js = tempfile.mkstemp(suffix=".json")
    os.close(fd)
    try:
        good, md = run_external([venv_py if os.path.exists(venv_py) else sys.executable, script, "--json", js]
                                + (["--quick"] if quick else []), timeout=900)
        data = json.load(open(js)) if good else {}
    except (OSError, ValueError) as exc:
        good, md, data = False, f"bench_live_grasp.py wrote no statistics: {exc}", {}
    finally:
        os.unlink(js)
    rows = []
    if data:
        a, target = data["main"]["analysis"], data["target_ms"]
        mu = data["main"]["mu_min"]
        ok = a["median_ms"] < target and a["p99_ms"] < target
        rows.append(f"| Live grasp analysis per display update < {target} ms, 2 bodies × 5 fingers | "
                    f"{a['median_ms']:.2f} ms median, p99 {a['p99_ms']:.2f} ms (of it `grasp_mu_min` alone: "
                    f"{mu['median_ms']:.2f} ms) | {'**met**' if ok else '**MISSED**'} |")
    return good, md, rows


# --- report ---------------------------------------------------------------------------
def us(x: float) -> str:
    return f"{x * 1e6:.2f}"


def unplug(trials: int) -> tuple[bool, str, list[str]]:
    """bench/bench_unplug.py: a device unplugged (and silenced) mid-grip, from the recording:
    (ok, its Markdown table, target rows for the summary)."""
    venv_py = os.path.join(ROOT, ".venv", "bin", "python")
    fd, js = tempfile.mkstemp(suffix=".json")
    os.close(fd)
    try:
        good, md = run_external([venv_py if os.path.exists(venv_py) else sys.executable,
                                 os.path.join(HERE, "bench_unplug.py"), "--trials", str(trials), "--json", js],
                                timeout=60 + 10 * trials)
        rows = [r for r in json.load(open(js)) if "error" not in r] if os.path.getsize(js) else []
    except (OSError, ValueError) as exc:
        good, md, rows = False, f"bench_unplug.py wrote no statistics: {exc}", []
    finally:
        os.unlink(js)
    out = []
    for how in ("hang-up", "silence"):
        rs = [r for r in rows if r["how"] == how]
        if rs:
            worst = max(max(r["release_ms"], r["zero_ms"]) for r in rs)
            out.append(f"| Device {how} mid-grip: fingers let go and device forces zero within 0.25 s, as the "
                       f"recording shows | worst of {len(rs)}: let go {max(r['release_ms'] for r in rs):.1f} ms, "
                       f"device forces zero {max(r['zero_ms'] for r in rs):.1f} ms | "
                       f"{'**met**' if worst < 250 else '**MISSED**'} |")
    return good, md, out


# --- report ---------------------------------------------------------------------------
def us(x: float) -> str:
    return f"{x * 1e6:.2f}"


def um(x: float) -> str:
    x = abs(x) * 1e6
    if x == 0.0:
        return "0"
    return f"{x:.3g}" if x >= 1e-3 else f"{x:.1e}"


def report(info, mjinfo, grasps, creep, profile, gjk, blender, xml3, meta, pbinfo=None,
           extra_targets=(), sections=()) -> str:
    L = []
    add = L.append
    add("# Benchmarks")
    add("")
    add(f"Generated by `make bench` (`bench/run_bench.py`) on {meta['date']}; "
        f"whole run {meta['wall_s']:.0f} s. Regenerate with `make bench`; do not edit by hand.")
    add("")
    add("## Machine")
    add("")
    add(f"- CPU: {info['cpu']}, {info['cores']} logical cores")
    add(f"- OS: {info['os']}")
    add(f"- graspcore {info['graspcore']} (git {info['commit']}), Python {info['python']}, "
        f"numpy {info['numpy']} (.venv)")
    if mjinfo:
        add(f"- MuJoCo {mjinfo['mujoco']}, Python {mjinfo['python']}, numpy {mjinfo['numpy']} (.venv-bench)")
    else:
        add(f"- MuJoCo: not run ({meta.get('mj_error', 'unavailable')})")
    if pbinfo:
        add(f"- PyBullet {pbinfo['pybullet']}, Python {pbinfo['python']}, numpy {pbinfo['numpy']} (.venv-bench)")
    else:
        add(f"- PyBullet: not run ({meta.get('pb_error', 'unavailable')})")
    add(f"- Load average at start / end: {meta['load_start']} / {meta['load_end']} "
        "(other jobs on the machine inflate both engines alike: repeats are interleaved)")
    add("")

    # targets summary
    add("## Targets")
    add("")
    add("| Target | Result | |")
    add("|---|---|---|")
    if mjinfo:
        for g in grasps:
            if g["fingers"] in (3, 5):
                ratio = g["ours"]["median"] / g["mujoco"][MJ_MAIN]["median"]
                add(f"| Step time ≤ 0.5× MuJoCo, box + {g['fingers']} fingers | "
                    f"{ratio:.2f}× ({us(g['ours']['median'])} vs {us(g['mujoco'][MJ_MAIN]['median'])} µs) | "
                    f"{'**met**' if ratio <= 0.5 else '**MISSED**'} |")
    else:
        add("| Step time ≤ 0.5× MuJoCo | MuJoCo not run | **not measured** |")
    c = creep["ours"]["displacement_m"]
    add(f"| Creep < 1 µm over 10 s (2-finger hold) | {um(c)} µm | {'**met**' if c < 1e-6 else '**MISSED**'} |")
    ratios = gjk_ratios(gjk)
    if ratios:
        for verts, r in ratios:
            add(f"| GJK+EPA ≤ 0.5× libccd, {verts}-vertex hulls | {r:.2f}× | "
                f"{'**met**' if r <= 0.5 else '**MISSED**'} |")
    else:
        add("| GJK+EPA ≤ 0.5× libccd | see [GJK/EPA](#gjkepa-vs-libccd) | |")
    for row in extra_targets:
        add(row)
    add("")

    # grasp timing
    add("## Step time, one held box (dt = 1 ms)")
    add("")
    add("A 0.2 kg, 6 cm box held still in the air by 8 mm spherical fingertips whose HIPs sit "
        "3 mm inside the faces (1000 N/m, 2 N s/m, µs 0.8 / µd 0.6, gravity on). "
        "Finger placement: 2 = opposed pinch on the ±x face centres; 3 = thumb on the +x face "
        "centre, two fingers on −x at y = ±15 mm; 5 = the 3-finger grasp plus an opposed pair on "
        "the ±y face centres. After 2 s of settling, each repeat runs "
        f"{grasps[0]['steps']} steps inside C (graspcore `w.step(dt, steps=N)`, MuJoCo "
        f"`mj_step(m, d, nstep=N)`), HIPs/controls held; {grasps[0]['repeats']} repeats per engine, "
        "interleaved; the table gives the median (25th–75th percentile) time per step. MuJoCo "
        "restarts each repeat from its settled snapshot (untimed), because without noslip its "
        "grasp slides (column *box moved*).")
    add("")
    add("What each engine does per step: graspcore runs collision, xFCA (god-object, friction "
        "circle, stick/slip) per finger and one implicitly coupled Newton–Euler step of the box; "
        "its fingertips are massless god-objects. MuJoCo integrates the box plus 3 slide DOF per "
        "fingertip body (6 + 3n DOF), collides, and solves the contact constraints with its Newton "
        "solver (see the model below). Both single-threaded.")
    add("")
    hdr = "| Fingers | graspcore µs/step | box moved | "
    sep = "|---|---|---|"
    if mjinfo:
        for cfg in MJ_CONFIGS:
            hdr += f"MuJoCo {cfg} µs/step | box moved / repeat | "
            sep += "---|---|"
        hdr += (f"ratio ours / MuJoCo {MJ_MAIN} | ratio ours / MuJoCo +noslip | "
                f"ratio of best repeats (ours / {MJ_MAIN}) |")
        sep += "---|---|---|"
    add(hdr)
    add(sep)
    for g in grasps:
        o = g["ours"]
        row = (f"| {g['fingers']} | {us(o['median'])} ({us(o['p25'])}–{us(o['p75'])}) | "
               f"{um(g['ours_drift_m'])} µm in {g['ours_sim_s']:.0f} s |")
        if mjinfo:
            for cfg in MJ_CONFIGS:
                m = g["mujoco"][cfg]
                row += f" {us(m['median'])} ({us(m['p25'])}–{us(m['p75'])}) | {um(m['moved_m'])} µm |"
            row += (f" **{o['median'] / g['mujoco'][MJ_MAIN]['median']:.2f}×** |"
                    f" {o['median'] / g['mujoco']['recommended+noslip']['median']:.2f}× |"
                    f" {o['min'] / g['mujoco'][MJ_MAIN]['min']:.2f}× ({us(o['min'])} / "
                    f"{us(g['mujoco'][MJ_MAIN]['min'])}) |")
        add(row)
    add("")
    add("All graspcore fingers were in `stick` at the end of every scene: "
        + ", ".join(f"{g['fingers']}: {'/'.join(g['ours_states'])}" for g in grasps) + ".")
    if mjinfo:
        add("MuJoCo kept every finger in contact in every repeat (fewest contacts seen: "
            + ", ".join(f"{g['fingers']} fingers → {min(g['mujoco'][c]['ncon_min'] for c in MJ_CONFIGS)}"
                        for g in grasps) + ").")
    add("")

    # MuJoCo model
    add("### The MuJoCo model")
    add("")
    add("- Each fingertip is a body with a sphere geom (r = 8 mm, 10 g) on three world-aligned "
        "slide joints; a `position` actuator per joint with `kp=1000`, `kv=2` has the HIP "
        "coordinate as its control. So the fingertip is pulled to the HIP by the same 1000 N/m "
        "spring and 2 N s/m damper as a graspcore finger (MuJoCo's fingertip has mass, "
        "graspcore's god-object does not). `gravcomp=1` on finger bodies; fingers collide only "
        "with the box.")
    add("- Settings (MuJoCo's advice for grasping): `cone=\"elliptic\"`, `impratio=\"10\"`, "
        "`condim=\"4\"` (sliding + torsional friction), friction `0.8 0.005 0.0001`, "
        "`integrator=\"implicitfast\"`, Newton solver with default iterations and tolerance, "
        "default `solimp`, contact `solref=\"0.002 1\"`. *recommended+noslip* adds "
        "`noslip_iterations=\"10\"`.")
    add("- Why `solref 0.002` (a time constant of 2 dt, the stiffest MuJoCo's documentation "
        "advises at this step): with the default 0.02 MuJoCo's contact stiffness scales with the "
        "10 g fingertip's mass, the tip sinks millimetres into the box, the 3 mm squeeze turns into "
        "well under 1 N of grip and the box falls out (see the creep sensitivity table).")
    if xml3:
        add("")
        add("<details><summary>Generated MJCF, 3-finger scene</summary>")
        add("")
        add("```xml")
        add(xml3.strip())
        add("```")
        add("")
        add("</details>")
    add("")

    # creep
    add("## Creep: two-finger hold, 10 s")
    add("")
    add("The 2-finger pinch above (3 N per finger, µs 0.8: 2.4× the grip the 1.96 N weight needs), "
        "gravity on. Settle 2 s, then the box displacement between t = 2 s and t = 12 s "
        "(and the largest excursion from the t = 2 s position, sampled every 100 ms). "
        "*Sag at settle* is how far the box sat down while settling (the finger springs carry "
        "the weight: 2 × 1000 N/m → 0.98 mm expected).")
    add("")
    add("| Engine / configuration | displacement over 10 s (µm) | largest excursion (µm) | sag at settle (mm) | contacts at end |")
    add("|---|---|---|---|---|")
    o = creep["ours"]
    add(f"| graspcore | **{um(o['displacement_m'])}** | {um(o['max_deviation_m'])} | "
        f"{o['sag_at_settle_m'] * 1e3:.3f} | {'/'.join(o['states'])} |")
    for label, r in creep.get("mujoco", []):
        add(f"| MuJoCo, {label} | {um(r['displacement_m'])} | {um(r['max_deviation_m'])} | "
            f"{r['sag_at_settle_m'] * 1e3:.3f} | {r['ncon']} |")
    add("")
    if o["displacement_m"] < 1e-9:
        add("graspcore's figure is floating-point round-off: both fingers stay in `stick` and the "
            "box does not move.")
        add("")
    if creep.get("mujoco"):
        rec = creep["mujoco"][0][1]["displacement_m"]
        ns = creep["mujoco"][1][1]["displacement_m"]
        add(f"MuJoCo with the recommended settings creeps {um(rec)} µm in 10 s "
            f"({rec * 1e6 / 10:.3g} µm/s); its `noslip` post-processing brings that to {um(ns)} µm, "
            "at the step-time cost shown above. MuJoCo's creep depends strongly on the fingertip mass "
            "(its contact regularisation scales with the effective mass) and on solref; displacements "
            "of a metre or more mean the box fell out of the grasp.")
        add("")

    # profile
    add("## Where graspcore's step time goes")
    add("")
    add(f"Same box, {profile['steps']} steps × {profile['repeats']} repeats per case (graspcore only). "
        "The best repeat is the least disturbed by other jobs on the machine; the fits and the "
        "sentences below use it.")
    add("")
    add("| Case | fingers | best µs/step | median µs/step | finger states |")
    add("|---|---|---|---|---|")
    for r in profile["rows"]:
        add(f"| {r['case']} | {r['fingers']} | {us(min(r['per_step']))} | "
            f"{us(statistics.median(r['per_step']))} | {'/'.join(r['states']) or '–'} |")
    add("")
    for label, slope, icpt in profile["fits"]:
        add(f"- {label}: {slope * 1e6:.2f} µs per finger + {icpt * 1e6:.2f} µs (least squares).")
    med = {r["case"]: min(r["per_step"]) for r in profile["rows"]}
    try:
        body = med["no fingers, dynamic box (falls freely)"] - med["no fingers, static box"]
        gyro = med["no fingers, dynamic box (falls freely)"] - med["no fingers, dynamic box, gyroscopic term off"]
        gyro5 = (med["5 fingers holding the dynamic box"]
                 - med["5 fingers holding the dynamic box, gyroscopic term off"])
        add(f"- One dynamic body with no contact costs {us(body)} µs per step, of which the implicit "
            f"gyroscopic term is {us(gyro)} µs; with 5 fingers holding it, turning the gyroscopic term "
            f"off saves {us(gyro5)} µs of {us(med['5 fingers holding the dynamic box'])}.")
    except KeyError:
        pass
    add("")

    for sec in sections:
        add(sec)
        add("")

    add("## GJK/EPA vs libccd")
    add("")
    add(gjk)
    add("")
    add("## Blender")
    add("")
    add(blender)
    add("")
    return "\n".join(L)


def gjk_ratios(md: str) -> list[tuple[str, float]]:
    """(vertices, ratio) from the first Markdown table of bench_gjk.sh whose header has a
    'ratio' column; [] when the format is not recognised."""
    lines = md.splitlines()
    for i, line in enumerate(lines):
        cells = [c.strip().lower() for c in line.strip().strip("|").split("|")]
        if line.lstrip().startswith("|") and any("ratio" in c for c in cells):
            col = next(k for k, c in enumerate(cells) if "ratio" in c)
            out = []
            for row in lines[i + 2:]:
                if not row.lstrip().startswith("|"):
                    break
                r = [c.strip() for c in row.strip().strip("|").split("|")]
                try:
                    out.append((r[0], float(r[col].strip("*× x"))))
                except (ValueError, IndexError):
                    return []
            return out
    return []


def fit(rows, keys) -> tuple[float, float]:
    xs = [r["fingers"] for r in rows if r["case"] in keys]
    ys = [min(r["per_step"]) for r in rows if r["case"] in keys]
    slope, icpt = np.polyfit(xs, ys, 1)
    return float(slope), float(icpt)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="few short repeats (checking the script)")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "benchmarks.md"))
    ap.add_argument("--skip-external", action="store_true", help="skip the GJK and Blender scripts")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    meta = {"date": _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"), "load_start": loadavg()}
    steps, repeats = (1000, 5) if args.quick else (5000, 31)

    info = machine_info()
    mj = mjinfo = pb = pbinfo = None
    xml3 = xml_mb = ""
    ok = True
    bench_py = None
    try:
        bench_py = ensure_bench_venv()
        mj = MuJoCo(bench_py)
        mjinfo = mj(cmd="info")
        xml3 = mj(cmd="xml", spec=core.scene_spec(3), variant=MJ_MAIN)["xml"]
        xml_mb = mj(cmd="mb_xml", spec=bench_scenes.scene_spec(bench_scenes.SCENES[0]), variant="recommended")["xml"]
    except Exception as exc:  # keep going: graspcore's numbers are still worth writing
        log(f"MuJoCo side unavailable: {exc}")
        meta["mj_error"] = str(exc)
        mj, ok = None, False
    if bench_py:
        try:
            pb = Worker(bench_py, "scenes_pybullet.py")
            pbinfo = pb(cmd="info")
        except Exception as exc:
            log(f"PyBullet side unavailable: {exc}")
            meta["pb_error"] = str(exc)
            pb, ok = None, False
    else:
        meta["pb_error"] = ".venv-bench could not be created"

    log("grasp step time (graspcore and MuJoCo interleaved)")
    grasps = grasp_timing(mj, (2, 3, 5), steps, repeats)
    held_section = ""
    if mj:
        log("held box against mocap-sphere fingertips (bench/bench_held.py)")
        held_repeats = max(5, repeats * 2 // 3)
        held_section = bench_held.section(bench_held.measure(mj, steps, held_repeats), steps, held_repeats)
    log("creep")
    creep = creep_all(mj)
    log("multi-body scenes (graspcore 1 and 2 threads, MuJoCo, PyBullet interleaved)")
    mb_rows = mb.run_all(mj, pb, quick=args.quick)
    if mj:
        mj.close()
    if pb:
        pb.close()
    overlaps = {"100-body pile": mb.initial_overlaps(bench_scenes.scene_spec("100-body pile"))}
    log("multi-body profile (perf)")
    mb_prof = mb.profile_all(mb_rows, quick=args.quick)
    log("per-finger profile")
    prof_rows = core.per_finger_profile(steps, max(5, repeats // 2))
    static = [r["case"] for r in prof_rows if "static box" in r["case"]]
    holding = [r["case"] for r in prof_rows if r["case"].endswith("holding the dynamic box")]
    free = [r["case"] for r in prof_rows if "free" in r["case"]]
    profile = {"rows": prof_rows, "steps": steps, "repeats": max(5, repeats // 2),
               "fits": [("Fingers free (no contact), dynamic box", *fit(prof_rows, free)),
                        ("Fingers pressing a static box (xFCA alone)", *fit(prof_rows, static)),
                        ("Fingers holding the dynamic box (xFCA + coupling)", *fit(prof_rows, holding))]}

    if args.skip_external:
        gjk = blender = "Skipped (`--skip-external`)."
    else:
        gjk_sh = os.path.join(HERE, "bench_gjk.sh")
        if os.path.exists(gjk_sh):
            log("GJK/EPA (bench/bench_gjk.sh)")
            good, gjk = run_external(["bash", gjk_sh], timeout=360)
            ok &= good
        else:
            gjk = "`bench/bench_gjk.sh` does not exist yet: GJK/EPA vs libccd not measured in this run."
        bl_py = os.path.join(HERE, "bench_blender.py")
        if os.path.exists(bl_py):
            log("Blender (bench/bench_blender.py)")
            venv_py = os.path.join(ROOT, ".venv", "bin", "python")
            good, blender = run_external([venv_py if os.path.exists(venv_py) else sys.executable, bl_py],
                                         timeout=240)
            ok &= good
        else:
            blender = "`bench/bench_blender.py` does not exist yet: no Blender numbers in this run."
        log("GUI Blender (bench/bench_gui.py)")
        good, gui = run_external([venv_py if os.path.exists(venv_py) else sys.executable,
                                  os.path.join(HERE, "bench_gui.py")], timeout=1200)
        ok &= good
        blender = blender.rstrip() + "\n\n" + gui
        log("recording (bench/bench_recording.py)")
        good, rec = run_external([venv_py if os.path.exists(venv_py) else sys.executable,
                                  os.path.join(HERE, "bench_recording.py")], timeout=900)
        ok &= good
        blender = blender.rstrip() + "\n\n" + rec
        log("viewer channels (bench/bench_viewer.py)")
        good, fox = run_external([venv_py if os.path.exists(venv_py) else sys.executable,
                                  os.path.join(HERE, "bench_viewer.py")], timeout=600)
        ok &= good
        blender = blender.rstrip() + "\n\n" + fox
        log("hearing the grasp (bench/bench_sound.py)")
        good, snd = run_external([venv_py if os.path.exists(venv_py) else sys.executable,
                                  os.path.join(HERE, "bench_sound.py")], timeout=900)
        ok &= good
        blender = blender.rstrip() + "\n\n" + snd
        log("Rerun copy (bench/bench_rerun.py)")
        good, rrd = run_external([venv_py if os.path.exists(venv_py) else sys.executable,
                                  os.path.join(HERE, "bench_rerun.py")], timeout=900)
        ok &= good
        blender = blender.rstrip() + "\n\n" + rrd
    jitter_s = 5.0 if args.quick else 60.0
    log(f"haptic-loop jitter (bench/bench_jitter.py, {jitter_s:g} s per run: bare loop and runtime, "
        "SCHED_FIFO and normal)")
    good, jitter_md, jitter_targets = jitter(jitter_s)
    ok &= good
    log(f"serial round trip (bench/bench_serial.py, {jitter_s:g} s per host: bare C echo loop, graspcore)")
    good, serial_md, serial_targets = serial_roundtrip(jitter_s)
    ok &= good
    log("device unplugged mid-grip (bench/bench_unplug.py)")
    good, unplug_md, unplug_targets = unplug(2 if args.quick else 10)
    ok &= good
    serial_md += "\n\n" + "\n".join([
        "### Unplugged mid-grip", "",
        "`bench/bench_unplug.py`: the emulator grips a box at 1 kHz with forces on (5 N, its limit), then is "
        "killed (its pty closes: a hang-up) or stopped with SIGSTOP (silence); from the recording and the "
        "device's `lost` event, the times after the cut until it is detected, until the fingers' spring "
        "forces stay below 1 µN (let go), and until the recorded device forces (what the device was sent, "
        "until that frame's 20 ms TTL) stay zero:", "", unplug_md])
    serial_section = "\n".join([
        "## Serial device round trip (1 kHz over a pseudo-terminal and over UDP, under Python CPU load)", "",
        f"`bench/bench_serial.py --seconds {jitter_s:g} --transport both` (docs/devices.md): a C device (`bench/serial_device.c`, "
        "SCHED_FIFO as hardware of its own would be) sends a pose every millisecond and times it until the force "
        "frame acknowledging it comes back. The hosts, in alternating rounds under the same load (Python threads "
        "burning CPU, the runtime running and snapshotted at 100 Hz): the bare C echo loop (decode, answer at once; "
        "SCHED_FIFO 70) and graspcore (pyserial opens the port, the runtime grips a box, the core's serial thread "
        "at SCHED_FIFO 70 pushes HIPs and answers with the haptic loop's forces). Both round trips cross the "
        "kernel's pty buffer twice (a worker thread at normal priority). Then the same over UDP on the loopback "
        "interface (docs/protocol.md section 7): the device on a UDP socket, the echo loop and graspcore's device "
        "thread on theirs. "
        "Its output:", "",
        serial_md])
    mb_section = mb.report_section(mb_rows, mjinfo, pbinfo, mb_prof, overlaps, xml_mb,
                                   pb_error=meta.get("pb_error", ""))
    jitter_section = "\n".join([
        "## Haptic loop period jitter (1 kHz, under Python CPU load)", "",
        "`bench/bench_jitter.py --seconds {0:g} --modes fifo,normal`: the runtime (`World.start`) with a held "
        "box, four boxes resting on a table and five fingers, the haptic loop at 1 kHz, while the main "
        "Python thread pushes HIPs at ~500 Hz and another Python thread burns CPU. Before each runtime run, "
        "under the same Python load, a bare C loop (`bench/jitter_baseline.c`) does the haptic loop's wait "
        "with the same scheduling and no work: what it suffers is the machine's (the OS, and in a VM the "
        "host), not the runtime's. Host steal time is read from /proc/stat around every run. Targets: p99 "
        "period error < 100 µs and no period more than 1 ms late over the run (docs/runtime.md, "
        "\"Measured jitter\"). Its output:".format(jitter_s), "",
        jitter_md])
    log("grasp quality (bench/bench_grasp_quality.py: graspcore beside scipy ConvexHull)")
    good, grasp_md, grasp_targets = grasp_quality(args.quick)
    ok &= good
    log("grasp analysis (bench/bench_analysis.py: a 10-minute recording through grasp-lab analyze)")
    good, analysis_md, analysis_targets = grasp_analysis(args.quick)
    ok &= good
    log("live grasp analysis (bench/bench_live_grasp.py: per display update, haptic loop beside it)")
    good, live_md, live_targets = live_grasp(args.quick)
    ok &= good
    log("sweeps (bench/bench_sweep.py: grasp-lab sweep in one process, a local pool, a Dask cluster on localhost)")
    good, sweep_md = run_external([sys.executable, os.path.join(HERE, "bench_sweep.py")]
                                  + (["--quick", "--samples", "2000"] if args.quick else []), timeout=1800)
    ok &= good
    log("hands (bench/bench_hands.py: two hands of capsules holding three boxes, beside MuJoCo)")
    good, hands_md = run_external([sys.executable, os.path.join(HERE, "bench_hands.py")]
                                  + (["--quick"] if args.quick else []), timeout=1800)
    ok &= good
    meta["load_end"] = loadavg()
    meta["wall_s"] = time.perf_counter() - t_start
    md = report(info, mjinfo, grasps, creep, profile, gjk, blender, xml3, meta, pbinfo=pbinfo,
                extra_targets=mb.target_rows(mb_rows, mjinfo is not None) + jitter_targets + serial_targets + unplug_targets
                + grasp_targets + analysis_targets + live_targets,
                sections=[s for s in (held_section, mb_section, jitter_section, serial_section, grasp_md,
                                      analysis_md, live_md, sweep_md, hands_md) if s])
    if args.quick:
        md = md.replace("# Benchmarks\n", "# Benchmarks (--quick run: too few repeats to quote)\n", 1)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as fh:
        fh.write(md + "\n")
    print(md)
    log(f"wrote {os.path.relpath(args.out, ROOT)} in {meta['wall_s']:.0f} s")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
