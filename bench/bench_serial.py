"""Pose in to force out over a pseudo-terminal at 1 kHz, under Python CPU load (issue 11).

A C device (bench/serial_device.c, the core's codec) opens a pty, sends a pose frame every
millisecond and times each pose until the force frame acknowledging it arrives. Two hosts
answer it, one after the other in the same run, each while Python threads of this process
burn CPU (bench_jitter.py's load) and the main thread takes runtime snapshots:
  - the bare C echo loop (serial_device echo): decode, answer with a zero force frame;
  - graspcore: the port opened by pyserial, the runtime running (two fingers gripping a
    box), the core's serial thread pushing HIPs and answering with the haptic loop's forces.
Target: p99 < 1 ms and no unacknowledged pose.

    .venv/bin/python bench/bench_serial.py [--seconds 60] [--rate 1000] [--load-threads 1] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
sys.path.insert(0, ROOT)

import graspcore  # noqa: E402
from bench_jitter import Load, cpu_times, steal_between  # noqa: E402

DEVICE_SRC = os.path.join(HERE, "serial_device.c")
DEVICE_BIN = os.path.join(ROOT, "build", "bench", "serial_device")


def build_device() -> str:
    os.makedirs(os.path.dirname(DEVICE_BIN), exist_ok=True)
    cc = os.environ.get("CC") or shutil.which("cc") or "cc"
    core = sorted(os.path.join(ROOT, "native", "src", f) for f in os.listdir(os.path.join(ROOT, "native", "src"))
                  if f.endswith(".c"))
    subprocess.run([cc, "-std=c11", "-O2", "-I" + os.path.join(ROOT, "native", "include"),
                    "-I" + os.path.join(ROOT, "native", "src"), DEVICE_SRC, *core, "-o", DEVICE_BIN, "-lm",
                    "-lpthread"], check=True)
    return DEVICE_BIN


def start_device(seconds, rate, fingers):
    proc = subprocess.Popen([DEVICE_BIN, "device", str(seconds), str(rate), str(fingers)], stdout=subprocess.PIPE,
                            text=True)
    line = proc.stdout.readline()
    if not line.startswith("PORT "):
        raise RuntimeError(f"serial_device: {line!r}")
    return proc, line.split()[1]


def finish(proc) -> dict:
    out, _ = proc.communicate(timeout=120)
    return json.loads(out.strip().splitlines()[-1])


def grip_world():
    h = 0.03
    w = graspcore.World(gravity=(0, 0, 0))
    w.add_body(np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)]), static=True)
    w.add_finger(position=(0.06, 0, 0))
    w.add_finger(position=(-0.06, 0, 0))
    return w


def under_load(proc, world, load_threads):
    """Python load until the device process ends; the main thread snapshots at ~100 Hz."""
    c0 = cpu_times()
    with Load(load_threads) as load:
        while proc.poll() is None:
            if world is not None:
                world.snapshot()
            time.sleep(0.01)
    result = finish(proc)
    result.update(steal_between(c0, cpu_times()))
    result["load_iterations"] = load.iterations
    return result


def run_echo(seconds, rate, load_threads):
    proc, port = start_device(seconds, rate, 2)
    echo = subprocess.Popen([DEVICE_BIN, "echo", port])
    try:
        r = under_load(proc, None, load_threads)
    finally:
        echo.wait(timeout=10)
    r["host"] = "bare C echo loop"
    return r


def run_graspcore(seconds, rate, load_threads):
    import serial
    proc, port = start_device(seconds, rate, 2)
    world = grip_world()
    world.start(haptic_rate=rate)
    port_handle = serial.Serial(port, 1_000_000, timeout=0)
    dev = world.attach_serial(port_handle.fileno(), finger_offset=0, num_fingers=2)
    world.serial_enable(dev, True)
    try:
        r = under_load(proc, world, load_threads)
        st = world.serial_stats(dev)
        r["host_stats"] = {k: st[k] for k in ("poses", "forces_sent", "dropped", "sequence_gaps", "write_errors",
                                              "latency_p50_us", "latency_p99_us", "latency_max_us", "stall_zeroes")}
        rs = world.stats()
        r["haptic"] = {"rt_priority": rs["rt_priority"], "jitter_p99_us": rs["jitter_p99_us"],
                       "late_periods": rs["late_periods"]}
    finally:
        world.detach_serial(dev)
        port_handle.close()
        world.stop()
    r["host"] = "graspcore (runtime + serial thread)"
    return r


def table(results, seconds, rate) -> str:
    lines = [f"Pose in to force out over a pty, {rate:g} Hz for {seconds:g} s each, under Python CPU load "
             f"({platform.machine()}, {os.cpu_count()} CPUs, Linux {platform.release()}, "
             f"{time.strftime('%Y-%m-%d', time.gmtime())}). Round trip measured by the C device: pose written to "
             "its force frame read.", "",
             "| host | poses | unacknowledged | p50 | p99 | p99.9 | max | > 1 ms | frame errors | host steal | target met |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in results:
        met = r["p99_us"] < 1000 and r["unacknowledged"] == 0
        steal = "-" if r.get("steal_pct") is None else f"{r['steal_pct']:.1f} %"
        lines.append(f"| {r['host']} | {r['poses']} | {r['unacknowledged']} | {r['p50_us']:.0f} us | "
                     f"{r['p99_us']:.0f} us | {r['p999_us']:.0f} us | {r['max_us']:.0f} us | {r['late_over_1ms']} | "
                     f"{r['frame_errors']} | {steal} | {'yes' if met else 'no'} |")
    g = next((r for r in results if "host_stats" in r), None)
    if g:
        s = g["host_stats"]
        lines += ["", f"graspcore's serial thread, its own measure (pose read to force frame written): p50 "
                      f"{s['latency_p50_us']:.0f} us, p99 {s['latency_p99_us']:.0f} us, max {s['latency_max_us']:.0f} us; "
                      f"{s['dropped']} frames dropped, {s['sequence_gaps']} sequence gaps, {s['write_errors']} write "
                      f"errors, {s['stall_zeroes']} stall zeroings; haptic loop p99 jitter "
                      f"{g['haptic']['jitter_p99_us']:.0f} us (SCHED_FIFO: {'yes' if g['haptic']['rt_priority'] else 'no'})."]
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--load-threads", type=int, default=1)
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args(argv)
    build_device()
    results = [run_echo(args.seconds, args.rate, args.load_threads),
               run_graspcore(args.seconds, args.rate, args.load_threads)]
    print(table(results, args.seconds, args.rate))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
