"""The tick log from Python (graspcore.World.tick_record / set_tick_log / drain_ticks): the
record layout, values against the world's own queries, the manual-clock runtime's records
against its snapshots, overflow counted, bad buffers refused."""
import numpy as np
import pytest

import graspcore
from scenes import box_points


def pinch_world():
    w = graspcore.World()
    w.add_body(box_points(0.03, 0.03, 0.03), mass=0.1, position=(0, 0, 0.2))
    w.add_body(box_points(0.2, 0.2, 0.01), static=True, position=(0.5, 0, 0))
    w.add_finger(radius=0.005, position=(-0.04, 0, 0.2))
    w.add_finger(radius=0.005, position=(0.04, 0, 0.2))
    return w


def test_layout_matches_the_core():
    for nb, nf in ((0, 0), (1, 2), (20, 10)):
        assert graspcore.tick_dtype(nb, nf).itemsize == graspcore._core.tick_record_size(nb, nf)
    with pytest.raises(ValueError):
        graspcore._core.tick_record_size(-1, 0)


def test_stopped_record_is_the_world():
    w = pinch_world()
    hips = np.array([[-0.028, 0, 0.2], [0.028, 0, 0.2]])
    for _ in range(20):
        w.set_hips(hips)
        w.step(1e-3)
    r = w.tick_record(tick=20)
    assert r["tick"] == 20 and r["time"] == w.time and r["state_hash"] == w.state_hash()
    np.testing.assert_array_equal(r["pose"], w.body_poses)
    np.testing.assert_array_equal(r["hip"], hips)
    np.testing.assert_array_equal(r["god_object"], w.god_objects)
    np.testing.assert_array_equal(r["force"], w.finger_forces)
    np.testing.assert_array_equal(r["device_force"], r["force"])
    for b in range(2):
        lin, ang = w.body_velocity(b)
        f, t = w.residual_wrench(b)
        np.testing.assert_array_equal(r["velocity"][b], np.concatenate([lin, ang]))
        np.testing.assert_array_equal(r["wrench"][b], np.concatenate([f, t]))
    assert list(r["contact"]) == [0, 0]
    assert [graspcore.FINGER_STATES[s] for s in r["state"]] == [w.finger_state(0), w.finger_state(1)]
    # Contact normals: out of the faces the fingers press on.
    np.testing.assert_allclose(r["normal"], [[-1, 0, 0], [1, 0, 0]], atol=1e-9)


def test_manual_clock_records_every_tick_as_its_snapshot():
    w = pinch_world()
    w.set_tick_log(64)
    w.start(realtime=False, haptic_rate=1000.0)
    try:
        out = np.zeros(64, w.tick_dtype())
        snaps = []
        for k in range(30):
            w.push_hips(np.array([[-0.04 + 0.0005 * k, 0, 0.2], [0.04 - 0.0005 * k, 0, 0.2]]), 1e-3 * k)
            w.advance(1)
            snaps.append(w.snapshot())
        got = w.drain_ticks(out)
        assert len(got) == 30 and list(got["tick"]) == list(range(1, 31))
        for r, s in zip(got, snaps):
            assert r["time"] == s["time"] and r["tick"] == s["tick"]
            np.testing.assert_array_equal(r["pose"], s["poses"])
            np.testing.assert_array_equal(r["device_force"], s["forces"])
            np.testing.assert_array_equal(r["force"], s["spring_forces"])
            np.testing.assert_array_equal(r["contact"], s["contact_bodies"])
            assert bool(r["flags"] & 1) == s["forces_enabled"]
        assert got["contact"][-1].tolist() == [0, 0]      # they closed on the box
        # Nobody drains: the ring keeps 64, drops the rest and counts them.
        w.advance(100)
        assert w.tick_log_overflow() == 36
        assert list(w.drain_ticks(out)["tick"]) == list(range(31, 95))
    finally:
        w.stop()


def test_bad_buffers_and_calls_refused():
    w = pinch_world()
    with pytest.raises(ValueError, match="out"):
        w.drain_ticks(np.zeros(4, graspcore.tick_dtype(1, 2)))
    with pytest.raises(ValueError, match="need at least"):
        w._tick_record(np.zeros(10, np.uint8), 0)
    with pytest.raises(ValueError, match="capacity"):
        w.set_tick_log(-5)
    with pytest.raises(ValueError, match=r"capacity 4294967299 is outside 0 \.\. 2147483647"):
        w.set_tick_log(2**32 + 3)           # would wrap to a 3-record ring in the core's C int
    w.set_tick_log(8)
    w.start(realtime=False)
    try:
        with pytest.raises(RuntimeError, match="running"):
            w.tick_record()
        with pytest.raises(RuntimeError, match="running"):
            w.set_tick_log(16)
    finally:
        w.stop()


def test_normal_is_the_reported_contacts():
    """A finger in two bodies at once reports its deepest contact: the record's and the
    snapshot's normal is that contact's, with its god-object and body (the grasp analysis takes
    them as one contact), not the first contact's."""
    w = graspcore.World()
    w.add_body(box_points(0.05, 0.05, 0.05), static=True, position=(-0.05, 0, 0))    # face x = 0, normal +x
    w.add_body(box_points(0.05, 0.05, 0.05), static=True, position=(0.05, 0, 0.1))   # face z = 0.05, normal -z
    hip = (0.008, 0.0, 0.044)       # 2 mm into the first (its contact comes first), 4 mm into the second
    w.add_finger(radius=0.01, position=hip)
    w.set_hips(np.array([hip]))
    w.step(1e-3)
    r = w.tick_record(tick=1)
    assert r["contact"][0] == 1 and r["state"][0] == 1
    np.testing.assert_allclose(r["god_object"][0], (0.008, 0.0, 0.04), atol=1e-9)
    np.testing.assert_allclose(r["normal"][0], (0.0, 0.0, -1.0), atol=1e-12)
    np.testing.assert_array_equal(w.snapshot()["normals"][0], r["normal"][0])
