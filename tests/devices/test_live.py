"""The bpy-free device-session logic of engine/devices/live.py: which device drives which
finger, the scripted track minus those fingers, and the losses told at the end of a run."""
import numpy as np
import pytest

from addon.engine.devices.live import (device_event_detail, device_fingers, loss_lines, losses,
                                       recorded_device_events, without_fingers)


def test_device_fingers_assigns_and_names_the_device_that_cannot_drive():
    owner = device_fingers([("/dev/a", 0, 2), ("/dev/b", 3, 1)], 4)
    assert owner.tolist() == [0, 0, -1, 1]
    with pytest.raises(ValueError, match=r"device /dev/c: drives fingers 2\.\.2, but the scene has fingers "
                                         r"0\.\.1 \(Finger 0, Finger 1\)"):
        device_fingers([("/dev/c", 2, 1)], 2, ["Finger 0", "Finger 1"])
    with pytest.raises(ValueError, match="the scene has no fingers"):
        device_fingers([("spacemouse", 0, 1)], 0)
    with pytest.raises(ValueError, match="device /dev/b: fingers 1..2 overlap those of device /dev/a"):
        device_fingers([("/dev/a", 0, 2), ("/dev/b", 1, 2)], 4)


def test_without_fingers_takes_the_devices_fingers_out_of_the_script():
    times, positions = np.array([0.0, 1.0]), np.zeros((2, 3, 3))
    t, p, mask = without_fingers((times, positions, None), np.array([True, False, False]))
    assert t is times and p is positions and mask.tolist() == [False, True, True]
    _, _, mask = without_fingers((times, positions, np.array([True, True, False])), np.array([False, True, True]))
    assert mask.tolist() == [True, False, False]
    assert without_fingers((times, positions, np.array([False, True, False])), np.array([False, True, False])) is None
    assert without_fingers(None, np.array([True])) is None


def test_losses_pair_each_loss_with_its_return():
    events = [(2.5, "/dev/a", "connected", 2), (0.1, "/dev/a", "connected", 2), (1.0, "/dev/a", "lost", 1),
              (1.2, "/dev/b", "lost", 0), (1.4, "/dev/b", "recovered", 0), (3.0, "/dev/b", "lost", 0),
              (1.1, "/dev/a", "lost", 0)]     # out of order, as polled: sorted by time; a second "lost" of
    assert losses(events) == [("/dev/a", 1.0, "hang-up", 2.5), ("/dev/b", 1.2, "silence", 1.4),
                              ("/dev/b", 3.0, "silence", None)]   # an open loss is one loss
    assert loss_lines(events)[2] == "/dev/b lost at 3.000 s (silence), not back by the end"
    assert loss_lines(events)[0] == "/dev/a lost at 1.000 s (hang-up), back at 2.500 s"
    assert loss_lines([(0.1, "/dev/a", "connected", 2)]) == []
    recorded = [{"time": 1.0, "kind": "device_lost", "subject": "/dev/a", "value": 1},
                {"time": 0.5, "kind": "contact_begin", "subject": "Finger 0"}]
    assert recorded_device_events(recorded) == [(1.0, "/dev/a", "lost", 1)]


def test_device_event_details_say_what_the_value_means():
    assert device_event_detail("lost", 1).startswith("hang-up")
    assert device_event_detail("lost", 0).startswith("silence")
    assert "stop button" in device_event_detail("estop", 1)
    assert "pose status" in device_event_detail("estop", 256)
    assert "reason 7" in device_event_detail("estop", 7)
    assert device_event_detail("enabled", 0).startswith("forces off")


def test_free_fingers_puts_a_new_device_on_the_fingers_no_device_drives():
    from addon.engine.devices.live import free_fingers
    # A device's hello says how many fingers it has; it goes on the first run of free ones.
    assert free_fingers([], 3, 2) == (0, 2)
    assert free_fingers([(0, 2)], 4, 2) == (2, 2)
    assert free_fingers([(1, 1)], 5, 2) == (2, 2)           # finger 0 alone is too short a run
    assert free_fingers([(0, 3)], 6, 3) == (3, 3)
    # Fewer free fingers than it has: the first free one and those after it (it drives its first ones).
    assert free_fingers([(0, 2)], 3, 2) == (2, 1)
    assert free_fingers([(1, 2)], 4, 5) == (0, 1)
    # Asked for at a finger (serial:PORT@FIRST).
    assert free_fingers([], 4, 2, first=1) == (1, 2)
    assert free_fingers([(3, 1)], 4, 2, first=2) == (2, 1)
    with pytest.raises(ValueError, match="no free finger: another device drives every finger of the scene"):
        free_fingers([(0, 2), (2, 1)], 3, 1)
    with pytest.raises(ValueError, match=r"finger 1: another device drives it already"):
        free_fingers([(0, 2)], 3, 1, first=1)
    with pytest.raises(ValueError, match=r"finger 4: the scene has fingers 0\.\.2"):
        free_fingers([], 3, 1, first=4)
    with pytest.raises(ValueError, match="the scene has no fingers"):
        free_fingers([], 0, 2)


def test_a_source_device_owns_its_fingers_in_the_core():
    """A device read in Python (push_device_hips) and a serial device never share a finger; its
    forces (device_forces) only for its own fingers, zero until enabled, and only while running;
    a SourceDevice without send_forces (a SpaceMouse) records zero forces sent."""
    import socket

    graspcore = pytest.importorskip("graspcore")
    from addon.engine.devices.live import DeviceSet
    world = graspcore.World(gravity=(0, 0, 0))
    world.add_finger(position=(0.0, 0, 0))
    world.add_finger(position=(0.1, 0, 0))
    out = np.ones((1, 3))
    with pytest.raises(RuntimeError, match="not running"):
        world.push_device_hips(0, np.zeros((1, 3)))
    world.start(priority=0)
    a, b = socket.socketpair()
    try:
        assert world.push_device_hips(0, np.array([[0.0, 0.0, 0.001]]))
        assert not world.push_device_hips(0, np.array([[np.nan, 0.0, 0.0]]))     # refused, nothing taken
        with pytest.raises(ValueError, match="push_device_hips"):
            world.attach_serial(a.fileno(), finger_offset=0, num_fingers=1)
        dev = world.attach_serial(a.fileno(), finger_offset=1, num_fingers=1)
        with pytest.raises(ValueError, match="a serial device drives"):
            world.push_device_hips(1, np.zeros((1, 3)))
        with pytest.raises(ValueError, match="not driven through push_device_hips"):
            world.device_forces(1, out, True)
        world.device_forces(0, out, False)
        assert not out.any()
        world.detach_serial(dev)

        class Mouse:            # an input-only source: fingertips, no forces
            name, n_fingers = "mouse", 1

            def open(self):
                pass

            def close(self):
                pass

            def hips_at(self, t):
                return np.array([[0.1, 0.0, 0.002]])

        devices = DeviceSet(world)
        devices.add_source(Mouse(), 1)      # the serial device's finger, free again
        devices.poll()
        assert devices.devices[0].polls == 1 and devices.devices[0].rejected == 0
    finally:
        world.stop()
        a.close()
        b.close()
    with pytest.raises(RuntimeError, match="not running"):
        world.device_forces(0, out, True)


def test_a_device_placed_where_it_has_too_few_fingers_is_refused():
    # Issue #29: a 2-finger device at @2 of a 3-finger scene drove finger 2 and silently dropped
    # its second finger. Placed by hand, it is refused, naming it; placed by the host it still
    # goes where it fits.
    from addon.engine.devices.live import assign_specs
    with pytest.raises(ValueError, match=r"serial:/dev/pts/77@2.*the device has 2 fingers .2\.\.3., the scene "
                                         r"has 3 and 1 of them free there"):
        assign_specs(["serial:/dev/pts/77@2"], 3, hellos={"/dev/pts/77": 2})
    placed = assign_specs(["serial:/dev/pts/77@1"], 3, hellos={"/dev/pts/77": 2})
    assert (placed[0]["finger_offset"], placed[0]["num_fingers"]) == (1, 2)
