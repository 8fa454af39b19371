"""Re-simulation (addon/engine/resim.py) in plain Python: an EXEC recording replayed with no
override is identical bit for bit (every tick's state hash); an override parts the runs
where physics says it must, and the report says when and where; KEY=VALUE parsing."""
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
