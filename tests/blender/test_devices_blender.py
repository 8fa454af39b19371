"""The emulator playing a .blend's fingertip animation (``--from``) over a real pty."""
import json
import os
import re
import select
import subprocess
import sys
import time
import tty

import grasp_env
import numpy as np
import pytest
from waiting import wait_until

sys.path.insert(0, grasp_env.ROOT)
from addon.engine.devices import protocol as P  # noqa: E402


def test_emulator_plays_the_fingertips_of_a_blend(bpy, sample, tmp_path):
    sample.build(bpy)
    scene = bpy.context.scene
    scene.frame_set(scene.frame_start)
    expected = [tuple(bpy.data.objects[f"Finger {i}"].matrix_world.translation) for i in (0, 1)]
    path = str(tmp_path / "pinch.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    emu = subprocess.Popen([sys.executable, "-m", "addon.emulate_blend", "--pty", "--from", path,
                            "--duration", "0.3"], cwd=grasp_env.ROOT, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    try:
        line = emu.stdout.readline()
        assert line.startswith("PORT "), emu.stderr.read()
        fd = os.open(line.split()[1], os.O_RDWR | os.O_NOCTTY)
        tty.setraw(fd)
        os.write(fd, P.encode(P.HELLO_HOST, 0, P.hello_host()))
        dec, frames, end = P.StreamDecoder(), [], time.monotonic() + 10
        while time.monotonic() < end and not any(f.type == P.POSE for f in frames):
            frames += dec.feed(os.read(fd, 4096))
        hello = P.parse_hello_device([f for f in frames if f.type == P.HELLO_DEVICE][0].payload)
        assert hello.n_fingers == 2
        first = P.parse_pose([f for f in frames if f.type == P.POSE][0].payload)
        for got, want in zip(first.positions, expected):
            assert max(abs(g - w) for g, w in zip(got, want)) < 1e-3, (first.positions, expected)
        os.close(fd)
    finally:
        emu.kill()
        emu.wait()


def test_live_session_with_an_emulated_device(bpy, sample, core):
    """A device in the scene's list drives the fingertips through its workspace frame; the
    panel's status and the HUD show it; finishing detaches it and keeps its events."""
    session = grasp_env.submodule("session")
    scene_devices = grasp_env.submodule("scene_devices")
    box = sample.build(bpy)
    for i in (0, 1):                                   # fingertips without animation: the device has them
        bpy.data.objects[f"Finger {i}"].animation_data_clear()
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--motion", "grip"],
                           cwd=grasp_env.ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = emu.stdout.readline().split()[1]
        bpy.context.scene.cursor.location = (1.0, 2.0, 3.0)          # not where the frame goes
        assert bpy.ops.grasp_lab.device_add(port=port) == {"FINISHED"}
        entry = bpy.context.scene.grasp_lab_devices[0]
        assert entry.frame is not None and entry.finger_offset == 0 and entry.num_fingers == 2
        # The workspace frame on the fingers it drives: at their centre, the emulator's 6 cm rest
        # ring scaled to their spread (engine.placement.workspace_frame)
        tips = np.array([tuple(bpy.data.objects[f"Finger {i}"].matrix_world.translation) for i in (0, 1)])
        centre = tips.mean(axis=0)
        np.testing.assert_allclose(tuple(entry.frame.location), centre, atol=1e-6)
        spread = np.linalg.norm(tips - centre, axis=1).mean()
        np.testing.assert_allclose(tuple(entry.frame.scale), [spread / 0.06] * 3, rtol=1e-6)
        bpy.context.scene.grasp_lab_device_forces = True          # Forces On before the session
        s = session.BlenderSession(bpy.context, live=True, duration=10.0)
        session._active = s          # what the operator does: the panel and operators see it
        try:
            assert s.devices is not None and not s.source.interactive
            wait_until(lambda: list(s.snapshot.contacts) == [0, 0], 60, "both fingertips gripping the box",
                       seen=lambda: s.snapshot.contacts, poll=0.02, each=s.tick)
            # the session started with forces on (the Devices panel's setting)
            lines = wait_until(lambda: (lambda ls: "forces enabled" in ls[0] and ls)(scene_devices.status_lines(
                s.devices)), 60, "the panel's status: forces enabled", seen=lambda: scene_devices.status_lines(
                s.devices), poll=0.02)
            assert lines[0].startswith(f"{port}: streaming, fingers 0..1"), lines
            assert lines[0] in s.hud_text()
            assert bpy.ops.grasp_lab.device_forces(on=False) == {"FINISHED"}     # Forces Off, now
            assert not bpy.context.scene.grasp_lab_device_forces and not s.devices.devices[0].enabled
        finally:
            session._active = None
            s.finish()
        events = [e[2] for e in s.result.stats["device_events"]]
        assert "connected" in events and "enabled" in events, events
        assert not s.devices.devices                  # detached
    finally:
        emu.kill()
        emu.wait()


def test_headless_realtime_run_with_a_device(bpy, sample, core, tmp_path):
    scene_devices = grasp_env.submodule("scene_devices")
    session = grasp_env.submodule("session")
    box = sample.build(bpy)
    for i in (0, 1):
        bpy.data.objects[f"Finger {i}"].animation_data_clear()
    emus = [subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--motion", "grip"],
                             cwd=grasp_env.ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            for _ in range(2)]
    try:
        ports = [e.stdout.readline().split()[1] for e in emus]
        bpy.context.scene.grasp_lab.display_rate = 50.0
        bpy.context.scene.cursor.location = box.matrix_world.translation     # the workspace frame at the box
        bpy.ops.grasp_lab.device_add(port=ports[0])
        bpy.context.scene.grasp_lab.record = True
        bpy.context.scene.grasp_lab.recording_folder = str(tmp_path)
        live = session.run_realtime(bpy.context, 1.5, forces=True)
        rec = grasp_env.submodule("engine.recording").open_recording(live.result.recording)
        dev = [e for e in rec.events if e["kind"].startswith("device_")]   # in the recording too
        # Forces were turned on as the session started, maybe before the device's hello came.
        assert {e["kind"] for e in dev[:2]} == {"device_connected", "device_enabled"} and dev[0]["subject"] == ports[0]
        # At session time, as they came (not the monotonic clock's stamps, not all at the end).
        assert all(0.0 <= e["time"] <= 1.5 for e in dev), [e["time"] for e in dev]
        assert dev[0]["time"] < 1.0, dev
        assert live.result.stats["runtime_haptic_rate"] > 250     # real-time order (benchmarked elsewhere)
        events = [e[2] for e in live.result.stats["device_events"]]
        assert set(events[:2]) == {"connected", "enabled"}, events
        assert list(live.snapshot.contacts) == [0, 0]
        emus[0].terminate()
        out = emus[0].communicate(timeout=20)[0]
        report = json.loads([l for l in out.splitlines() if l.startswith("REPORT ")][0][7:])
        assert report["max_force_n"] > 1.0 and report["violations"] == dict.fromkeys(report["violations"], 0), report

        # A --device spec is added for the session only (after the list's own devices).
        bpy.context.scene.grasp_lab_devices.clear()
        live = session.run_realtime(bpy.context, 0.5, [f"serial:{ports[1]}"])
        assert len(bpy.context.scene.grasp_lab_devices) == 0
        assert [e[2] for e in live.result.stats["device_events"]][:1] == ["connected"]
        with pytest.raises(ValueError, match="unknown kind"):
            session.run_realtime(bpy.context, 0.1, [f"serial:{ports[1]}", "tcp:1234"])
        assert len(bpy.context.scene.grasp_lab_devices) == 0      # nothing added when a spec is wrong
        added = scene_devices.add_device_specs(bpy.context, ["serial:/dev/null@1", "spacemouse"])
        entries = bpy.context.scene.grasp_lab_devices
        # /dev/null says no hello: the free fingers from 1 on; the SpaceMouse takes the free finger 0.
        assert [(e.kind, e.port, e.finger_offset, e.num_fingers) for e in entries] == [
            ("SERIAL", "/dev/null", 1, 1), ("SPACEMOUSE", "", 0, 1)]
        # A glove (five fingers) has none free: refused by its spec, the list left as it was.
        with pytest.raises(ValueError, match="opengloves:/dev/x.*no free finger"):
            scene_devices.add_device_specs(bpy.context, ["opengloves:/dev/x"])
        assert len(entries) == 2
        scene_devices.remove_entries(bpy.context, added)
        assert len(entries) == 0
    finally:
        for e in emus:
            e.kill()
            e.wait()


def test_live_session_with_a_glove_in_the_device_list(bpy, core):
    """A glove (OpenGloves lines over a pty) listed as a device drives five fingertips."""
    from addon.engine.devices import opengloves as G
    session = grasp_env.submodule("session")
    for i in range(5):
        f = bpy.data.objects.new(f"Tip {i}", None)
        bpy.context.scene.collection.objects.link(f)
        f.grasp_lab.role = "FINGER"
        f.grasp_lab.channel = i
        f.location = (0.0, 0.3, 0.1 * i)
    master, slave = os.openpty()
    tty.setraw(master)
    try:
        assert bpy.ops.grasp_lab.device_add(port=os.ttyname(slave), kind="OPENGLOVES") == {"FINISHED"}
        entry = bpy.context.scene.grasp_lab_devices[0]
        assert entry.num_fingers == 5
        entry.frame = None                                   # hand frame = the scene
        s = session.BlenderSession(bpy.context, live=True, duration=120.0)
        try:
            assert not s.devices.failed, s.devices.failed
            os.write(master, b"A4095B2048C0D0E1000\n")
            curls = [1.0, 2048 / 4095, 0.0, 0.0, 1000 / 4095]
            # The tips start up to 45 cm from the glove's: the soft start walks them there at
            # 0.2 m/s (docs/devices.md: 2.4 s of haptic ticks, longer on a busy machine).
            wait_until(lambda: np.allclose(s.snapshot.hips, G.fingertips(curls), atol=1e-9), 60,
                       "the glove's fingertips", seen=lambda: s.snapshot.hips, poll=0.02, each=s.tick)
            assert os.read(master, 4096).endswith(b"A0B0C0D0E0\n")     # forces off: a zero brake line
        finally:
            s.finish()
    finally:
        os.close(master)
        os.close(slave)


def test_run_device_drives_animated_fingers_forces_on_recording_is_the_truth(bpy, sample, core, tmp_path):
    """`grasp-lab run --realtime --device serial:PTY --forces on` on the sample scene, whose
    fingertips are keyframed: the device (the emulator: grip and lift around the origin)
    drives them, not their animation; forces go on headless; every device force the recording
    holds is one the device received; its stop button zeroes them (the recording says so at
    the time it happened); its unplug is on standard error and in the exit code (3) and `info`."""
    import csv
    box = sample.build(bpy)
    for name in ("Box", "Table"):       # the box centred on the device's origin (identity workspace)
        bpy.data.objects[name].location.z -= box.location.z
    assert bpy.data.objects["Finger 0"].animation_data is not None   # the fingertips stay keyframed
    blend, rec, log = tmp_path / "pinch.blend", tmp_path / "run.mcap", tmp_path / "forces.csv"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    # The lift ends 1.5 s into streaming; the button at 2.5 s. The emulator's clock starts at the
    # run's probe (a hello) and again at the session's: the test waits for the button pressed
    # to the streaming session (the emulator says so), then unplugs it (SIGTERM: it reports and
    # closes the pty), however long a busy machine took to get there. The session runs 10 s:
    # 7.5 s after the button for the test to see it and unplug (every window below is found from
    # the recording, not the clock).
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--motion", "lift",
                            "--estop-at", "2.5", "--force-log", str(log),
                            "--wait", "600"],     # for the run's hello: Blender starts slowly on a busy machine
                           cwd=grasp_env.ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    launcher = os.path.join(grasp_env.ROOT, ".venv", "bin", "grasp-lab")
    run = None
    try:
        port = emu.stdout.readline().split()[1]
        run = subprocess.Popen([launcher, "run", str(blend), "--realtime", "--device", f"serial:{port}",
                                "--forces", "on", "--duration", "10.0", "--record", str(rec)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        said = []

        def pressed_to_the_session():
            if select.select([emu.stdout], [], [], 0.1)[0]:
                said.append(emu.stdout.readline())
            return any(line.startswith("ESTOP ") and line.split()[2] == "streaming" for line in said) \
                or run.poll() is not None
        wait_until(pressed_to_the_session, 600, "the emulator's button pressed to the streaming session",
                   seen=lambda: said, poll=0.0)
        assert run.poll() is None, ("the run ended before the button", said, run.communicate())
        emu.terminate()                      # the unplug
        out, err = emu.communicate(timeout=60)
        run_out, run_err = run.communicate(timeout=300)
    finally:
        emu.kill()
        if run is not None:
            run.kill()
            run.wait()
    r = subprocess.CompletedProcess(run.args, run.returncode, run_out, run_err)
    reports = [line for line in out.splitlines() if line.startswith("REPORT ")]
    assert reports, ("the emulator's report", out, err, r.stdout, r.stderr)
    report = json.loads(reports[0][7:])
    # The unplug is said, and the exit code says so.
    assert r.returncode == 3, (r.returncode, r.stdout, r.stderr)
    assert f"fingers: Finger 0, Finger 1: serial device {port}" in r.stdout, r.stdout
    recording = grasp_env.submodule("engine.recording").open_recording(str(rec))
    ticks, events = recording.ticks, recording.events
    t = ticks["time"]
    hip, device_force, spring = ticks["hip"], ticks["device_force"], ticks["force"]
    kinds = {e["kind"]: e for e in events}
    # The losses the recording holds: the unplug last; before it, on a busy machine, maybe a pause
    # of the emulator longer than the 0.1 s lost_timeout (a silence, then recovered). The unplug
    # itself is seen as a hang-up, or first as a silence when the emulator, ending, takes longer
    # than that to write its log and close the pty. The summary says as many as the recording.
    losses = [e for e in events if e["kind"] == "device_lost"]
    assert losses and losses[-1]["value"] in (0, 1), events
    how = "(hang-up)" if losses[-1]["value"] == 1 else "(silence)"
    summary = [line for line in r.stdout.splitlines() if line.startswith(f"device {port}: ")]
    counts = re.search(r"(\d+) frames dropped(?: \([^)]*\))?, (\d+) missing, 1 e-stops, (\d+) losses",
                       summary[0] if summary else "")
    assert counts and int(counts[3]) == len(losses), r.stdout
    # Frames lost on the way: only those the emulator could not write (the pty full while a busy
    # machine kept the host's thread from reading), as its report counts them.
    assert int(counts[1]) + int(counts[2]) <= report["write_errors"], (summary, report["write_errors"])
    assert f"grasp-lab run: device {port} lost at" in r.stderr and f"{how}, not back by the end" in r.stderr, \
        r.stderr
    t_conn, t_estop, t_lost = kinds["device_connected"]["time"], kinds["device_estop"]["time"], losses[-1]["time"]
    assert kinds["device_estop"]["value"] == 1 and kinds["device_enabled"]["value"] == 1, events
    assert t_conn < t_estop < t_lost, events

    # The device drives its fingers: the emulator's lift (radius 3 cm, z up to 5 cm), not the
    # keyframes (whose fingertips stay 4.8 cm out and 2.5 cm above the table until frame 19).
    # The hold (1 s of the emulator's, before its button): the ticks before the e-stop whose
    # HIPs are at the lift's top, as the recording has them.
    before = t < t_estop
    at_top = np.all(np.abs(hip[:, :, 2] - 0.05) < 2e-3, axis=1)
    holding = before & at_top
    assert holding.sum() > 100, (holding.sum(), t[before][-5:], hip[before][-5:])
    np.testing.assert_allclose(np.abs(hip[holding][:, :, 0]), 0.03, atol=2e-3)
    assert recording.ticks["pose"][holding][-1, 0, 2] > 0.02       # and lifted the box (from z = 0) with them

    # Forces reached the device, and the recording holds only forces the device received.
    received = set()
    with open(log) as fh:
        for row in csv.reader(fh):
            v = [float(x) for x in row[3:]]
            received.update(tuple(v[3 * i:3 * i + 3]) for i in range(len(v) // 3))
    nonzero = np.linalg.norm(device_force, axis=2) > 0
    assert nonzero.sum() > 500 and report["max_force_n"] > 1.0, (nonzero.sum(), report)
    missing = [tuple(f) for f in device_force[nonzero] if tuple(f) not in received]
    assert not missing, f"{len(missing)} recorded device forces were never sent, e.g. {missing[:3]}"
    assert np.linalg.norm(device_force - spring, axis=2).max() > 0.1      # not the computed forces
    # The stop button: zero from the e-stop on, in the recording and at the device, at its time.
    after = t >= t_estop
    assert not nonzero[after].any(), t[after][nonzero[after].any(axis=1)][:5]
    assert nonzero[holding].any(), "no device force while the box was held up, before the e-stop"   # on until then
    assert report["forces_after_estop"] == 0 and report["violations"] == dict.fromkeys(report["violations"], 0)
    # The unplug: the fingers let go (no spring force) within 0.25 s.
    released = (t > t_lost + 0.25)
    assert released.any() and np.linalg.norm(spring[released], axis=2).max() < 1e-6
    # Device events at the session time they were observed (not the monotonic clock's stamps, not
    # all at the end): the button was pressed 2.5 s of the emulator's time after the device's
    # hello (the connected event; session time is the haptic loop's, a little behind the wall on
    # a loaded machine, and a busy machine only delays the button); no force is recorded after
    # it. (How close the stamp is to the tick is checked in C, native/tests/test_serial_io.c:
    # here a loaded machine may pause the emulator, and the host's TTL zeroes the record first.)
    last_force = t[nonzero.any(axis=1)][-1]
    assert t_estop - t_conn >= 2.0 and t_lost < t[-1] and last_force <= t_estop, (t_conn, t_estop, last_force)

    info = subprocess.run([launcher, "info", str(rec)], capture_output=True, text=True, timeout=60).stdout
    assert f"Finger 0, Finger 1: serial device {port}" in info, info
    assert f"device      {port} lost at" in info and f"{how}, not back by the end" in info, info
    subprocess.run([launcher, "export", str(rec), "--csv", str(tmp_path / "csv")], check=True, timeout=60,
                   capture_output=True)
    with open(tmp_path / "csv" / "events.csv") as fh:
        times = [float(row["time"]) for row in csv.DictReader(fh)]
    assert times == sorted(times) and len(times) > 3


def test_a_device_with_no_finger_to_drive_is_an_error_naming_it(bpy, sample, core):
    session = grasp_env.submodule("session")
    sample.build(bpy)
    with pytest.raises(ValueError, match=r"--device 'serial:/dev/null@2': finger 2: the scene has fingers 0\.\.1$"):
        session.run_realtime(bpy.context, 0.1, ["serial:/dev/null@2"])
    assert len(bpy.context.scene.grasp_lab_devices) == 0
    assert grasp_env.submodule("session").active_session() is None


def test_run_forces_on_needs_a_device(tmp_path):
    launcher = os.path.join(grasp_env.ROOT, ".venv", "bin", "grasp-lab")
    r = subprocess.run([launcher, "run", str(tmp_path / "none.blend"), "--realtime", "--forces", "on"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 1 and "--forces on needs --device" in r.stderr, (r.returncode, r.stderr)
    r = subprocess.run([launcher, "run", str(tmp_path / "none.blend"), "--forces", "sometimes"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--forces" in r.stderr, (r.returncode, r.stderr)


def test_a_device_that_only_sends_garbage_is_an_error(bpy, sample, core, tmp_path):
    """A port whose device answers the hello with noise: the session runs its time, and run
    says on standard error that the device never sent a valid pose, with what it dropped (exit
    3, as for a device lost: its fingers never followed it)."""
    import threading
    sample.build(bpy)
    blend, rec = tmp_path / "pinch.blend", tmp_path / "run.mcap"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    master, slave = os.openpty()
    tty.setraw(slave)
    port = os.ttyname(slave)
    stop = threading.Event()

    def noise():
        rng = np.random.default_rng(7)
        while not stop.is_set():
            try:
                os.write(master, rng.integers(1, 256, 64, dtype=np.uint8).tobytes() + b"\x00")
                while select.select([master], [], [], 0)[0]:
                    os.read(master, 4096)       # the host's hellos and force frames, unanswered
            except OSError:
                return
            time.sleep(0.005)
    t = threading.Thread(target=noise, daemon=True)
    t.start()
    launcher = os.path.join(grasp_env.ROOT, ".venv", "bin", "grasp-lab")
    try:
        r = subprocess.run([launcher, "run", str(blend), "--realtime", "--device", f"serial:{port}",
                            "--duration", "1.0", "--record", str(rec)], capture_output=True, text=True, timeout=120)
    finally:
        stop.set()
        t.join(5)
        os.close(master)
        os.close(slave)
    assert r.returncode == 3, r.stderr
    line = [s for s in r.stderr.splitlines() if "never sent a valid pose" in s]
    assert len(line) == 1 and line[0].startswith(f"grasp-lab run: device {port}") and "frames dropped" in line[0], r.stderr
    assert int(line[0].split("(")[1].split()[0]) > 0        # the noise was dropped and counted
    assert rec.exists()                                     # the session's recording is finished


def test_a_found_device_brings_its_finger_count_and_its_fingers_follow_it(bpy, sample, core):
    """Find Devices lists the emulator by its hello; + adds it with the hello's finger count on
    the fingers no device drives; in a live session the Finger objects it drives go where it
    has them (not only the HIP markers), and stay there when the session ends."""
    session = grasp_env.submodule("session")
    devices_ui = grasp_env.submodule("devices_ui")
    box = sample.build(bpy)
    extra = bpy.data.objects.new("Finger 2", None)          # a third fingertip: a 3-finger scene
    bpy.context.scene.collection.objects.link(extra)
    extra.location = (0.0, 0.3, 0.2)
    extra.grasp_lab.role = "FINGER"
    extra.grasp_lab.channel = 2
    tips = [bpy.data.objects[f"Finger {i}"] for i in (0, 1)]
    for tip in tips:                                          # the device has them, not their keys
        tip.animation_data_clear()
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--motion", "lift",
                            "--fingers", "2"], cwd=grasp_env.ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
    try:
        port = emu.stdout.readline().split()[1]
        assert bpy.ops.grasp_lab.devices_refresh() == {"FINISHED"}
        found = [d for d in devices_ui._discovered["devices"] if d["port"] == port]
        assert [(d["name"], d["n_fingers"]) for d in found] == [("grasp-lab-emulator", 2)], devices_ui._discovered
        bpy.context.scene.cursor.location = box.matrix_world.translation
        # What the panel's + does: the port and the hello's count.
        assert bpy.ops.grasp_lab.device_add(port=port, fingers=found[0]["n_fingers"]) == {"FINISHED"}
        # Typed in (no count given): the hello is asked for; the device takes the free fingers.
        entries = bpy.context.scene.grasp_lab_devices
        assert [(e.finger_offset, e.num_fingers) for e in entries] == [(0, 2)]
        entries.clear()
        assert bpy.ops.grasp_lab.device_add(port=port) == {"FINISHED"}
        assert [(e.port, e.finger_offset, e.num_fingers) for e in entries] == [(port, 0, 2)]
        start = [tuple(t.matrix_world.translation) for t in tips]
        s = session.BlenderSession(bpy.context, live=True, duration=120.0)
        try:
            # The emulator's lift about the workspace frame on the fingertips (scaled to their
            # spread): 3 cm out, 5 cm up, in device metres (waited for, the session ticking as
            # Blender's timer would).
            frame = np.array(entries[0].frame.matrix_world.translation)
            scale = entries[0].frame.scale.x
            wait_until(lambda: np.allclose(s.snapshot.hips[:2, 2] - frame[2], 0.05 * scale, atol=2e-3), 60,
                       "the lift's top", seen=lambda: s.snapshot.hips, poll=0.02, each=s.tick)
            hips = s.snapshot.hips
            np.testing.assert_allclose(np.abs(hips[:2, 0] - frame[0]), 0.03 * scale, atol=2e-3)
            np.testing.assert_allclose(hips[:2, 2] - frame[2], 0.05 * scale, atol=2e-3)
            for i, tip in enumerate(tips):
                np.testing.assert_allclose(tip.matrix_world.translation, hips[i], atol=1e-6)
            np.testing.assert_allclose(extra.matrix_world.translation, (0.0, 0.3, 0.2))   # no device: stays
        finally:
            s.finish()
        for i, tip in enumerate(tips):          # where the device left them, not where they started
            np.testing.assert_allclose(tip.matrix_world.translation, hips[i], atol=2e-3)
            assert np.linalg.norm(np.array(tip.matrix_world.translation) - start[i]) > 0.02
        # A second device finds no free run of 2: it gets the one free finger, and says so.
        assert bpy.ops.grasp_lab.device_add(port=port, fingers=2) == {"FINISHED"}
        assert [(e.finger_offset, e.num_fingers) for e in entries] == [(0, 2), (2, 1)]
        # None free: added after them all the same (fingers may come later), with a warning.
        assert bpy.ops.grasp_lab.device_add(port=port, fingers=1) == {"FINISHED"}
        assert [(e.finger_offset, e.num_fingers) for e in entries] == [(0, 2), (2, 1), (3, 1)]
    finally:
        emu.kill()
        emu.wait()


def test_a_device_the_scene_declares_without_a_port_waits_for_one(bpy, sample, core):
    """An entry without a port (a scene's declared device) is not connected: its fingers play
    their animation; Find Devices' + and a --device spec give it a port (and fewer fingers when
    the device's hello says fewer); after the run the entry is as the file had it."""
    session = grasp_env.submodule("session")
    scene_devices = grasp_env.submodule("scene_devices")
    sample.build(bpy)
    entries = bpy.context.scene.grasp_lab_devices
    entry = entries.add()
    entry.kind, entry.port, entry.finger_offset, entry.num_fingers = "SERIAL", "", 0, 2
    s = session.BlenderSession(bpy.context, live=True, duration=2.0)
    try:
        assert s.devices is None and s.source.script() is not None      # the animation drives them
    finally:
        s.finish()
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--fingers", "1"],
                           cwd=grasp_env.ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = emu.stdout.readline().split()[1]
        changed = scene_devices.add_device_specs(bpy.context, [f"serial:{port}"])
        assert [(e.port, e.finger_offset, e.num_fingers) for e in entries] == [(port, 0, 1)]   # its hello: 1
        scene_devices.remove_entries(bpy.context, changed)
        assert [(e.port, e.finger_offset, e.num_fingers) for e in entries] == [("", 0, 2)]
        assert bpy.ops.grasp_lab.device_add(port=port, fingers=1) == {"FINISHED"}             # the panel's +
        assert [(e.port, e.finger_offset, e.num_fingers) for e in entries] == [(port, 0, 1)]
    finally:
        emu.kill()
        emu.wait()


def test_emulate_from_a_blend_is_a_blender_command(bpy, sample, tmp_path):
    """`grasp-lab emulate --from SCENE.blend` reads the .blend in Blender (the launcher loads the
    extension, emulate_blend.py plays it); the engine's emulator alone refuses --from, saying where."""
    sample.build(bpy)
    path = str(tmp_path / "pinch.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    launcher = os.path.join(os.path.dirname(sys.executable), "grasp-lab")
    r = subprocess.run([launcher, "emulate", "--pty", "--from", path, "--wait", "0.5"], capture_output=True,
                       text=True, timeout=120)
    ports = [line for line in r.stdout.splitlines() if line.startswith("PORT /dev/")]
    assert r.returncode == 2 and len(ports) == 1 and "no hello from the host" in r.stderr, (r.stdout, r.stderr)
    r = subprocess.run([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--from", path],
                       cwd=grasp_env.ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "reading a .blend needs Blender: grasp-lab emulate --from" in r.stderr, r.stderr
