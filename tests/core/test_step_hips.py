"""World.step_hips (a HIP stream replayed in C, what resim and sweep run) against the same
steps taken one by one from Python: the same records byte for byte; HIPs that reach it
unaligned (as Dask's deserialiser leaves them) taken as well; bad arguments refused with
the world unchanged."""
import numpy as np
import pytest

import graspcore
from scenes import box_points


def pinch_world():
    w = graspcore.World()
    w.add_body(box_points(0.03, 0.03, 0.03), mass=0.1, position=(0, 0, 0.2))
    w.add_finger(radius=0.005, damping=2.0, position=(-0.04, 0, 0.2))
    w.add_finger(radius=0.005, damping=2.0, position=(0.04, 0, 0.2))
    return w


def squeeze_and_lift(steps):
    k = np.arange(steps)
    x = np.full(steps, 0.032)                       # 3 mm into the box's faces from the start
    z = 0.2 + 0.0002 * np.maximum(k - 100, 0)
    return np.ascontiguousarray(np.stack([np.stack([-x, 0 * x, z], 1), np.stack([x, 0 * x, z], 1)], 1))


def test_the_same_records_as_step_by_step():
    hips = squeeze_and_lift(600)
    a, b = pinch_world(), pinch_world()
    one = np.zeros(600, a.tick_dtype())
    for k in range(600):
        a.set_hips(hips[k])
        a.step(0.001)
        a._tick_record(one[k:k + 1], k + 1)
    all_ = np.zeros(600, b.tick_dtype())
    assert b.step_hips(hips, 0.001, all_).base is all_
    assert one.tobytes() == all_.tobytes()
    assert b.state_hash() == a.state_hash() and all_["tick"][-1] == 600
    assert all_["contact"][-1].tolist() == [0, 0] and all_["pose"][-1, 0, 2] > 0.28      # squeezed and lifted
    c = pinch_world()
    assert c.step_hips(hips, 0.001, None) is None           # the steps alone: the same state
    assert c.state_hash() == a.state_hash()


def test_unaligned_hips_are_taken():
    hips = squeeze_and_lift(50)
    raw = bytearray(hips.nbytes + 1)
    shifted = np.ndarray(hips.shape, dtype=np.float64, buffer=raw, offset=1)
    shifted[:] = hips
    assert not shifted.flags["ALIGNED"]
    a, b = pinch_world(), pinch_world()
    ta, tb = np.zeros(50, a.tick_dtype()), np.zeros(50, b.tick_dtype())
    a.step_hips(hips, 0.001, ta)
    b.step_hips(shifted, 0.001, tb)
    assert ta.tobytes() == tb.tobytes()


def test_bad_arguments_change_nothing():
    w = pinch_world()
    out = np.zeros(10, w.tick_dtype())
    hips = squeeze_and_lift(10)
    with pytest.raises(ValueError, match="hips: expected a \\(steps, fingers, 3\\) array"):
        w.step_hips(hips[:, :, :2], 0.001, out)
    with pytest.raises(ValueError, match="out: expected"):
        w.step_hips(hips, 0.001, out[:5])
    with pytest.raises(ValueError, match="out: expected"):
        w.step_hips(hips, 0.001, np.zeros(10, graspcore.tick_dtype(1, 3)))
    with pytest.raises(ValueError, match="dt"):
        w.step_hips(hips, -0.001, out)
    bad = hips.copy()
    bad[0, 1, 2] = np.nan
    with pytest.raises(ValueError, match="positions"):
        w.step_hips(bad, 0.001, out)
    assert w.time == 0.0 and not out.tobytes().strip(b"\0")
    with pytest.raises(ValueError, match="positions"):
        w.step_hips(np.zeros((3, 5, 3)), 0.001, out)     # more fingers than the world has


def test_the_trace_holds_the_records_fields_tick_by_tick():
    """step_hips_trace: each field (time, contact, state, force, god_object, pose) equal to the
    records' of step_hips on the same HIPs, bit for bit, whether in one call or in two at an
    offset; the same final state; a layout or range that does not fit refused."""
    hips = squeeze_and_lift(600)
    a, b, c = pinch_world(), pinch_world(), pinch_world()
    records = a.step_hips(hips, 0.001, np.zeros(600, a.tick_dtype()))
    one = b.step_hips_trace(hips, 0.001, np.zeros((), b.trace_dtype(600)))
    two = np.zeros((), c.trace_dtype(601))
    c.step_hips_trace(hips[:250], 0.001, two, first=1)
    c.step_hips_trace(hips[250:], 0.001, two, first=251)
    for name in ("time", "contact", "state", "force", "god_object", "pose"):
        assert one[name].tobytes() == records[name].tobytes(), name
        assert two[name][1:].tobytes() == records[name].tobytes(), name
        assert one[name].flags.c_contiguous
    assert a.state_hash() == b.state_hash() == c.state_hash()
    assert records["state"].max() > 0 and records["contact"].min() == 0       # in contact throughout
    with pytest.raises(ValueError, match="first"):
        c.step_hips_trace(hips[:10], 0.001, two, first=595)
    with pytest.raises(ValueError, match="out"):
        c.step_hips_trace(hips[:10], 0.001, np.zeros(10, c.tick_dtype()))
