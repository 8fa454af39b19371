"""Peak memory of `grasp-lab run` and `grasp-lab resim` for 1, 10 and 100 s sessions of the
sample scene (docs/reliability.md, "Bounded resources"): each command in its own process, its
peak resident set (ru_maxrss of that child alone) next to what the documented formula gives.

    .venv/bin/python bench/bench_memory.py [--seconds 1 10 100]

Needs `make core` and a sample scene (built here into a temporary folder).
"""
from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PY = os.path.join(ROOT, ".venv", "bin", "python")
LAUNCHER = os.path.join(ROOT, ".venv", "bin", "grasp-lab")
# A process of its own that runs one command and reports that command's peak RSS (kB).
PEAK = ("import resource, subprocess, sys; r = subprocess.run(sys.argv[1:], capture_output=True); "
        "sys.exit(r.stderr.decode()) if r.returncode else "
        "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")


def peak_mb(*args) -> float:
    out = subprocess.run([PY, "-c", PEAK, *map(str, args)], capture_output=True, text=True, check=True)
    return int(out.stdout.strip()) / 1024


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, nargs="+", default=[1.0, 10.0, 100.0])
    args = ap.parse_args(argv)
    sys.path.insert(0, ROOT)
    from addon.engine.recording import tick_dtype
    record = tick_dtype(2, 2).itemsize
    with tempfile.TemporaryDirectory() as tmp:
        scene = os.path.join(tmp, "pinch.blend")
        subprocess.run([PY, os.path.join(ROOT, "sample_scenes", "build_pinch_and_lift.py"), "--save", scene],
                       check=True, capture_output=True)
        base = peak_mb(LAUNCHER, "info", "--help")
        print(f"machine: {platform.node()}, {os.cpu_count()} cores, Python {platform.python_version()}")
        print(f"tick record {record} bytes (2 bodies, 2 fingers, 1000 Hz); `info --help` {base:.0f} MB")
        print(f"{'session':>9} {'run MB':>8} {'resim MB':>9} {'2 x ticks x record MB':>22}")
        for s in args.seconds:
            rec, new = os.path.join(tmp, f"r{s:g}.mcap"), os.path.join(tmp, f"n{s:g}.mcap")
            run = peak_mb(LAUNCHER, "run", scene, "--duration", s, "--record", rec)
            resim = peak_mb(LAUNCHER, "resim", rec, "--set", "Box.mass=0.2", "--record", new)
            ticks = s * 1000 + 1
            print(f"{s:>8g}s {run:>8.0f} {resim:>9.0f} {2 * ticks * record / 1e6:>22.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
