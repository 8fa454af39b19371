"""HIP input of the haptic loop (docs/runtime.md "Input"): a scripted track sampled at the
loop's own tick times, and timestamped samples walked at a bounded speed. Both make the
haptic rate independent of how often the caller (a Blender display) runs."""
import numpy as np
import pytest

import graspcore
from test_runtime import DT, pinch_hips, pinch_scene


def frames_of_pinch(fps):
    """The pinch motion as a timeline would give it: one sample a frame."""
    times = np.arange(0.0, 1.0 + 1e-9, 1.0 / fps)
    return times, np.stack([pinch_hips(t / DT) for t in times])


def interpolate(times, positions, t):
    """Reference: linear between samples, held at either end (the Python SampledTrajectory)."""
    return np.stack([[np.interp(t, times, positions[:, f, k]) for k in range(3)]
                     for f in range(positions.shape[1])])


@pytest.mark.parametrize("fps", [24.0, 5.0])
def test_a_track_reproduces_synchronous_steps_bit_for_bit(fps):
    times, positions = frames_of_pinch(fps)
    ticks = 900
    ref = pinch_scene()
    t0 = times[0]
    for i in range(ticks):
        tt = t0 + (i + 1) * DT
        j = min(int(np.searchsorted(times, tt, side="right")) - 1, len(times) - 2)
        a = (tt - times[j]) / (times[j + 1] - times[j])
        hips = (1.0 - a) * positions[j] + a * positions[j + 1] if tt < times[-1] else positions[-1]
        ref.set_hips(np.ascontiguousarray(hips))
        ref.step(DT)
    w = pinch_scene()
    w.set_hip_track(times, positions)
    w.start(realtime=False, object_rate=1000)
    w.advance(ticks)                      # no push at all: the track is the input
    snap = w.snapshot()
    stats = w.stats()
    w.stop()
    assert w.state_hash() == ref.state_hash()
    assert snap["forces_enabled"] and stats["stale_inputs"] == 0   # a track is never stale
    np.testing.assert_allclose(snap["hips"], interpolate(times, positions, ticks * DT), atol=1e-12)


def test_a_track_is_held_past_its_end_and_refused_while_running():
    w = pinch_scene()
    times = np.array([0.0, 0.1])
    pos = np.array([[[-0.05, 0, 0.0], [0.05, 0, 0.0]], [[-0.05, 0, 0.01], [0.05, 0, 0.01]]])
    w.set_hip_track(times, pos)
    w.start(realtime=False)
    w.advance(300)
    np.testing.assert_array_equal(w.snapshot()["hips"], pos[-1])
    with pytest.raises(RuntimeError, match="running"):
        w.set_hip_track(times, pos)
    w.stop()
    w.set_hip_track(None, None)           # cleared: pushed input drives every finger again
    w.start(realtime=False)
    w.push_hips(np.zeros((2, 3)), 0.0)
    w.advance(1)
    np.testing.assert_array_equal(w.snapshot()["hips"], np.zeros((2, 3)))
    w.stop()


@pytest.mark.parametrize("times, positions, message", [
    ([0.0, 0.0], np.zeros((2, 2, 3)), "strictly increasing"),
    ([0.0, np.nan], np.zeros((2, 2, 3)), "times\\[1\\]"),
    ([0.0, 1.0], np.full((2, 2, 3), np.inf), "non-finite"),
    ([0.0, 1.0], np.zeros((2, 3, 3)), "num_fingers 3"),
    ([0.0, 1.0], np.zeros((3, 2, 3)), "expected times"),
])
def test_bad_tracks_are_refused_naming_what_is_wrong(times, positions, message):
    with pytest.raises(ValueError, match=message):
        pinch_scene().set_hip_track(times, positions)


def test_a_partial_track_leaves_the_other_fingers_to_pushed_samples():
    w = pinch_scene()
    times, positions = frames_of_pinch(30.0)
    w.set_hip_track(times, positions, scripted=[True, False])
    w.start(realtime=False)
    pushed = np.array([[9.0, 9.0, 9.0], [0.2, 0.0, 0.3]])
    w.push_hips(pushed, 0.0)
    w.advance(100)
    hips = w.snapshot()["hips"]
    w.stop()
    np.testing.assert_allclose(hips[0], interpolate(times, positions, 0.1)[0], atol=1e-12)
    np.testing.assert_array_equal(hips[1], pushed[1])   # finger 0 ignored its pushed sample


def test_slow_samples_are_walked_smoothly_at_a_bounded_speed():
    """A 5 Hz caller: each sample is reached over the 0.2 s since the previous one, never
    faster than max_hip_speed, with no jump at the moment a sample arrives."""
    w = graspcore.World()
    w.add_finger(position=(0.0, 0.0, 1.0))
    w.start(realtime=False, max_hip_speed=0.5)
    path = []
    w.push_hips(np.array([[0.0, 0.0, 1.0]]), 0.0)
    w.advance(1)
    for k in range(1, 6):
        w.push_hips(np.array([[0.02 * k, 0.0, 1.0]]), 0.2 * k)   # 0.1 m/s in 2 cm steps
        for _ in range(200):
            w.advance(1)
            path.append(w.snapshot()["hips"][0, 0])
    steps = np.diff(np.concatenate([[0.0], path]))
    assert np.all(steps >= 0) and steps.max() == pytest.approx(0.1 * DT, rel=1e-6)  # 0.1 mm a tick
    assert path[199] == pytest.approx(0.02, abs=1e-12) and path[-1] == pytest.approx(0.1, abs=1e-12)
    # A jump of 1 m is walked at 0.5 m/s: 0.5 mm a tick, reached after 2 s, never skipped.
    w.push_hips(np.array([[1.1, 0.0, 1.0]]), 1.2)
    w.advance(10)
    assert w.snapshot()["hips"][0, 0] == pytest.approx(0.1 + 10 * 0.5 * DT, abs=1e-9)
    w.advance(2000)
    assert w.snapshot()["hips"][0, 0] == pytest.approx(1.1, abs=1e-12)
    w.stop()


def test_max_hip_speed_is_validated():
    with pytest.raises(ValueError, match="max_hip_speed"):
        pinch_scene().start(realtime=False, max_hip_speed=-1.0)
