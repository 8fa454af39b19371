"""The devices and emulate commands, and --device specs."""
import argparse
import json
import math
import os
import subprocess
import sys

import pytest

from addon.engine.devices import cli_commands as C

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


# grasp-lab as the venv's launcher runs it (addon.launcher), from this checkout.
GRASP_LAB = [sys.executable, "-c", "import sys; from addon.launcher import launch; sys.exit(launch())"]


def run_cli(*args, timeout=30):
    return subprocess.run(GRASP_LAB + [*args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def test_devices_probe_finds_the_emulator():
    emu = subprocess.Popen(GRASP_LAB + ["emulate", "--pty",
                            "--fingers", "3", "--force-max", "2.5"],   # until the test ends it
                           cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        port = emu.stdout.readline().split()[1]
        out = run_cli("devices", "--json", "--probe", port)
        assert out.returncode == 0, out.stderr
        entry = [d for d in json.loads(out.stdout) if d.get("port") == port and "grasp_lab" in d][0]
        assert entry["grasp_lab"] == {"n_fingers": 3, "renders_forces": True, "units": 0, "rate_hz": 1000,
                                      "force_max": 2.5, "ttl_max_ms": 50, "name": "grasp-lab-emulator",
                                      "orientations": False}
        emu.terminate()     # (a --duration would count from the probe's hello: a race with a busy machine)
        report = json.loads([l for l in emu.communicate(timeout=20)[0].splitlines() if l.startswith("REPORT ")][0][7:])
        assert report["host_hellos"] == 1 and report["force_frames"] == 0 and report["poses_sent"] > 0
    finally:
        emu.kill()


def test_devices_probe_of_a_silent_port_says_so():
    master, slave = os.openpty()
    try:
        out = run_cli("devices", "--probe", os.ttyname(slave), "--timeout", "0.2")
        assert out.returncode == 0 and "no Grasp Lab hello within 0.2 s" in out.stdout
    finally:
        os.close(master)
        os.close(slave)


def test_emulate_rejects_bad_arguments():
    out = run_cli("emulate", "--pty", "--fingers", "40")
    assert out.returncode != 0 and "--fingers: 40 outside 1..32" in out.stderr
    out = run_cli("emulate", "--pty", "--motion", "dance")
    assert out.returncode != 0 and "invalid choice: 'dance'" in out.stderr
    out = run_cli("emulate", "--pty", "--first", "2")
    assert out.returncode != 0 and "--first: only with --from" in out.stderr
    out = run_cli("emulate", "--pty", "--wait", "0.2")
    assert out.returncode == 2 and "no hello from the host within 0.2 s" in out.stderr


def test_device_specs():
    assert C.parse_device_spec("serial:/dev/ttyACM0") == {"kind": "serial", "port": "/dev/ttyACM0", "finger_offset": 0}
    assert C.parse_device_spec("serial:/dev/pts/3@5")["finger_offset"] == 5
    assert C.parse_device_spec("spacemouse") == {"kind": "spacemouse", "path": None}
    assert C.parse_device_spec("opengloves:/dev/ttyUSB0")["port"] == "/dev/ttyUSB0"
    for bad, msg in [("serial:", "needs a port"), ("serial:/dev/x@a", "integer"), ("joystick:1", "unknown kind"),
                     ("opengloves", "needs a port"), ("serial:/dev/x@-1", ">= 0")]:
        with pytest.raises(ValueError, match=msg):
            C.parse_device_spec(bad)


def test_emulate_on_a_named_port():
    """PORT instead of --pty: the emulator opens it with pyserial; here the host holds the
    master of a pty whose slave is that port."""
    import tty
    from addon.engine.devices import protocol as P
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    path = os.ttyname(slave)
    emu = subprocess.Popen(GRASP_LAB + ["emulate", path,
                            "--fingers", "1", "--motion", "circle", "--rate", "200"],   # until the test ends it
                           cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert emu.stdout.readline().strip() == f"PORT {path}"
        os.write(master, P.encode(P.HELLO_HOST, 0, P.hello_host()))
        dec, poses = P.StreamDecoder(), []
        import select
        import time
        end = time.monotonic() + 60         # a hang's bound: 20 poses take 0.1 s on a quiet machine
        while len(poses) < 20 and time.monotonic() < end:
            if select.select([master], [], [], 0.1)[0]:
                poses += [P.parse_pose(f.payload) for f in dec.feed(os.read(master, 4096)) if f.type == P.POSE]
        assert len(poses) >= 20 and dec.dropped == 0
        r = [math.hypot(*p.positions[0][:2]) for p in poses]
        assert all(0.035 < v < 0.085 for v in r)     # the circle motion: 6 cm ring, 2 cm circle
        emu.terminate()
        report = json.loads([l for l in emu.communicate(timeout=20)[0].splitlines() if l.startswith("REPORT ")][0][7:])
        assert report["rate_hz"] == 200 and report["host_hellos"] == 1
    finally:
        emu.kill()
        os.close(master)
        os.close(slave)


def test_the_grasp_lab_dispatcher_carries_the_device_commands_and_kinds():
    """grasp-lab's dispatcher (addon/engine/cli.py) registers devices, emulate and the --device
    kinds from engine/devices: they work through its own argparse."""
    import io
    from addon.engine import cli
    assert {"devices", "emulate"} <= set(cli.COMMANDS)
    assert {"serial", "udp", "spacemouse", "opengloves"} <= set(cli.DEVICE_BACKENDS)
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    for name in ("devices", "emulate"):
        cli.COMMANDS[name].configure(sub.add_parser(name))
    args = parser.parse_args(["devices", "--json", "--no-probe"])
    out = io.StringIO()
    assert cli.COMMANDS["devices"].run(args, out, None) == 0 and isinstance(json.loads(out.getvalue()), list)
    assert parser.parse_args(["emulate", "--pty", "--fingers", "3"]).fingers == 3
    assert not cli.COMMANDS["emulate"].needs_blender(parser.parse_args(["emulate", "--pty"]))
    assert cli.DEVICE_BACKENDS["serial"]("serial:/dev/ttyACM0@2", 5)["finger_offset"] == 2
    with pytest.raises(ValueError, match="needs a port"):
        cli.DEVICE_BACKENDS["opengloves"]("opengloves", 5)
