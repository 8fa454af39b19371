"""Pose in to force out over a pseudo-terminal at 1 kHz, under Python CPU load (issue 11).

A C device (bench/serial_device.c, the core's codec) opens a pty, sends a pose frame every
millisecond and times each pose until the force frame acknowledging it arrives. Two hosts
answer it in the same run, in alternating rounds (so that both see the same machine: other
jobs come and go), each while Python threads of this process burn CPU (bench_jitter.py's
load) and the main thread takes runtime snapshots:
  - the bare C echo loop (serial_device echo): decode, answer with a zero force frame (this
    process runs the same runtime meanwhile, unconnected, so that the load is the same);
  - graspcore: the port opened by pyserial, the runtime running (two fingers gripping a
    box), the core's serial thread pushing HIPs and answering with the haptic loop's forces.
Target: p99 < 1 ms and no unacknowledged pose. `--transport udp` runs the same over UDP on the
loopback interface (the C device on a UDP socket; the echo loop and graspcore's device thread
on theirs, docs/protocol.md section 7); `both` runs the pty and UDP, each in its own rounds.

    .venv/bin/python bench/bench_serial.py [--seconds 60] [--rounds 6] [--rate 1000] [--load-threads 1]
                                           [--transport pty|udp|both] [--json out.json]

--seconds is per host, split into --rounds rounds; the statistics are over all its rounds.
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


def start_device(seconds, rate, fingers, udp=False):
    proc = subprocess.Popen([DEVICE_BIN, "device", str(seconds), str(rate), str(fingers)] + (["udp"] if udp else []),
                            stdout=subprocess.PIPE, text=True)
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


def run_echo(seconds, rate, load_threads, udp=False):
    """The same process load as graspcore's run (the runtime running, snapshots, Python
    threads); only the host that answers the device differs."""
    proc, port = start_device(seconds, rate, 2, udp)
    echo = subprocess.Popen([DEVICE_BIN, "echo", port])
    world = grip_world()
    world.start(haptic_rate=rate)
    try:
        r = under_load(proc, world, load_threads)
    finally:
        echo.wait(timeout=10)
        world.stop()
    r["host"] = "bare C echo loop" + (" (UDP)" if udp else "")
    return r


def run_graspcore(seconds, rate, load_threads, udp=False):
    import socket

    import serial
    proc, port = start_device(seconds, rate, 2, udp)
    world = grip_world()
    world.start(haptic_rate=rate)
    if udp:
        port_handle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        port_handle.bind(("127.0.0.1", 0))
        port_handle.setblocking(False)
        dev = world.attach_serial(port_handle.fileno(), finger_offset=0, num_fingers=2, udp_host="127.0.0.1",
                                  udp_port=int(port.rsplit(":", 1)[1]))
    else:
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
    r["host"] = "graspcore (runtime + serial thread)" + (" (UDP)" if udp else "")
    r["transport"] = "udp" if udp else "pty"
    return r


def merge(rounds: list, host: str) -> dict:
    """One host's rounds as one run: counts added, percentiles from the merged histogram."""
    hist: dict = {}
    for r in rounds:
        for b, n in r["hist"]:
            hist[b] = hist.get(b, 0) + n
    total = sum(hist.values())
    bins = sorted(hist)

    def pct(q):
        want, seen = q * total, 0
        for b in bins:
            seen += hist[b]
            if seen >= want:
                return float(b)
        return 0.0
    out = {"host": host, "rounds": len(rounds), "transport": "udp" if "UDP" in host else "pty"}
    for k in ("poses", "acknowledged", "unacknowledged", "late_over_1ms", "frame_errors", "load_iterations"):
        out[k] = sum(r[k] for r in rounds)
    out.update(p50_us=pct(0.5), p99_us=pct(0.99), p999_us=pct(0.999), max_us=max(r["max_us"] for r in rounds))
    steal = [r["steal_pct"] for r in rounds if r.get("steal_pct") is not None]
    out["steal_pct"] = sum(steal) / len(steal) if steal else None
    out["round_p99_us"] = [r["p99_us"] for r in rounds]
    extra = [r for r in rounds if "host_stats" in r]
    if extra:
        out["host_stats"] = {k: max(r["host_stats"][k] for r in extra) if k.startswith("latency") else
                             sum(r["host_stats"][k] for r in extra) for k in extra[0]["host_stats"]}
        out["haptic"] = {"rt_priority": all(r["haptic"]["rt_priority"] for r in extra),
                         "jitter_p99_us": max(r["haptic"]["jitter_p99_us"] for r in extra),
                         "late_periods": sum(r["haptic"]["late_periods"] for r in extra)}
    return out


def table(results, seconds, rate) -> str:
    rounds = results[0]["rounds"]
    link = "UDP on the loopback interface" if results[0]["transport"] == "udp" else "a pty"
    lines = [f"Pose in to force out over {link}, {rate:g} Hz for {seconds:g} s per host in {rounds} alternating rounds, "
             f"under Python CPU load ({platform.machine()}, {os.cpu_count()} CPUs, Linux {platform.release()}, "
             f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average at the end "
             f"{' '.join(open('/proc/loadavg').read().split()[:3])}). Round trip measured by the C device: pose "
             "written to its force frame read.", "",
             "| host | poses | unacknowledged | p50 | p99 | p99.9 | max | > 1 ms | frame errors | p99 of each round | host steal | target met |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---|"]
    for r in results:
        met = r["p99_us"] < 1000 and r["unacknowledged"] == 0
        steal = "-" if r.get("steal_pct") is None else f"{r['steal_pct']:.1f} %"
        per_round = " ".join(f"{v:.0f}" for v in r["round_p99_us"])
        lines.append(f"| {r['host']} | {r['poses']} | {r['unacknowledged']} | {r['p50_us']:.0f} us | "
                     f"{r['p99_us']:.0f} us | {r['p999_us']:.0f} us | {r['max_us']:.0f} us | {r['late_over_1ms']} | "
                     f"{r['frame_errors']} | {per_round} | {steal} | {'yes' if met else 'no'} |")
    g = next((r for r in results if "host_stats" in r), None)
    if g:
        s = g["host_stats"]
        lines += ["", f"graspcore's serial thread, its own measure (pose read to force frame written; the worst "
                      f"round): p99 {s['latency_p99_us']:.0f} us, max {s['latency_max_us']:.0f} us; "
                      f"{s['dropped']} frames dropped, {s['sequence_gaps']} sequence gaps, {s['write_errors']} write "
                      f"errors, {s['stall_zeroes']} stall zeroings; haptic loop p99 jitter (worst round) "
                      f"{g['haptic']['jitter_p99_us']:.0f} us (SCHED_FIFO: {'yes' if g['haptic']['rt_priority'] else 'no'})."]
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--load-threads", type=int, default=1)
    ap.add_argument("--transport", choices=("pty", "udp", "both"), default="pty")
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args(argv)
    build_device()
    per_round = args.seconds / args.rounds
    results = []
    for udp in {"pty": (False,), "udp": (True,), "both": (False, True)}[args.transport]:
        echo, core = [], []
        for _ in range(args.rounds):
            echo.append(run_echo(per_round, args.rate, args.load_threads, udp))
            core.append(run_graspcore(per_round, args.rate, args.load_threads, udp))
        mark = " (UDP)" if udp else ""
        pair = [merge(echo, "bare C echo loop" + mark), merge(core, "graspcore (runtime + serial thread)" + mark)]
        print(table(pair, args.seconds, args.rate) + "\n")
        results += pair
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
