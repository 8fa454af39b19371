"""Haptic-loop period jitter of the runtime under Python CPU load, beside a bare C loop (issue 3, item 7).

The world runs on its threads (`World.start`, 1 kHz haptic loop, 500 Hz object manager)
with a held box, four boxes resting on a table (body contacts in the object manager) and
five fingers. Meanwhile the main Python thread pushes HIPs at ~500 Hz and another Python
thread burns CPU (holding the GIL most of the time). The runtime measures every haptic
period; this prints its statistics as a Markdown table, once with the haptic loop at
SCHED_FIFO (when the OS grants it) and once at normal priority.

Beside each runtime run, under the same Python load, it runs a bare-loop baseline
(bench/jitter_baseline.c, built here with the C compiler): the same wait as the haptic loop
(absolute CLOCK_MONOTONIC deadlines; same SCHED_FIFO priority, or at normal priority the
same 0.1 ms time slice; timer slack 1 ns; stack locked) doing no work, measured the same way. The order is baseline, runtime for each mode, so that the
two see the same machine. What the bare loop suffers comes from the OS and, in a VM, from
the host; only what the runtime adds is the runtime's. The host's steal time
(/proc/stat, the CPU time the hypervisor gave to others while this VM wanted it) is read
before and after every run.

Period error = |actual period - nominal period|. Target: p99 < 100 us and no period
late by more than 1 ms ("periods > 1 ms late" = 0). "Longest tick" is the loop's own work;
"latest wake-up" is how late the OS woke it after a deadline: a large wake-up with a short
tick is scheduling (or, in a VM, the host), not the loop.

    .venv/bin/python bench/bench_jitter.py [--seconds 60] [--rate 1000] [--modes fifo,normal]
                                           [--load-threads 1] [--no-baseline] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import threading
import time

import numpy as np

import graspcore

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
BASELINE_SRC = os.path.join(HERE, "jitter_baseline.c")
BASELINE_BIN = os.path.join(ROOT, "build", "bench", "jitter_baseline")
PRIORITY = 80


def box(h):
    return np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)], dtype=float)


def build_world():
    w = graspcore.World()
    w.add_body(box(0.03), mass=0.2)                                   # held between two fingers
    w.add_body(box(0.2) * [1, 1, 0.25], static=True, position=(0.4, 0, -0.1))   # table top at -0.05
    for i in range(4):                                                # boxes resting on it
        w.add_body(box(0.02), mass=0.1, position=(0.3 + 0.06 * i, 0, -0.05 + 0.02 + 1e-4))
    for x in (-0.041, 0.041):
        w.add_finger(damping=2.0, position=(x, 0, 0))
    for i in range(3):                                                # three free fingers
        w.add_finger(position=(-0.3, 0.05 * i, 0.2))
    return w


def hips_at(t):
    """Pinch, lift 5 cm over 1 s, then sway the held box slowly; free fingers circle."""
    lift = 0.05 * min(t, 1.0)
    sway = 0.02 * np.sin(2 * np.pi * 0.5 * (t - 1.0)) if t > 1.0 else 0.0
    rows = [[-0.035 + sway, 0, lift], [0.035 + sway, 0, lift]]
    for i in range(3):
        a = 2 * np.pi * 0.3 * t + i
        rows.append([-0.3 + 0.02 * np.cos(a), 0.05 * i + 0.02 * np.sin(a), 0.2])
    return np.array(rows)


def cpu_load(stop: threading.Event, counter: list):
    """Pure-Python arithmetic: holds the GIL except at the interpreter's switch points."""
    n = 0
    while not stop.is_set():
        s = 0
        for i in range(20000):
            s += i * i
        n += 1
    counter[0] = n


def cpu_times() -> tuple[int, int] | None:
    """(steal, total) jiffies of all CPUs from /proc/stat; None where there is none."""
    try:
        with open("/proc/stat") as fh:
            f = [int(x) for x in fh.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    # user nice system idle iowait irq softirq steal [guest guest_nice: already in user/nice]
    return (f[7] if len(f) > 7 else 0), sum(f[:8])


def steal_between(a, b) -> dict:
    if a is None or b is None:
        return {"steal_ms": None, "steal_pct": None}
    hz = os.sysconf("SC_CLK_TCK")
    d_steal, d_total = b[0] - a[0], b[1] - a[1]
    return {"steal_ms": 1000.0 * d_steal / hz, "steal_pct": 100.0 * d_steal / d_total if d_total > 0 else 0.0}


class Load:
    """The Python CPU-load threads, for one run."""

    def __init__(self, threads: int):
        self.stop = threading.Event()
        self.counters = [[0] for _ in range(threads)]
        self.threads = [threading.Thread(target=cpu_load, args=(self.stop, c), daemon=True) for c in self.counters]

    def __enter__(self):
        for th in self.threads:
            th.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        for th in self.threads:
            th.join()
        self.iterations = sum(c[0] for c in self.counters)


def run(seconds: float, rate: float, priority: int, load_threads: int) -> dict:
    w = build_world()
    c0 = cpu_times()
    with Load(load_threads) as load:
        w.start(haptic_rate=rate, priority=priority)
        t0 = time.monotonic()
        pushes = 0
        while (t := time.monotonic() - t0) < seconds:
            w.push_hips(hips_at(t), t)
            pushes += 1
            time.sleep(0.002)
        snap = w.snapshot()
        stats = w.stats()
        w.stop()
    stats.update(steal_between(c0, cpu_times()))
    stats.update(kind="runtime", seconds=seconds, pushes=pushes, push_rate=pushes / seconds,
                 load_iterations=load.iterations,
                 held_box_z=float(snap["poses"][0, 2]), priority_requested=priority)
    return stats


def build_baseline() -> str:
    """Compiles bench/jitter_baseline.c (when its binary is missing or older); its path."""
    if os.path.exists(BASELINE_BIN) and os.path.getmtime(BASELINE_BIN) >= os.path.getmtime(BASELINE_SRC):
        return BASELINE_BIN
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or "cc"
    os.makedirs(os.path.dirname(BASELINE_BIN), exist_ok=True)
    subprocess.run([cc, "-std=c11", "-O2", "-Wall", "-Wextra", BASELINE_SRC, "-o", BASELINE_BIN,
                    "-lm", "-lpthread"], check=True)
    return BASELINE_BIN


def run_baseline(exe: str, seconds: float, rate: float, priority: int, load_threads: int) -> dict:
    """The bare loop in its own process, while this process runs the same Python load as
    during a runtime run (the load threads; the main thread computing HIPs every 2 ms)."""
    c0 = cpu_times()
    with Load(load_threads) as load:
        p = subprocess.Popen([exe, "--seconds", f"{seconds:g}", "--rate", f"{rate:g}", "--priority", str(priority)],
                             stdout=subprocess.PIPE, text=True)
        t0 = time.monotonic()
        while p.poll() is None:
            hips_at(time.monotonic() - t0)
            time.sleep(0.002)
        out = p.stdout.read()
    if p.returncode != 0:
        raise RuntimeError(f"{exe} failed (exit {p.returncode})")
    stats = json.loads(out)
    stats.update(steal_between(c0, cpu_times()))
    stats.update(kind="baseline", load_iterations=load.iterations)
    return stats


def mode_name(r: dict) -> str:
    if r["rt_priority"]:
        return f"SCHED_FIFO {r['priority_requested']}"
    mode = "normal priority" if not r["priority_requested"] else "normal priority (SCHED_FIFO refused)"
    note = r["priority_note"]
    if "ms slice" in note:
        mode += ", " + note[:note.index(" slice")].rsplit(", ", 1)[-1] + " slice"
    return mode


def loop_name(r: dict) -> str:
    return f"{'bare loop' if r['kind'] == 'baseline' else '**graspcore**'}, {mode_name(r)}"


def met(r: dict) -> bool:
    return r["jitter_p99_us"] < 100.0 and r["late_periods"] == 0


def fmt_steal(r: dict) -> str:
    if r.get("steal_ms") is None:
        return "n/a"
    return f"{r['steal_ms']:.0f} ms ({r['steal_pct']:.2f} %)"


def table(rows: list[dict], rate: float) -> str:
    period_us = 1e6 / rate
    out = ["| loop | s | p50 (µs) | p99 (µs) | max (µs) | periods > "
           f"{period_us / 1000:g} ms late | overruns | longest tick (µs) | latest wake-up (µs) | rate (Hz) | "
           "host steal | Python load (iter/s) | target |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        rt = r["kind"] == "runtime"
        out.append(f"| {loop_name(r)} | {r['seconds']:.0f} | {r['jitter_p50_us']:.0f} | "
                   f"{r['jitter_p99_us']:.0f} | {r['jitter_max_us']:.0f} | {r['late_periods']} | "
                   f"{r['overruns']} | {r['tick_max_us']:.0f} | " if rt else
                   f"| {loop_name(r)} | {r['seconds']:.0f} | {r['jitter_p50_us']:.0f} | "
                   f"{r['jitter_p99_us']:.0f} | {r['jitter_max_us']:.0f} | {r['late_periods']} | "
                   f"{r['overruns']} | (no work) | ")
        out[-1] += (f"{r['wake_max_us']:.0f} | "
                    f"{r['haptic_rate'] if rt else r['periods'] / r['seconds']:.1f} | {fmt_steal(r)} | "
                    f"{r['load_iterations'] / r['seconds']:.0f} | {'met' if met(r) else 'missed'} |")
    return "\n".join(out)


def ratio(a: float, b: float) -> str:
    return f"{a / b:.2f}×" if b > 0 else "n/a"


def pairs(rows: list[dict]) -> list[tuple[dict, dict]]:
    """(runtime, baseline) of the same mode, in run order."""
    out = []
    for r in rows:
        if r["kind"] != "runtime":
            continue
        b = next((x for x in rows if x["kind"] == "baseline" and x["priority_requested"] == r["priority_requested"]),
                 None)
        if b:
            out.append((r, b))
    return out


def comparison(rows: list[dict]) -> str:
    ps = pairs(rows)
    if not ps:
        return ""
    out = ["| mode | p99 graspcore / bare | max graspcore / bare | periods > 1 ms late graspcore / bare | "
           "latest wake-up graspcore / bare (µs) | target graspcore / bare |",
           "|---|---|---|---|---|---|"]
    for r, b in ps:
        out.append(f"| {mode_name(r)} | {r['jitter_p99_us']:.0f} / {b['jitter_p99_us']:.0f} µs "
                   f"({ratio(r['jitter_p99_us'], b['jitter_p99_us'])}) | "
                   f"{r['jitter_max_us']:.0f} / {b['jitter_max_us']:.0f} µs "
                   f"({ratio(r['jitter_max_us'], b['jitter_max_us'])}) | "
                   f"{r['late_periods']} / {b['late_periods']} | {r['wake_max_us']:.0f} / {b['wake_max_us']:.0f} | "
                   f"{'met' if met(r) else 'missed'} / {'met' if met(b) else 'missed'} |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="duration of each run (default 60)")
    ap.add_argument("--rate", type=float, default=1000.0, help="haptic rate, Hz (default 1000)")
    ap.add_argument("--modes", default="fifo,normal", help="comma list of fifo and/or normal")
    ap.add_argument("--load-threads", type=int, default=1, help="Python CPU-load threads (default 1)")
    ap.add_argument("--no-baseline", action="store_true", help="skip the bare-loop baseline runs")
    ap.add_argument("--json", help="also write the raw statistics here (one object per run, 'kind' "
                                   "runtime or baseline)")
    args = ap.parse_args(argv)
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    for mode in modes:
        if mode not in ("fifo", "normal"):
            ap.error(f"--modes: unknown mode {mode!r}")
    exe = None if args.no_baseline else build_baseline()
    rows = []
    for mode in modes:
        prio = PRIORITY if mode == "fifo" else 0
        what = f"{args.seconds:g} s at {args.rate:g} Hz with {args.load_threads} Python load thread(s)"
        if exe:
            print(f"[jitter] bare loop, {mode}: {what}...", file=sys.stderr, flush=True)
            rows.append(run_baseline(exe, args.seconds, args.rate, prio, args.load_threads))
        print(f"[jitter] runtime, {mode}: {what}...", file=sys.stderr, flush=True)
        rows.append(run(args.seconds, args.rate, prio, args.load_threads))
    print(f"Haptic loop period error over {args.seconds:g} s at {args.rate:g} Hz, "
          f"{args.load_threads} Python CPU-load thread(s), {os.cpu_count()} CPUs, "
          f"{platform.platform()} (target: p99 < 100 µs, no period > 1 ms late). "
          "Runs in the order listed.\n")
    print(table(rows, args.rate))
    notes = sorted({r["priority_note"] for r in rows if r["kind"] == "runtime"})
    if notes:
        print("\nThe runtime's own note (`stats()['priority_note']`): " + "; ".join(f"“{n}”" for n in notes) + ".")
    cmp_md = comparison(rows)
    if cmp_md:
        print("\ngraspcore beside the bare loop of the same mode (ratio graspcore / bare):\n")
        print(cmp_md)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
