"""Fault injection, third pass (issue #29; docs/reliability.md): a .blend checked whole before
it replaces the old one, refusals before anything is written (a busy port, a bound address, a
claimed --save), stop signals at every moment of a command (also while Blender loads, also
SIGHUP), analyze/export outputs whole or not at all and naming their file, a sweep that keeps
to its own files, bounded arguments, true last lines, bake of another scene's recording.

Each case drives the real ``grasp-lab`` launcher; moments are found by the process's state
(its signal mask, the libraries it has mapped, the files it has made), never by sleeping."""
import fcntl
import os
import pty
import signal
import socket
import time

import pytest

from test_reliability import Guard, copy, grasp_lab, one_line_error, start
from test_reliability import files, small_disk  # noqa: F401 - pytest fixtures shared with the first suite

from addon.engine import outputs, recording

STOP = {signal.SIGINT: "SIGINT (Ctrl-C)", signal.SIGTERM: "SIGTERM", signal.SIGHUP: "SIGHUP (terminal closed)"}


def wait_for(proc, what, check, seconds=120):
    """Until ``check()`` holds (a state of the process or its files); the process must live."""
    deadline = time.monotonic() + seconds
    while not check():
        if proc.poll() is not None:
            pytest.fail(f"exited ({proc.returncode}) before {what}: {proc.stderr.read()}")
        assert time.monotonic() < deadline, f"no {what} in {seconds} s"
        time.sleep(0.005)


def blocked_signals(pid) -> int:
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("SigBlk:"):
                    return int(line.split()[1], 16)
    except OSError:
        pass
    return 0


def maps_hold(pid, needle) -> bool:
    try:
        with open(f"/proc/{pid}/maps") as fh:
            return needle in fh.read()
    except OSError:
        return False


def _holds_our_mask(pid) -> bool:
    mask = blocked_signals(pid)
    return all(mask & (1 << (s - 1)) for s in STOP)


# ----------------------------------------------------------------- 2/8: signals at any moment

MOMENTS = {
    # the launcher's first line ran: the stop signals are held, nothing imported yet
    "first line": lambda pid, out: _holds_our_mask(pid),
    # Blender's library is being loaded (bpy's shared object mapped, the extension not yet)
    "bpy loading": lambda pid, out: maps_hold(pid, "/bpy/") or maps_hold(pid, "libcycles"),
}


@pytest.mark.parametrize("sig", list(STOP), ids=lambda s: signal.Signals(s).name)
@pytest.mark.parametrize("moment", list(MOMENTS))
def test_a_signal_before_the_session_leaves_the_recording_untouched(files, tmp_path, sig, moment):
    keep = copy(files["rec"], tmp_path / "keep.mcap")
    g = Guard(keep)
    proc = start("run", files["scene"], "--record", keep)
    wait_for(proc, moment, lambda: MOMENTS[moment](proc.pid, keep))
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    lines = [line for line in err.splitlines() if line.strip()]
    assert proc.returncode == 128 + sig and "Traceback" not in err, err
    assert len(lines) == 1 and f"stopped by {STOP[sig]}" in lines[0] and "nothing was written" in lines[0], err
    g.check()
    assert sorted(os.listdir(tmp_path)) == ["keep.mcap"]


def test_sighup_finishes_the_recording(files, tmp_path):
    out = tmp_path / "hup.mcap"
    proc = start("run", files["scene"], "--realtime", "--duration", "600", "--record", out)
    partial = tmp_path / "hup.mcap.partial"
    wait_for(proc, "a recording", lambda: partial.exists() and partial.stat().st_size > 50_000)
    proc.send_signal(signal.SIGHUP)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 129, err
    assert [line for line in err.splitlines() if line.strip()] == [
        f"grasp-lab run: stopped by SIGHUP (terminal closed); finished {out}"], err
    rec = recording.open_recording(out)
    assert rec.damage == [] and rec.end["clean"] is False and rec.end["ended_by"] == "SIGHUP (terminal closed)"
    assert not partial.exists()


# ----------------------------------------------------------------- 3: refuse before writing

def test_a_busy_device_port_leaves_the_recording_it_would_replace(files, tmp_path):
    keep = copy(files["rec"], tmp_path / "keep.mcap")
    g = Guard(keep)
    main, sub = pty.openpty()
    port = os.ttyname(sub)
    held = os.open(port, os.O_RDWR | os.O_NOCTTY)
    fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)        # another program has the port
    try:
        r = grasp_lab("run", files["scene"], "--realtime", "--duration", "2", "--device", f"serial:{port}",
                      "--record", keep)
    finally:
        for fd in (held, sub, main):
            os.close(fd)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert port in r.stderr and "recording:" not in r.stdout, (r.stdout, r.stderr)
    g.check()
    assert os.listdir(tmp_path) == ["keep.mcap"]


def test_a_bound_live_view_port_leaves_the_recording_it_would_replace(files, tmp_path):
    keep = copy(files["rec"], tmp_path / "keep.mcap")
    g = Guard(keep)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        r = grasp_lab("run", files["scene"], "--realtime", "--duration", "2", "--live-view", port,
                      "--record", keep)
    one_line_error(r, 1, f"127.0.0.1:{port}")
    g.check()
    assert os.listdir(tmp_path) == ["keep.mcap"]


def test_two_bakes_to_one_path_the_second_is_refused_before_its_work(files, tmp_path):
    out = tmp_path / "baked.blend"
    long = tmp_path / "long.mcap"
    assert grasp_lab("run", files["scene"], "--duration", "60", "--record", long).returncode == 0
    first = start("bake", long, files["scene"], "--save", out, "--every-tick")
    try:
        # Its claim: the partial file made and locked (made a moment before it is locked)
        wait_for(first, "its claim on --save", lambda: outputs.writer_of(str(tmp_path / "baked.blend.partial")))
        first.send_signal(signal.SIGSTOP)       # held mid-bake, however fast this machine is
        r = grasp_lab("bake", files["rec"], files["scene"], "--save", out)
        line = one_line_error(r, 1, "another Grasp Lab process", f"pid {first.pid}")
        assert "baked" not in r.stdout and "saved" not in r.stdout, (line, r.stdout)
    finally:
        first.send_signal(signal.SIGCONT)
        so, err = first.communicate(timeout=600)
    assert first.returncode == 0 and f"saved: {out}" in so, err
    g = Guard(out)
    g.check(may_write=[out])


# ----------------------------------------------------------------- 1/4/9: whole or not at all

def test_a_blend_cut_short_is_not_renamed_into_place(tmp_path, files):
    old = copy(files["scene"], tmp_path / "scene.blend")
    g = Guard(old)
    out = outputs.AtomicFile(str(old))
    cut = tmp_path / "cut.blend"
    with open(files["scene"], "rb") as fh:
        cut.write_bytes(fh.read()[:300_000])            # what a silently failed write leaves
    with pytest.raises(outputs.OutputError, match=f"{old}: could not be written .*no ENDB block"):
        out.commit(verify=outputs.blend_is_whole, source=str(cut))
    g.check()
    assert sorted(os.listdir(tmp_path)) == ["scene.blend"]


def test_analyze_csv_on_a_full_disk_keeps_the_old_tables(files, small_disk):
    disk = small_disk("400k")
    r = grasp_lab("analyze", files["rec"], "--csv", disk, "--every", "200")
    assert r.returncode == 0, r.stderr
    g = Guard(disk / "grasp.csv", disk / "contacts.csv")
    r = grasp_lab("analyze", files["rec"], "--csv", disk)      # every tick: megabytes
    line = one_line_error(r, 1, "No space left on device", "it is as it was")
    assert str(disk / "grasp.csv") in line or str(disk / "contacts.csv") in line, line
    g.check()
    assert sorted(os.listdir(disk)) == ["contacts.csv", "grasp.csv"]


def test_export_foxglove_onto_a_folder_or_a_full_disk(files, tmp_path, small_disk):
    folder = tmp_path / "a_folder"
    folder.mkdir()
    r = grasp_lab("export", files["rec"], "--foxglove", folder)
    one_line_error(r, 1, str(folder), "is a folder")
    assert os.listdir(folder) == []
    disk = small_disk("48k")
    r = grasp_lab("export", files["rec"], "--foxglove", disk / "view.mcap")
    line = one_line_error(r, 1, str(disk / "view.mcap"), "could not be written", "it is as it was")
    assert "No space left on device" in line or "bytes free there" in line, line
    assert os.listdir(disk) == []


# ----------------------------------------------------------------- 5/7/10: the sweep

def test_a_sweep_refuses_a_folder_with_files_it_did_not_write(files, tmp_path):
    out = tmp_path / "sweep"
    out.mkdir()
    mine = out / "map.png"
    mine.write_bytes(b"the user's own picture")
    g = Guard(mine)
    r = grasp_lab("sweep", files["rec"], "--samples", "2", "--workers", "1", "--no-analysis", "--out", out)
    one_line_error(r, 1, str(out), "map.png", "--force")
    g.check()
    assert os.listdir(out) == ["map.png"]
    # Its own folder it resumes, and --force writes beside the others' files.
    r = grasp_lab("sweep", files["rec"], "--samples", "2", "--workers", "1", "--no-analysis", "--out", out,
                  "--force")
    assert r.returncode == 0, r.stderr
    r = grasp_lab("sweep", files["rec"], "--samples", "3", "--workers", "1", "--no-analysis", "--out", out)
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("args, needles", [
    (("--samples", "2147483648"), ("--samples", "must be in 1 .. 1,000,000")),
    (("--samples", "2", "--workers", "1000"), ("--workers", f"must be in 1 .. {os.cpu_count()}")),
])
def test_sweep_sizes_have_ranges(files, tmp_path, args, needles):
    r = grasp_lab("sweep", files["rec"], "--out", tmp_path / "s", *args)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    for n in needles:
        assert n in r.stderr.strip().splitlines()[-1], r.stderr
    assert os.listdir(tmp_path) == []


def test_a_stopped_sweep_says_what_it_kept(files, tmp_path):
    out = tmp_path / "sweep"
    proc = start("sweep", files["rec"], "--samples", "100000", "--workers", "1", "--no-analysis", "--out", out)
    wait_for(proc, "a sample written", lambda: (out / "samples.csv").exists()
             and (out / "samples.csv").read_text().count("\n") > 2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith("sweep:")]
    assert proc.returncode == 130, err
    assert len(lines) == 1 and "nothing was written" not in lines[0], err
    assert f"{out / 'samples.csv'} (" in lines[0] and "samples)" in lines[0], err


# ----------------------------------------------------------------- 10/11: true words, bake's scene

def test_a_disk_full_run_prints_no_recording_line(files, small_disk):
    disk = small_disk("6m")
    proc = start("run", files["scene"], "--realtime", "--duration", "4", "--record", disk / "new.mcap")
    partial = disk / "new.mcap.partial"
    wait_for(proc, "a recording", lambda: partial.exists() and partial.stat().st_size > 20_000)
    with open(disk / "filler", "wb") as fh:                # everything that is left
        try:
            while True:
                fh.write(b"\0" * 65536)
                fh.flush()
        except OSError:
            pass
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 1 and "No space left on device" in err, err
    assert "recording:" not in out, out          # it was not written: nothing says it was
    assert not (disk / "new.mcap").exists()


def test_bake_refuses_a_recording_of_another_scene(files, tmp_path):
    import bpy
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_cube_add()
    other = tmp_path / "other.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(other))
    g = Guard(other)
    out = tmp_path / "baked.blend"
    r = grasp_lab("bake", files["rec"], other, "--save", out)
    one_line_error(r, 1, "none of its bodies and fingers", "Box", "--force")
    g.check()
    assert not out.exists()
    r = grasp_lab("bake", files["rec"], other, "--save", out, "--force")
    assert r.returncode == 0 and out.exists(), r.stderr


def _chunks(path):
    """(offset, body offset, body length) of each MCAP chunk record of a file."""
    data = open(path, "rb").read()
    pos, out = 8, []
    while pos + 9 <= len(data):
        opcode = data[pos]
        length = int.from_bytes(data[pos + 1:pos + 9], "little")
        if opcode == 0x06:
            out.append((pos, pos + 9, length))
        if opcode == 0x02:      # the footer
            break
        pos += 9 + length
    return out


def test_a_crc_error_skips_its_chunk_and_reads_on(files, tmp_path):
    bad = copy(files["rec"], tmp_path / "bad.mcap")
    chunks = _chunks(bad)
    assert len(chunks) > 6
    whole = recording.open_recording(str(files["rec"]))
    offset, body, _ = chunks[len(chunks) // 2]
    with open(bad, "r+b") as fh:                # the chunk's CRC of its records: one bit off
        fh.seek(body + 24)
        crc = fh.read(4)
        fh.seek(body + 24)
        fh.write(bytes([crc[0] ^ 1]) + crc[1:])
    rec = recording.open_recording(str(bad))
    assert len(rec.damage) == 1 and f"chunk at byte {offset} fails its CRC" in rec.damage[0], rec.damage
    lost = len(whole.ticks) - len(rec.ticks)
    assert 0 < lost < len(whole.ticks) // 4, lost        # one chunk's ticks lost, the rest read
    assert rec.ticks["tick"][-1] == whole.ticks["tick"][-1] and rec.end is not None
    r = grasp_lab("resim", bad)
    assert r.returncode == 0 and r.stdout.strip() != "identical", r.stdout
    assert "damaged" in r.stdout or "diverged" in r.stdout, r.stdout


def test_info_of_a_session_still_being_written_does_not_say_cut_short(files, tmp_path):
    out = tmp_path / "live.mcap"
    proc = start("run", files["scene"], "--realtime", "--duration", "600", "--record", out)
    partial = tmp_path / "live.mcap.partial"
    try:
        wait_for(proc, "a recording", lambda: partial.exists() and partial.stat().st_size > 50_000)
        r = grasp_lab("info", partial)
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
    assert r.returncode == 0, r.stderr
    assert "cut short" not in r.stderr and f"still being written (a Grasp Lab process (pid {proc.pid})" in r.stderr, \
        r.stderr
