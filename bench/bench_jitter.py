"""Haptic-loop period jitter of the runtime under Python CPU load (issue 3, item 7).

The world runs on its threads (`World.start`, 1 kHz haptic loop, 500 Hz object manager)
with a held box, four boxes resting on a table (body contacts in the object manager) and
five fingers. Meanwhile the main Python thread pushes HIPs at ~500 Hz and another Python
thread burns CPU (holding the GIL most of the time). The runtime measures every haptic
period; this prints its statistics as a Markdown table, once with the haptic loop at
SCHED_FIFO (when the OS grants it) and once at normal priority.

Period error = |actual period - nominal period|. Target: p99 < 100 us and no period
late by more than 1 ms ("periods > 1 ms late" = 0). "Longest tick" is the loop's own work;
"latest wake-up" is how late the OS woke it after a deadline: a large wake-up with a short
tick is scheduling (or, in a VM, the host), not the loop.

    .venv/bin/python bench/bench_jitter.py [--seconds 60] [--rate 1000] [--modes fifo,normal]
                                           [--load-threads 1] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import threading
import time

import numpy as np

import graspcore


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


def run(seconds: float, rate: float, priority: int, load_threads: int) -> dict:
    w = build_world()
    stop = threading.Event()
    counters = [[0] for _ in range(load_threads)]
    loads = [threading.Thread(target=cpu_load, args=(stop, c), daemon=True) for c in counters]
    for th in loads:
        th.start()
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
    stop.set()
    for th in loads:
        th.join()
    stats.update(seconds=seconds, pushes=pushes, push_rate=pushes / seconds,
                 load_iterations=sum(c[0] for c in counters),
                 held_box_z=float(snap["poses"][0, 2]), priority_requested=priority)
    return stats


def table(rows: list[dict], rate: float) -> str:
    period_us = 1e6 / rate
    out = ["| haptic loop | s | rate (Hz) | p50 (µs) | p99 (µs) | max (µs) | overruns | periods > "
           f"{period_us / 1000:g} ms late | longest tick (µs) | latest wake-up (µs) | object rate (Hz) | "
           "object speed | adopted | target |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ok = r["jitter_p99_us"] < 100.0 and r["late_periods"] == 0
        mode = r["priority_note"] if r["priority_requested"] else "normal priority (not requested)"
        out.append(f"| {mode} | {r['seconds']:.0f} | {r['haptic_rate']:.1f} | {r['jitter_p50_us']:.0f} | "
                   f"{r['jitter_p99_us']:.0f} | {r['jitter_max_us']:.0f} | {r['overruns']} | "
                   f"{r['late_periods']} | {r['tick_max_us']:.0f} | {r['wake_max_us']:.0f} | "
                   f"{r['object_rate']:.1f} | {r['object_speed']:.3f} | "
                   f"{r['adopted_bodies']} | {'met' if ok else 'missed'} |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="duration of each run (default 60)")
    ap.add_argument("--rate", type=float, default=1000.0, help="haptic rate, Hz (default 1000)")
    ap.add_argument("--modes", default="fifo,normal", help="comma list of fifo and/or normal")
    ap.add_argument("--load-threads", type=int, default=1, help="Python CPU-load threads (default 1)")
    ap.add_argument("--json", help="also write the raw statistics here")
    args = ap.parse_args(argv)
    rows = []
    for mode in [m.strip() for m in args.modes.split(",") if m.strip()]:
        if mode not in ("fifo", "normal"):
            ap.error(f"--modes: unknown mode {mode!r}")
        print(f"[jitter] {mode}: {args.seconds:g} s at {args.rate:g} Hz with {args.load_threads} "
              "Python load thread(s)...", file=sys.stderr, flush=True)
        rows.append(run(args.seconds, args.rate, 80 if mode == "fifo" else 0, args.load_threads))
    print(f"Haptic loop period error over {args.seconds:g} s at {args.rate:g} Hz, "
          f"{args.load_threads} Python CPU-load thread(s), {os.cpu_count()} CPUs, "
          f"{platform.platform()} (target: p99 < 100 µs, no period > 1 ms late)\n")
    print(table(rows, args.rate))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
