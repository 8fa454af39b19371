"""The live view (grasp-lab run --realtime --live-view, docs/viewers.md): a plain WebSocket
client (the ``websockets`` package, speaking Foxglove's published WebSocket protocol by
hand) connects, reads the advertised channels, subscribes, and decodes what arrives with
Foxglove's published protobuf schemas; the messages are checked against the snapshots the
session showed. Viewers come and go; requests a watching-only server does not take are
refused."""
from __future__ import annotations

import itertools
import json
import os
import re
import struct
import subprocess
import threading
import time

import numpy as np
import pytest

import grasp_env
from waiting import wait_until
import recordings
from addon.engine import analysis, viewer
from addon.engine.recording import open_recording
from addon.engine.runner import Snapshot

from addon.engine.live_view import LiveView

try:
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from websockets.exceptions import WebSocketException
    from websockets.sync.client import connect
    MISSING = None
except ImportError as ex:       # the bpy 4.2 / 5.0 venvs collect this file but run only -m multiversion
    MISSING = ex

pytestmark = pytest.mark.needs_core


@pytest.fixture(autouse=True)
def _test_dependencies():
    """requirements.txt has them: missing is a failure, not a skip."""
    if MISSING is not None:
        raise MISSING
SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01
LAUNCHER = os.path.join(grasp_env.ROOT, ".venv", "bin", "grasp-lab")


class Viewer:
    """A Foxglove WebSocket client: server info, advertised channels, subscriptions, messages."""

    def __init__(self, address):
        self.ws = connect(address, subprotocols=[SUBPROTOCOL], open_timeout=10)
        assert self.ws.subprotocol == SUBPROTOCOL
        self.info = json.loads(self.ws.recv(timeout=10))
        assert self.info["op"] == "serverInfo"
        self.channels = {}
        self.status = []
        self.messages = []          # (topic, log_time ns, payload bytes, received wall s)
        self._subs = {}

    def read(self, seconds, until=None):
        end = time.time() + seconds
        while time.time() < end and not (until and until()):
            try:
                m = self.ws.recv(timeout=max(0.01, end - time.time()))
            except TimeoutError:
                break
            if isinstance(m, bytes):
                op, sub, log_time = struct.unpack_from("<BIQ", m)
                assert op == MESSAGE_DATA
                self.messages.append((self._subs[sub], log_time, m[13:], time.time()))
                continue
            msg = json.loads(m)
            if msg["op"] == "advertise":
                self.channels.update({c["id"]: c for c in msg["channels"]})
            elif msg["op"] == "status":
                self.status.append(msg)

    def subscribe_all(self):
        subs = [{"id": 100 + cid, "channelId": cid} for cid in self.channels]
        self._subs.update({100 + cid: self.channels[cid]["topic"] for cid in self.channels})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def topics(self):
        return {c["topic"]: c for c in self.channels.values()}

    def of(self, topic):
        return [(t, data) for name, t, data, _ in self.messages if name == topic]

    def close(self):
        self.ws.close()


@pytest.fixture(scope="module")
def pinch(core, tmp_path_factory):
    path = tmp_path_factory.mktemp("live") / "pinch.mcap"
    recordings.record_exec(path, core, seconds=3.0)
    return open_recording(str(path))


def snapshots(rec, every=33):
    for k in range(0, len(rec.ticks), every):
        t = rec.ticks[k]
        yield Snapshot(float(t["time"]), t["pose"].copy(), t["pose"][:, :3].copy(), t["wrench"][:, :3].copy(),
                       t["wrench"][:, 3:].copy(), t["hip"].copy(), t["god_object"].copy(), t["force"].copy(),
                       t["state"].copy(), t["contact"].copy(), t["force"].copy(), t["normal"].copy(),
                       t["velocity"].copy())


def test_a_viewer_receives_the_advertised_channels_as_the_session_runs(pinch):
    lv = LiveView(pinch.header, port=0)
    try:
        assert lv.address.startswith("ws://127.0.0.1:")        # this machine only, unless told
        v = Viewer(lv.address)
        # Offered only so that such requests reach the listener, which refuses and counts them.
        assert sorted(v.info["capabilities"]) == ["clientPublish", "parameters", "parametersSubscribe"]
        v.read(30, until=lambda: len(v.channels) >= 8)
        topics = v.topics()
        expected = {viewer.TOPIC_SCENE: "foxglove.SceneUpdate", viewer.TOPIC_BODIES: "foxglove.SceneUpdate",
                    viewer.TOPIC_TRANSFORMS: "foxglove.FrameTransforms", viewer.TOPIC_LOG: "foxglove.Log",
                    "/grasp_lab/finger/Finger_0": "grasp_lab.FingerNumbers",
                    "/grasp_lab/finger/Finger_1": "grasp_lab.FingerNumbers",
                    "/grasp_lab/body/Box": "grasp_lab.BodyNumbers", "/grasp_lab/body/Table": "grasp_lab.BodyNumbers"}
        assert {t: c["schemaName"] for t, c in topics.items()} == expected
        v.subscribe_all()
        v.read(0.3)
        shown, analysed = {}, {}
        models = analysis.body_models(pinch.header["scene"])
        radii = [f["radius"] for f in pinch.header["scene"]["fingers"]]
        for snap in snapshots(pinch):
            shown[round(snap.time, 9)] = snap
            # As the session does: the display update's analysis handed over with its snapshot.
            grasps = analysis.analyse(models, snap.poses, snap.god_objects, snap.spring_forces, snap.normals,
                                      snap.finger_states, snap.contacts, radii, volume=False)
            analysed[round(snap.time, 9)] = grasps
            lv.offer(snap, grasps)
            v.read(1 / 30)
        v.read(30, until=lambda: not lv.pending and len(v.of(viewer.TOPIC_SCENE)) >= lv.updates)
        v.read(0.5)         # the last one may have been on its way when the offers ran out
        scenes = v.of(viewer.TOPIC_SCENE)
        assert len(scenes) >= 0.8 * len(shown) and len(scenes) == lv.updates
        # Each message is one snapshot the session showed, all of it.
        fingers = v.of("/grasp_lab/finger/Finger_0")
        assert len(fingers) == len(scenes)
        for (t_scene, scene_data), (t_tf, tf_data), (t_f, f_data) in zip(
                scenes, v.of(viewer.TOPIC_TRANSFORMS), fingers):
            assert t_scene == t_tf == t_f
            numbers = json.loads(f_data)
            snap = shown[round(numbers["time"], 9)]
            assert [numbers["force"][k] for k in "xyz"] == list(snap.finger_forces[0])
            # Snapshots carry the contact normals: the numbers that need them, recomputed here.
            f, n = snap.spring_forces[0], snap.normals[0]
            fn = f @ n
            assert numbers["normal_force"] == pytest.approx(abs(fn), rel=1e-9, abs=1e-12)
            assert numbers["tangential_force"] == pytest.approx(np.linalg.norm(f - fn * n), rel=1e-9, abs=1e-9)
            if snap.contacts[0] >= 0 and abs(fn) > 1e-9:
                mu = pinch.header["scene"]["bodies"][snap.contacts[0]]["mu_" + ("d" if snap.finger_states[0] == 2
                                                                                 else "s")]
                assert numbers["friction_use"] == pytest.approx(np.linalg.norm(f - fn * n) / (mu * abs(fn)),
                                                                rel=1e-9)
            tf = FrameTransforms.FromString(tf_data)
            for frame, pose in zip(tf.transforms, snap.poses):
                assert [frame.translation.x, frame.translation.y, frame.translation.z] == list(pose[:3])
                assert [frame.rotation.w, frame.rotation.x, frame.rotation.y, frame.rotation.z] == list(pose[3:])
            scene = {e.id: e for e in SceneUpdate.FromString(scene_data).entities}
            go = scene["finger/Finger 1"].spheres[0].pose.position
            assert [go.x, go.y, go.z] == list(snap.god_objects[1])
        # The body numbers are the analysis handed over, not one made again.
        box = pinch.body_names.index("Box")
        held = 0
        for _, data in v.of("/grasp_lab/body/Box"):
            numbers = json.loads(data)
            g = [g for g in analysed[round(numbers["time"], 9)] if g.body == box]
            if not g:
                assert numbers["held"] == 0 and numbers["slip_finger"] == -1
                continue
            held += 1
            g, = g
            assert (numbers["held"], numbers["closure"]) == (1, float(g.force_closure))
            assert numbers["epsilon"] == g.epsilon and numbers["resisted_force"] == g.resisted_force
            assert numbers["mu_min"] == (g.mu_min if np.isfinite(g.mu_min) else analysis.NONE)
            assert numbers["slip_margin"] == g.min_slip_margin and numbers["slip_finger"] == g.min_slip_finger
            assert numbers["grip_load"] == (g.grip_ratio if np.isfinite(g.grip_ratio) else analysis.NONE)
        assert held > 5
        assert lv.error == ""
        v.close()
    finally:
        lv.close()


def test_viewers_come_and_go_and_cannot_publish(pinch):
    lv = LiveView(pinch.header, port=0)
    feeding = threading.Event()

    def feed():             # the session goes on (round and round) until the test ends
        for snap in itertools.cycle(list(snapshots(pinch, every=10))):
            if feeding.is_set():
                return
            lv.offer(snap)
            time.sleep(1 / 60)
    th = threading.Thread(target=feed)
    th.start()
    try:
        first = Viewer(lv.address)
        first.read(30, until=lambda: len(first.channels) >= 8)
        first.subscribe_all()
        first.read(30, until=lambda: len(first.of(viewer.TOPIC_SCENE)) > 0)
        n_first = len(first.of(viewer.TOPIC_SCENE))
        assert n_first > 0
        # It tries to publish, read and set parameters: each refused with an error status and
        # counted, nothing new advertised, nothing answered.
        first.ws.send(json.dumps({"op": "advertise", "channels": [
            {"id": 1, "topic": "/grasp_lab/scene", "encoding": "json", "schemaName": "x"}]}))
        first.ws.send(struct.pack("<BI", 0x01, 1) + b'{"mu_s": 0}')     # clientMessageData on it
        first.ws.send(json.dumps({"op": "getParameters", "parameterNames": ["mu_s"], "id": "g"}))
        first.ws.send(json.dumps({"op": "setParameters", "parameters": [{"name": "mu_s", "value": 0.0}],
                                  "id": "s"}))
        first.ws.send(json.dumps({"op": "subscribeParameterUpdates", "parameterNames": ["mu_s"]}))
        first.read(30, until=lambda: len(first.status) >= 5)
        assert len(first.status) == 5 and all(s["level"] == 2 for s in first.status)
        assert all("watching only" in s["message"] for s in first.status)
        assert any("publishing on '/grasp_lab/scene'" in s["message"] for s in first.status)
        assert any("setting parameters" in s["message"] for s in first.status)
        assert dict(lv.viewers.refused) == {"publish": 1, "message": 1, "get_parameters": 1, "set_parameters": 1,
                                            "subscribe_parameters": 1}
        assert "5 requests refused" in lv.status()
        assert len(first.channels) == 8                 # its channel was not advertised to anyone
        first.ws.close()                                # leaves mid-session
        updates = lv.updates
        second = Viewer(lv.address)                     # a new viewer joins
        second.read(30, until=lambda: len(second.channels) >= 8)
        assert len(second.channels) == 8
        second.subscribe_all()
        second.read(30, until=lambda: lv.updates > updates and second.of(viewer.TOPIC_SCENE)
                    and second.of(viewer.TOPIC_BODIES))
        assert lv.updates > updates
        assert len(second.of(viewer.TOPIC_SCENE)) > 0
        assert len(second.of(viewer.TOPIC_BODIES)) > 0          # the meshes, sent again for the newcomer
        second.close()
        assert lv.error == ""
    finally:
        feeding.set()
        th.join()
        lv.close()


def test_a_bind_address_that_cannot_be_served_is_named(pinch):
    with pytest.raises(OSError, match="203.0.113.7"):
        LiveView(pinch.header, port=0, bind="203.0.113.7")     # TEST-NET-3: not this machine's


@pytest.fixture()
def blend(bpy, sample, tmp_path):
    sample.build(bpy)
    path = tmp_path / "pinch.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def test_a_live_blender_session_with_the_panels_live_view(bpy, sample, core):
    """The session panel's Live View settings and start_live_view (shared with the command
    line): a threaded live session served while the display updates run, its address and
    updates in the HUD, the server closed when the session finishes."""
    session = grasp_env.submodule("session")
    sample.build(bpy)
    s = bpy.context.scene.grasp_lab
    assert (s.live_view, s.live_view_port, s.live_view_bind) == (False, 8765, "127.0.0.1")
    s.live_view_port = 0
    live = session.BlenderSession(bpy.context, live=True, duration=2.0)
    try:
        lv = session.start_live_view(live, s.live_view_port, s.live_view_bind)
        v = Viewer(lv.address)
        v.read(30, until=lambda: len(v.channels) >= 8)
        v.subscribe_all()
        v.read(0.2)
        t0 = time.perf_counter()

        def display_update(_):          # as Blender's timer would, the viewer reading meanwhile
            live.tick(time.perf_counter() - t0)
            v.read(0.03)
        wait_until(lambda: lv.updates >= 5, 60, "5 display updates offered to the live view",
                   seen=lambda: lv.updates, poll=0.0, each=display_update)
        v.read(30, until=lambda: len(v.of(viewer.TOPIC_SCENE)) >= lv.updates)
        assert lv.address in live.hud_text() and f"{lv.updates} updates" in live.hud_text()
        scenes = v.of(viewer.TOPIC_SCENE)
        assert len(scenes) >= 5
        shown = SceneUpdate.FromString(scenes[-1][1])
        go = {e.id: e for e in shown.entities}["finger/Finger 0"].spheres[0].pose.position
        assert [go.x, go.y, go.z] == pytest.approx(list(live.snapshot.god_objects[0]), abs=0.05)
        v.close()
    finally:
        result = live.finish()
    assert result.stats["live_view"]["updates"] > 0 and result.stats["live_view"]["error"] == ""
    with pytest.raises((OSError, WebSocketException)):    # closed with the session
        Viewer(lv.address)


def served_address(proc) -> str:
    """The live view's address, as `grasp-lab run --live-view` prints it (this machine only)."""
    lines = []
    while True:
        line = proc.stdout.readline()
        assert line, f"no address printed: {lines} {proc.stderr.read()}"
        lines.append(line)
        m = re.search(r"live view: (ws://127\.0\.0\.1:\d+)", line)
        if m:
            return m.group(1)


def test_cli_realtime_live_view(blend, tmp_path):
    """`grasp-lab run --realtime --live-view 0`: the address printed, a viewer receives the
    advertised channels at the display rate while the session runs, the session ends as usual."""
    proc = subprocess.Popen([LAUNCHER, "run", str(blend), "--realtime", "--duration", "4", "--live-view", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        v = Viewer(served_address(proc))
        v.read(30, until=lambda: len(v.channels) >= 8)
        assert set(v.topics()) >= {viewer.TOPIC_SCENE, viewer.TOPIC_TRANSFORMS, viewer.TOPIC_BODIES,
                                   viewer.TOPIC_LOG, "/grasp_lab/finger/Finger_0", "/grasp_lab/body/Box"}
        v.subscribe_all()
        v.read(30, until=lambda: len(v.of(viewer.TOPIC_SCENE)) >= 10)   # a display rate of 30 Hz: ~45 in 1.5 s
        scenes = v.of(viewer.TOPIC_SCENE)
        assert len(scenes) >= 10, len(scenes)
        for _, data in scenes:
            ids = {e.id for e in SceneUpdate.FromString(data).entities}
            assert {"finger/Finger 0", "finger/Finger 1", "residual/Box"} <= ids
        v.ws.send(json.dumps({"op": "setParameters", "parameters": [{"name": "mu_s", "value": 0.0}]}))
        v.read(30, until=lambda: v.status)
        assert v.status and "watching only" in v.status[0]["message"]
        v.close()
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    m = re.search(r"live view: (\d+) updates", out)
    assert m and int(m.group(1)) >= len(scenes), (out, len(scenes))    # at least what this viewer got
    assert "1 client requests refused (set_parameters 1)" in out, out


def test_cli_live_view_needs_realtime(blend):
    r = subprocess.run([LAUNCHER, "run", str(blend), "--live-view"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 1 and "--live-view needs --realtime" in r.stderr
    r = subprocess.run([LAUNCHER, "run", str(blend), "--realtime", "--live-view", "70000"], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 2 and "0..65535" in r.stderr


def test_cli_live_view_serves_a_device_session(blend):
    """`grasp-lab run --realtime --device serial:PTY --live-view 0`: a session the emulator
    drives is served like any other (one live loop); the viewer sees the fingers the device moves."""
    import sys
    # Streaming until the test ends it (a --duration would count from the run's probe, and a busy
    # machine may take longer than that to connect the session).
    emu = subprocess.Popen([sys.executable, "-m", "addon.engine.devices.emulator", "--pty", "--motion", "lift",
                            "--wait", "600"], cwd=grasp_env.ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
    proc = None
    try:
        port = emu.stdout.readline().split()[1]
        proc = subprocess.Popen([LAUNCHER, "run", str(blend), "--realtime", "--device", f"serial:{port}",
                                 "--duration", "3", "--live-view", "0"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        v = Viewer(served_address(proc))
        v.read(30, until=lambda: len(v.channels) >= 8)
        v.subscribe_all()
        v.read(30, until=lambda: len(v.of(viewer.TOPIC_SCENE)) >= 10 and len(v.of("/grasp_lab/finger/Finger_0")) >= 10
               and v.of(viewer.TOPIC_TRANSFORMS))
        frames = [FrameTransforms.FromString(d) for _, d in v.of(viewer.TOPIC_TRANSFORMS)]
        assert len(v.of(viewer.TOPIC_SCENE)) >= 10 and frames
        fingers = [json.loads(d) for _, d in v.of("/grasp_lab/finger/Finger_0")]
        assert len(fingers) >= 10
        v.close()
        out, err = proc.communicate(timeout=120)
    finally:
        for p in (proc, emu):
            if p is not None and p.poll() is None:
                p.kill()
    assert proc.returncode == 0, err
    assert "fingers: Finger 0, Finger 1: serial device" in out, out
    m = re.search(r"live view: (\d+) updates", out)
    assert m and int(m.group(1)) >= len(v.of(viewer.TOPIC_SCENE)), out    # at least what this viewer got
