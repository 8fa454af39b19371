"""grasp-lab sweep (addon/engine/sweep.py) in plain Python (no bpy) on a recorded three-finger
lift: specs and their errors; held or dropped where the friction and the weight say (12 N of
squeeze against m g); a push that knocks the box out; the Wilson interval against scipy's;
the same samples bit for bit from one process, two, a resumed sweep and a real Dask cluster
that loses a worker mid-sweep."""
import csv
import io
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import recordings
from addon.engine import cli, recording, sweep

SQUEEZE_FORCE = 12.0    # N: the fingers' normal forces, k x depth: 3 + 3 + 6 (recordings.three_finger_lift)
G = 9.81


@pytest.fixture(scope="module")
def lift(core, tmp_path_factory):
    path = tmp_path_factory.mktemp("sweep") / "three.mcap"
    desc, hips = recordings.three_finger_lift()
    recordings.record_scene(path, core, desc, hips, 3.0)
    return recording.open_recording(str(path))


def V(*texts):
    return [sweep.parse_vary(t) for t in texts]


def read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


# ------------------------------------------------------------------------ specs

def test_specs_read_as_documented():
    u, n, g = V("Box.mu_s=0.2:0.9", "Box.mass=0.2~0.05", "Finger 0.stiffness=500,1000,2000")
    assert (u.obj, u.prop, u.dist.kind, u.dist.a, u.dist.b) == ("Box", "mu_s", "uniform", 0.2, 0.9)
    assert (n.dist.kind, n.dist.a, n.dist.b) == ("normal", 0.2, 0.05)
    assert (g.obj, g.prop, g.grid) == ("Finger 0", "stiffness", (500.0, 1000.0, 2000.0))
    com, noise, push = V("Box.com=0.005", "hip_noise=0.0005", "push=1:4@2.5")
    assert (com.kind, com.obj, com.sd) == ("com", "Box", 0.005)
    assert (noise.kind, noise.sd) == ("hip_noise", 0.0005)
    assert (push.kind, push.at, push.dist.a, push.dist.b) == ("push", 2.5, 1.0, 4.0)


@pytest.mark.parametrize("text, says", [
    ("Box.mass", "expected KEY=LO:HI"),
    ("Box.mass=-1:2", "mass must be > 0"),
    ("Box.mass=0.3:0.1", "LO <= HI"),
    ("Box.mu_s=0.5~-0.1", "SD >= 0"),
    ("Box.mu_s=a:b", "mu_s expects a number"),
    ("Box.mu_s=nan:1", "must be finite"),
    ("Box.colour=1:2", "unknown property 'colour'"),
    ("wind=1:2", "unknown key 'wind'"),
    ("push=3", "push=NEWTONS@SECONDS"),
    ("push=3@-1", "push time must be >= 0"),
    ("hip_noise=-0.001", "standard deviation"),
])
def test_malformed_specs_name_what_is_wrong(text, says):
    with pytest.raises(sweep.SweepError) as ex:
        sweep.parse_vary(text)
    assert text in str(ex.value) and says in str(ex.value)


def test_keys_must_name_what_the_recording_has(lift, tmp_path, capsys):
    with pytest.raises(sweep.SweepError, match="no body or finger named 'Crate'.*bodies: Box, Table"):
        sweep.make_job(lift, V("Crate.mass=0.1:0.2"), 0)
    with pytest.raises(sweep.SweepError, match="'Table' is static"):
        sweep.make_job(lift, V("Table.mass=0.1:0.2"), 0)
    with pytest.raises(sweep.SweepError, match="no dynamic body named 'Table'"):
        sweep.make_job(lift, V("Table.com=0.01"), 0)
    with pytest.raises(sweep.SweepError, match="varied twice"):
        sweep.make_job(lift, V("Box.mass=0.1:0.2", "Box.mass=0.3"), 0)
    with pytest.raises(sweep.SweepError, match="ends at 3.000 s, before the push"):
        sweep.make_job(lift, V("push=1@3.5"), 0)
    with pytest.raises(sweep.SweepError, match="--body 'Table' is static"):
        sweep.make_job(lift, [], 0, body_name="Table")
    # On the command line a malformed spec is a usage error (2), a missing object a failure (1).
    assert cli.main(["sweep", lift.path, "--samples", "2", "--vary", "Box.mass=-1", "--out", str(tmp_path)],
                    out=io.StringIO(), err=io.StringIO()) == 2
    assert "--vary 'Box.mass=-1': mass must be > 0" in capsys.readouterr().err    # argparse's own stderr
    err = io.StringIO()
    assert cli.main(["sweep", lift.path, "--samples", "2", "--vary", "Crate.mass=1", "--out", str(tmp_path)],
                    out=io.StringIO(), err=err) == 1
    assert "Crate" in err.getvalue()


def test_sample_seeds_depend_on_the_sweep_seed_and_the_sample_only():
    a = [sweep.sample_seed(7, i) for i in range(50)]
    assert len(set(a)) == 50
    assert a[10:20] == [sweep.sample_seed(7, i) for i in range(10, 20)]
    assert a != [sweep.sample_seed(8, i) for i in range(50)]


@pytest.mark.parametrize("stretch", [8192, 700])
def test_a_sample_with_nothing_varied_is_the_recording(lift, core, monkeypatch, stretch):
    """The sweep's worlds are made with just the scene's capacities (scene.build_world(exact=
    True)); a sample with no variation replays the recording bit for bit all the same, in one
    stretch of C steps or in several (resim.STRETCH), with Python hooks between some steps."""
    from addon.engine import resim, scene
    monkeypatch.setattr(resim, "STRETCH", stretch)
    job = sweep.make_job(lift, [], 0)
    desc = recording.scene_from_dict(lift.header["scene"])
    handle = scene.build_world(desc, core, exact=True)
    called = []
    hooks = {k: (lambda world, k=k: called.append(k)) for k in (0, 1, 699, 700, 2998, 5000)}
    ticks = resim.replay(handle.world, job.hips, 1.0 / job.rate, job.has_start, hooks)
    assert called == [0, 1, 699, 700, 2998]          # in order, each once; past the end: never
    np.testing.assert_array_equal(ticks["state_hash"], lift.ticks["state_hash"])
    np.testing.assert_array_equal(ticks["tick"], lift.ticks["tick"])
    row = sweep.run_sample(job, 0, core)
    assert row["held"] == 1 and row["drop_time"] is None
    assert row["held_time"] == lift.ticks["time"][job.window[1]] - lift.ticks["time"][job.window[0]]


@pytest.mark.parametrize("stretch", [8192, 700])
def test_outcomes_from_the_traces_are_those_from_the_records(lift, core, monkeypatch, stretch):
    """A sample without the grasp measures replays with each step's short trace
    (sweep.replay_trace) instead of its record: the same fields tick by tick, in stretches with
    hooks between (a push), and the same outcomes, for samples that hold, slip and drop."""
    from addon.engine import resim, scene
    monkeypatch.setattr(resim, "STRETCH", stretch)
    job = sweep.make_job(lift, V("Box.mu_s=0.05:0.6", "hip_noise=0.0005", "push=0:4@1.5"), 3, analysis=False)
    held = set()
    for i in range(12):
        rng = np.random.default_rng(sweep.sample_seed(job.seed, i))
        d = sweep.draw(job, i, rng)
        desc = sweep._fresh_desc(job)
        sweep.apply_to_desc(desc, d.overrides)
        hips = job.hips + rng.normal(0.0, d.hip_noise, job.hips.shape)
        runs = []
        for replay in (resim.replay, sweep.replay_trace):
            h = scene.build_world(desc, core, exact=True)
            body = h.body_ids[job.body]
            runs.append(replay(h.world, hips, 1.0 / job.rate, job.has_start,
                               sweep._pusher(body, desc.bodies[job.body].mass_properties.mass, d.push,
                                             1.0 / job.rate, job.has_start)))
        records, traces = runs
        assert len(traces) == len(records)
        for name in ("time", "contact", "state", "force", "god_object", "pose"):
            assert traces[name].tobytes() == np.ascontiguousarray(records[name]).tobytes(), (i, name)
        out = sweep.outcomes(job, traces, desc)
        assert out == sweep.outcomes(job, records, desc), i
        held.add(out["held"])
        if out["max_slip"]:
            held.add("slipped")
    assert held == {0, 1, "slipped"}       # both outcomes, and slips, among the samples


# ------------------------------------------------------------------------ statistics

@pytest.mark.parametrize("k, n", [(0, 10), (3, 10), (10, 10), (37, 50), (9512, 10000), (1, 1)])
def test_wilson_interval_is_scipys(k, n):
    import scipy.stats  # the dev venv's (this module is not in the multi-version set)
    ref = scipy.stats.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    assert sweep.wilson(k, n) == pytest.approx((ref.low, ref.high), abs=1e-12)


# ------------------------------------------------------------------------ physics

def test_held_where_the_squeeze_carries_the_weight(lift, tmp_path):
    """Held when mu_s x 12 N of squeeze clearly exceeds m g, dropped when it clearly falls short
    (the lift's start and the slip to mu_d blur the boundary: +-25 % left out); the grasp is
    in force closure while held (three fingers), its epsilon larger with wider friction cones, a held grasp slips by a few mm at most (none
    with a 60 % margin) and a dropped box slides off the fingertips after the lift begins (1.0 s)."""
    res = sweep.sweep(lift, V("Box.mu_s=0.1:1.0", "Box.mass=0.05:0.6"), 24, 5, str(tmp_path), pictures=False)
    ratios = [r["Box.mu_s"] * SQUEEZE_FORCE / (r["Box.mass"] * G) for r in res.rows]
    clear = [(ratio, r) for ratio, r in zip(ratios, res.rows) if not 0.8 < ratio < 1.25]
    assert len(clear) >= 16
    for ratio, r in clear:
        assert r["held"] == (ratio > 1), (ratio, r)
        if r["held"]:
            assert r["drop_time"] is None and r["max_slip"] < (1e-9 if ratio > 1.6 else 0.01)
            assert r["closure_time"] > 2.0
            if r["Box.mu_s"] > 0.5:         # wide cones: in closure all along (narrow ones waver)
                assert r["min_epsilon"] > 0.01
        else:
            assert 1.0 < r["drop_time"] < 2.2 and r["max_slip"] > 0.005
    held = [r for r in res.rows if r["held"]]
    assert np.corrcoef([r["Box.mu_s"] for r in held], [r["min_epsilon"] for r in held])[0, 1] > 0.5
    assert 0 < res.summary["held"] < 24
    s = res.summary["sensitivity"]
    assert s["Box.mu_s"]["correlation_with_held"] > 0.3 and s["Box.mass"]["correlation_with_held"] < 0
    assert res.summary["ci95"] == list(sweep.wilson(res.summary["held"], 24))
    # the finger forces: 3, 3 and 6 N of squeeze plus the box's weight shared out
    assert all(5.9 < r["max_force"] < 9 for r in res.rows)


def test_a_push_knocks_the_box_out_a_feather_does_not(lift, tmp_path):
    res = sweep.sweep(lift, V("push=0.01,40@2.5"), 1, 0, str(tmp_path), analysis=False, pictures=False)
    feather, shove = res.rows
    assert (feather["push"], shove["push"]) == (0.01, 40.0)
    assert feather["held"] == 1 and shove["held"] == 0 and 2.5 <= shove["drop_time"] < 2.7


def test_grid_axes_multiply_and_take_their_values(lift, tmp_path):
    res = sweep.sweep(lift, V("Box.mass=0.1,5.0", "Finger 2.stiffness=1000,3000", "hip_offset=0.0005"), 2, 0,
                      str(tmp_path), analysis=False, pictures=False)
    assert len(res.rows) == 8
    cells = {(r["Box.mass"], r["Finger 2.stiffness"]) for r in res.rows}
    assert cells == {(0.1, 1000.0), (0.1, 3000.0), (5.0, 1000.0), (5.0, 3000.0)}
    assert all(r["held"] == (r["Box.mass"] == 0.1) for r in res.rows)     # 5 kg: 49 N against 12 mu N
    assert all(0 < r["hip_offset"] < 0.005 for r in res.rows)
    by_value = res.summary["sensitivity"]["Box.mass"]["by_value"]
    assert by_value == [{"value": 0.1, "n": 4, "p_held": 1.0}, {"value": 5.0, "n": 4, "p_held": 0.0}]


# ------------------------------------------------------------------------ same answer anywhere

SPECS = ["Box.mu_s=0.1:0.6", "Box.mass=0.1~0.05", "Box.com=0.003", "hip_noise=0.0002"]


def test_the_same_samples_from_one_process_two_and_a_resumed_sweep(lift, tmp_path):
    one = sweep.sweep(lift, V(*SPECS), 12, 11, str(tmp_path / "one"), workers=1)
    two = sweep.sweep(lift, V(*SPECS), 12, 11, str(tmp_path / "two"), workers=2)
    files = ("samples.csv", "summary.json", "map.png", "outcomes.png")
    for name in files:
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "two" / name).read_bytes(), name
    assert one.ran == 12 and len(read_csv(tmp_path / "one" / "samples.csv")) == 12
    # A sweep killed mid-write: 5 whole rows and a torn sixth. It runs the other 7 and ends the same.
    lines = (tmp_path / "one" / "samples.csv").read_text().splitlines(keepends=True)
    (tmp_path / "cut").mkdir()
    for name in ("sweep.json", sweep.MANIFEST_FILE):    # what it wrote first: its files, its spec
        (tmp_path / "cut" / name).write_bytes((tmp_path / "one" / name).read_bytes())
    (tmp_path / "cut" / "samples.csv").write_text("".join(lines[:6]) + lines[6][:17])
    resumed = sweep.sweep(lift, V(*SPECS), 12, 11, str(tmp_path / "cut"), workers=1)
    assert resumed.ran == 7
    for name in files:
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "cut" / name).read_bytes(), name
    # More samples later: the first 12 stay as they were.
    more = sweep.sweep(lift, V(*SPECS), 15, 11, str(tmp_path / "cut"), workers=1, pictures=False)
    assert more.ran == 3 and more.rows[:12] == one.rows
    # Another sweep in the same folder is refused, naming what differs.
    with pytest.raises(sweep.SweepError, match="holds another sweep \\(seed: 11 there, 12 now\\)"):
        sweep.sweep(lift, V(*SPECS), 12, 12, str(tmp_path / "cut"))
    # A different seed draws different samples.
    other = sweep.sweep(lift, V(*SPECS), 12, 12, str(tmp_path / "other"), pictures=False)
    assert [r["Box.mu_s"] for r in other.rows] != [r["Box.mu_s"] for r in one.rows]


def _start(args, cwd, env):
    return subprocess.Popen(args, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def test_a_dask_cluster_that_loses_a_worker_gives_the_same_samples(lift, tmp_path, monkeypatch):
    """A real `dask scheduler` and two `dask worker` processes (no nanny: a killed worker stays
    dead) on localhost, started without this checkout on their path: the engine reaches them
    as the sweep's upload. One worker is killed with SIGKILL once the first task is back."""
    from distributed import Client
    dask = os.path.join(os.path.dirname(sys.executable), "dask")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    cwd = tmp_path / "cluster"
    cwd.mkdir()
    scheduler_file = str(cwd / "scheduler.json")
    procs = [_start([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                     "--scheduler-file", scheduler_file], cwd, env)]
    try:
        deadline = time.monotonic() + 60
        while not os.path.exists(scheduler_file) and time.monotonic() < deadline:
            time.sleep(0.1)
        workers = [_start([dask, "worker", "--scheduler-file", scheduler_file, "--no-nanny", "--nthreads", "1",
                           "--no-dashboard", "--local-directory", str(cwd / f"w{i}")], cwd, env) for i in range(2)]
        procs += workers
        with Client(scheduler_file=scheduler_file, timeout=60) as client:
            client.wait_for_workers(2, timeout=60)
            address = client.scheduler.address
        monkeypatch.setattr(sweep, "CHUNK_SECONDS_DASK", 0.1)     # many tasks, so the kill lands mid-sweep
        killed = []

        def progress(done, total, seconds):
            if done > 1 and not killed:        # the first task from the cluster is back
                workers[0].send_signal(signal.SIGKILL)
                killed.append(done)
        res = sweep.sweep(lift, V(*SPECS), 40, 3, str(tmp_path / "dask"), scheduler=address, progress=progress)
        assert killed and killed[0] < 40 and workers[0].wait(10) == -signal.SIGKILL
        local = sweep.sweep(lift, V(*SPECS), 40, 3, str(tmp_path / "local"), workers=2)
        for name in ("samples.csv", "summary.json"):
            assert (tmp_path / "dask" / name).read_bytes() == (tmp_path / "local" / name).read_bytes(), name
        assert res.rows == local.rows and len(res.rows) == 40
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()


def test_unreachable_scheduler_says_so(lift, tmp_path, monkeypatch):
    monkeypatch.setattr(sweep, "CONNECT_TIMEOUT", 2.0)
    with pytest.raises(sweep.SweepError, match="tcp://127.0.0.1:9: cannot connect"):
        sweep.sweep(lift, V("Box.mu_s=0.5:0.6"), 3, 0, str(tmp_path), scheduler="tcp://127.0.0.1:9")


# ------------------------------------------------------------------------ command line

def test_command_line_end_to_end(lift, tmp_path):
    out, err = io.StringIO(), io.StringIO()
    rc = cli.main(["sweep", lift.path, "--samples", "6", "--seed", "2", "--vary", "Box.mu_s=0.1:1.0",
                   "--vary", "Box.mass=0.1:0.5", "--out", str(tmp_path), "--workers", "1"], out=out, err=err)
    assert rc == 0, err.getvalue()
    text = out.getvalue()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert f"{summary['held']} of 6 samples held 'Box'" in text and "95 % interval" in text
    rows = read_csv(tmp_path / "samples.csv")
    assert list(rows[0]) == ["sample", "seed", "Box.mu_s", "Box.mass", "held", "drop_time", "held_time",
                             "max_slip", "max_force", "closure_time", "min_epsilon"]
    assert [int(r["sample"]) for r in rows] == list(range(6))
    assert [int(r["seed"]) for r in rows] == [sweep.sample_seed(2, i) for i in range(6)]
    assert all(r["drop_time"] == "" for r in rows if r["held"] == "1")
    for name in ("map.png", "outcomes.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # run again: everything is there, nothing is re-simulated
    out = io.StringIO()
    assert cli.main(["sweep", lift.path, "--samples", "6", "--seed", "2", "--vary", "Box.mu_s=0.1:1.0",
                     "--vary", "Box.mass=0.1:0.5", "--out", str(tmp_path)], out=out, err=io.StringIO()) == 0
    assert "re-simulated" not in out.getvalue()


def test_a_scene_is_recorded_first(bpy, sample, tmp_path):
    """`grasp-lab sweep SCENE.blend`: the launcher runs the scene headless into DIR/recording.mcap
    (Blender in the parent only), then sweeps that recording; run again, it is not recorded again."""
    sample.build(bpy)
    blend = tmp_path / "pinch.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    launcher = os.path.join(os.path.dirname(sys.executable), "grasp-lab")
    out = tmp_path / "sweep"
    args = [launcher, "sweep", str(blend), "--samples", "3", "--vary", "Box.mass=0.05:0.2", "--out", str(out),
            "--workers", "2", "--no-analysis"]
    r = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    rec = recording.open_recording(str(out / "recording.mcap"))
    assert rec.header["mode"] == "exec" and rec.header["body_names"] == ["Box", "Table"]
    assert "3 samples held 'Box'" in r.stdout and len(read_csv(out / "samples.csv")) == 3
    stamp = os.stat(out / "recording.mcap").st_mtime_ns
    r = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and os.stat(out / "recording.mcap").st_mtime_ns == stamp


def test_a_sweep_killed_mid_run_resumes_to_the_same_files(lift, tmp_path):
    """`grasp-lab sweep` killed with SIGKILL while its pool works: the rows it had finished stay,
    its worker processes end with it, and the sweep run again finishes with the same files as
    one never stopped."""
    import psutil
    launcher = os.path.join(os.path.dirname(sys.executable), "grasp-lab")
    args = [launcher, "sweep", lift.path, "--samples", "200", "--seed", "4", "--vary", "Box.mu_s=0.1:1.0",
            "--vary", "Box.mass=0.05:0.6", "--no-analysis", "--workers", "2"]
    killed = tmp_path / "killed"
    p = subprocess.Popen(args + ["--out", str(killed)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    rows = 0
    while time.monotonic() < deadline and p.poll() is None:
        if (killed / "samples.csv").exists():
            rows = (killed / "samples.csv").read_text().count("\n") - 1
            if rows >= 20:
                break
        time.sleep(0.02)
    assert p.poll() is None, "the sweep ended before it could be killed"
    children = psutil.Process(p.pid).children(recursive=True)
    p.send_signal(signal.SIGKILL)
    p.wait(10)
    gone, alive = psutil.wait_procs(children, timeout=10)
    for c in alive:         # not to leave them behind when the check below fails
        c.kill()
    assert not alive, f"workers left running: {alive}"
    kept = read_csv(killed / "samples.csv")
    assert 20 <= len(kept) < 200
    r = subprocess.run(args + ["--out", str(killed)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert f"{200 - len(kept)} samples re-simulated" in r.stdout
    whole = tmp_path / "whole"
    r = subprocess.run(args + ["--out", str(whole)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    for name in ("samples.csv", "summary.json", "map.png", "outcomes.png"):
        assert (killed / name).read_bytes() == (whole / name).read_bytes(), name


def test_inside_blender_the_sweep_runs_in_blenders_process(ext, lift, tmp_path):
    """The extension's own copy of the command line (as `blender -c grasp_lab sweep` runs it):
    its pool workers could not import a module of Blender's extension package, so the samples
    run in this process, the same samples as outside."""
    import importlib
    ext_cli = importlib.import_module(f"{ext}.engine.cli")
    out, err = io.StringIO(), io.StringIO()
    args = ["sweep", lift.path, "--samples", "4", "--vary", "Box.mu_s=0.1:1.0", "--no-analysis"]
    assert ext_cli.main(args + ["--out", str(tmp_path / "in"), "--workers", "2"], out=out, err=err) == 0, \
        err.getvalue()
    assert cli.main(args + ["--out", str(tmp_path / "out"), "--workers", "2"], out=io.StringIO(),
                    err=io.StringIO()) == 0
    assert (tmp_path / "in" / "samples.csv").read_bytes() == (tmp_path / "out" / "samples.csv").read_bytes()
