"""SpaceMouse decoding and rate control, from reports laid out as the devices send them
(split models: report 1 translation, 2 rotation, 3 buttons; single-report models: report
1 with all six axes)."""
import math

import numpy as np
import pytest

from addon.engine.devices.spacemouse import SpaceMouseHand, SpaceMouseState

# Reports as hidraw hands them over (report id first), e.g. a SpaceNavigator pushed right
# and away from the user, then twisted, then button 1.
SPLIT = [
    bytes.fromhex("015e01a2fe0000"),        # report 1: x +350, y -350, z 0
    bytes.fromhex("0200000000af00"),        # report 2: rz +175
    bytes.fromhex("0301"),                  # report 3: button 0
]
SINGLE = bytes.fromhex("01" "5e01" "0000" "a2fe" "0000" "af00" "0000")  # x +350, z -350, ry +175


def test_split_reports():
    s = SpaceMouseState()
    assert all(s.feed(r) for r in SPLIT)
    np.testing.assert_allclose(s.translation, [1.0, 1.0, 0.0])       # y and z change sign
    np.testing.assert_allclose(s.rotation, [0.0, 0.0, -0.5])
    assert s.buttons == 1 and s.reports == 3


def test_single_report_model():
    s = SpaceMouseState()
    assert s.feed(SINGLE)
    np.testing.assert_allclose(s.translation, [1.0, 0.0, 1.0])
    np.testing.assert_allclose(s.rotation, [0.0, -0.5, 0.0])


@pytest.mark.parametrize("report", [b"", b"\x01\x00", b"\x02\x01", b"\x07\x00\x00\x00\x00\x00\x00", b"\x03"])
def test_malformed_reports_are_counted(report):
    s = SpaceMouseState()
    assert not s.feed(report)
    assert s.rejected == 1 and s.reports == 0
    np.testing.assert_array_equal(s.translation, 0)


def make_hand(**kw):
    return SpaceMouseHand(open_tips=[(0.04, 0, 0), (-0.04, 0, 0)], closed_tips=[(0.01, 0, 0), (-0.01, 0, 0)], **kw)


def test_rate_control_translation_and_deadzone():
    hand, s = make_hand(speed=0.2), SpaceMouseState()
    s.feed(bytes.fromhex("015e0100000000"))          # full right
    for _ in range(100):
        hand.update(s, 0.01)
    np.testing.assert_allclose(hand.position, [0.2, 0, 0], atol=1e-12)
    s.feed(bytes.fromhex("010a000a000a00"))          # 10/350 on every axis: inside the 5 % dead zone
    hand.update(s, 1.0)
    np.testing.assert_allclose(hand.position, [0.2, 0, 0], atol=1e-12)


def test_rate_control_rotation_turns_the_fingertips():
    hand, s = make_hand(turn_rate=1.5), SpaceMouseState()
    s.feed(bytes.fromhex("020000000000a2fe"))        # rz -350: +1 about the hand's z (up)
    steps = 1000
    for _ in range(steps):
        hand.update(s, (math.pi / 2 / 1.5) / steps)
    np.testing.assert_allclose(hand.tips(), [(0, 0.04, 0), (0, -0.04, 0)], atol=1e-9)


def test_grip_button_closes_the_fingers():
    hand, s = make_hand(grip_time=0.5), SpaceMouseState()
    s.feed(bytes.fromhex("0301"))
    for _ in range(25):
        hand.update(s, 0.01)
    np.testing.assert_allclose(hand.tips(), [(0.025, 0, 0), (-0.025, 0, 0)], atol=1e-12)
    for _ in range(50):
        hand.update(s, 0.01)
    np.testing.assert_allclose(hand.tips()[0], (0.01, 0, 0), atol=1e-12)
    s.feed(bytes.fromhex("0300"))
    for _ in range(100):
        hand.update(s, 0.01)
    np.testing.assert_allclose(hand.tips()[0], (0.04, 0, 0), atol=1e-12)


class Replay:
    """Recorded reports, handed over one per read as hidapi does (then nothing)."""

    def __init__(self, reports):
        self.reports = list(reports)
        self.closed = False

    def read(self, n):
        return list(self.reports.pop(0)) if self.reports else []

    def close(self):
        self.closed = True


def test_spacemouse_drives_fingers_of_a_running_world():
    import time

    graspcore = pytest.importorskip("graspcore")
    from addon.engine.devices.live import DeviceSet
    from addon.engine.devices.spacemouse import SpaceMouseSource, hand_from_fingertips
    tips = np.array([(0.04, 0.0, 0.1), (-0.04, 0.0, 0.1)])
    world = graspcore.World(gravity=(0, 0, 0))
    for p in tips:
        world.add_finger(position=p)
    world.start(priority=0, watchdog_timeout=0.05)
    replay = Replay([bytes.fromhex("0301")])            # grip button held, no motion
    devices = DeviceSet(world)
    try:
        hand = hand_from_fingertips(tips)
        np.testing.assert_allclose(hand.tips(), tips, atol=1e-12)
        devices.add_source(SpaceMouseSource(hand, device=replay), 0, "spacemouse")
        closed = np.array([(0.012, 0, 0.1), (-0.012, 0, 0.1)])   # 30 % of 4 cm
        started = time.monotonic()
        while True:                                     # grip_time 0.5 s, then the haptic loop's tick
            devices.poll()
            time.sleep(0.01)
            hips = world.snapshot()["hips"]
            if time.monotonic() - started > 0.8 and np.allclose(hips, closed, atol=1e-9) \
                    or time.monotonic() - started > 5.0:
                break
        np.testing.assert_allclose(hips, closed, atol=1e-9)
    finally:
        devices.close()
        world.stop()
    assert replay.closed
