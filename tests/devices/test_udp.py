"""The protocol over UDP (docs/protocol.md section 8), end to end on the loopback interface:
the emulator (`--udp`) drives the runtime through the core's device thread, with datagrams
lost, duplicated and reordered on the way (counted, and a late pose never moves a HIP back);
a second sender is ignored and counted; a stalled device is lost and its fingers let go."""
import json
import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

graspcore = pytest.importorskip("graspcore")

from addon.engine.devices import protocol as P  # noqa: E402
from addon.engine.devices.cli_commands import parse_device_spec  # noqa: E402
from addon.engine.devices.serial_device import UdpDevice  # noqa: E402
from waiting import wait_until  # noqa: E402  (tests/support, docs/testing.md)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BOX, RADIUS = 0.03, 0.008



def emulator(*args):
    proc = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--udp", "0", *args], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    assert line.startswith("PORT udp:127.0.0.1:"), (line, proc.stderr.read() if proc.poll() is not None else "")
    return proc, int(line.split(":")[-1])


def report_of(proc) -> dict:
    if proc.poll() is None:
        proc.terminate()
    out, err = proc.communicate(timeout=20)
    lines = [line for line in out.splitlines() if line.startswith("REPORT ")]
    assert lines, err
    return json.loads(lines[-1][7:])


def gripping_world():
    world = graspcore.World(gravity=(0, 0, 0))
    world.add_body([(sx * BOX, sy * BOX, sz * BOX) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)],
                   static=True)
    world.add_finger(position=(0.06, 0, 0))
    world.add_finger(position=(-0.06, 0, 0))
    world.set_tick_log(1 << 15)
    world.start(priority=0, ramp_time=0.0, watchdog_timeout=0.05)
    return world


def test_udp_spec():
    assert parse_device_spec("udp:127.0.0.1:5555@2") == {"kind": "udp", "host": "127.0.0.1", "port": "127.0.0.1:5555",
                                                         "udp_port": 5555, "finger_offset": 2}
    assert parse_device_spec("udp:[::1]:9")["host"] == "::1"
    for bad in ("udp:127.0.0.1", "udp::5555", "udp:h:0", "udp:h:70000", "udp:h:5@x"):
        with pytest.raises(ValueError, match="udp"):
            parse_device_spec(bad)


def test_udp_lost_duplicated_reordered_and_a_second_sender():
    world = gripping_world()
    emu, port = emulator("--motion", "grip", "--drop-every", "50", "--dup-every", "37", "--reorder-every", "41")
    dev = UdpDevice(world, "127.0.0.1", port, 0, 2, ramp_time=0.0, stall_timeout=0.05)
    records = np.zeros(1 << 15, dtype=world.tick_dtype())
    intruder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        dev.connect()
        assert dev.bind == "127.0.0.1"                 # a device on this machine: only loopback listens
        wait_until(lambda: dev.stats()["state"] == "streaming" and dev.stats()["poses"] > 200, 30, "streaming")
        assert dev.stats()["peer"] == f"127.0.0.1:{port}"
        closing = world.drain_ticks(records)["hip"].copy()
        # Someone else sends valid poses (fingertips far away) to the host's socket: ignored.
        for k in range(200):
            intruder.sendto(P.encode(P.POSE, k, P.pose(k, [(0.5, 0.5, 0.5), (0.5, 0.5, 0.5)])),
                            ("127.0.0.1", dev.local_port))
        dev.enable()
        wait_until(lambda: dev.stats()["poses"] > 1500, 30, "more poses")
        st = dev.stats()
        closing = np.concatenate([closing, world.drain_ticks(records)["hip"]])
    finally:
        report = report_of(emu)
        intruder.close()
        dev.disconnect()
        world.stop()
    assert st["foreign_datagrams"] == 200, st
    assert np.abs(closing).max() < 0.07                               # never the intruder's 0.5 m
    # The grip closes from 6 to 3 cm: a HIP never moves back out (a late pose would).
    radius = np.abs(closing[:, 0, 0])
    assert np.all(np.diff(radius) <= 1e-12), np.diff(radius).max()
    np.testing.assert_allclose(radius[-1], 0.03, atol=1e-6)
    inj = report["injected"]
    assert inj["dropped"] > 10 and inj["duplicated"] > 10 and inj["reordered"] > 10, inj
    assert st["duplicate_poses"] > 0 and st["late_poses"] > 0 and st["sequence_gaps"] > 0, st
    assert st["duplicate_poses"] <= inj["duplicated"] and st["late_poses"] <= inj["reordered"], (st, inj)
    assert st["dropped"] == 0 and report["violations"] == dict.fromkeys(report["violations"], 0), (st, report)
    assert report["max_force_n"] > 4.9 and report["foreign_datagrams"] == 0, report
    events = [e[1] for e in dev.events()] if dev.device_id is not None else None
    assert events is None       # detached: the events went with it (DeviceSet collects them while attached)


def test_udp_stalled_device_is_lost_and_lets_go():
    world = gripping_world()
    emu, port = emulator("--motion", "grip")
    dev = UdpDevice(world, "127.0.0.1", port, 0, 2, ramp_time=0.0, stall_timeout=0.05)
    try:
        dev.connect()
        wait_until(lambda: dev.stats()["state"] == "streaming" and dev.stats()["poses"] > 700, 30, "gripping")
        dev.enable()
        wait_until(lambda: dev.stats()["gain"] == 1.0, 30, "forces on")
        emu.send_signal(signal.SIGSTOP)               # the network (or the bridge) stalls
        wait_until(lambda: np.linalg.norm(world.snapshot()["spring_forces"], axis=1).max() < 1e-6, 30, "let go")
        # (How soon: bench/bench_unplug.py; exactly, on the manual clock: native/tests/test_serial_io.c.)
        wait_until(lambda: dev.stats()["state"] == "lost", 30, "the state to say so")      # published every 10 ms
        emu.send_signal(signal.SIGCONT)                # back: picked up again
        wait_until(lambda: dev.stats()["state"] == "streaming", 30, "streaming again")
        names = [e[1] for e in dev.events()]
        # Back with a pose ("recovered") or first with its answer to the hellos sent while it was
        # silent ("connected": it says hello again, forces off until the host's ENABLE).
        assert names[names.index("lost") + 1] in ("recovered", "connected"), names
        wait_until(lambda: dev.stats()["gain"] == 1.0 and dev.stats()["enabled"], 30, "forces on again")
    finally:
        emu.send_signal(signal.SIGCONT)
        report = report_of(emu)
        dev.disconnect()
        world.stop()
    assert report["ttl_expiries"] >= 0 and report["violations"] == dict.fromkeys(report["violations"], 0), report
