"""Hearing the grasp (addon/engine/sound.py, docs/sound.md) in plain Python: a synthetic recording
with known events (two contact onsets at known approach speeds, a normal force ramp, a slip, a
slip margin below the threshold) through the real recording writer and reader, then its sound
measured: clicks at the onset ticks (+-1 ms) and louder for the faster approach, the tone's
frequency (FFT over 50 ms windows) within 2 % of the mapping of the normal force, scrape noise only
while slipping, the warning only while the margin is low, exact silence when nothing touches; any
pieces give the same samples as the whole; `resim` of a recording and `grasp-lab export --wav`
give identical WAV bytes; malformed WAVs and mappings are refused with a message."""
import io

import numpy as np
import pytest

import recordings
from addon.engine import cli, recording, resim, sound

RATE = 48000
HAPTIC = 1000.0
ONSET = {0: 0.2, 1: 0.35}           # s: contact onsets
APPROACH = {0: 0.1, 1: 0.2}         # m/s: fingertip speeds into the box before them
RELEASE = {0: 0.8, 1: 0.7}
SLIP = (0.5, 0.6)                   # finger 0 slips
F1_FORCE = 10.0                     # N: finger 1's constant normal force (the top pitch)


def f0_force(t):
    return 2.0 + 4.0 * (t - ONSET[0]) / (RELEASE[0] - ONSET[0])        # 2 N -> 6 N


def synthetic_ticks(core, desc):
    """1.0 s at 1 kHz: finger 0 on the box's +x face (outward normal +x), finger 1 on its -x face."""
    n = 1001
    ticks = np.zeros(n, dtype=core.tick_dtype(len(desc.bodies), len(desc.fingers)))
    t = np.arange(n) / HAPTIC
    ticks["tick"] = np.arange(n)
    ticks["time"] = t
    ticks["pose"][:, :, 3] = 1.0
    ticks["contact"] = -1
    normals = {0: np.array([1.0, 0, 0]), 1: np.array([-1.0, 0, 0])}
    for f in (0, 1):
        on = (t >= ONSET[f] - 1e-9) & (t < RELEASE[f] - 1e-9)
        # The fingertip moves into the box at APPROACH until the onset, then rests.
        depth = APPROACH[f] * np.minimum(t, ONSET[f])
        ticks["hip"][:, f] = normals[f] * (0.05 - depth)[:, None]
        ticks["god_object"][:, f] = ticks["hip"][:, f]
        force = f0_force(t) if f == 0 else np.full(n, F1_FORCE)
        ticks["force"][on, f] = normals[f] * force[on, None]
        ticks["normal"][on, f] = normals[f]
        ticks["contact"][on, f] = 0
        ticks["state"][on, f] = 1
    slipping = (t >= SLIP[0] - 1e-9) & (t < SLIP[1] - 1e-9)
    ticks["state"][slipping, 0] = 2
    # Slipping: the god-object slides along +y at 5 cm/s, the tangential force beyond the cone.
    ticks["god_object"][:, 0, 1] = 0.05 * np.clip(t - SLIP[0], 0.0, SLIP[1] - SLIP[0])
    ticks["force"][slipping, 0, 1] = 0.6 * f0_force(t[slipping]) + 1.0
    return ticks


@pytest.fixture(scope="module")
def synthetic(core, tmp_path_factory):
    desc, _ = recordings.pinch_desc()
    path = tmp_path_factory.mktemp("sound") / "synthetic.mcap"
    header = recording.make_header(desc, mode="exec", haptic_rate=HAPTIC, fps=24)
    writer = recording.RecordingWriter(str(path), header)
    writer.write_ticks(synthetic_ticks(core, desc))
    writer.close({"overflow": 0})
    rec = recording.open_recording(str(path))
    samples, son = sound.sonify(rec.header["scene"], rec.ticks)
    return rec, samples.astype(np.float64), son


def window(samples, t0, t1):
    return samples[int(round(t0 * RATE)):int(round(t1 * RATE))]


def test_the_recording_has_the_length_of_its_ticks_and_nothing_sounds_before_a_touch_or_after_release(synthetic):
    rec, x, son = synthetic
    assert len(x) == int(round(rec.ticks["time"][-1] * RATE))
    assert np.all(window(x, 0.0, ONSET[0]) == 0.0)
    # After the last release: the fades (attack) and the click tails are over.
    assert np.all(window(x, RELEASE[0] + 0.006, 1.0) == 0.0)
    assert np.abs(window(x, ONSET[0], RELEASE[0])).max() > 0.05


def test_clicks_at_the_contact_onset_ticks_and_louder_for_a_faster_approach(synthetic):
    rec, x, son = synthetic
    assert [(round(t, 6), f) for t, f, _ in son.clicks] == [(ONSET[0], 0), (ONSET[1], 1)]
    # Found in the sound itself: the click rings at 3 kHz from its first sample, the tones (<= 880
    # Hz) change little from one sample to the next, so the click is the first large step.
    step = np.abs(np.diff(x, prepend=0.0))
    peaks = {}
    for f, t_on in ONSET.items():
        near = np.arange(int((t_on - 0.01) * RATE), int((t_on + 0.01) * RATE))
        first = near[np.argmax(step[near] > 0.03)]
        assert step[first] > 0.03, f"no click near {t_on} s"
        assert abs(first / RATE - t_on) <= 0.001, (f, first / RATE, t_on)
        peaks[f] = step[first]
    # The faster approach (0.2 m/s, the full click) is twice as loud as the slower (0.1 m/s).
    assert peaks[1] / peaks[0] == pytest.approx(APPROACH[1] / APPROACH[0], rel=0.1)


def peak_frequency(segment, low, high):
    w = segment * np.hanning(len(segment))
    spectrum = np.abs(np.fft.rfft(w, 1 << 17))
    freqs = np.fft.rfftfreq(1 << 17, 1.0 / RATE)
    band = np.flatnonzero((freqs >= low) & (freqs <= high))
    k = band[np.argmax(spectrum[band])]
    a, b, c = np.log(spectrum[k - 1:k + 2])
    return freqs[k] + 0.5 * (a - c) / (a - 2 * b + c) * (freqs[1] - freqs[0])


def test_the_tone_follows_the_mapping_of_the_normal_force_within_2_percent(synthetic):
    rec, x, son = synthetic
    mapping = son.mapping
    checked = 0
    for t0 in np.arange(ONSET[0] + 0.01, RELEASE[0] - 0.06, 0.05):
        t1 = t0 + 0.05
        if t1 > SLIP[0] - 0.002 and t0 < SLIP[1] + 0.01:
            continue            # the scrape and the warning
        expected = float(mapping.pitch(f0_force(0.5 * (t0 + t1))))
        got = peak_frequency(window(x, t0, t1), 0.85 * expected, 1.15 * expected)
        assert got == pytest.approx(expected, rel=0.02), (t0, got, expected)
        if ONSET[1] + 0.01 < t0 and t1 < RELEASE[1]:
            top = peak_frequency(window(x, t0, t1), 800.0, 960.0)
            assert top == pytest.approx(float(mapping.pitch(F1_FORCE)), rel=0.02)
            assert float(mapping.pitch(F1_FORCE)) == mapping.pitch_high
        checked += 1
    assert checked >= 7
    # The mapping itself: from pitch_low at no force along (F / force_full) ** curve, in log frequency.
    assert mapping.pitch(0.0) == pytest.approx(mapping.pitch_low)
    assert mapping.pitch(2.5) == pytest.approx(mapping.pitch_low * (mapping.pitch_high / mapping.pitch_low) ** 0.5)


def band_energy(segment, low, high):
    spectrum = np.abs(np.fft.rfft(segment * np.hanning(len(segment)))) ** 2
    freqs = np.fft.rfftfreq(len(segment), 1.0 / RATE)
    return float(spectrum[(freqs >= low) & (freqs <= high)].sum())


def test_noise_only_while_slipping_and_the_warning_only_while_the_margin_is_low(synthetic):
    rec, x, son = synthetic
    clicks_over = {t: t + 0.015 for t in ONSET.values()}
    noisy, quiet, warned, unwarned = [], [], [], []
    for t0 in np.arange(ONSET[0], RELEASE[0], 0.01):
        t1 = t0 + 0.01
        if any(t0 < end and t1 > on for on, end in clicks_over.items()):
            continue
        seg = window(x, t0, t1)
        hiss = band_energy(seg, 2000.0, 20000.0)
        beep = band_energy(seg, 1250.0, 1400.0)
        if SLIP[0] + 0.006 <= t0 and t1 <= SLIP[1]:
            noisy.append(hiss)
            warned.append(beep)
        elif t1 <= SLIP[0] or t0 >= SLIP[1] + 0.006:
            quiet.append(hiss)
            unwarned.append(beep)
    assert len(noisy) >= 8 and len(quiet) >= 30
    assert min(noisy) > 1000 * max(quiet), (min(noisy), max(quiet))
    assert sum(warned) / len(warned) > 100 * max(unwarned)


def test_any_pieces_give_the_samples_of_the_whole(synthetic):
    rec, x, son = synthetic
    s = sound.Sonifier(rec.header["scene"])
    rng = np.random.default_rng(7)
    parts, i = [], 0
    while i < len(rec.ticks):
        n = int(rng.integers(1, 90))
        parts.append(s.feed(rec.ticks[i:i + n]))
        i += n
    assert np.array_equal(np.concatenate(parts), x.astype(np.float32))
    assert s.feed(rec.ticks[-5:]).size == 0         # records already fed: nothing more


def test_resim_and_export_give_identical_wav_bytes(core, tmp_path):
    path = tmp_path / "pinch.mcap"
    recordings.record_exec(path, core, seconds=3.0)
    rec = recording.open_recording(str(path))
    replay = resim.resimulate(rec, core)
    assert replay.divergence.identical
    a = sound.wav_bytes(sound.sonify(rec.header["scene"], rec.ticks)[0], RATE)
    b = sound.wav_bytes(sound.sonify(replay.header["scene"], replay.ticks)[0], RATE)
    assert a == b
    samples, rate = sound.read_wav(a)
    assert rate == RATE and len(samples) == int(round(rec.ticks["time"][-1] * RATE)) and np.abs(samples).max() > 0.05
    out, err = io.StringIO(), io.StringIO()
    assert cli.main(["export", str(path), "--wav", str(tmp_path / "pinch.wav")], out=out, err=err) == 0, err.getvalue()
    assert (tmp_path / "pinch.wav").read_bytes() == a
    assert "pinch.wav: 3.000 s" in out.getvalue() and "2 clicks" in out.getvalue()
    # An output that is a folder is refused, naming it.
    out, err = io.StringIO(), io.StringIO()
    assert cli.main(["export", str(path), "--wav", str(tmp_path)], out=out, err=err) != 0
    assert str(tmp_path) in err.getvalue()


def test_malformed_wavs_and_mappings_are_refused_with_a_message():
    good = sound.wav_bytes(np.zeros(10), RATE)
    for data, why in [(b"RIFX" + good[4:], "not a RIFF/WAVE"), (good[:46], "cut short"),
                      (good[:12], "no data chunk"),
                      (good[:22] + (2).to_bytes(2, "little") + good[24:], "2 channels")]:
        with pytest.raises(ValueError, match=why):
            sound.read_wav(data)
    with pytest.raises(ValueError, match="pitch_high"):
        sound.SoundMapping(pitch_low=900.0, pitch_high=400.0)
    with pytest.raises(ValueError, match="force_full must be > 0"):
        sound.SoundMapping(force_full=0.0)
    with pytest.raises(ValueError, match="half the sample rate"):
        sound.SoundMapping(sample_rate=8000, click_freq=5000.0)
    with pytest.raises(ValueError, match="curve must be finite"):
        sound.SoundMapping(curve=float("nan"))


def test_the_mapping_is_adjustable_from_the_command_line(synthetic, tmp_path):
    rec, x, son = synthetic
    out, err = io.StringIO(), io.StringIO()
    wav = tmp_path / "high.wav"
    assert cli.main(["export", str(rec.path), "--wav", str(wav), "--sound-map", "pitch_low=300",
                     "--sound-map", "pitch_high=1200", "--sound-map", "curve=1"], out=out, err=err) == 0, err.getvalue()
    samples, _ = sound.read_wav(wav.read_bytes())
    mapping = sound.SoundMapping(pitch_low=300.0, pitch_high=1200.0, curve=1.0)
    t0, t1 = 0.25, 0.30                 # finger 0 alone, 2.3 N
    expected = float(mapping.pitch(f0_force(0.5 * (t0 + t1))))
    assert peak_frequency(window(samples, t0, t1), 0.85 * expected, 1.15 * expected) == \
        pytest.approx(expected, rel=0.02)
    for bad, why in [(["--sound-map", "pitch=3"], "KEY one of"), (["--sound-map", "curve=steep"], "not a number"),
                     (["--sound-map", "pitch_low=900"], "pitch_high")]:
        out, err = io.StringIO(), io.StringIO()
        assert cli.main(["export", str(rec.path), "--wav", str(tmp_path / "bad.wav"), *bad], out=out, err=err) != 0
        assert why in err.getvalue(), err.getvalue()
        assert not (tmp_path / "bad.wav").exists()
    out, err = io.StringIO(), io.StringIO()
    assert cli.main(["export", str(rec.path), "--npz", str(tmp_path / "x.npz"), "--sound-map", "curve=1"],
                    out=out, err=err) != 0 and "--sound-map goes with --wav" in err.getvalue()


def test_sound_options_are_checked_before_anything_runs(ext, tmp_path):
    ext_cli = __import__("grasp_env").submodule("engine.cli")      # the extension's, Blender's commands in it
    out, err = io.StringIO(), io.StringIO()
    assert ext_cli.main(["run", str(tmp_path / "s.blend"), "--sound"], out=out, err=err) == 1
    assert "--sound needs --realtime" in err.getvalue()
    assert cli.main(["export", "x.mcap", "--wav", "a.wav", "--npz", "b.npz"], out=out, err=err) == 2
