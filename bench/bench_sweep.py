"""Sweep benchmarks (issue 17, docs/sweeps.md); prints a Markdown section for docs/benchmarks.md.

The scene: a recorded 3 s three-finger lift (tests/blender/recordings.three_finger_lift: box on
a table, three fingertips close, lift it 8 cm, hold), swept over Box.mu_s and Box.mass.

1. Samples per second on one core: the sweep in this process (draw, world made, HIPs replayed
   with each step's trace, outcomes, samples.csv) beside the bare C step loop on the same scene
   (``World.step_hips`` of the recorded HIPs into a preallocated record array, the world made
   once; and the steps alone): repeats interleaved. Target: >= 80 %. With the grasp measures
   (analysis every 20 ms, whole records) beside it. ``--one-core``: this part alone.
2. Two local worker processes against one (the pool, spawned workers). Target: >= 1.8x.
3. An existing Dask cluster on localhost (a real `dask scheduler`, two `dask worker` processes
   of one thread each) against the local pool of two, the same sweep. Target: within 15 %.
4. 10 000 samples on the local pool of two: the time, and each worker's resident memory after
   the first tenth and at the end (bounded: it must not grow with the sample count).

Usage: .venv/bin/python bench/bench_sweep.py [--samples 10000] [--quick]
"""
from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests", "blender"))
sys.path.insert(0, ROOT)

import graspcore  # noqa: E402
import recordings  # noqa: E402
from addon.engine import recording, scene, sweep  # noqa: E402

VARY = ("Box.mu_s=0.1:1.0", "Box.mass=0.05:0.6")


def log(msg):
    print(f"[bench_sweep] {msg}", file=sys.stderr, flush=True)


def varies():
    return [sweep.parse_vary(t) for t in VARY]


def bare_loop(rec, job, repeats, records=True):
    """CPU seconds per sample of the bare C step loop: step_hips over the recorded HIPs (into a
    preallocated record array, or the steps alone), the world made beforehand."""
    desc = recording.scene_from_dict(rec.header["scene"])
    out = []
    for _ in range(repeats):
        world = scene.build_world(desc, graspcore, exact=True).world
        ticks = np.zeros(len(job.hips), dtype=world.tick_dtype()) if records else None
        t = time.process_time()
        world.step_hips(job.hips, 1.0 / job.rate, ticks)
        out.append(time.process_time() - t)
    return out


def timed_sweep(rec, n, folder, clock=time.perf_counter, **kw):
    shutil.rmtree(folder, ignore_errors=True)
    t = clock()
    res = sweep.sweep(rec, varies(), n, 1, folder, pictures=False, **kw)
    return clock() - t, res


class RssWatch:
    """Resident memory of this process's children (the pool's workers), sampled every 0.2 s."""

    def __init__(self):
        import psutil
        self.me = psutil.Process()
        self.samples = []           # (time, {pid: rss})
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    def run(self):
        t0 = time.perf_counter()
        while not self.stop.wait(0.2):
            rss = {}
            for c in self.me.children():
                try:
                    rss[c.pid] = c.memory_info().rss
                except Exception:
                    pass
            self.samples.append((time.perf_counter() - t0, rss))

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join()


def start_cluster(folder, workers=2):
    dask = os.path.join(os.path.dirname(sys.executable), "dask")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    sf = os.path.join(folder, "scheduler.json")
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--scheduler-file", sf], cwd=folder, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    while not os.path.exists(sf):
        time.sleep(0.1)
    for i in range(workers):
        procs.append(subprocess.Popen([dask, "worker", "--scheduler-file", sf, "--nthreads", "1", "--no-dashboard",
                                       "--local-directory", os.path.join(folder, f"w{i}")], cwd=folder, env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
    from distributed import Client
    with Client(scheduler_file=sf, timeout=60) as c:
        c.wait_for_workers(workers, timeout=60)
        address = c.scheduler.address
    return procs, address


def stop_cluster(procs):
    for p in procs:
        p.terminate()
    for p in procs:
        try:
            p.wait(20)
        except subprocess.TimeoutExpired:
            p.kill()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=10000, help="the long sweep's samples (0: skip it)")
    ap.add_argument("--quick", action="store_true", help="fewer repeats and samples")
    ap.add_argument("--one-core", action="store_true",
                    help="the per-core comparison alone (1.: the sweep in process against the C loop)")
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="bench_sweep_")
    load0 = os.getloadavg()
    try:
        path = os.path.join(tmp, "three.mcap")
        desc, hips = recordings.three_finger_lift()
        recordings.record_scene(path, graspcore, desc, hips, 3.0)
        rec = recording.open_recording(path)
        job = sweep.make_job(rec, varies(), 1, analysis=False)
        n_one = 100 if args.quick else 300
        repeats = 3 if args.quick else 5

        # 1. one core: the sweep in this process vs the bare C step loop, interleaved
        log("one core: sweep in process vs bare step loop")
        bare, steps_only, swept, analysed = [], [], [], []
        for r in range(repeats):
            bare += bare_loop(rec, job, 20)
            steps_only += bare_loop(rec, job, 20, records=False)
            s, _ = timed_sweep(rec, n_one, os.path.join(tmp, "one"), time.process_time, workers=1, analysis=False)
            swept.append(s / n_one)
            s, res_a = timed_sweep(rec, n_one // 3, os.path.join(tmp, "one_a"), time.process_time, workers=1,
                                   analysis=True)
            analysed.append(s / (n_one // 3))
        bare_s, sweep_s, an_s = statistics.median(bare), statistics.median(swept), statistics.median(analysed)
        bare_min = min(bare)
        steps_s = statistics.median(steps_only)
        # a sample in parts, for where the rest goes
        rng = np.random.default_rng(0)
        t_parts = {"draw": [], "world": [], "replay": [], "outcomes": []}
        clock = time.process_time
        for i in range(200):
            t0 = clock()
            d = sweep.draw(job, i, rng)
            dsc = sweep._fresh_desc(job)
            sweep.apply_to_desc(dsc, d.overrides)
            t1 = clock()
            h = scene.build_world(dsc, graspcore, exact=True)
            t2 = clock()
            ticks = sweep.replay_trace(h.world, job.hips, 1.0 / job.rate, job.has_start)   # as run_sample
            t3 = clock()
            sweep.outcomes(job, ticks, dsc)
            t4 = clock()
            for k, v in zip(t_parts, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
                t_parts[k].append(v)
        parts = {k: statistics.median(v) * 1e3 for k, v in t_parts.items()}
        if args.one_core:
            load1 = os.getloadavg()
            print_one_core(args, rec, load0, load1, bare_s, bare_min, steps_s, sweep_s, an_s, parts, repeats, n_one)
            return

        # 2. two local workers vs one (both through sweep(), workers=1 in process, 2 spawned)
        n_pool = 600 if args.quick else 3000     # a pool starts in about 0.2 s: amortised
        log("pool: 1 vs 2 workers")
        import resource

        def cpu_all():      # this process and its reaped children (the pool's workers), CPU s
            c = resource.getrusage(resource.RUSAGE_CHILDREN)
            return time.process_time() + c.ru_utime + c.ru_stime
        one_t, two_t, one_cpu, two_cpu = [], [], [], []
        for r in range(2 if args.quick else 3):
            c = cpu_all()
            one_t.append(timed_sweep(rec, n_pool, os.path.join(tmp, "p1"), workers=1, analysis=False)[0])
            one_cpu.append(cpu_all() - c)
            c = cpu_all()
            two_t.append(timed_sweep(rec, n_pool, os.path.join(tmp, "p2"), workers=2, analysis=False)[0])
            two_cpu.append(cpu_all() - c)
        one_rate, two_rate = n_pool / statistics.median(one_t), n_pool / statistics.median(two_t)
        same_bytes = open(os.path.join(tmp, "p1", "samples.csv"), "rb").read() == \
            open(os.path.join(tmp, "p2", "samples.csv"), "rb").read()

        # 3. Dask on localhost vs the local pool of two, the same sweep, interleaved
        log("dask vs local pool")
        cdir = os.path.join(tmp, "cluster")
        os.makedirs(cdir)
        c_section = cpu_all()
        procs, address = start_cluster(cdir)
        try:
            dask_t, pool_t, pool_cpu = [], [], []
            for r in range(2 if args.quick else 3):
                dask_t.append(timed_sweep(rec, n_pool, os.path.join(tmp, "d"), scheduler=address, analysis=False)[0])
                c = cpu_all()
                pool_t.append(timed_sweep(rec, n_pool, os.path.join(tmp, "p2"), workers=2, analysis=False)[0])
                pool_cpu.append(cpu_all() - c)
            dask_same = open(os.path.join(tmp, "d", "samples.csv"), "rb").read() == \
                open(os.path.join(tmp, "p2", "samples.csv"), "rb").read()
        finally:
            stop_cluster(procs)
        # the cluster's processes are this one's children, reaped above: all their CPU (start-up,
        # scheduler, idle) and the client's, per run
        dask_cpu = (cpu_all() - c_section - sum(pool_cpu)) / len(dask_t)
        dask_rate, pool_rate = n_pool / statistics.median(dask_t), n_pool / statistics.median(pool_t)

        # 4. the long sweep on the pool of two, memory watched
        long_row = None
        if args.samples:
            n = args.samples if not args.quick else min(args.samples, 2000)
            log(f"{n} samples on the pool of two")
            with RssWatch() as watch:
                t_long, res = timed_sweep(rec, n, os.path.join(tmp, "long"), workers=2, analysis=False)
            t = time.perf_counter()
            sweep.draw_pictures(job, res.rows, os.path.join(tmp, "long"))
            t_pics = time.perf_counter() - t
            series = [(t_, rss) for t_, rss in watch.samples if len(rss) >= 2]     # both workers up
            tenth = [rss for t_, rss in series if t_ >= 0.1 * t_long]
            last = [rss for t_, rss in series if t_ <= 0.95 * t_long]       # before the pool shuts down
            early = max(tenth[0].values()) / 2 ** 20 if tenth else float("nan")
            late = max(last[-1].values()) / 2 ** 20 if last else float("nan")
            peak = max(max(r.values()) for _, r in series) / 2 ** 20 if series else float("nan")
            s = res.summary
            long_row = (n, t_long, t_pics, early, late, peak, s)
            n_a = 1000 if not args.quick else 200
            log(f"{n_a} samples with the grasp measures on the pool of two")
            t_long_a, res_a = timed_sweep(rec, n_a, os.path.join(tmp, "long_a"), workers=2, analysis=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    load1 = os.getloadavg()

    import dask
    import matplotlib
    ratio = bare_s / sweep_s
    print("# Sweeps (grasp-lab sweep)\n")     # run_bench.py nests it: "## Sweeps"
    print(f"Run on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} by `.venv/bin/python bench/bench_sweep.py"
          f"{' --quick' if args.quick else ''}` ({platform.machine()}, {os.cpu_count()} logical cores, shared: "
          f"load average {load0[0]:.2f} at start, {load1[0]:.2f} at end). Python {platform.python_version()}, "
          f"numpy {np.__version__}, dask {dask.__version__}, matplotlib {matplotlib.__version__}. "
          f"The scene: a recorded 3 s three-finger lift ({len(rec.ticks)} ticks at 1 kHz: box and table, three "
          f"fingertips), swept over `{VARY[0]}` and `{VARY[1]}`; without the grasp measures unless said.\n")
    print("| target | result | met |\n|---|---|---|")
    print(f"| samples/s per core ≥ 80 % of the bare C step loop, same scene (CPU time) | {ratio * 100:.0f} % "
          f"({1 / sweep_s:.0f} vs {1 / bare_s:.0f} samples/s) | {'yes' if ratio >= 0.8 else '**no**'} |")
    print(f"| the same against the C steps alone (no tick records: the physics, nothing else) | "
          f"{steps_s / sweep_s * 100:.0f} % ({1 / sweep_s:.0f} vs {1 / steps_s:.0f} samples/s) | "
          f"{'yes' if steps_s / sweep_s >= 0.8 else '**no**'} |")
    print(f"| 2 local workers ≥ 1.8× one | {two_rate / one_rate:.2f}× ({two_rate:.0f} vs {one_rate:.0f} samples/s) | "
          f"{'yes' if two_rate / one_rate >= 1.8 else '**no**'} |")
    print(f"| Dask on localhost within 15 % of the local pool, same sweep | {dask_rate / pool_rate * 100:.0f} % "
          f"({dask_rate:.0f} vs {pool_rate:.0f} samples/s) | {'yes' if dask_rate >= 0.85 * pool_rate else '**no**'} |")
    if long_row:
        n, t_long, t_pics, early, late, peak, s = long_row
        print(f"| {n} samples of the 3 s three-finger lift on this 2-core machine | {t_long:.1f} s "
              f"({n / t_long:.0f} samples/s; pictures {t_pics:.1f} s more) | reported |")
        print(f"| memory per worker bounded | {early:.0f} MB after the first tenth, {late:.0f} MB at 95 % "
              f"(peak {peak:.0f} MB) | {'yes' if late <= early * 1.1 + 5 else '**no**'} |")
    print()
    print("| measurement | value |\n|---|---|")
    print(f"| bare C step loop (`World.step_hips`, 3000 ticks), CPU time: median / best | {bare_s * 1e3:.2f} / "
          f"{bare_min * 1e3:.2f} ms a sample |")
    print(f"| the C steps alone (`World.step_hips(hips, dt, None)`), CPU time: median | {steps_s * 1e3:.2f} ms a sample |")
    print(f"| the sweep in one process (`--workers 1`), CPU time: median of {repeats} × {n_one} samples | "
          f"{sweep_s * 1e3:.2f} ms a sample |")
    print(f"| a sample in parts, CPU time (median of 200): draw + scene, world made, replay, outcomes | "
          f"{parts['draw']:.2f} + {parts['world']:.2f} + {parts['replay']:.2f} + {parts['outcomes']:.2f} ms |")
    print(f"| the same with the grasp measures (every 20 ms while held), CPU time | {an_s * 1e3:.2f} ms a sample |")
    print(f"| 1 / 2 local workers, {n_pool} samples (median of runs) | {statistics.median(one_t):.2f} / "
          f"{statistics.median(two_t):.2f} s; samples.csv the same bytes: {'yes' if same_bytes else 'NO'} |")
    print(f"| CPU for {n_pool} samples, all processes: 1 worker (in process) / pool of 2 (its start, pickling, "
          f"the parent) | {statistics.median(one_cpu):.2f} / {statistics.median(two_cpu):.2f} s: the pool's overhead "
          f"{(statistics.median(two_cpu) / statistics.median(one_cpu) - 1) * 100:+.0f} %, so 2 free cores would give "
          f"{2 * statistics.median(one_cpu) / statistics.median(two_cpu):.2f}× at most |")
    print(f"| Dask (2 workers × 1 thread) / local pool of 2, {n_pool} samples | {statistics.median(dask_t):.2f} / "
          f"{statistics.median(pool_t):.2f} s; samples.csv the same bytes: {'yes' if dask_same else 'NO'} |")
    print(f"| CPU for {n_pool} samples, all processes: Dask (scheduler, workers, client; start-up shared out) / "
          f"local pool of 2 | {dask_cpu:.2f} / {statistics.median(pool_cpu):.2f} s "
          f"({(dask_cpu / statistics.median(pool_cpu) - 1) * 100:+.0f} %) |")
    if long_row:
        print(f"| {n} samples: held, P(held), 95 % interval | {s['held']}, {s['p_held']:.4f}, "
              f"{s['ci95'][0]:.4f} .. {s['ci95'][1]:.4f} |")
        print(f"| {n_a} samples with the grasp measures, pool of two | {t_long_a:.1f} s ({n_a / t_long_a:.0f} "
              f"samples/s) |")


def print_one_core(args, rec, load0, load1, bare_s, bare_min, steps_s, sweep_s, an_s, parts, repeats, n_one):
    """--one-core: the per-core rows alone, as a section of their own."""
    ratio = bare_s / sweep_s
    print("# Sweeps: samples per core (grasp-lab sweep)\n")
    print(f"Run on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} by `.venv/bin/python bench/bench_sweep.py "
          f"--one-core` ({platform.machine()}, {os.cpu_count()} logical cores, shared: load average {load0[0]:.2f} "
          f"at start, {load1[0]:.2f} at end). Python {platform.python_version()}, numpy {np.__version__}. The "
          f"scene: a recorded 3 s three-finger lift ({len(rec.ticks)} ticks at 1 kHz), swept over `{VARY[0]}` and "
          f"`{VARY[1]}`, without the grasp measures unless said; the C loop and the sweep interleaved, CPU time.\n")
    print("| target | result | met |\n|---|---|---|")
    print(f"| samples/s per core ≥ 80 % of the bare C step loop, same scene (CPU time) | {ratio * 100:.0f} % "
          f"({1 / sweep_s:.0f} vs {1 / bare_s:.0f} samples/s) | {'yes' if ratio >= 0.8 else '**no**'} |")
    print(f"| the same against the C steps alone (no tick records: the physics, nothing else) | "
          f"{steps_s / sweep_s * 100:.0f} % ({1 / sweep_s:.0f} vs {1 / steps_s:.0f} samples/s) | "
          f"{'yes' if steps_s / sweep_s >= 0.8 else '**no**'} |")
    print()
    print("| measurement | value |\n|---|---|")
    print(f"| bare C step loop (`World.step_hips`, 3000 ticks), CPU time: median / best | {bare_s * 1e3:.2f} / "
          f"{bare_min * 1e3:.2f} ms a sample |")
    print(f"| the C steps alone (`World.step_hips(hips, dt, None)`), CPU time: median | {steps_s * 1e3:.2f} ms a sample |")
    print(f"| the sweep in one process (`--workers 1`), CPU time: median of {repeats} × {n_one} samples | "
          f"{sweep_s * 1e3:.2f} ms a sample |")
    print(f"| a sample in parts, CPU time (median of 200): draw + scene, world made, replay, outcomes | "
          f"{parts['draw']:.2f} + {parts['world']:.2f} + {parts['replay']:.2f} + {parts['outcomes']:.2f} ms |")
    print(f"| the same with the grasp measures (every 20 ms while held), CPU time | {an_s * 1e3:.2f} ms a sample |")


if __name__ == "__main__":
    main()
