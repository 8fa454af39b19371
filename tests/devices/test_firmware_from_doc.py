"""Firmware written from docs/protocol.md alone (firmware_from_doc.c: no Grasp Lab code or
header) against the host over a real pseudo-terminal: the document is enough to build a device.
It streams millimetres with heartbeats between its poses, clamps to its own limit, lets go when
the host's TTL runs out, answers a restarted host, and presses its stop button; both sides
count no dropped frame and no sequence gap."""
import json
import os
import shutil
import subprocess
import time

import numpy as np
import pytest

graspcore = pytest.importorskip("graspcore")
pytest.importorskip("serial")

from addon.engine.devices.serial_device import SerialDevice  # noqa: E402
from waiting import wait_until  # noqa: E402  (tests/support, docs/testing.md)

HERE = os.path.dirname(os.path.abspath(__file__))
BOX, RADIUS = 0.03, 0.008



@pytest.fixture(scope="module")
def firmware(tmp_path_factory):
    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc, "a C compiler is needed (the project builds its core with one)"
    exe = str(tmp_path_factory.mktemp("fw") / "firmware_from_doc")
    subprocess.run([cc, "-std=c11", "-Wall", "-Wextra", "-Werror", "-O2", "-o", exe,
                    os.path.join(HERE, "firmware_from_doc.c"), "-lm"], check=True)
    return exe


def test_firmware_written_from_the_document_alone(firmware):
    world = graspcore.World(gravity=(0, 0, 0))
    world.add_body([(sx * BOX, sy * BOX, sz * BOX) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)],
                   static=True)
    world.add_finger(position=(0.06, 0, 0))
    world.add_finger(position=(-0.06, 0, 0))
    world.start(priority=0, ramp_time=0.0, watchdog_timeout=0.05)
    fw = subprocess.Popen([firmware, "3.0", "2.0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    dev = SerialDevice(world, fw.stdout.readline().split()[1], 0, 2, ramp_time=0.1, stall_timeout=0.05)
    events = []
    try:
        dev.connect()
        wait_until(lambda: dev.stats()["state"] == "streaming" and dev.stats()["poses"] > 300, 30, "streaming")
        st = dev.stats()
        assert (st["name"], st["device_fingers"], st["units"], st["device_force_max"]) == ("doc-fw-1", 2, 1, 2.0)
        # Its millimetres, in the scene: fingertips 35 mm out, 3 mm into the box: 3 N of spring.
        np.testing.assert_allclose(world.snapshot()["hips"], [(0.035, 0, 0), (-0.035, 0, 0)], atol=1e-7)
        np.testing.assert_allclose(np.linalg.norm(world.snapshot()["spring_forces"], axis=1),
                                   1000.0 * (BOX + RADIUS - 0.035), rtol=0.02)
        dev.enable()
        wait_until(lambda: dev.stats()["gain"] == 1.0, 30, "forces ramped in")
        time.sleep(0.2)
        # The host stops (detached): the firmware's TTL lets go. Then a new host says hello.
        dev.disconnect()
        time.sleep(0.1)
        dev.connect()
        wait_until(lambda: dev.stats()["state"] == "streaming" and dev.stats()["gain"] == 1.0, 30, "forces again")
        # Its stop button (2 s into streaming): forces off on the host's side too.
        def estopped():
            events.extend(dev.events())
            return any(e[1] == "estop" for e in events)
        wait_until(estopped, 30, "the e-stop")
        estop = [e for e in events if e[1] == "estop"][0]
        assert estop[2] == 1 and estop[3] > 0, estop                    # reason 1, at session time
        st = wait_until(lambda: (lambda st: not st["enabled"] and st["gain"] == 0.0 and st)(dev.stats()), 30,
                        "forces off after the e-stop (its stats published)", seen=dev.stats)
        assert st["dropped"] == 0 and st["sequence_gaps"] == 0 and st["heartbeats"] > 10, st
        out, err = fw.communicate(timeout=20)
    finally:
        fw.kill()
        dev.disconnect()
        world.stop()
    report = json.loads([line for line in out.splitlines() if line.startswith("REPORT ")][0][7:])
    assert report["dropped"] == [0, 0, 0, 0] and report["rejected"] == 0, report      # every host frame valid
    assert report["forces_while_off"] == 0, report      # zero while off and while e-stopped
    assert report["hellos"] >= 2 and report["enables"] >= 2, report     # more if it was ever silent 0.1 s
    assert report["max_norm"] == pytest.approx(2.0, abs=1e-6), report    # its own 2 N limit (the spring: 3 N)
    # The TTL the host sent (20 ms, under its 30 ms limit) ran out after the host went: it let go.
    assert report["ttl_expiries"] >= 1 and 19.9 <= report["max_ttl_gap_ms"] < 40, report
    assert report["estop_latched"] == 1 and report["rendered_at_end"] == 0.0, report
