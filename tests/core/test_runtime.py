"""The runtime's Python API (docs/runtime.md): start/stop, push_hips, snapshot, stats,
the manual clock that reproduces synchronous stepping, safety, refusals while running.
Behaviour only: rates and jitter are measured by bench/bench_jitter.py, not asserted."""
import pathlib
import re
import threading
import time

import numpy as np
import pytest

import graspcore
from scenes import box_points
from waiting import wait_until

DT = 1e-3


def pinch_scene():
    """A 6 cm box between two fingers, a box on a static table, a box falling freely."""
    w = graspcore.World()
    w.add_body(box_points(0.03, 0.03, 0.03), mass=0.2)
    w.add_body(box_points(0.05, 0.05, 0.05), static=True, position=(0.5, 0, -0.1))
    w.add_body(box_points(0.02, 0.02, 0.02), mass=0.1, position=(0.5, 0, -0.07 + 1e-4))
    w.add_body(box_points(0.02, 0.02, 0.02), mass=0.1, position=(-0.5, 0, 0.2))
    w.add_finger(damping=2.0, position=(-0.041, 0, 0))
    w.add_finger(damping=2.0, position=(0.041, 0, 0))
    return w


def pinch_hips(i):
    """Squeeze 3 mm and lift 5 cm over 0.5 s, hold, open the hand from 0.7 s."""
    lift = 0.05 * min(i / 500, 1.0)
    opening = 0.03 * min((i - 700) / 100, 1.0) if i > 700 else 0.0
    return np.array([[-0.035 - opening, 0, lift], [0.035 + opening, 0, lift]])


def test_manual_clock_reproduces_synchronous_steps_through_a_hand_over():
    ticks = 1000
    ref = pinch_scene()
    for i in range(ticks):
        ref.set_hips(pinch_hips(i))
        ref.step(DT)

    w = pinch_scene()
    w.start(realtime=False, object_rate=1000)
    adopted = []
    for i in range(ticks):
        assert w.push_hips(pinch_hips(i), i * DT)
        w.advance(1)
        adopted.append(w.stats()["adopted_bodies"])
    snap = w.snapshot()
    w.stop()
    assert w.state_hash() == ref.state_hash()
    assert max(adopted) == 1 and adopted[-1] == 0   # taken over while held, handed back
    assert snap["tick"] == ticks and snap["time"] == pytest.approx(ticks * DT)
    assert snap["poses"].shape == (4, 7) and snap["hips"].shape == (2, 3)
    np.testing.assert_array_equal(w.body_poses, ref.body_poses)


def test_manual_clock_with_a_slower_object_manager_is_deterministic():
    hashes = []
    for _ in range(2):
        w = pinch_scene()
        w.start(realtime=False)                     # object manager at 500 Hz
        for i in range(600):
            w.push_hips(pinch_hips(i), i * DT)
            w.advance(1)
        stats = w.stats()
        w.stop()
        assert stats["object_ticks"] == 300 and stats["haptic_ticks"] == 600
        assert w.body_pose(0)[0][2] == pytest.approx(0.049, abs=2e-3)   # held and lifted
        hashes.append(w.state_hash())
    assert hashes[0] == hashes[1]


def test_snapshot_layout_and_queries_while_running():
    w = pinch_scene()
    snap = w.snapshot()                              # stopped: the world's own state
    assert snap["tick"] == 0 and not snap["forces_enabled"]
    assert snap["finger_states"].dtype == np.int32 and snap["contact_bodies"].tolist() == [-1, -1]
    w.start(realtime=False)
    w.push_hips(pinch_hips(0), 0.0)
    w.advance(20)
    snap = w.snapshot()
    assert set(snap) >= {"time", "object_time", "tick", "forces_enabled", "poses", "residual_forces",
                         "residual_torques", "adopted", "god_objects", "hips", "forces", "spring_forces",
                         "finger_states", "contact_bodies"}
    assert snap["residual_forces"].shape == (4, 3) and snap["adopted"].dtype == bool
    assert snap["contact_bodies"].tolist() == [0, 0]
    assert [graspcore.FINGER_STATES[s] for s in snap["finger_states"]] == ["stick", "stick"]
    # Queries and views answer from the last snapshot while running.
    assert w.time == snap["time"]
    np.testing.assert_array_equal(w.body_poses, snap["poses"])
    assert w.finger_contact(0) == 0
    w.stop()


def test_snapshot_normals_and_velocities_running_and_stopped():
    """Normals point out of the box touched (the fingers squeeze it from -x and +x); the
    falling box moves at -g t (semi-implicit Euler is exact for it), the lifted box at the
    hand's 0.1 m/s; the stopped world answers the same way."""
    w = pinch_scene()
    snap = w.snapshot()
    assert snap["normals"].shape == (2, 3) and not snap["normals"].any()        # free
    assert snap["linear_velocities"].shape == (4, 3) and not snap["linear_velocities"].any()
    w.start(realtime=False, object_rate=1000)
    for i in range(300):
        w.push_hips(pinch_hips(i), i * DT)
        w.advance(1)
    snap = w.snapshot()
    np.testing.assert_allclose(snap["normals"], [[-1, 0, 0], [1, 0, 0]], atol=1e-6)
    lin, ang = snap["linear_velocities"], snap["angular_velocities"]
    assert lin[3] == pytest.approx([0, 0, -9.81 * snap["object_time"]], abs=1e-9)
    assert lin[0][2] == pytest.approx(0.1, abs=0.01) and abs(lin[0][0]) < 1e-3
    assert np.abs(ang[0]).max() < 0.05 and not ang[3].any()
    assert w.body_velocity(3)[0] == pytest.approx(tuple(lin[3]), abs=0)     # queries answer from it
    w.stop()
    stopped = w.snapshot()
    np.testing.assert_allclose(stopped["normals"], [[-1, 0, 0], [1, 0, 0]], atol=1e-6)
    assert stopped["linear_velocities"][3] == pytest.approx([0, 0, -9.81 * w.time], abs=1e-9)
    record = w.tick_record()
    np.testing.assert_array_equal(record["normal"], stopped["normals"])


def test_mutating_calls_are_refused_while_running():
    w = pinch_scene()
    w.start(realtime=False)
    for call in (lambda: w.step(DT), lambda: w.set_hip(0, (0, 0, 0)), lambda: w.set_hips(np.zeros((2, 3))),
                 lambda: w.add_body(box_points(0.01, 0.01, 0.01)), lambda: w.add_finger(),
                 lambda: w.set_gravity((0, 0, 0)), lambda: w.set_body_pose(0, (0, 0, 0), (1, 0, 0, 0)),
                 lambda: w.start(realtime=False)):
        with pytest.raises(RuntimeError):
            call()
    w.stop()
    w.stop()                                         # a no-op
    w.step(DT)                                       # synchronous again
    with pytest.raises(RuntimeError):
        w.push_hips(np.zeros((2, 3)), 0.0)
    with pytest.raises(RuntimeError):
        w.advance(1)


def test_start_arguments_are_checked_and_named():
    w = pinch_scene()
    for kwargs, name in [({"haptic_rate": 1.0}, "haptic_rate"), ({"object_rate": 2000.0}, "object_rate"),
                         ({"max_force": float("nan")}, "max_force"), ({"watchdog_timeout": 1e-4}, "watchdog"),
                         ({"hip_timeout": 0.0}, "hip_timeout"), ({"max_adopted_bodies": -1}, "max_adopted"),
                         ({"priority": 200}, "priority")]:
        with pytest.raises(ValueError, match=name):
            w.start(**kwargs)
        assert not w.running
    w.start(realtime=False)
    with pytest.raises(RuntimeError):
        w.start()                                    # already running
    with pytest.raises(ValueError, match="delay"):
        w.advance(1, delay=-1.0)
    with pytest.raises(ValueError, match="ticks"):
        w.advance(-1)
    w.stop()


def test_bad_input_is_rejected_counted_and_never_propagated():
    w = pinch_scene()
    w.start(realtime=False)
    good = pinch_hips(0)
    assert w.push_hips(good, 1.0)
    assert not w.push_hips([[np.nan, 0, 0], [0, 0, 0]], 2.0)
    assert not w.push_hips([[np.inf, 0, 0], [0, 0, 0]], 2.0)
    assert not w.push_hips(good + 0.01, float("nan"))
    assert not w.push_hips(good + 0.01, 0.5)        # older than the last push
    with pytest.raises(ValueError, match="positions"):
        w.push_hips(np.zeros((3, 3)), 3.0)          # more rows than fingers: a programming error
    with pytest.raises(ValueError, match="positions"):
        w.push_hips(np.zeros((2, 2)), 3.0)
    w.advance(5)
    stats = w.stats()
    assert stats["rejected_inputs"] == 4 and stats["accepted_inputs"] == 1
    snap = w.snapshot()
    np.testing.assert_array_equal(snap["hips"], good)
    assert np.all(np.isfinite(snap["poses"])) and np.all(np.isfinite(snap["forces"]))
    w.stop()


def press_scene():
    """One finger that will be held 5 cm deep in a static block: a 50 N spring."""
    w = graspcore.World()
    w.add_body(box_points(0.1, 0.1, 0.1), static=True)
    w.add_finger(position=(0, 0, 0.2))
    return w


def press(w, ticks, t0, z=0.058):
    for i in range(ticks):
        w.push_hips([[0, 0, z]], t0 + i * DT)
        w.advance(1)
    return t0 + ticks * DT


def test_clamp_ramp_watchdog_and_stale_input():
    w = press_scene()
    w.start(realtime=False, max_force=10.0, ramp_time=0.2, hip_timeout=0.05, watchdog_timeout=0.004)
    w.advance(3)
    assert not w.snapshot()["forces_enabled"]       # no input yet: forces off
    t = 0.0
    for i in range(20):                              # sweep in (the entry needs the path)
        w.push_hips([[0, 0, 0.2 - 0.142 * min(i / 18, 1.0)]], t)
        w.advance(1)
        t += DT
    snap = w.snapshot()
    np.testing.assert_allclose(snap["spring_forces"][0], (0, 0, 50.0), atol=1e-6)
    assert 0.0 < snap["forces"][0, 2] < 0.15 * 50.0              # ramping in
    t = press(w, 100, t)
    snap = w.snapshot()
    assert np.linalg.norm(snap["forces"][0]) == pytest.approx(10.0)   # clamped
    assert snap["spring_forces"][0, 2] == pytest.approx(50.0)         # physics unclamped
    # A stalled loop (the manual clock jumps 10 ms) trips the watchdog: zero, ramp again.
    w.push_hips([[0, 0, 0.058]], t)
    w.advance(1, delay=0.010)
    snap = w.snapshot()
    assert not snap["forces_enabled"] and not snap["forces"].any()
    assert w.stats()["watchdog_trips"] == 1
    t = press(w, 10, t + DT)
    assert 0.0 < np.linalg.norm(w.snapshot()["forces"][0]) < 10.0
    # Stale input: nothing pushed for longer than hip_timeout.
    w.advance(80)
    snap = w.snapshot()
    assert not snap["forces_enabled"] and not snap["forces"].any()
    assert snap["spring_forces"][0, 2] == pytest.approx(50.0)   # the physics goes on
    assert w.stats()["stale_inputs"] == 1
    w.stop()
    assert not w.snapshot()["forces"].any()          # stopped: nothing is rendered


def test_realtime_threads_with_inputs_and_snapshots_from_other_threads():
    w = pinch_scene()
    w.start(watchdog_timeout=0.05)
    stats = w.stats()
    assert stats["running"] and stats["realtime"] and isinstance(stats["rt_priority"], bool)
    assert stats["priority_note"]
    done = threading.Event()
    counts = {"pushes": 0, "snapshots": 0}
    t0 = time.monotonic()

    def pusher():
        while not done.is_set():
            try:
                if w.push_hips(pinch_hips(300), time.monotonic() - t0):
                    counts["pushes"] += 1
            except RuntimeError:                     # stopped under its feet: expected
                return
            time.sleep(0.001)

    def reader():
        while not done.is_set():
            snap = w.snapshot()
            assert np.all(np.isfinite(snap["poses"]))
            counts["snapshots"] += 1
            time.sleep(0.002)

    threads = [threading.Thread(target=pusher), threading.Thread(target=reader)]
    for th in threads:
        th.start()
    wait_until(lambda: w.stats()["adopted_bodies"] == 1, 60, "the haptic loop to adopt the gripped box",
               seen=lambda: w.stats()["adopted_bodies"])
    adopted = w.stats()["adopted_bodies"]
    w._debug_stall(0.02)                             # stop while the haptic loop is stalled
    time.sleep(0.002)
    started = time.monotonic()
    w.stop()
    assert time.monotonic() - started < 5.0
    done.set()
    for th in threads:
        th.join()
    assert adopted == 1
    assert counts["pushes"] > 0 and counts["snapshots"] > 0
    stats = w.stats()
    assert not stats["running"] and stats["haptic_ticks"] > 0 and stats["object_ticks"] > 0
    assert stats["jitter_p50_us"] <= stats["jitter_p99_us"] <= stats["jitter_max_us"]
    assert np.all(np.isfinite(w.body_poses)) and w.time > 0.0
    w.step(DT)                                       # synchronous again


def test_haptic_thread_reports_its_setup():
    """The haptic thread sets itself up before its first tick (docs/runtime.md, "Getting on
    time"); start() returns once the note says how it runs and whether memory is locked."""
    w = pinch_scene()
    for priority, head in ((0, r"normal priority \(priority=0\), (0\.1 ms|default) slice"),
                           (80, r"(haptic loop at SCHED_FIFO 80|SCHED_FIFO 80 refused \(.+\): haptic loop at "
                                r"normal priority, (0\.1 ms|default) slice)")):
        w.start(watchdog_timeout=0.05, priority=priority)
        note = w.stats()["priority_note"]
        assert re.fullmatch(head + r"; (\d+ KiB locked|memory not locked \(.+\))", note), note
        assert w.stats()["rt_priority"] == note.startswith("haptic loop at SCHED_FIFO")
        tasks = pathlib.Path("/proc/self/task")
        if tasks.is_dir():
            # start() waits for the haptic thread's set-up only; the object manager names
            # itself as it starts, a moment later.
            def names():
                return {(t / "comm").read_text().strip() for t in tasks.iterdir()}
            wait_until(lambda: {"gc-haptic", "gc-object"} <= names(), 60, "both threads named", seen=names,
                       poll=0.001)
        w.stop()


def test_many_start_stop_cycles_and_deleting_a_running_world():
    w = pinch_scene()
    for i in range(200):
        w.start(watchdog_timeout=0.05)
        if i % 20 == 0:
            w.push_hips(pinch_hips(0), 0.0)
            time.sleep(0.002)
        w.stop()
        assert not w.running
    w.start()
    del w                                            # destroy stops the threads


def test_replay_ticks_reproduces_a_manual_clock_run_and_names_a_bad_schedule():
    """World.replay_ticks: a run on the manual clock (object manager at 500 Hz: results taken
    every other tick) recorded by its tick log, replayed from its records' HIPs and schedule on
    a fresh world: every state hash equal. A schedule going back raises ValueError naming the
    step; the ticks before it ran."""
    w = pinch_scene()
    w.set_tick_log(2048)
    w.start(realtime=False)
    for i in range(600):
        w.push_hips(pinch_hips(i), i * DT)
        w.advance(1)
    w.stop()
    rec = w.drain_ticks(np.zeros(2048, dtype=w.tick_dtype()))
    # object tick k runs after haptic tick 2k and is taken at tick 2k + 1
    assert len(rec) == 600 and rec["object_tick"][-1] == 299 and rec["adopted"].max() == 1
    np.testing.assert_array_equal(rec["object_reads"], np.arange(600) // 2)
    np.testing.assert_array_equal(rec["object_tick"], np.arange(600) // 2)
    r = pinch_scene()
    r.start(realtime=False)
    out = r.replay_ticks(rec["hip"], rec["object_tick"], rec["object_reads"],
                         np.zeros(600, dtype=r.tick_dtype()), orientations=rec["orientation"])
    r.stop()
    np.testing.assert_array_equal(out["state_hash"], rec["state_hash"])
    np.testing.assert_array_equal(out["pose"], rec["pose"])
    b = pinch_scene()
    b.start(realtime=False)
    reads = rec["object_reads"][:20].copy()
    reads[12] -= 2                                  # fewer object ticks than had already run
    with pytest.raises(ValueError, match=r"at step 12 \(tick 13\): object_reads goes back"):
        b.replay_ticks(rec["hip"][:20], rec["object_tick"][:20], reads, None)
    with pytest.raises(ValueError, match="object_ticks"):
        b.replay_ticks(rec["hip"][:5], rec["object_tick"][:4], rec["object_reads"][:5], None)
    b.stop()
    with pytest.raises(RuntimeError, match="manual clock"):
        b.replay_ticks(rec["hip"][:5], rec["object_tick"][:5], rec["object_reads"][:5], None)
