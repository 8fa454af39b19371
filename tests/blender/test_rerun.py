"""A session in Rerun (grasp-lab export --rerun, grasp-lab view; docs/viewers.md), read back
with Rerun's own reader (rerun.dataframe, the SDK's recording reader, and the viewer
binary's ``rerun rrd print``), not our writer's code, and checked against the recording's
ticks and ``analysis.analyse_recording``. The real viewer's screenshot is tests/gui's."""
from __future__ import annotations

import io
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

import recordings
from addon.engine import analysis, cli, viewer
from addon.engine.recording import open_recording

try:
    import rerun.dataframe as rd
    from addon.engine import rerun_view
    MISSING = None
except ImportError as ex:       # the bpy 4.2 / 5.0 venvs collect this file but run only -m multiversion
    MISSING = ex

pytestmark = pytest.mark.needs_core


@pytest.fixture(autouse=True)
def _test_dependencies():
    """requirements.txt has rerun-sdk: missing is a failure, not a skip."""
    if MISSING is not None:
        raise MISSING


@pytest.fixture(scope="module")
def pinch(core, tmp_path_factory):
    path = tmp_path_factory.mktemp("rerun") / "pinch.mcap"
    recordings.record_exec(path, core)
    return open_recording(str(path))


@pytest.fixture(scope="module")
def exported(pinch, tmp_path_factory):
    path = tmp_path_factory.mktemp("rerun_copy") / "pinch.rrd"
    done = rerun_view.export_rerun(pinch, str(path))
    return str(path), done


@pytest.fixture(scope="module")
def closure(core, tmp_path_factory):
    """Three fingers on a box in force closure (test_analysis's grasp), and its Rerun copy."""
    from test_analysis import HALF, R, SQUEEZE, X, box_scene, record
    folder = tmp_path_factory.mktemp("rerun_three")
    hips = [(X, 0.015, 0), (-(HALF + R - 2 * SQUEEZE), 0, 0), (X, -0.015, 0)]
    rec = record(folder / "three.mcap", box_scene(hips), lambda t: hips, 1.0)
    rrd = folder / "three.rrd"
    rerun_view.export_rerun(rec, str(rrd))
    return rec, str(rrd)


def load(path):
    archive = rd.load_archive(path)
    assert archive.num_recordings() == 1
    return archive.all_recordings()[0]


def column(recording, entity: str, component: str, index: str = "session_time"):
    """(times or ticks, values) of one component of one entity, a row per logged time: times in
    s (session_time) or ticks (tick); values as numpy rows (None where a row is empty)."""
    table = recording.view(index=index, contents=entity).select().read_all()
    name = f"{entity}:{component}"
    assert name in table.column_names, (name, table.column_names)
    idx = table.column(index)
    times = (np.array([v.value for v in idx]) / 1e9 if index == "session_time"
             else np.array(idx.to_pylist(), dtype=np.int64))
    values = [None if v is None else np.array(v, dtype=np.float64) for v in table.column(name).to_pylist()]
    return times, values


def static(recording, entity: str, component: str) -> np.ndarray:
    """A component logged once (static), as numbers."""
    table = recording.view(index="session_time", contents=entity).select_static().read_all()
    return np.array(table.column(f"{entity}:{component}").to_pylist()[0], dtype=np.float64)


def entity_paths(recording) -> set:
    return {c.entity_path for c in recording.schema().component_columns()}


def part(name):
    return rerun_view.part(name)


# --------------------------------------------------------------------------- the copy

def test_entity_paths_and_timelines(pinch, exported):
    path, done = exported
    rec = load(path)
    assert rec.application_id() == "grasp_lab"
    paths = entity_paths(rec)
    expected = {"/world", "/events"}
    for b in pinch.body_names:
        expected |= {f"/world/bodies/{part(b)}", f"/world/bodies/{part(b)}/part_0"}
    for f in pinch.finger_names:
        base = f"/world/fingers/{part(f)}"
        expected |= {f"{base}/god_object", f"{base}/hip", f"{base}/spring", f"{base}/force",
                     f"/plots/finger_force/{part(f)}/normal", f"/plots/finger_force/{part(f)}/tangential",
                     f"/plots/friction_use/{part(f)}"}
    expected |= {"/world/residual/Box/force", "/world/residual/Box/torque", "/world/weakest/Box/force",
                 "/world/weakest/Box/torque", "/plots/grip/Box/grip", "/plots/grip/Box/load",
                 "/plots/grip_load/Box", "/plots/closure/Box/closure", "/plots/closure/Box/epsilon",
                 "/plots/slip_margin/Box"}
    assert expected <= paths, sorted(expected - paths)
    assert not any("Table" in p for p in paths if p.startswith(("/world/residual", "/plots"))), "static body plotted"
    indexes = {c.name for c in rec.schema().index_columns()}
    assert {"session_time", "tick"} <= indexes
    assert done["frames"] == 181 and done["rate"] == 30.0 and done["events"] == len(pinch.events)


def test_body_transforms_are_the_ticks(pinch, exported):
    """Each body's Transform3D at every frame is the pose of the tick that frame shows."""
    rec = load(exported[0])
    model = viewer.SceneModel(pinch.header)
    times = model.frame_times(pinch)
    for i, name in enumerate(pinch.body_names):
        entity = f"/world/bodies/{part(name)}"
        t, translation = column(rec, entity, "Translation3D")
        _, rotation = column(rec, entity, "RotationQuat")
        np.testing.assert_allclose(t, times, atol=1e-9)
        pose = pinch.ticks["pose"][pinch.sample(times), i]
        np.testing.assert_allclose(np.concatenate(translation), pose[:, :3], atol=1e-6, rtol=0)
        np.testing.assert_allclose(np.concatenate(rotation), pose[:, [4, 5, 6, 3]], atol=1e-6, rtol=0)
    # The box moves (lifted): the check is not one pose repeated.
    box = pinch.ticks["pose"][pinch.sample(times), pinch.body_names.index("Box"), 2]
    assert np.ptp(box) > 0.01


def test_body_meshes_are_the_convex_parts(pinch, exported):
    rec = load(exported[0])
    for i, name in enumerate(pinch.body_names):
        points = static(rec, f"/world/bodies/{part(name)}/part_0", "Position3D").reshape(-1, 3)
        parts = np.asarray(pinch.header["scene"]["bodies"][i]["parts"][0]).reshape(-1, 3)
        # every vertex is a point of the part, and every corner of the part is a vertex
        d = np.linalg.norm(points[:, None] - parts[None], axis=2)
        assert d.min(axis=1).max() < 1e-6 and d.min(axis=0).max() < 1e-6


def test_fingers_are_the_ticks(pinch, exported):
    """God-objects and HIPs where the ticks put them, with the finger's radius; springs
    coloured by stick/slip; the finger's push arrow ending at the god-object."""
    rec = load(exported[0])
    model = viewer.SceneModel(pinch.header)
    times = model.frame_times(pinch)
    ticks = pinch.ticks[pinch.sample(times)]
    for j, name in enumerate(pinch.finger_names):
        base = f"/world/fingers/{part(name)}"
        _, go = column(rec, f"{base}/god_object", "Position3D")
        np.testing.assert_allclose(np.concatenate(go), ticks["god_object"][:, j], atol=1e-6, rtol=0)
        _, hip = column(rec, f"{base}/hip", "Position3D")
        np.testing.assert_allclose(np.concatenate(hip), ticks["hip"][:, j], atol=1e-6, rtol=0)
        radius = static(rec, f"{base}/god_object", "Radius")
        assert radius[0] == pytest.approx(pinch.header["scene"]["fingers"][j]["radius"], rel=1e-6)
        _, colors = column(rec, f"{base}/spring", "Color")
        packed = np.array([int(c[0]) for c in colors])
        want = np.array([int.from_bytes(bytes(round(255 * c) for c in viewer.STATE_COLORS[s]), "big")
                         for s in ticks["state"][:, j]])
        np.testing.assert_array_equal(packed, want)
        assert set(ticks["state"][:, j]) >= {0, 1}      # free and sticking frames both checked
        t, origins = column(rec, f"{base}/force", "Position3D")
        _, vectors = column(rec, f"{base}/force", "Vector3D")
        k = np.searchsorted(times, t)
        shown = [n for n, v in enumerate(vectors) if v is not None and len(v)]
        assert len(shown) > 50
        for n in shown:
            head = origins[n].reshape(3) + vectors[n].reshape(3)
            np.testing.assert_allclose(head, ticks["god_object"][k[n], j], atol=1e-6)
            np.testing.assert_allclose(vectors[n].reshape(3), -ticks["force"][k[n], j] * viewer.FORCE_SCALE,
                                       atol=1e-6)


def test_finger_force_plots_are_analyze_numbers(closure):
    """Each finger's normal and tangential force and friction use, and the body's closure,
    epsilon, load and slip margin, are grasp-lab analyze's numbers at the ticks the frames show."""
    rec, rrd = closure
    recording = load(rrd)
    model = viewer.SceneModel(rec.header)
    times = model.frame_times(rec)
    rows = rec.sample(times)
    table = analysis.analyse_recording(rec, rows=np.unique(rows))
    checked = 0
    for j, name in enumerate(rec.finger_names):
        t, normal = column(recording, f"/plots/finger_force/{part(name)}/normal", "Scalar")
        _, tangential = column(recording, f"/plots/finger_force/{part(name)}/tangential", "Scalar")
        _, use = column(recording, f"/plots/friction_use/{part(name)}", "Scalar")
        np.testing.assert_allclose(t, times, atol=1e-9)
        for n, r in enumerate(rows):
            sets = np.flatnonzero(table.snapshot == int(r))
            contacts = [c for s in sets for c in range(table.first[s], table.first[s] + table.count[s])
                        if table.finger[c] == j]
            if not contacts:
                assert normal[n][0] == 0.0
                continue
            c = contacts[0]
            assert normal[n][0] == pytest.approx(abs(table.fn[c]), rel=1e-12, abs=1e-12)
            assert tangential[n][0] == pytest.approx(table.ft[c], rel=1e-12, abs=1e-12)
            assert use[n][0] == pytest.approx(table.friction_use[c], rel=1e-12, abs=1e-12)
            checked += 1
    assert checked > 60
    _, closed = column(recording, "/plots/closure/Box/closure", "Scalar")
    _, eps = column(recording, "/plots/closure/Box/epsilon", "Scalar")
    _, load_ = column(recording, "/plots/grip/Box/load", "Scalar")
    _, margin = column(recording, "/plots/slip_margin/Box", "Scalar")
    in_closure = 0
    for n, r in enumerate(rows):
        sets = np.flatnonzero((table.snapshot == int(r)) & (table.body == 0))
        if not len(sets):
            assert closed[n][0] == 0.0
            continue
        s = sets[0]
        assert closed[n][0] == float(table.quality["force_closure"][s])
        assert eps[n][0] == pytest.approx(table.quality["epsilon"][s], rel=1e-12, abs=1e-15)
        assert load_[n][0] == pytest.approx(table.load_force[s], rel=1e-12)
        assert margin[n][0] == pytest.approx(table.min_slip_margin[s], rel=1e-12, abs=1e-15)
        in_closure += int(table.quality["force_closure"][s])
    assert in_closure > 10
    # The weakest-wrench arrows while in closure, none out of it.
    _, vectors = column(recording, "/world/weakest/Box/force", "Vector3D")
    drawn = np.array([v is not None and len(v) > 0 for v in vectors])
    np.testing.assert_array_equal(drawn, np.array([c[0] for c in closed]) == 1.0)


def test_a_convex_finger_is_its_hull_at_its_god_pose(core, tmp_path):
    """A palm (a convex finger, test_area_analysis's plate on a palm): its hull logged once,
    in its own frame, under a transform at the god-object turned by the recorded orientation."""
    from test_area_analysis import K, PALM, PLATE_H, PLATE_HALF, PLATE_M, _body, _mesh, _record
    from addon.engine import scene
    d = scene.SceneDesc()
    _body(d, "Plate", (PLATE_HALF, PLATE_HALF, PLATE_H), (0, 0, PLATE_H), PLATE_M)
    d.fingers.append(scene.FingerDesc("Palm", np.array([0.0, 0.0, -PALM[2]]), 0.0, K, 2.0, 0,
                                      points=_mesh(PALM, "Palm").vertices))
    rec = _record(tmp_path / "plate.mcap", scene.prepare(d), lambda t: [[0.0, 0.0, -PALM[2]]], 0.6)
    rrd = tmp_path / "palm.rrd"
    rerun_view.export_rerun(rec, str(rrd))
    recording = load(str(rrd))
    base = "/world/fingers/Palm/god_pose"
    hull = static(recording, f"{base}/hull", "Position3D").reshape(-1, 3)
    corners = np.asarray(_mesh(PALM, "Palm").vertices)
    d = np.linalg.norm(hull[:, None] - corners[None], axis=2)
    assert d.min(axis=1).max() < 1e-6 and d.min(axis=0).max() < 1e-6
    times = viewer.SceneModel(rec.header).frame_times(rec)
    ticks = rec.ticks[rec.sample(times)]
    _, translation = column(recording, base, "Translation3D")
    _, rotation = column(recording, base, "RotationQuat")
    np.testing.assert_allclose(np.concatenate(translation), ticks["god_object"][:, 0], atol=1e-6)
    np.testing.assert_allclose(np.concatenate(rotation), ticks["orientation"][:, 0][:, [1, 2, 3, 0]], atol=1e-6)
    assert "/world/fingers/Palm/god_object" not in entity_paths(recording)


def test_every_tick(closure, tmp_path):
    rec, _ = closure
    path = tmp_path / "every.rrd"
    done = rerun_view.export_rerun(rec, str(path), every_tick=True)
    assert done["frames"] == len(rec.ticks) and done["rate"] == rec.haptic_rate
    t, translation = column(load(str(path)), "/world/bodies/Box", "Translation3D", index="tick")
    np.testing.assert_array_equal(t, rec.ticks["tick"])
    np.testing.assert_allclose(np.concatenate(translation), rec.ticks["pose"][:, 0, :3], atol=1e-6, rtol=0)


def test_events_are_a_text_log(pinch, exported):
    rec = load(exported[0])
    # by log_tick: events of one tick are rows of one session_time, which the view would merge
    table = rec.view(index="log_tick", contents="/events").select().read_all()
    texts = [v[0] for v in table.column("/events:Text").to_pylist() if v]
    levels = [v[0] for v in table.column("/events:TextLogLevel").to_pylist() if v]
    assert len(texts) == len(pinch.events)
    for e in pinch.events:
        k = texts.index(" ".join(x for x in (e["kind"], e.get("subject", ""), e.get("detail", "")) if x))
        assert levels[k] == ("WARN" if e["kind"] == "slip" else "INFO")


def test_the_file_has_its_blueprint(exported):
    """The layout is in the file, as Rerun's own command line lists it."""
    binary = rerun_view.viewer_binary()
    printed = subprocess.run([binary, "rrd", "print", "-vvv", exported[0]], capture_output=True, text=True,
                             timeout=120)
    assert printed.returncode == 0, printed.stderr
    text = printed.stdout
    assert "kind: Blueprint" in text and "kind: Recording" in text
    for title in [t for _, t in rerun_view.PLOTS] + ["Grasp", "Events"]:
        assert title in text, title
    assert text.count("TimeSeries") == len(rerun_view.PLOTS)


# --------------------------------------------------------------------------- the commands

def test_cli_export_rerun(pinch, tmp_path):
    out, err = io.StringIO(), io.StringIO()
    path = tmp_path / "copy.rrd"
    assert cli.main(["export", pinch.path, "--rerun", str(path)], out=out, err=err) == 0, err.getvalue()
    assert f"{path}: 181 frames at 30 Hz, 8 events" in out.getvalue()
    assert not (tmp_path / "copy.rrd.partial").exists()
    assert load(str(path)).recording_id()
    # --every-tick is --rerun's
    err = io.StringIO()
    assert cli.main(["export", pinch.path, "--csv", str(tmp_path / "c"), "--every-tick"], out=io.StringIO(),
                    err=err) == 1
    assert "--every-tick goes with --rerun" in err.getvalue()
    # the recording itself is refused, untouched
    before = open(pinch.path, "rb").read()
    err = io.StringIO()
    assert cli.main(["export", pinch.path, "--rerun", pinch.path], out=io.StringIO(), err=err) == 1
    assert "refusing to write over an input" in err.getvalue()
    assert open(pinch.path, "rb").read() == before
    # a folder that is not there: exit 1 naming it
    err = io.StringIO()
    assert cli.main(["export", pinch.path, "--rerun", str(tmp_path / "missing" / "x.rrd")], out=io.StringIO(),
                    err=err) == 1
    assert "missing" in err.getvalue()


def test_cli_exports_what_a_damaged_recording_kept(pinch, tmp_path):
    """A recording cut short: export and view say so and write what the reader recovered."""
    data = open(pinch.path, "rb").read()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) // 2])
    kept = open_recording(str(cut))
    assert kept.damage and 0 < len(kept.ticks) < len(pinch.ticks)
    out, err = io.StringIO(), io.StringIO()
    path = tmp_path / "cut.rrd"
    assert cli.main(["export", str(cut), "--rerun", str(path)], out=out, err=err) == 0, err.getvalue()
    assert "warning" in err.getvalue() and str(cut) in err.getvalue()
    frames = int(np.floor(kept.ticks["time"][-1] * 30 + 1e-9)) + 1
    assert f"{frames} frames" in out.getvalue()
    t, translation = column(load(str(path)), "/world/bodies/Box", "Translation3D")
    assert len(t) == frames
    box = kept.body_names.index("Box")
    np.testing.assert_allclose(np.concatenate(translation), kept.ticks["pose"][kept.sample(t), box, :3], atol=1e-6)


def test_view_caches_the_copy_by_fingerprint(pinch, tmp_path):
    """view converts once; the same recording again uses the copy; a recording re-made at the
    same path gets a new copy and the old one goes."""
    rec = tmp_path / "rec.mcap"
    shutil.copy(pinch.path, rec)
    first = rerun_view.view_recording(str(rec), screenshot=None, warn=None, launch=False)
    assert first["converted"] and os.path.exists(first["rrd"])
    assert os.path.dirname(first["rrd"]) == str(tmp_path)
    again = rerun_view.view_recording(str(rec), launch=False)
    assert not again["converted"] and again["rrd"] == first["rrd"]
    data = open(pinch.path, "rb").read()
    rec.write_bytes(data[:len(data) * 3 // 4])        # another recording at the same path
    third = rerun_view.view_recording(str(rec), launch=False)
    assert third["converted"] and third["rrd"] != first["rrd"]
    assert not os.path.exists(first["rrd"])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["rec.mcap", os.path.basename(third["rrd"])])


def test_commands_without_the_sdk_say_what_to_install(pinch, tmp_path, monkeypatch):
    for name in [n for n in sys.modules if n == "rerun" or n.startswith("rerun.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "rerun", None)      # import rerun -> ImportError
    for argv in (["view", pinch.path], ["export", pinch.path, "--rerun", str(tmp_path / "x.rrd")]):
        err = io.StringIO()
        assert cli.main(argv, out=io.StringIO(), err=err) == 1
        lines = err.getvalue().strip().splitlines()
        assert len(lines) == 1 and "pip install rerun-sdk==" in lines[0], lines
    assert list(tmp_path.iterdir()) == []
    assert not any(n.endswith(".rrd") for n in os.listdir(os.path.dirname(pinch.path)))


# --------------------------------------------------------------------------- live

def free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(check, deadline: float, what: str):
    """``check()``'s first true answer, looking until ``deadline`` seconds have passed."""
    import time
    end = time.monotonic() + deadline
    while True:
        answer = check()
        if answer:
            return answer
        if time.monotonic() > end:
            raise AssertionError(f"{what}: not within {deadline:g} s")
        time.sleep(0.2)


def received_frames(path):
    """The Box's transforms a Rerun receiver has written so far (None while unreadable)."""
    try:
        return column(load(str(path)), "/world/bodies/Box", "Translation3D")
    except Exception:       # the receiver is still writing its first chunk
        return None


def test_cli_realtime_live_view_rerun(bpy, sample, tmp_path):
    """`grasp-lab run --realtime --live-view rerun:PORT` streams the session to a Rerun
    receiver (the viewer binary, saving what it receives): every display update arrives, with
    the bodies where the session's own recording has them at those times."""
    import socket
    sample.build(bpy)
    blend = tmp_path / "pinch.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    port = free_port()
    received = tmp_path / "live.rrd"
    receiver = subprocess.Popen([rerun_view.viewer_binary(), "--bind", "127.0.0.1", "--port", str(port),
                                 "--save", str(received)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        def listening():
            with socket.socket() as s:
                return s.connect_ex(("127.0.0.1", port)) == 0
        wait_for(listening, 60, "the Rerun receiver listening")
        launcher = os.path.join(recordings.ROOT, ".venv", "bin", "grasp-lab")
        rec = tmp_path / "live.mcap"
        run = subprocess.run([launcher, "run", str(blend), "--realtime", "--duration", "3", "--record", str(rec),
                              "--live-view", f"rerun:{port}"], capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, run.stdout + run.stderr
        assert f"live view: rerun+http://127.0.0.1:{port}/proxy" in run.stdout
        import re
        updates = int(re.search(r"live view: (\d+) updates", run.stdout).group(1))
        assert updates >= 10, run.stdout
        times, translation = wait_for(lambda: (lambda r: r if r and len(r[0]) == updates else None)(
            received_frames(received)), 120, f"{updates} frames received")
    finally:
        receiver.terminate()
        receiver.wait(timeout=60)
    recording = load(str(received))
    paths = entity_paths(recording)
    assert {"/world/fingers/Finger\\ 0/god_object", "/plots/finger_force/Finger\\ 0/normal",
            "/plots/closure/Box/closure", "/world/bodies/Box/part_0"} <= paths, sorted(paths)
    recorded = open_recording(str(rec))
    box = recorded.body_names.index("Box")
    np.testing.assert_allclose(np.concatenate(translation), recorded.ticks["pose"][recorded.sample(times), box, :3],
                               atol=1e-6)


# --------------------------------------------------------------------------- Blender

def test_open_in_rerun_operator(bpy, pinch, tmp_path, monkeypatch):
    """The Recording panel's Open in Rerun: the same copy as `grasp-lab view` (beside the
    recording), the viewer started as a separate process that Blender does not wait for.
    Without a display the viewer gives up by itself (after the operator has returned)."""
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    rec = tmp_path / "rec.mcap"
    shutil.copy(pinch.path, rec)
    started = []
    real_popen = subprocess.Popen

    def watch(*args, **kwargs):         # the real Popen; the test only keeps the process to wait for it
        proc = real_popen(*args, **kwargs)
        started.append(proc)
        return proc
    monkeypatch.setattr(rerun_view.subprocess, "Popen", watch)
    assert bpy.ops.grasp_lab.open_in_rerun(filepath=str(rec)) == {"FINISHED"}
    copies = [p for p in tmp_path.iterdir() if p.suffix == ".rrd"]
    assert len(copies) == 1 and load(str(copies[0])).application_id() == "grasp_lab"
    assert len(started) == 1 and started[0].args[0] == rerun_view.viewer_binary()
    assert started[0].args[-1] == str(copies[0])
    assert started[0].wait(timeout=120) != 0          # no display: it ends by itself
    # Without the SDK: cancelled, saying what to install.
    monkeypatch.setitem(sys.modules, "rerun", None)
    for name in [n for n in sys.modules if n.startswith("rerun.")]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.raises(RuntimeError, match="pip install rerun-sdk=="):
        bpy.ops.grasp_lab.open_in_rerun(filepath=str(rec))


def test_the_session_panels_live_view_in_rerun(bpy, sample, core, tmp_path):
    """The Session panel's Live View set to Rerun: a live Blender session streamed to the Rerun
    viewer on this machine at the panel's port (start_live_view, shared with the command line),
    every display update received; the HUD names the address."""
    import grasp_env
    import socket
    session = grasp_env.submodule("session")
    sample.build(bpy)
    s = bpy.context.scene.grasp_lab
    assert (s.live_view_viewer, s.live_view_rerun_port) == ("FOXGLOVE", 9876)
    assert session.live_view_target(s) == s.live_view_port
    s.live_view_viewer = "RERUN"
    s.live_view_rerun_port = free_port()
    assert session.live_view_target(s) == f"rerun:127.0.0.1:{s.live_view_rerun_port}"
    received = tmp_path / "panel.rrd"
    receiver = subprocess.Popen([rerun_view.viewer_binary(), "--bind", "127.0.0.1", "--port",
                                 str(s.live_view_rerun_port), "--save", str(received)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        def listening():
            with socket.socket() as sock:
                return sock.connect_ex(("127.0.0.1", s.live_view_rerun_port)) == 0
        wait_for(listening, 60, "the Rerun receiver listening")
        live = session.BlenderSession(bpy.context, live=True, duration=2.0)
        try:
            lv = session.start_live_view(live, session.live_view_target(s), s.live_view_bind)
            import time
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < 1.0:
                live.tick(time.perf_counter() - t0)
                time.sleep(0.03)
            assert lv.address in live.hud_text()
        finally:
            result = live.finish()
        stats = result.stats["live_view"]
        assert stats["updates"] >= 5 and stats["error"] == "", stats
        wait_for(lambda: (lambda r: r is not None and len(r[0]) == stats["updates"])(received_frames(received)),
                 120, f"{stats['updates']} frames received")
    finally:
        receiver.terminate()
        receiver.wait(timeout=60)


@pytest.mark.parametrize("spec, url", [("rerun", "rerun+http://127.0.0.1:9876/proxy"),
                                       ("rerun:9000", "rerun+http://127.0.0.1:9000/proxy"),
                                       ("rerun:10.0.0.5:9001", "rerun+http://10.0.0.5:9001/proxy")])
def test_live_view_addresses(spec, url):
    assert rerun_view.live_url(spec) == url


@pytest.mark.parametrize("spec", ["rerun:abc", "rerun:0", "rerun:70000", "rerun:host:"])
def test_live_view_bad_addresses_are_usage_errors(spec, tmp_path, capsys):
    assert cli.main(["run", str(tmp_path / "x.blend"), "--realtime", "--live-view", spec], out=io.StringIO(),
                    err=io.StringIO()) == 2
    assert f"--live-view {spec}" in capsys.readouterr().err       # argparse's own usage error
