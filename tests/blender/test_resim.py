"""Re-simulation (addon/engine/resim.py) in plain Python: an EXEC recording replayed with no
override is identical bit for bit (every tick's state hash), and so is a live recording of the
threaded runtime (replayed on its recorded hand-over schedule); an override parts the runs
where physics says it must, and the report says when and where; KEY=VALUE parsing."""
import dataclasses

import numpy as np
import pytest

import recordings
from addon.engine import recording, resim


@pytest.fixture(scope="module")
def rec(core, tmp_path_factory):
    path = tmp_path_factory.mktemp("resim") / "pinch.mcap"
    recordings.record_exec(path, core)
    return recording.open_recording(path)


def test_unchanged_parameters_reproduce_every_tick(rec, core):
    result = resim.resimulate(rec, core)
    assert result.divergence.identical and result.divergence.report() == "identical"
    np.testing.assert_array_equal(result.ticks["state_hash"], rec.ticks["state_hash"])
    np.testing.assert_array_equal(result.ticks["pose"], rec.ticks["pose"])


@pytest.fixture(scope="module")
def live(core, tmp_path_factory):
    """A 2 s pinch and lift on the threaded runtime, real threads, recorded."""
    path = tmp_path_factory.mktemp("resim_live") / "live.mcap"
    recordings.record_realtime(path, core, seconds=2.0)
    return recording.open_recording(path)


def test_a_live_recording_replays_bit_for_bit_on_its_hand_over_schedule(live, core):
    ticks = live.ticks
    assert live.header["runtime"]["threaded"] and len(ticks) > 1900
    np.testing.assert_array_equal(ticks["tick"], np.arange(len(ticks)))     # none dropped
    assert ticks["adopted"].max() == 1                  # the box was handed to the haptic loop
    assert ticks["object_tick"][-1] > 800               # the object manager ran alongside
    result = resim.resimulate(live, core)
    assert result.divergence.report() == "identical"
    np.testing.assert_array_equal(result.ticks["state_hash"], ticks["state_hash"])
    np.testing.assert_array_equal(result.ticks["pose"], ticks["pose"])
    assert result.header["runtime"]["replayed_schedule"]


def test_without_its_schedule_a_live_recording_does_not_replay(live, core):
    """The same ticks with the schedule taken away (as recorded before it was: the fields
    dropped), or with one object result (the box resting on the table) taken a tick late: not
    identical, and the report says why when the schedule is missing."""
    old = live.ticks.dtype
    names = [n for n in old.names if n not in ("object_tick", "object_reads")]
    stripped = np.zeros(len(live.ticks), dtype=[(n, old.fields[n][0]) for n in names])
    for n in names:
        stripped[n] = live.ticks[n]
    div = resim.resimulate(dataclasses.replace(live, ticks=stripped), core).divergence
    assert not div.identical and "before its hand-over schedule was recorded" in div.report()

    late = live.ticks.copy()
    o = late["object_tick"]
    free = late["adopted"] == 0        # the box the object manager's, before the grasp
    k = next(k for k in range(50, len(o) - 1) if free[k] and o[k] > o[k - 1] and o[k + 1] == o[k])
    o[k] = o[k - 1]
    div = resim.resimulate(dataclasses.replace(live, ticks=late), core).divergence
    assert not div.identical and div.first_hash_tick == int(late["tick"][k])


def test_a_live_recording_with_missing_ticks_says_it_cannot_replay_them(live, core):
    gap = live.ticks[np.arange(len(live.ticks)) != 700]
    report = resim.resimulate(dataclasses.replace(live, ticks=gap), core).divergence.report()
    assert "ticks of the threaded runtime are missing (after tick 699" in report


def test_heavier_box_parts_after_the_grasp(rec, core, tmp_path):
    out = tmp_path / "heavy.mcap"
    result = resim.resimulate(rec, core, overrides=[resim.parse_override("Box.mass=0.2")],
                              tolerance=1e-6, record_path=str(out))
    div = result.divergence
    assert not div.identical
    contact = int(np.argmax(rec.ticks["contact"][:, 0] >= 0))
    # Resting on the table the box's mass changes nothing visible; once lifted it sags more
    # (m g / 2k: 0.49 mm for 100 g, 0.98 mm for 200 g).
    assert div.first_tick > rec.ticks["tick"][contact]
    worst = dict((s, d) for s, d, _ in div.worst)
    assert worst["body Table"] == 0.0 and worst["body Box"] > 1e-4
    sag = 0.1 * 9.81 / (2 * 1000.0)       # the extra 100 g on two 1000 N/m springs
    for t in (2.0, 3.0, 4.5):             # lifting, carrying, putting down at constant speed
        k = int(round(t * 1000))
        dz = rec.ticks["pose"][k, 0, 2] - result.ticks["pose"][k, 0, 2]
        assert dz == pytest.approx(sag, rel=0.02)
    text = div.report()
    assert "first over tolerance: tick" in text and "body Box" in text
    # The new run as a recording: its own header (mass 0.2), readable, the same length.
    new = recording.open_recording(out)
    assert new.damage == [] and len(new.ticks) == len(rec.ticks)
    assert new.header["scene"]["bodies"][0]["mass"] == pytest.approx(0.2)
    assert new.header["overrides"] == ["Box.mass=0.2"] and new.header["mode"] == "resim"
    assert resim.resimulate(new, core).divergence.identical


def test_friction_too_low_to_hold_slips(rec, core):
    result = resim.resimulate(rec, core, overrides=[resim.parse_override("Box.mu_s=0.05"),
                                                    resim.parse_override("Box.mu_d=0.04")], tolerance=1e-3)
    assert not result.divergence.identical and result.divergence.first_tick is not None
    assert (result.ticks["state"] == 2).sum() > (rec.ticks["state"] == 2).sum()   # more slip
    assert result.ticks["pose"][:, 0, 2].max() < rec.ticks["pose"][:, 0, 2].max() - 0.05  # not lifted


def test_other_haptic_rate_resamples_the_hips(rec, core):
    result = resim.resimulate(rec, core, overrides=[resim.parse_override("haptic_rate=2000")], tolerance=1e-3)
    assert len(result.ticks) == 2 * (len(rec.ticks) - 1) + 1
    assert result.ticks["time"][-1] == pytest.approx(rec.ticks["time"][-1], abs=1e-9)
    # The same grasp at twice the rate: within a millimetre all along.
    assert result.divergence.first_tick is None


def test_gravity_override(rec, core):
    result = resim.resimulate(rec, core, overrides=[resim.parse_override("gravity=0,0,0")])
    assert not result.divergence.identical
    assert result.header["scene"]["gravity"] == [0.0, 0.0, 0.0]


@pytest.mark.parametrize("text, match", [
    ("Box.mass", "expected KEY=VALUE"),
    ("Box.colour=3", "unknown property"),
    ("mass=3", "OBJECT.PROPERTY=VALUE"),
    ("Box.mass=heavy", "expects a number"),
    ("Box.mass=0", r"mass must be in 1e-06 \.\. 1e\+06 kg, got 0.0"),
    ("Finger 0.damping=-1", r"damping must be in 0 \.\. 10000 N s/m"),
    ("Finger 0.stiffness=0.5", r"stiffness must be in 1 \.\. 1e\+06 N/m"),
    ("gravity=0,0", "X,Y,Z"),
    ("gravity=0,0,1e308", r"gravity must be in -1000 \.\. 1000"),
    ("gyroscopic=yes", "0 or 1"),
    ("haptic_rate=-5", r"haptic_rate must be in 100 \.\. 10000 Hz"),
    ("haptic_rate=1e9", r"haptic_rate must be in 100 \.\. 10000 Hz"),
])
def test_bad_overrides(text, match):
    with pytest.raises(resim.OverrideError, match=match):
        resim.parse_override(text)


def test_overrides_that_name_nothing(rec, core):
    for text, match in (("Mug.mass=1", "no body or finger named 'Mug'"),
                        ("Table.mass=2", "static"),
                        ("Box.stiffness=5", "is a body"),
                        ("Finger 0.mu_s=0.5", "is a finger")):
        with pytest.raises(resim.OverrideError, match=match):
            resim.resimulate(rec, core, overrides=[resim.parse_override(text)])
    o = resim.parse_override("Finger 0.stiffness=2000")
    assert (o.obj, o.key, o.value) == ("Finger 0", "stiffness", 2000.0)
