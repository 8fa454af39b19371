"""OpenGloves / LucidGloves: golden input lines in both encodings, malformed lines, the
finger model against a hand computation, force-feedback strings, and a glove over a real
pseudo-terminal."""
import math
import os
import tty

import numpy as np
import pytest

from addon.engine.devices import opengloves as G
from waiting import wait_until  # noqa: E402  (tests/support, docs/testing.md)

ALPHA = b"A0B1024C2048D3072E4095F2048G0IL\n"
LEGACY = b"4095,0,0,0,0,2048,2048,0,1,0,0,1,0\n"


def test_alpha_golden_line():
    s = G.GloveState()
    assert s.feed_line(ALPHA)
    np.testing.assert_allclose(s.curls, [0, 1024 / 4095, 2048 / 4095, 3072 / 4095, 1.0])
    assert s.joystick[1] == pytest.approx(-1.0, abs=1e-3) and abs(s.joystick[0]) < 1e-3
    assert s.buttons["trigger"] and s.buttons["grab"] and not s.buttons["a"]
    assert s.encoding == "alpha"


def test_alpha_extended_keys_are_kept():
    s = G.GloveState()
    assert s.feed_line("A10B20C30D40E50(AB)2000(BB)1900\n")
    assert s.extended == {"(AB)": 2000, "(BB)": 1900}


def test_legacy_golden_line():
    s = G.GloveState()
    assert s.feed_line(LEGACY)
    np.testing.assert_allclose(s.curls, [1, 0, 0, 0, 0])
    assert s.buttons["trigger"] and s.buttons["grab"] and not s.buttons["pinch"]
    assert s.encoding == "legacy"


@pytest.mark.parametrize("line", ["A5000B0C0D0E0", "A1B2C3", "hello", "A1B2xC3D4E5", "", "1,2,3", "-1,0,0,0,0",
                                  "A1B2C3D4E-5"])
def test_malformed_lines_are_dropped_and_counted(line):
    s = G.GloveState()
    s.feed_line("A100B100C100D100E100")
    assert not s.feed_line(line)
    assert s.rejected == 1
    np.testing.assert_allclose(s.curls, 100 / 4095)    # the last good sample stays


def test_finger_model_against_hand_computation():
    index = G.HAND_MODEL[1]
    np.testing.assert_allclose(G.fingertip(index, 0.0), (0.022, 0.090 + 0.045 + 0.025 + 0.020, 0.0), atol=1e-12)
    # Curl 1: joint angles 90, 90+100, 90+100+70 degrees, flexing towards -z.
    y, z = 0.090, 0.0
    for length, angle in ((0.045, 90), (0.025, 190), (0.020, 260)):
        y += length * math.cos(math.radians(angle))
        z -= length * math.sin(math.radians(angle))
    np.testing.assert_allclose(G.fingertip(index, 1.0), (0.022, y, z), atol=1e-12)
    tips = G.fingertips([0.5] * 5)
    assert np.all(tips[1:, 2] < 0)                       # curled fingers go to the palm side
    mirrored = G.fingertips([0.5] * 5, left=True)
    np.testing.assert_allclose(mirrored[:, 0], -tips[:, 0])


def test_fingertips_in_a_hand_frame():
    frame = np.eye(4)
    frame[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]   # 90 degrees about z
    frame[:3, 3] = (1.0, 2.0, 3.0)
    local = G.fingertips([0.2] * 5)
    world = G.fingertips([0.2] * 5, frame)
    np.testing.assert_allclose(world, np.c_[-local[:, 1] + 1.0, local[:, 0] + 2.0, local[:, 2] + 3.0])


def test_force_feedback_golden_strings():
    assert G.force_feedback_line([0, 1, 2, 4, 8], full_scale=4.0) == b"A0B250C500D1000E1000\n"
    forces = np.zeros((5, 3))
    forces[1] = (0.0, 3.0, 4.0)                          # |f| = 5 N
    assert G.force_feedback_line(forces, full_scale=10.0) == b"A0B500C0D0E0\n"
    assert G.force_feedback_line([1, 1, 1, 1, 1], enabled=False) == b"A0B0C0D0E0\n"
    assert G.force_feedback_line([float("nan"), 1, 1, 1, 1], full_scale=1.0) == b"A0B1000C1000D1000E1000\n"


def test_sent_forces_are_what_the_brake_levels_stand_for():
    f = np.zeros((5, 3))
    f[1] = (0.0, 0.0, 2.0013)           # level 500 of 4 N: 2 N along +z
    f[2] = (3.0, 4.0, 0.0)              # 5 N: clipped to level 1000, 4 N along (0.6, 0.8, 0)
    f[3] = (float("nan"), 0.0, 0.0)     # never reaches the glove
    sent = G.sent_forces(f, full_scale=4.0)
    np.testing.assert_allclose(sent, [(0, 0, 0), (0, 0, 2.0), (2.4, 3.2, 0), (0, 0, 0), (0, 0, 0)], atol=1e-12)
    assert not G.sent_forces(f, full_scale=4.0, enabled=False).any()


def test_glove_over_a_pseudo_terminal():
    master, slave = os.openpty()
    tty.setraw(master)
    src = G.OpenGlovesSource(os.ttyname(slave))
    src.open()
    try:
        os.write(master, b"garbage-without-newline-" * 30 + b"\n" + ALPHA[:10])
        src.poll()
        os.write(master, ALPHA[10:] + LEGACY[:5])
        hips = src.hips_at(0.0)
        np.testing.assert_allclose(hips, G.fingertips(G.GloveState().curls * 0 + [0, 1024 / 4095, 2048 / 4095,
                                                                                  3072 / 4095, 1.0]))
        assert src.state.lines == 1 and src.state.rejected == 1
        src.send_forces([0, 2, 0, 0, 0], enabled=True)
        assert os.read(master, 100) == b"A0B500C0D0E0\n"
    finally:
        src.close()
        os.close(master)
        os.close(slave)


def test_glove_drives_fingers_of_a_running_world_and_feels_the_box():
    """A glove in a DeviceSet: its five fingertips (through a hand frame) reach the runtime
    by push_device_hips; the index presses 4 mm into a small box and its brake line says
    so once forces are enabled (zero before)."""
    graspcore = pytest.importorskip("graspcore")
    from addon.engine.devices.live import DeviceSet
    frame = np.eye(4)
    frame[:3, 3] = (0.5, 0.0, 0.0)
    tips = G.fingertips(np.zeros(5), frame)
    world = graspcore.World(gravity=(0, 0, 0))
    h = 0.01
    box = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)]
    world.add_body(box, position=tips[1] - (0, 0, h + 0.004), static=True)   # top face 4 mm under the index tip
    for p in tips:
        world.add_finger(position=p + (0, 0, 0.05))
    world.set_tick_log(1 << 15)
    world.start(priority=0, ramp_time=0.0, watchdog_timeout=0.5)
    master, slave = os.openpty()
    tty.setraw(master)
    devices = DeviceSet(world)
    records = np.zeros(1 << 15, dtype=world.tick_dtype())
    try:
        glove = devices.add_source(G.OpenGlovesSource(os.ttyname(slave), hand_frame=frame, full_scale=4.0), 0, "glove")
        os.write(master, b"A0B0C0D0E0\n")
        # The fingers start 5 cm above the glove's tips: the soft start walks them down at
        # 0.2 m/s (0.25 s), never faster, on the same per-finger channel as a serial device.
        wait_until(lambda: np.abs(world.snapshot()["hips"] - tips).max() < 1e-12, 60, "the fingers at the glove's tips",
                   seen=lambda: world.snapshot()["hips"], poll=0.01, each=lambda _: devices.poll())
        devices.poll()
        snap = world.snapshot()
        np.testing.assert_allclose(snap["hips"], tips, atol=1e-12)
        assert abs(np.linalg.norm(snap["spring_forces"][1]) - 4.0) < 0.05
        lines = os.read(master, 4096)
        assert lines.split(b"\n")[-2] == b"A0B0C0D0E0"             # forces off until enabled
        walk = world.drain_ticks(records)
        hips = walk["hip"]
        assert hips[0, 1, 2] > tips[1, 2] + 0.04                       # it did start 5 cm away
        steps = np.linalg.norm(np.diff(hips, axis=0), axis=2)
        assert steps.max() <= 0.2 * 1e-3 * (1 + 1e-9), steps.max()   # 0.2 m/s at 1 kHz
        assert (steps[:, 1] > 1.999e-4).sum() >= 0.04 / 2e-4 * 0.99   # walked, at that speed
        # The recording says what the glove got: nothing, though the index presses with 4 N.
        off = walk["device_force"]
        assert len(off) > 50 and not off.any()
        devices.enable(True)
        # The brake line follows the core's device forces, which the watchdog holds at zero
        # after a late poll on a loaded machine: poll until the line comes.
        last = [b""]

        def brake_line():
            devices.poll()
            last[0] = os.read(master, 4096).split(b"\n")[-2]
            return last[0] == b"A0B1000C0D0E0"
        wait_until(brake_line, 60, "the index's brake line", seen=lambda: last[0], poll=0.01)
        # Level 1000 of the 4 N full scale: 4 N along the index's force, in the record (the
        # haptic ticks after the line was sent, as they come).
        latest = [None]

        def recorded():
            ticks = world.drain_ticks(records)["device_force"]
            if len(ticks):
                latest[0] = ticks[-1].copy()
            return latest[0] is not None and latest[0].any()
        wait_until(recorded, 60, "the glove's force in the tick log", seen=lambda: latest[0])
        on = latest[0]
        assert np.linalg.norm(on[1]) == pytest.approx(4.0, rel=1e-12) and on[1, 2] > 3.9 and not on[[0, 2, 3, 4]].any()
        assert devices.status()[0]["state"] == "streaming" and glove.stats()["poses"] == 1
    finally:
        devices.close()
        world.stop()
        os.close(master)
        os.close(slave)
