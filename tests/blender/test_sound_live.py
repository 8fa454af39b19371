"""The live sound's feed (addon/engine/tick_tap.py, docs/sound.md "Live"): every haptic tick of a
running session reaches the display thread, none lost or repeated between display updates, on
the threaded runtime with and without a recording and on synchronous steps; fed to the
Sonifier piece by piece as the display takes them, the sound is the recording's, sample for
sample. Headless with sound asked for: the session says there is no audio device and runs."""
import time

import numpy as np
import pytest

import recordings
from addon.engine import inputs, recording, runner, scene, sound
from addon.engine.tick_tap import TickTap


def _session(core, threaded, record_path=None, seconds=1.0):
    desc, S = recordings.pinch_desc()
    handle = scene.build_world(desc, core)
    rec = None
    if record_path is not None:
        header = recording.make_header(desc, mode="realtime" if threaded else "exec", haptic_rate=1000.0, fps=24,
                                       runtime={"threaded": threaded})
        rec = recording.SessionRecorder(recording.RecordingWriter(str(record_path), header), handle.world)
    tap = TickTap(handle.world, core.tick_dtype(len(desc.bodies), len(desc.fingers)), 1000.0)
    run = runner.SessionRunner(handle, inputs.CallableInput(len(desc.fingers), S.hip_positions, duration=seconds),
                               1000.0, use_runtime=threaded, recorder=rec, tap=tap)
    return desc, run, tap


def _drive(run, tap, seconds, threaded, take_every=0.05):
    """Display updates: advance, take what came. Returns the pieces taken."""
    pieces = []
    run.start()
    t0 = time.monotonic()
    k = 0
    while True:
        if threaded:
            now = run.snapshot().time
            if now >= seconds:
                break
            run.advance_to(time.monotonic() - t0)
            time.sleep(take_every)
        else:
            k += 1
            if k * take_every > seconds + 1e-9:
                break
            run.advance_to(k * take_every)
        pieces.append(tap.take())
    run.stop()
    pieces.append(tap.take())
    return pieces


@pytest.mark.parametrize("threaded,recorded", [(True, False), (True, True), (False, False), (False, True)])
def test_every_tick_reaches_the_display_thread_once(core, tmp_path, threaded, recorded):
    path = tmp_path / "tapped.mcap" if recorded else None
    desc, run, tap = _session(core, threaded, path)
    pieces = _drive(run, tap, 1.0, threaded)
    ticks = np.concatenate(pieces)
    assert tap.mode == ("steps" if not threaded else "recorder" if recorded else "log")
    assert len(pieces) > 5 and sum(len(p) > 0 for p in pieces) > 5          # it came in many pieces
    first = ticks["tick"][0]
    np.testing.assert_array_equal(ticks["tick"], np.arange(first, first + len(ticks)))     # none lost or twice
    assert first <= 1 and ticks["time"][-1] >= 1.0 - 1e-9 and tap.overflow == 0
    assert np.any(ticks["contact"] >= 0)
    if recorded:
        rec = recording.open_recording(str(path))
        np.testing.assert_array_equal(rec.ticks["state_hash"][rec.ticks["tick"] >= first], ticks["state_hash"])
        # The sound of the pieces as the display took them is the recording's.
        s = sound.Sonifier(desc)
        live = np.concatenate([s.feed(p) for p in pieces])
        whole, _ = sound.sonify(rec.header["scene"], rec.ticks[rec.ticks["tick"] >= first])
        np.testing.assert_array_equal(live, whole)
        assert np.abs(live).max() > 0.05


def test_headless_with_sound_asked_for_says_there_is_no_audio_device_and_runs(bpy, sample, core):
    sample.build(bpy)
    session_mod = __import__("grasp_env").submodule("session")
    live = session_mod.BlenderSession(bpy.context, live=True, duration=0.3, sound=True)
    assert live.sound is None
    assert "no audio device" in live.sound_message and "background mode" in live.sound_message
    live.run_live()
    st = live.result.stats
    assert st["sound"] == {"message": live.sound_message} and st["time"] >= 0.3 - 1e-9
    # Not asked for (the default in background mode): no sound, no message.
    quiet = session_mod.BlenderSession(bpy.context, live=True, duration=0.1)
    assert quiet.sound is None and quiet.sound_message == "" and bpy.context.scene.grasp_lab.sound
    quiet.run_live()
    assert "sound" not in quiet.result.stats


@pytest.mark.xfail(strict=False, reason="known defect (issue #33 open, docs/sound.md 'Known limits'): audaspace's "
                   "offline mix drops whole short entries of a sequence of abutting stretches, and under load "
                   "the clicks that fall in them are lost; the fix is one stream instead of many entries")
def test_the_live_stretches_join_in_blenders_mixer_as_the_recording_sounds(bpy, core, tmp_path):
    """LiveSound (addon/sound_live.py) fed at each display update of a live session on the threaded
    runtime: the stretches it placed in its aud.Sequence, mixed by audaspace (written out, as no
    audio device exists here: the bpy module has none), are the recording's sound shifted by the
    latency: every stretch where it belongs, within the one sample audaspace rounds a start to."""
    sound_live = __import__("grasp_env").submodule("sound_live")
    path = tmp_path / "live.mcap"
    desc, run, tap = _session(core, True, path, seconds=1.0)
    player = sound_live.LiveSound(desc, display_rate=20.0, volume=1.0, device=None)
    run.start()
    t0 = time.monotonic()
    while run.snapshot().time < 1.0:
        run.advance_to(time.monotonic() - t0)
        time.sleep(0.05)
        player.update(tap.take(), run.snapshot().time)
    run.stop()
    player.update(tap.take(), run.snapshot().time)
    assert player.updates > 10 and player.late == 0 and player.offset > 0
    rec = recording.open_recording(str(path))
    first = rec.ticks["tick"] >= 1
    whole, _ = sound.sonify(rec.header["scene"], rec.ticks[first])
    mixed = player.render((player.offset + len(whole)) / player.rate + 0.1).astype(np.float64)
    assert np.abs(whole).max() > 0.05
    assert np.all(mixed[:player.offset - 48] == 0.0)
    # Every sample of the session placed once, stretch after stretch.
    assert [f for f, _ in player.placed] == list(np.cumsum([0] + [n for _, n in player.placed[:-1]]))
    assert sum(n for _, n in player.placed) == len(whole)
    # audaspace mixes the entries with sub-sample placement (not bit for bit): the sound's loudness
    # over 10 ms windows is the recording's, and each click is heard at its tick (+-1 ms) after
    # the latency: none lost at the joins.
    placed = mixed[player.offset:player.offset + len(whole)]
    w = 480
    rms = lambda x: np.sqrt(np.mean(x[:len(x) // w * w].reshape(-1, w) ** 2, axis=1))  # noqa: E731
    a, b = rms(placed), rms(whole.astype(np.float64))
    # audaspace's offline mix drops an occasional stretch of a sequence of abutting entries
    # (measured: 0-3 windows of 100; docs/sound.md, "Known limits"): most windows are the recording's.
    matched = np.abs(a - b) <= 0.01
    assert matched.mean() >= 0.9, np.flatnonzero(~matched)
    step = np.abs(np.diff(placed, prepend=0.0))
    heard = 0
    for t, f, amp in player.sonifier.clicks:
        near = np.arange(int(t * player.rate) - 96, int(t * player.rate) + 96)
        first = near[np.argmax(step[near] > 0.5 * amp)]
        heard += step[first] > 0.5 * amp and abs(first / player.rate - t) <= 0.001
    assert len(player.sonifier.clicks) >= 2 and heard == len(player.sonifier.clicks)
