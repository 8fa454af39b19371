"""Viewer channels (grasp-lab export --foxglove, docs/viewers.md), read back independently:
the ``mcap`` reader and Foxglove's published protobuf schemas (foxglove-schemas-protobuf),
not the SDK that wrote them, checked against the recording's tick data; the hull meshes
against scipy's."""
from __future__ import annotations

import io
import json
import os
import sys

import numpy as np
import pytest

import recordings
from addon.engine import cli, viewer
from addon.engine.recording import open_recording

try:
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from foxglove_schemas_protobuf.Log_pb2 import Log
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from google.protobuf import descriptor_pb2
    from mcap.reader import make_reader
    from scipy.spatial import ConvexHull
    from scipy.spatial.transform import Rotation
    MISSING = None
except ImportError as ex:       # the bpy 4.2 / 5.0 venvs collect this file but run only -m multiversion
    MISSING = ex

pytestmark = pytest.mark.needs_core


@pytest.fixture(autouse=True)
def _test_dependencies():
    """requirements.txt has them: missing is a failure, not a skip."""
    if MISSING is not None:
        raise MISSING
PROTOBUF = {} if MISSING else {"foxglove.SceneUpdate": SceneUpdate, "foxglove.FrameTransforms": FrameTransforms,
                                "foxglove.Log": Log}
STICK, SLIP = 1, 2


@pytest.fixture(scope="module")
def pinch(core, tmp_path_factory):
    path = tmp_path_factory.mktemp("viewer") / "pinch.mcap"
    recordings.record_exec(path, core)
    return open_recording(str(path))


def read_back(path):
    """{topic: [(log_time_s, decoded)]} in file order, and the schemas and channels."""
    out, schemas, channels = {}, {}, {}
    last = -1
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert message.log_time >= last, "messages not in log-time order"
            last = message.log_time
            schemas[schema.name] = schema
            channels[channel.topic] = (channel, schema)
            if channel.message_encoding == "protobuf":
                decoded = PROTOBUF[schema.name].FromString(message.data)
            else:
                assert channel.message_encoding == "json"
                decoded = json.loads(message.data)
            out.setdefault(channel.topic, []).append((message.log_time / 1e9, decoded))
    return out, schemas, channels


def xyz(v):
    return np.array([v.x, v.y, v.z])


def arrow_vector(arrow):
    """Tail and vector of a foxglove.ArrowPrimitive: +x of its pose, shaft + head long."""
    q = arrow.pose.orientation
    d = Rotation.from_quat([q.x, q.y, q.z, q.w]).apply([1.0, 0.0, 0.0])
    return xyz(arrow.pose.position), d * (arrow.shaft_length + arrow.head_length)


def friction_use(rec, tick):
    mu = [b["mu_s"] for b in rec.header["scene"]["bodies"]]
    out = []
    for f, n, c in zip(tick["force"], tick["normal"], tick["contact"]):
        fn = f @ n
        ft = np.linalg.norm(f - fn * n)
        out.append(ft / (mu[c] * abs(fn)) if c >= 0 and abs(fn) > 1e-12 else 0.0)
    return out


# --------------------------------------------------------------------------- hull

def hull_volume(tris):
    return float(np.einsum("ij,ij->i", tris[:, 0], np.cross(tris[:, 1], tris[:, 2])).sum() / 6.0)


@pytest.mark.parametrize("kind", ["gaussian", "sphere_1024", "cube_with_face_points", "thin_slab"])
def test_hull_meshes_match_scipy(kind):
    rng = np.random.default_rng(7)
    if kind == "gaussian":
        pts = rng.normal(size=(300, 3))
    elif kind == "sphere_1024":
        v = rng.normal(size=(1024, 3))
        pts = 0.05 * v / np.linalg.norm(v, axis=1)[:, None]
    elif kind == "cube_with_face_points":      # coplanar points on every face, and inside
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        face = rng.uniform(-1, 1, size=(60, 3))
        face[np.arange(60), rng.integers(0, 3, 60)] = rng.choice([-1.0, 1.0], 60)
        pts = np.concatenate([face, corners, rng.uniform(-0.9, 0.9, size=(40, 3))])
    else:
        pts = rng.uniform(-1, 1, size=(200, 3)) * [0.1, 0.05, 0.001]
    tris = viewer.hull_triangles(pts)
    ref = ConvexHull(pts)
    assert hull_volume(tris) == pytest.approx(ref.volume, rel=1e-9)
    # Outward and convex: every point on the inner side of every triangle's plane.
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    side = np.einsum("tj,ptj->pt", n, pts[:, None, :] - tris[None, :, 0])
    assert side.max() <= 1e-9 * np.ptp(pts)
    # Closed: every edge used once each way.
    edges = [tuple(map(tuple, (t[a], t[b]))) for t in tris for a, b in ((0, 1), (1, 2), (2, 0))]
    assert sorted(edges) == sorted((b, a) for a, b in edges)
    assert set(map(tuple, tris.reshape(-1, 3))) <= set(map(tuple, pts))


@pytest.mark.parametrize("pts, what", [
    (np.zeros((3, 3)), "at least 4"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 3, 0]], float), "no volume"),
    (np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]], float), "no volume"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.nan]]), "finite")])
def test_hull_refuses_points_without_volume(pts, what):
    with pytest.raises(ValueError, match=what):
        viewer.hull_triangles(pts)


# --------------------------------------------------------------------------- the copy, read back

@pytest.fixture(scope="module")
def exported(pinch, tmp_path_factory):
    path = tmp_path_factory.mktemp("viewer") / "pinch_foxglove.mcap"
    done = viewer.export_foxglove(pinch, str(path))
    return path, done, read_back(path)


def test_channels_use_the_published_schemas(exported):
    path, done, (topics, schemas, channels) = exported
    for name in ("foxglove.SceneUpdate", "foxglove.FrameTransforms", "foxglove.Log"):
        assert schemas[name].encoding == "protobuf"
        fds = descriptor_pb2.FileDescriptorSet.FromString(schemas[name].data)
        names = {f"{f.package}.{m.name}" for f in fds.file for m in f.message_type}
        assert name in names
    assert channels[viewer.TOPIC_SCENE][1].name == "foxglove.SceneUpdate"
    assert channels[viewer.TOPIC_BODIES][1].name == "foxglove.SceneUpdate"
    assert channels[viewer.TOPIC_TRANSFORMS][1].name == "foxglove.FrameTransforms"
    assert channels[viewer.TOPIC_LOG][1].name == "foxglove.Log"
    for topic in ("/grasp_lab/finger/Finger_0", "/grasp_lab/finger/Finger_1", "/grasp_lab/body/Box",
                  "/grasp_lab/body/Table"):
        channel, schema = channels[topic]
        assert schema.encoding == "jsonschema"
        props = set(json.loads(schema.data)["properties"])
        if topic == "/grasp_lab/body/Table":        # static: never analysed
            props -= set(viewer.GRASP_IDLE) | {"slip_finger_name"}
        for _, msg in topics[topic]:
            assert set(msg) == props


def test_display_rate_frames(pinch, exported):
    path, done, (topics, _, _) = exported
    rate = pinch.header["rates"]["display_hz"]
    times = np.array([t for t, _ in topics[viewer.TOPIC_SCENE]])
    expected = np.arange(0, int(np.floor(pinch.ticks["time"][-1] * rate + 1e-9)) + 1) / rate
    assert done["frames"] == len(expected)
    np.testing.assert_allclose(times, expected, atol=1e-9)
    for topic in (viewer.TOPIC_TRANSFORMS, "/grasp_lab/finger/Finger_0", "/grasp_lab/body/Box"):
        np.testing.assert_allclose([t for t, _ in topics[topic]], expected, atol=1e-9)
    # Body meshes: at the start and once a second.
    np.testing.assert_allclose([t for t, _ in topics[viewer.TOPIC_BODIES]],
                               expected[np.r_[0, np.flatnonzero(np.diff(np.floor(expected + 1e-9)))  + 1]],
                               atol=1e-9)


def test_body_frames_are_the_recorded_poses(pinch, exported):
    _, _, (topics, _, _) = exported
    rng = np.random.default_rng(1)
    msgs = topics[viewer.TOPIC_TRANSFORMS]
    for k in sorted(rng.choice(len(msgs), 25, replace=False)):
        t, m = msgs[k]
        tick = pinch.ticks[pinch.sample([t])[0]]
        assert tick["time"] <= t + 1e-9 < tick["time"] + 1e-3 + 1e-9
        assert [tf.child_frame_id for tf in m.transforms] == pinch.body_names
        for tf, pose in zip(m.transforms, tick["pose"]):
            assert tf.parent_frame_id == "world"
            assert tf.timestamp.seconds + tf.timestamp.nanos * 1e-9 == pytest.approx(t, abs=1e-9)
            np.testing.assert_array_equal(xyz(tf.translation), pose[:3])
            np.testing.assert_array_equal([tf.rotation.w, tf.rotation.x, tf.rotation.y, tf.rotation.z], pose[3:])


def test_body_meshes_are_the_convex_parts(pinch, exported):
    _, _, (topics, _, _) = exported
    S = recordings.sample_module()
    _, first = topics[viewer.TOPIC_BODIES][0]
    by_id = {e.id: e for e in first.entities}
    assert set(by_id) == {"body/Box", "body/Table"}
    for e, name in ((by_id["body/Box"], "Box"), (by_id["body/Table"], "Table")):
        assert e.frame_id == name and e.frame_locked
        part = np.array(pinch.header["scene"]["bodies"][pinch.body_names.index(name)]["parts"][0])
        tris = np.array([[p.x, p.y, p.z] for p in e.triangles[0].points]).reshape(-1, 3, 3)
        assert hull_volume(tris) == pytest.approx(ConvexHull(part).volume, rel=1e-12)
    assert hull_volume(np.array([[p.x, p.y, p.z] for p in by_id["body/Box"].triangles[0].points])
                       .reshape(-1, 3, 3)) == pytest.approx(S.BOX_SIZE ** 3, rel=1e-12)


def check_scene(rec, t, m, scale=viewer.FORCE_SCALE, torque_scale=viewer.TORQUE_SCALE):
    """One SceneUpdate against the tick the session showed at ``t``; returns the states seen."""
    tick = rec.ticks[rec.sample([t])[0]]
    by_id = {e.id: e for e in m.entities}
    radii = [f["radius"] for f in rec.header["scene"]["fingers"]]
    states = []
    for j, name in enumerate(rec.finger_names):
        e = by_id[f"finger/{name}"]
        assert e.frame_id == "world"
        go_sphere, hip_sphere = e.spheres
        np.testing.assert_array_equal(xyz(go_sphere.pose.position), tick["god_object"][j])
        assert go_sphere.size.x == pytest.approx(2 * max(radii[j], viewer.MIN_GO_RADIUS))
        np.testing.assert_array_equal(xyz(hip_sphere.pose.position), tick["hip"][j])
        spring = e.lines[0]
        np.testing.assert_array_equal([xyz(p) for p in spring.points], [tick["hip"][j], tick["god_object"][j]])
        state = int(tick["state"][j])
        states.append(state)
        color = (spring.color.r, spring.color.g, spring.color.b)
        if state == STICK:
            assert color[1] > max(color[0], color[2])       # green
        elif state == SLIP:
            assert color[0] > max(color[1], color[2])       # orange-red
        else:
            assert color[0] == color[1] == color[2]         # grey
        f = tick["force"][j]
        if np.linalg.norm(f) * scale > 1e-6:
            (tail, vec), = [arrow_vector(a) for a in e.arrows]
            np.testing.assert_allclose(vec, -f * scale, rtol=1e-6, atol=1e-9)
            np.testing.assert_allclose(tail + vec, tick["god_object"][j], atol=1e-9)   # pushes at the god-object
        else:
            assert len(e.arrows) == 0
    for i, name in enumerate(rec.body_names):
        if rec.header["scene"]["bodies"][i]["static"]:
            assert f"residual/{name}" not in by_id
            continue
        pose = tick["pose"][i]
        com_local = rec.header["scene"]["bodies"][i]["center_of_mass"]
        com = pose[:3] + Rotation.from_quat([*pose[4:], pose[3]]).apply(com_local)
        arrows = [arrow_vector(a) for a in by_id[f"residual/{name}"].arrows]
        expected = [v for v in (tick["wrench"][i, :3] * scale, tick["wrench"][i, 3:] * torque_scale)
                    if np.linalg.norm(v) > 1e-6]
        assert len(arrows) == len(expected)
        for (tail, vec), want in zip(arrows, expected):
            np.testing.assert_allclose(tail, com, atol=1e-12)
            np.testing.assert_allclose(vec, want, rtol=1e-6, atol=1e-9)
    return states


def test_scene_shows_the_recorded_grasp(pinch, exported):
    _, _, (topics, _, _) = exported
    seen = set()
    for t, m in topics[viewer.TOPIC_SCENE]:
        seen.update(check_scene(pinch, t, m))
    assert {0, STICK} <= seen


def test_slip_frames_at_the_haptic_rate(pinch, tmp_path):
    """Every tick a frame (rate = haptic rate) around the slip: the springs turn orange."""
    path = tmp_path / "fine.mcap"
    viewer.export_foxglove(pinch, str(path), rate=pinch.haptic_rate)
    topics, _, _ = read_back(path)
    slipping = set(pinch.ticks["time"][(pinch.ticks["state"] == SLIP).any(axis=1)].round(9))
    assert slipping
    seen = set()
    for t, m in topics[viewer.TOPIC_SCENE]:
        if round(t, 9) in slipping or np.random.default_rng(int(t * 1e3)).random() < 0.02:
            seen.update(check_scene(pinch, t, m))
    assert SLIP in seen


def test_plot_channels_are_the_tick_numbers(pinch, exported):
    _, _, (topics, _, _) = exported
    mu = {b["name"]: b["mu_s"] for b in pinch.header["scene"]["bodies"]}
    assert mu
    for j, name in enumerate(pinch.finger_names):
        for t, msg in topics[f"/grasp_lab/finger/{name.replace(' ', '_')}"][::7]:
            tick = pinch.ticks[pinch.sample([t])[0]]
            f = tick["force"][j]
            assert msg["time"] == pytest.approx(t, abs=1e-9)
            assert [msg["force"][k] for k in "xyz"] == list(f)
            assert msg["force_norm"] == pytest.approx(np.linalg.norm(f), rel=1e-12)
            assert msg["normal_force"] == pytest.approx(abs(f @ tick["normal"][j]), rel=1e-9, abs=1e-12)
            assert msg["friction_use"] == pytest.approx(friction_use(pinch, tick)[j], rel=1e-9, abs=1e-12)
            assert msg["state"] == tick["state"][j]
            c = tick["contact"][j]
            assert msg["contact"] == (pinch.body_names[c] if c >= 0 else "")
    box = pinch.body_names.index("Box")
    grips = []
    for t, msg in topics["/grasp_lab/body/Box"]:
        tick = pinch.ticks[pinch.sample([t])[0]]
        on = tick["contact"] == box
        grip = sum(abs(tick["force"][j] @ tick["normal"][j]) for j in np.flatnonzero(on))
        assert msg["grip"] == pytest.approx(grip, rel=1e-9, abs=1e-12)
        assert msg["fingers_in_contact"] == on.sum()
        assert msg["residual_force"] == pytest.approx(np.linalg.norm(tick["wrench"][box, :3]), rel=1e-12)
        assert [msg["position"][k] for k in "xyz"] == list(tick["pose"][box, :3])
        grips.append(grip)
    assert max(grips) > 0.5          # the pinch squeezes


def check_grasp_channels(rec, topics) -> tuple:
    """Per body closure, epsilon, resisted force, slip margin and its finger, grip/load and the
    weakest-wrench arrows of a copy, decoded with the published schemas, against
    analysis.analyse_recording (with volume and mu_min) at the ticks its frames show.
    Returns (frames held, frames in closure) of the box."""
    from addon.engine import analysis
    box = rec.body_names.index("Box")
    body_msgs = topics["/grasp_lab/body/Box"]
    rows = rec.sample(np.array([t for t, _ in body_msgs]))
    table = analysis.analyse_recording(rec, rows=np.unique(rows))
    grasps = {(int(table.snapshot[k]), int(table.body[k])): g for k, g in enumerate(analysis.body_grasps(table))}
    scenes = dict(topics[viewer.TOPIC_SCENE])
    closed = held = 0
    for (t, msg), row in zip(body_msgs, rows):
        g = grasps.get((int(row), box))
        arrows = [arrow_vector(a) for a in {e.id: e for e in scenes[t].entities}["weakest/Box"].arrows]
        if g is None:
            assert (msg["held"], msg["closure"], msg["epsilon"], msg["slip_finger"], msg["mu_min"]) == \
                (0, 0, 0, -1, analysis.NONE)
            assert arrows == []
            continue
        held += 1
        assert msg["held"] == 1
        assert msg["closure"] == float(g.force_closure)
        assert msg["epsilon"] == pytest.approx(g.epsilon, rel=1e-9, abs=1e-12)
        assert msg["resisted_force"] == pytest.approx(g.resisted_force, rel=1e-9, abs=1e-12)
        assert msg["slip_margin"] == pytest.approx(g.min_slip_margin, rel=1e-9, abs=1e-12)
        assert msg["mu_min"] == pytest.approx(g.mu_min if np.isfinite(g.mu_min) else analysis.NONE, rel=1e-9)
        assert msg["slip_finger"] == g.min_slip_finger
        assert msg["slip_finger_name"] == (rec.finger_names[g.min_slip_finger] if g.min_slip_finger >= 0 else "")
        want = g.grip_ratio if np.isfinite(g.grip_ratio) else analysis.NONE
        assert msg["grip_load"] == pytest.approx(want, rel=1e-9, abs=1e-12)
        if not g.force_closure:
            assert arrows == []
            continue
        closed += 1
        # As the viewport draws it: from the centre of mass, twice the torque radius per unit.
        expected = [v for v in (2 * g.radius * g.weakest[:3], 2 * g.radius * g.weakest[3:])
                    if np.linalg.norm(v) > 1e-6]
        assert len(arrows) == len(expected) >= 1
        for (tail, vec), v in zip(arrows, expected):
            np.testing.assert_allclose(tail, g.center, atol=1e-12)
            np.testing.assert_allclose(vec, v, rtol=1e-6, atol=1e-9)
    return held, closed


def test_grasp_channels_of_a_pinch(pinch, exported):
    """Two point fingers never close a grasp (nothing resists a turn about the line joining
    them): the box is held, never in closure, no weakest-wrench arrow."""
    _, _, (topics, _, _) = exported
    held, closed = check_grasp_channels(pinch, topics)
    assert held > 10 and closed == 0


def test_grasp_channels_of_a_grasp_in_closure(tmp_path):
    """Three fingers on a box (test_analysis's grasp in force closure): closure 1, epsilon and
    the weakest wrench's arrows as the analysis gives them."""
    from test_analysis import HALF, R, SQUEEZE, X, box_scene, record
    hips = [(X, 0.015, 0), (-(HALF + R - 2 * SQUEEZE), 0, 0), (X, -0.015, 0)]
    rec = record(tmp_path / "three.mcap", box_scene(hips), lambda t: hips, 1.0)
    viewer.export_foxglove(rec, str(tmp_path / "three_foxglove.mcap"))
    topics, _, _ = read_back(tmp_path / "three_foxglove.mcap")
    held, closed = check_grasp_channels(rec, topics)
    assert closed > 10, (held, closed)
    mu_min = [msg["mu_min"] for _, msg in topics["/grasp_lab/body/Box"] if msg["closure"]]
    assert 0 < min(mu_min) and max(mu_min) < 0.8      # closes below the box's mu_s
    # The live view's path: one snapshot's BodyGrasp list (the display update's analysis) gives
    # the same numbers and arrows as the copy's table.
    from addon.engine import analysis
    model = viewer.SceneModel(rec.header)
    row = len(rec.ticks) // 2
    table = analysis.analyse_recording(rec, rows=[row], volume=False)
    live = viewer.grasp_arrays_of(analysis.body_grasps(table), len(rec.body_names))
    copy = model.grasp_numbers(rec, np.array([row]))
    assert live["closure"][0, 0] == 1 and set(live) == set(copy)
    for name in copy:
        np.testing.assert_array_equal(live[name], copy[name], err_msg=name)


def test_events_are_logs(pinch, exported):
    _, done, (topics, _, _) = exported
    logs = topics[viewer.TOPIC_LOG]
    assert len(logs) == len(pinch.events) == done["events"]
    for e in sorted(pinch.events, key=lambda e: e["time"]):
        match = [m for t, m in logs if m.message.startswith(f"{e['kind']} {e['subject']}")
                 and abs(m.timestamp.seconds + m.timestamp.nanos * 1e-9 - e["time"]) < 1e-9]
        assert match, e
        expected_level = Log.WARNING if e["kind"] == "slip" else Log.INFO
        assert match[0].level == expected_level


def panels(node):
    if node.get("type") == "panel":
        yield node
    for item in node.get("items", []):
        yield from panels(item["content"])


def test_layout_shows_what_the_copy_has(exported):
    path, done, (topics, _, _) = exported
    with open(done["layout"]) as fh:
        text = fh.read()
    docs = os.path.join(recordings.ROOT, "docs", "foxglove", "grasp_lab_layout.json")
    with open(docs) as fh:
        assert fh.read() == text, "docs/foxglove/grasp_lab_layout.json is not the sample scene's layout"
    layout = json.loads(text)
    found = {p["panelType"]: p for p in panels(layout["content"])}
    assert set(found) == {"ThreeDee", "Plot", "StateTransitions", "Log"}
    assert set(found["ThreeDee"]["config"]["topics"]) == {viewer.TOPIC_SCENE, viewer.TOPIC_BODIES}
    assert found["Log"]["config"]["topicToRender"] == viewer.TOPIC_LOG
    series = [s["value"] for p in panels(layout["content"]) if p["panelType"] in ("Plot", "StateTransitions")
              for s in p["config"]["paths"]]
    # forces (Fn, Ft) and use per finger, Box grip and residual, Box closure and epsilon, states
    assert len(series) == 2 * 2 + 2 + 2 + 2 + 2
    for value in series:
        topic, field = value.split(".", 1)
        assert topic in topics, value
        assert all(field in msg for _, msg in topics[topic]), value
    for name in ("Finger 0", "Finger 1"):
        assert any(name in s.get("label", "") for p in panels(layout["content"]) if p["panelType"] == "Plot"
                   for s in p["config"]["paths"])


# --------------------------------------------------------------------------- the command

def test_cli_export_foxglove(pinch, tmp_path):
    out, err = io.StringIO(), io.StringIO()
    path = tmp_path / "copy.mcap"
    assert cli.main(["export", pinch.path, "--foxglove", str(path)], out=out, err=err) == 0, err.getvalue()
    assert f"{path}: 181 frames at 30 Hz, 8 events" in out.getvalue()
    assert f"layout {tmp_path / 'copy.layout.json'}" in out.getvalue()
    assert not (tmp_path / "copy.mcap.partial").exists()
    topics, _, _ = read_back(path)
    assert len(topics[viewer.TOPIC_SCENE]) == 181
    # A folder that is not there: exit 1, naming it; nothing left behind.
    bad = tmp_path / "missing" / "copy.mcap"
    err = io.StringIO()
    assert cli.main(["export", pinch.path, "--foxglove", str(bad)], out=io.StringIO(), err=err) == 1
    assert "missing" in err.getvalue()


def test_cli_refuses_to_overwrite_the_recording(pinch, tmp_path):
    import shutil
    rec = tmp_path / "rec.mcap"
    shutil.copy(pinch.path, rec)
    before = rec.read_bytes()
    err = io.StringIO()
    assert cli.main(["export", str(rec), "--foxglove", str(tmp_path / "." / "rec.mcap")], out=io.StringIO(),
                    err=err) == 1
    assert "refusing to write over an input" in err.getvalue() and str(rec) in err.getvalue()
    assert rec.read_bytes() == before


def test_cli_exports_what_a_cut_recording_kept(pinch, tmp_path):
    """A recording cut short (a killed session): the copy has what the reader recovered, and
    the command warns as the other commands do."""
    data = open(pinch.path, "rb").read()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) // 2])
    kept = open_recording(str(cut))
    assert kept.damage and 0 < len(kept.ticks) < len(pinch.ticks)
    out, err = io.StringIO(), io.StringIO()
    path = tmp_path / "copy.mcap"
    assert cli.main(["export", str(cut), "--foxglove", str(path)], out=out, err=err) == 0
    assert "warning" in err.getvalue()
    topics, _, _ = read_back(path)
    times = [t for t, _ in topics[viewer.TOPIC_SCENE]]
    assert len(times) == int(np.floor(kept.ticks["time"][-1] * 30 + 1e-9)) + 1
    for t, m in topics[viewer.TOPIC_SCENE][::10]:
        check_scene(kept, t, m)


def test_cli_without_the_sdk_says_what_to_install(pinch, tmp_path, monkeypatch):
    for name in [n for n in sys.modules if n == "foxglove" or n.startswith("foxglove.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "foxglove", None)      # import foxglove -> ImportError
    err = io.StringIO()
    assert cli.main(["export", pinch.path, "--foxglove", str(tmp_path / "x.mcap")], out=io.StringIO(),
                    err=err) == 1
    assert "foxglove-sdk" in err.getvalue()
    assert not (tmp_path / "x.mcap").exists()
    # The other exports do not need it.
    assert cli.main(["export", pinch.path, "--npz", str(tmp_path / "x.npz")], out=io.StringIO(),
                    err=io.StringIO()) == 0
