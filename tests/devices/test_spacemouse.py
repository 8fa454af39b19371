"""SpaceMouse decoding and rate control, from reports laid out as the devices send them
(split models: report 1 translation, 2 rotation, 3 buttons; single-report models: report
1 with all six axes)."""
import math

import numpy as np
import pytest

from addon.engine.devices.spacemouse import SpaceMouseHand, SpaceMouseState, hand_from_fingertips
from addon.engine.runner import quat_rotate
from waiting import wait_until  # noqa: E402  (tests/support, docs/testing.md)

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


def axis_angle_quat(axis, angle):
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    return np.array([math.cos(angle / 2), *(math.sin(angle / 2) * axis)])


def quat_mul(a, b):
    """Hamilton's product, written out (the reference for the hand's)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def same_rotation(q, r, atol=1e-9):
    """q and -q are the same rotation."""
    q, r = np.asarray(q), np.asarray(r)
    return np.allclose(q, r, atol=atol) or np.allclose(q, -r, atol=atol)


@pytest.mark.parametrize("report, hand_axis", [
    ("020000000000a2fe", (0, 0, 1)),      # rz -350: +1 about the hand's z (up)
    ("02a2fe00000000", (-1, 0, 0)),       # rx -350: -1 about the hand's x
    ("0200005e010000", (0, -1, 0)),       # ry +350: -1 about the hand's y (the device's y is flipped)
])
def test_rotation_input_turns_a_palm_by_the_integrated_angle(report, hand_axis):
    """A palm tilted 20 deg about x in a hand whose frame is itself turned 30 deg about z: a
    rotation input of 1 for t s turns the palm by turn_rate t about the hand's axis (in the
    world: the frame's rotation of it), the palm's own tilt kept: q(t) = turn q(0)."""
    tips = np.array([(0.0, 0.0, 0.1), (0.04, 0.0, 0.1)])
    frame = np.eye(4)
    c, s_ = math.cos(math.radians(30)), math.sin(math.radians(30))
    frame[:3, :3] = [[c, -s_, 0], [s_, c, 0], [0, 0, 1]]
    palm_q = axis_angle_quat((1, 0, 0), math.radians(20))
    start = np.array([palm_q, (1.0, 0, 0, 0)])
    hand = hand_from_fingertips(tips, frame, orientations=start)
    for q, r in zip(hand.orientations(), start):
        assert same_rotation(q, r, atol=1e-14)              # nothing turned yet
    s = SpaceMouseState()
    s.feed(bytes.fromhex(report))
    steps, angle = 500, 1.2                                 # 0.8 s at 1.5 rad/s
    for _ in range(steps):
        hand.update(s, angle / 1.5 / steps)
    turn = axis_angle_quat(frame[:3, :3] @ np.array(hand_axis, dtype=float), angle)
    for q, r in zip(hand.orientations(), start):
        assert same_rotation(q, quat_mul(turn, r))
        assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    # The palm's angle from where it started is the integrated angle.
    rel = quat_mul(hand.orientations()[0], palm_q * np.array([1, -1, -1, -1]))
    assert 2 * math.acos(min(1.0, abs(rel[0]))) == pytest.approx(angle, abs=1e-9)
    # The fingertips turned with it.
    np.testing.assert_allclose(hand.tips() - hand.position,
                               quat_rotate(turn, tips - frame[:3, 3]), atol=1e-9)


def test_a_hand_without_orientations_gives_none_and_bad_ones_are_refused():
    assert make_hand().orientations() is None
    with pytest.raises(ValueError, match="finger_orientations"):
        make_hand(finger_orientations=[(0, 0, 0, 0), (1, 0, 0, 0)])
    with pytest.raises(ValueError, match="finger_orientations"):
        make_hand(finger_orientations=[(np.nan, 0, 0, 0), (1, 0, 0, 0)])


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
        # grip_time 0.5 s (of polls), then the haptic loop's tick: waited for, polling meanwhile.
        wait_until(lambda: np.allclose(world.snapshot()["hips"], closed, atol=1e-9), 60, "the grip closed",
                   seen=lambda: world.snapshot()["hips"], poll=0.01, each=lambda _: devices.poll())
        devices.poll()
        np.testing.assert_allclose(world.snapshot()["hips"], closed, atol=1e-9)     # and it stays closed
    finally:
        devices.close()
        world.stop()
    assert replay.closed


def test_spacemouse_turns_a_palm_of_a_running_world():
    """A twist of the cap turns a convex palm in the running core: the palm ends at the hand's
    last orientation (what the slot was given), turned about the world's z from its tilt."""
    import time

    graspcore = pytest.importorskip("graspcore")
    from addon.engine.devices.live import DeviceSet
    from addon.engine.devices.spacemouse import SpaceMouseSource
    world = graspcore.World(gravity=(0, 0, 0))
    tilt = axis_angle_quat((1, 0, 0), math.radians(20))
    box = np.array([(x, y, z) for x in (-0.045, 0.045) for y in (-0.04, 0.04) for z in (-0.01, 0.01)])
    palm = world.add_finger(radius=0.0, position=(0, 0, 0.1), points=box)
    world.set_finger_pose(palm, (0, 0, 0.1), tuple(tilt))
    world.set_tick_log(1 << 16)
    records = np.zeros(1 << 16, dtype=world.tick_dtype())
    world.start(priority=0, watchdog_timeout=0.05)
    replay = Replay([bytes.fromhex("020000000000a2fe")])     # rz -350: turning about z (up), 1.5 rad/s
    devices = DeviceSet(world)
    try:
        hand = hand_from_fingertips(world.snapshot()["hips"], orientations=[world.finger_pose(palm)[1]])
        source = SpaceMouseSource(hand, device=replay)
        devices.add_source(source, 0, "spacemouse")
        started = time.monotonic()
        while time.monotonic() - started < 0.3:
            devices.poll()
            time.sleep(0.01)
        polled = time.monotonic() - started                 # (a busy machine's sleeps run over)
        last = source.live_orientations()[0]
        latest = [None]

        def at_last_sample():                               # no more polls: the palm reaches it
            ticks = world.drain_ticks(records)
            if len(ticks):
                latest[0] = ticks["orientation"][-1, palm].copy()
            return latest[0] is not None and same_rotation(latest[0], last, atol=1e-12)
        wait_until(at_last_sample, 60, "the palm at the last sample's orientation (tick log)",
                   seen=lambda: (latest[0], last))
    finally:
        devices.close()
        world.stop()
    q = np.array(world.finger_pose(palm)[1])
    assert same_rotation(q, last, atol=1e-12)
    turn = quat_mul(q, tilt * np.array([1, -1, -1, -1]))   # what turned it, in the world
    angle = 2 * math.acos(min(1.0, abs(turn[0])))
    assert 0.2 < angle < 1.5 * polled + 0.1, (angle, polled)  # about 0.3 s (or what the polls took) at 1.5 rad/s
    np.testing.assert_allclose(np.abs(turn[1:]) / math.sin(angle / 2), [0, 0, 1], atol=1e-9)
