"""Find Devices over real pseudo-terminals: the emulator is found with its finger count; a
silent port, a port answering garbage, a port answering a broken hello and a port in use are
not, each said why; the probe is bounded in time, leaves no descriptor open and leaves a
port nothing but its hellos. Which pseudo-terminals are candidates (raw, nobody's terminal)."""
import json
import os
import select
import subprocess
import sys
import termios
import threading
import time
import tty

import numpy as np
import pytest

from addon.engine.devices import discovery as D
from addon.engine.devices import protocol as P

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def open_fds_on(path):
    """Descriptors of this process open on ``path``."""
    out = []
    for fd in os.listdir("/proc/self/fd"):
        try:
            if os.readlink(f"/proc/self/fd/{fd}") == path:
                out.append(int(fd))
        except OSError:
            pass
    return out


def drain(fd):
    data = b""
    while select.select([fd], [], [], 0.05)[0]:
        try:
            data += os.read(fd, 4096)
        except OSError:
            break
    return data


@pytest.fixture
def emulator():
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--fingers", "3",
                            "--duration", "0.5"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        yield emu, emu.stdout.readline().split()[1]
    finally:
        emu.kill()
        emu.wait()


@pytest.fixture
def raw_pty():
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        yield master, slave, os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


def test_the_emulator_is_found_with_its_finger_count(emulator):
    emu, port = emulator
    assert port in D.candidate_ports()          # a pty, raw, nobody's terminal
    (r,) = D.probe_ports([port])
    assert r["status"] == "grasp_lab" and r["port"] == port, r
    assert r["hello"] == {"n_fingers": 3, "renders_forces": True, "units": 0, "rate_hz": 1000, "force_max": 5.0,
                          "ttl_max_ms": 50, "name": "grasp-lab-emulator", "orientations": False}
    assert open_fds_on(port) == []              # the port is closed again
    report = json.loads([l for l in emu.communicate(timeout=20)[0].splitlines() if l.startswith("REPORT ")][0][7:])
    assert report["host_hellos"] == 1 and report["force_frames"] == 0 and report["host_frames_dropped"] == \
        dict.fromkeys(report["host_frames_dropped"], 0), report
    # Its duration over, the emulator has closed its pty: no longer a candidate, nor a device.
    assert port not in D.candidate_ports()
    devices, probed = D.find_devices(extra_ports=[port])     # (other emulators on this machine may answer)
    assert all(d["port"] != port for d in devices) and \
        [(p["status"], p["detail"]) for p in probed if p["port"] == port] == [
            ("error", "cannot open (No such file or directory)")], probed


def test_a_silent_port_gets_its_hellos_and_nothing_else(raw_pty):
    master, slave, port = raw_pty
    before = termios.tcgetattr(slave)
    assert port in D.candidate_ports()
    t0 = time.monotonic()
    (r,) = D.probe_ports([port], timeout=0.35)
    elapsed = time.monotonic() - t0
    assert r["status"] == "silent" and r["detail"] == "no Grasp Lab hello within 0.35 s: silent", r
    # It waited its timeout; the upper bound only catches a hang (a busy machine adds seconds).
    assert 0.35 <= elapsed < 30, elapsed
    wire = drain(master)
    assert wire.startswith(b"\x00")             # a delimiter first: flushes a half-received frame
    dec = P.StreamDecoder()
    frames = dec.feed(wire)
    # HELLO_HOST every 100 ms while waiting (protocol.md section 3): 4 in 0.35 s, nothing else.
    assert [f.type for f in frames] == [P.HELLO_HOST] * 4 and dec.dropped == 0, (frames, dec.errors)
    assert [f.seq for f in frames] == [0, 1, 2, 3] and all(P.parse_hello_host(f.payload) == 0 for f in frames)
    assert termios.tcgetattr(slave) == before and open_fds_on(port) == [slave]


def test_a_port_answering_garbage_is_not_a_device(raw_pty):
    master, slave, port = raw_pty
    stop = threading.Event()

    def noise():
        rng = np.random.default_rng(3)
        while not stop.is_set():
            try:
                os.write(master, rng.integers(0, 256, 97, dtype=np.uint8).tobytes())
                drain(master)
            except OSError:
                return
    t = threading.Thread(target=noise, daemon=True)
    t.start()
    try:
        t0 = time.monotonic()
        (r,) = D.probe_ports([port], timeout=0.3)
        elapsed = time.monotonic() - t0
    finally:
        stop.set()
        t.join(5)
    assert r["status"] == "not_grasp_lab" and elapsed < 30, (r, elapsed)      # (a hang, not a busy machine)
    received = int(r["detail"].split(": ")[1].split()[0])
    assert received > 0 and "not in the protocol" in r["detail"], r
    assert open_fds_on(port) == [slave]


def test_a_hello_that_breaks_the_protocol_is_said(raw_pty):
    master, slave, port = raw_pty
    hello = bytearray(P.hello_device(2, True, P.UNITS_METRE, 1000, 5.0, 50, "bad units"))
    hello[2] = 7                                # units: neither metres nor millimetres

    def device():
        dec, end = P.StreamDecoder(), time.monotonic() + 5
        while time.monotonic() < end:
            if select.select([master], [], [], 0.05)[0]:
                if any(f.type == P.HELLO_HOST for f in dec.feed(os.read(master, 4096))):
                    os.write(master, P.encode(P.HELLO_DEVICE, 0, bytes(hello)))
                    return
    t = threading.Thread(target=device, daemon=True)
    t.start()
    (r,) = D.probe_ports([port], timeout=1.0)
    t.join(5)
    assert r["status"] == "invalid" and "units" in r["detail"], r


def test_a_port_in_use_is_not_written_to(raw_pty):
    import serial
    master, slave, port = raw_pty
    held = serial.Serial(port, 1_000_000, timeout=0, exclusive=True)     # as a running session holds it
    try:
        (r,) = D.probe_ports([port], timeout=0.2)
        assert r["status"] == "busy", r
        assert drain(master) == b""
    finally:
        held.close()


def test_one_probe_of_many_ports_is_bounded_and_tells_each_apart(emulator, raw_pty, tmp_path):
    _, port = emulator
    master, slave, silent = raw_pty
    missing = str(tmp_path / "no-such-port")
    plain = tmp_path / "a-file"
    plain.write_text("x")
    t0 = time.monotonic()
    results = D.probe_ports([port, silent, missing, str(plain), port], timeout=0.4)
    elapsed = time.monotonic() - t0
    assert [(r["port"], r["status"]) for r in results] == [
        (port, "grasp_lab"), (silent, "silent"), (missing, "error"), (str(plain), "error")], results
    assert "No such file" in results[2]["detail"] and results[3]["detail"] == "not a serial port"
    assert elapsed < 30, elapsed        # no hang (the silent port's 0.4 s, and a busy machine's)
    assert plain.read_text() == "x"     # not a terminal: nothing written
    with pytest.raises(ValueError, match="timeout: must be > 0 s"):
        D.probe_ports([port], timeout=0)


def test_a_terminal_in_line_mode_keeps_its_settings_and_is_no_candidate():
    master, slave = os.openpty()        # a fresh pty is in line mode with echo: a terminal
    try:
        port = os.ttyname(slave)
        before = termios.tcgetattr(slave)
        assert port not in D.candidate_ports()
        (r,) = D.probe_ports([port], timeout=0.15)     # named by hand: probed raw, then put back
        assert r["status"] == "silent" and termios.tcgetattr(slave) == before
    finally:
        os.close(master)
        os.close(slave)


def test_a_raw_pty_that_is_a_controlling_terminal_is_no_candidate(raw_pty):
    """An editor or a full-screen program keeps its terminal raw: it is its session's
    controlling terminal, so the probe leaves it alone."""
    master, slave, port = raw_pty
    assert port in D.candidate_ports()
    # A new session opening the pty without O_NOCTTY takes it as its controlling terminal.
    holder = subprocess.Popen([sys.executable, "-c", "import os, sys, time; fd = os.open(sys.argv[1], os.O_RDWR); "
                               "print(os.ttyname(fd) == os.ctermid() or os.readlink('/proc/self/fd/%d' % fd), "
                               "flush=True); time.sleep(30)", port], stdout=subprocess.PIPE, text=True,
                              start_new_session=True)
    try:
        holder.stdout.readline()
        stat = open(f"/proc/{holder.pid}/stat").read()
        assert int(stat[stat.rfind(")") + 2:].split()[4]) != 0      # it is its controlling terminal
        assert port not in D.candidate_ports()
        # Named by hand (--probe, a typed-in port): still left alone.
        (r,) = D.probe_ports([port], timeout=0.2)
        assert r["status"] == "terminal" and drain(master) == b"", r
    finally:
        holder.kill()
        holder.wait()
    assert port in D.candidate_ports()


def test_after_a_probe_the_session_sees_the_emulator_motion_from_its_start():
    """The probe's hello starts the emulator streaming; the session's hello starts its motion
    (here: lift) again, however soon after the probe (a probe answers no pose); a hello from a
    host that has been answering poses (one waiting for poses that stopped) does not."""
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--motion", "lift",
                            "--rate", "200"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = emu.stdout.readline().split()[1]
        assert D.probe_ports([port])[0]["status"] == "grasp_lab"
        time.sleep(0.05)                                # a session opening the port right after

        def first_pose_after_hello(fd):
            os.write(fd, P.encode(P.HELLO_HOST, 0, P.hello_host()))
            dec, frames, end = P.StreamDecoder(), [], time.monotonic() + 5
            while time.monotonic() < end and not any(f.type == P.POSE for f in frames):
                if select.select([fd], [], [], 0.05)[0]:
                    frames += dec.feed(os.read(fd, 4096))
            seen = [f.type for f in frames]
            pose_frame = frames[seen.index(P.POSE, seen.index(P.HELLO_DEVICE))]
            # Answered, as a streaming host answers every pose.
            os.write(fd, P.encode(P.FORCE, 1, P.force(pose_frame.seq, 20000, [(0.0, 0.0, 0.0)] * 2)))
            return P.parse_pose(pose_frame.payload)

        fd = os.open(port, os.O_RDWR | os.O_NOCTTY)
        try:
            termios.tcflush(fd, termios.TCIFLUSH)       # what it streamed to nobody
            pose = first_pose_after_hello(fd)
            x, _, z = pose.positions[0]
            assert abs(x - 0.06) < 2e-3 and abs(z) < 1e-6 and pose.time_us < 50_000, pose   # t = 0: open, down
            time.sleep(0.1)
            termios.tcflush(fd, termios.TCIFLUSH)
            pose = first_pose_after_hello(fd)           # 0.1 s after its answer: the same conversation
            assert pose.time_us > 100_000 and pose.positions[0][0] < 0.06 - 2e-3, pose
        finally:
            os.close(fd)
    finally:
        emu.kill()
        emu.wait()


def test_a_stop_button_pressed_to_nobody_after_a_probe_is_pressed_again_in_the_session():
    """``--estop-at`` counts from the session's hello, as the motion does: a button the script
    pressed while nobody streamed (a probe's conversation, a slow session start: its ESTOP
    frame went to nobody) is neither latched in the session's poses nor forgotten."""
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--motion", "lift",
                            "--rate", "200", "--estop-at", "0.2", "--duration", "5"], cwd=ROOT,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = emu.stdout.readline().split()[1]
        assert D.probe_ports([port])[0]["status"] == "grasp_lab"
        time.sleep(0.5)                                 # the script's button: pressed to nobody
        fd = os.open(port, os.O_RDWR | os.O_NOCTTY)
        try:
            termios.tcflush(fd, termios.TCIFLUSH)
            os.write(fd, P.encode(P.HELLO_HOST, 0, P.hello_host()))
            dec, frames, end = P.StreamDecoder(), [], time.monotonic() + 5
            while time.monotonic() < end and not any(f.type == P.ESTOP for f in frames):
                if select.select([fd], [], [], 0.05)[0]:
                    for f in dec.feed(os.read(fd, 4096)):
                        frames.append(f)
                        if f.type == P.POSE:            # answered, as a streaming host does
                            os.write(fd, P.encode(P.FORCE, 1, P.force(f.seq, 20000, [(0.0, 0.0, 0.0)] * 2)))
            seen = [f.type for f in frames]
            poses = [P.parse_pose(f.payload) for f in frames[seen.index(P.HELLO_DEVICE):] if f.type == P.POSE]
            assert P.ESTOP in seen, "no ESTOP in the session"
            before = poses[:seen[seen.index(P.HELLO_DEVICE):].index(P.ESTOP) - 1]
            assert before and not any(p.status & P.STATUS_ESTOPPED for p in before), [p.status for p in before]
            assert abs(before[-1].time_us * 1e-6 - 0.2) < 0.05, before[-1]      # pressed 0.2 s into the session
        finally:
            os.close(fd)
    finally:
        emu.kill()
        emu.wait()
