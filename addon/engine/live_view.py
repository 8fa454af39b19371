"""A running session served live to Foxglove (``grasp-lab run --realtime --live-view``,
docs/viewers.md): the viewer channels of engine/viewer.py over Foxglove's WebSocket protocol
(foxglove-sdk's server).

Watching only, and every refusal counted: the server lets client publishing and parameter
requests reach its listener (foxglove-sdk refuses requests for a capability it does not
offer by itself, without telling the listener, so they could not be counted), and the
listener refuses each one: published messages are dropped, no parameter is read or set, and
the client gets an error status saying so. No service is offered, so a service call has
nothing to name. It binds to localhost unless told otherwise. Never on the haptic thread: the display update hands the latest snapshot over
(an assignment: no copy, lock or wake-up) as its last step, and the live view's own thread,
looking every 5 ms, turns it into messages while the main thread waits for its next update;
when it falls behind it skips snapshots, never queues them. Clients come and go; the
session goes on.
"""
from __future__ import annotations

import collections
import threading
import time

import numpy as np

from .recording import FLAG_FORCES_ENABLED, EventDetector, scene_to_dict, tick_dtype
from .viewer import SceneModel, _sdk, frame_batch, grasp_arrays_of, viewer_frames

DEFAULT_PORT = 8765
DEFAULT_BIND = "127.0.0.1"
POLL = 0.005        # s: how often the live view's thread looks for a new snapshot


def header_of(desc, haptic_rate: float, runtime: dict | None = None) -> dict:
    """What the viewer channels need of a session's scene (the recording header's keys)."""
    return {"scene": scene_to_dict(desc), "body_names": [b.name for b in desc.bodies],
            "finger_names": [f.name for f in desc.fingers], "runtime": runtime or {},
            "rates": {"haptic_hz": float(haptic_rate), "display_hz": float(desc.display_rate)}, "source": "live"}


class _Viewers:
    """The server's listener: how many subscriptions viewers hold (for the HUD), whether one
    is new (it gets the body meshes with the next update, not a second later), and every
    request a watching-only server refuses (``refused``: by kind)."""

    def __init__(self):
        self.subscribed = 0
        self.joined = False
        self.refused = collections.Counter()
        self.server = None                  # set once the server runs: refusals are told to the client
        self.error_level = None             # foxglove.websocket.StatusLevel.Error, with the server
        self._lock = threading.Lock()

    def on_subscribe(self, client, channel):
        with self._lock:
            self.subscribed += 1
            self.joined = True

    def on_unsubscribe(self, client, channel):
        with self._lock:
            self.subscribed -= 1

    def _refuse(self, kind: str, what: str) -> None:
        with self._lock:
            self.refused[kind] += 1
        if self.server is not None:
            self.server.publish_status(f"Grasp Lab live view is watching only: {what} refused", self.error_level)

    def on_client_advertise(self, client, channel):
        self._refuse("publish", f"publishing on {channel.topic!r}")

    def on_message_data(self, client, client_channel_id, data):
        self._refuse("message", "a published message")

    def on_get_parameters(self, client, param_names, request_id=None):
        self._refuse("get_parameters", "reading parameters")
        return []

    def on_set_parameters(self, client, parameters, request_id=None):
        self._refuse("set_parameters", "setting parameters")
        return []

    def on_parameters_subscribe(self, param_names):
        self._refuse("subscribe_parameters", "subscribing to parameters")

    def refused_total(self) -> int:
        with self._lock:
            return sum(self.refused.values())


class BoundServer:
    """A live view's server, bound (``bind_server``) before the session it serves exists: a
    port that is taken refuses the command before its recording is opened."""

    def __init__(self, port: int = DEFAULT_PORT, bind: str = DEFAULT_BIND):
        foxglove = _sdk()
        self.context = foxglove.Context()
        self.viewers = _Viewers()
        try:
            from foxglove.websocket import Capability, StatusLevel
            # Offered only so that the listener sees (refuses and counts) these requests: _Viewers.
            self.server = foxglove.start_server(name="Grasp Lab", host=bind, port=int(port),
                                                capabilities=[Capability.ClientPublish, Capability.Parameters],
                                                supported_encodings=["json", "protobuf"],
                                                server_listener=self.viewers, context=self.context)
        except Exception as ex:         # the SDK's own error type: say what could not be bound
            raise OSError(f"live view: cannot serve on {bind}:{port} ({ex})") from None
        self.viewers.server, self.viewers.error_level = self.server, StatusLevel.Error
        self.bind = bind

    def close(self) -> None:
        self.server.stop()


def bind_server(port: int = DEFAULT_PORT, bind: str = DEFAULT_BIND) -> BoundServer:
    return BoundServer(port, bind)


class LiveLoop:
    """A live view's machinery, whatever the viewer: ``offer(snapshot)`` from the display
    update; the view's own thread turns the latest snapshot into the viewer frames' numbers
    (viewer.frame_batch, as a recording's copy) and hands them to ``publish``; ``close()`` at
    the end. Subclasses set up their viewer, then call ``_start()``."""

    address = ""

    def __init__(self, header: dict):
        self.model = SceneModel(header)
        self.header = header
        self.dtype = tick_dtype(len(self.model.body_names), len(self.model.finger_names))
        self.events = EventDetector(header)
        self.updates = 0
        self.dropped = 0                    # snapshots replaced before the thread took them
        self.cost_us = []                   # per update: snapshot to messages sent, this thread's wall time
        self.error = ""
        self._slot = collections.deque(maxlen=1)    # (snapshot, grasps, wall time offered): the latest, unsent
        self._stop = threading.Event()
        self._tick = 0
        self._thread = threading.Thread(target=self._loop, name="grasp_lab live view", daemon=True)

    def _start(self) -> None:
        self._thread.start()

    @property
    def pending(self) -> bool:
        """A snapshot is offered and not yet sent."""
        return bool(self._slot)

    def offer(self, snap, grasps=None) -> None:
        """The latest snapshot (engine.runner.Snapshot) and, if the display update analysed it,
        its BodyGrasp list (engine.grasp_display.GraspMonitor.grasps; None: no analysis shown):
        one assignment, no lock, no wake-up (the thread polls every ``POLL`` s), so the
        display update pays next to nothing."""
        if self._slot:
            self.dropped += 1
        self._slot.append((snap, grasps, time.time()))     # a deque of one: the older one goes

    def _row(self, snap) -> np.ndarray:
        r = np.zeros(1, self.dtype)
        r["tick"], r["time"] = self._tick, snap.time
        self._tick += 1
        r["flags"] = FLAG_FORCES_ENABLED
        r["pose"][0], r["wrench"][0, :, :3], r["wrench"][0, :, 3:] = snap.poses, snap.force, snap.torque
        r["hip"][0], r["god_object"][0] = snap.hips, snap.god_objects
        # As a recording: force is the coupling force on the contact, device_force what the device got.
        r["force"][0], r["device_force"][0] = snap.spring_forces, snap.finger_forces
        r["normal"][0] = snap.normals
        r["state"][0], r["contact"][0] = snap.finger_states, snap.contacts
        if "orientation" in self.dtype.names:
            r["orientation"][0] = (1.0, 0.0, 0.0, 0.0)      # a snapshot has no finger orientations
        return r

    def publish(self, batch, events: list, time_offset: float) -> None:
        """One display update's FrameBatch (one frame) and the events since the last, to the
        viewer; stamps are session time + ``time_offset`` (the wall clock of the update)."""
        raise NotImplementedError

    def _loop(self):
        try:
            while True:
                try:
                    snap, grasps, offered = self._slot.popleft()
                except IndexError:
                    if self._stop.wait(POLL):
                        return
                    continue
                t0 = time.perf_counter()
                row = self._row(snap)
                batch = frame_batch(self.model, self, row, [snap.time],
                                    grasp=None if grasps is None else grasp_arrays_of(grasps,
                                                                                      len(self.model.body_names)))
                events = [{"tick": tick, "time": t, "kind": kind, "subject": subject, "detail": detail}
                          for tick, t, kind, subject, detail in self.events(row)]
                # Stamped with the wall clock of the display update that offered it: a viewer's
                # timeline is the wall clock, and its delay is what it receives minus the stamp.
                self.publish(batch, events, offered - snap.time)
                self.updates += 1
                self.cost_us.append((time.perf_counter() - t0) * 1e6)
        except Exception as ex:     # the session goes on without its viewers; close() reports it
            self.error = f"live view stopped: {ex}"

    def _close_viewer(self) -> dict:
        """The viewer's end; extra keys for close()'s answer."""
        return {}

    def close(self) -> dict:
        self._stop.set()
        self._thread.join()
        extra = self._close_viewer()
        return {"updates": self.updates, "dropped": self.dropped, "error": self.error, **extra}


class LiveView(LiveLoop):
    """Serves one session to Foxglove viewers over its WebSocket protocol, on a server bound
    before the session (``bound``, bind_server) or bound here."""

    hint = "Foxglove: open a connection, Foxglove WebSocket, to this address"

    def __init__(self, header: dict, port: int = DEFAULT_PORT, bind: str = DEFAULT_BIND,
                 bound: BoundServer | None = None):
        from .viewer import FoxgloveChannels
        bound = bound or BoundServer(port, bind)
        super().__init__(header)
        self.context = bound.context
        self.server, self.viewers = bound.server, bound.viewers
        self.channels = FoxgloveChannels(self.model, self.context)
        self.bind, self.port = bound.bind, int(self.server.port)
        self._start()

    @property
    def address(self) -> str:
        return f"ws://{self.bind}:{self.port}"

    def status(self) -> str:
        refused = self.viewers.refused_total()
        return (f"live view {self.address}: {self.viewers.subscribed} subscriptions, {self.updates} updates, "
                f"{self.dropped} skipped" + (f", {refused} requests refused" if refused else "")
                + (f"; {self.error}" if self.error else ""))

    def publish(self, batch, events, time_offset) -> None:
        self.channels.time_offset = time_offset
        if self.viewers.joined:
            self.viewers.joined = False
            self.channels.resend_bodies()
        for e in events:
            self.channels.log_event(e)
        self.channels.log_frame(viewer_frames(self.model, batch)[0])

    def _close_viewer(self) -> dict:
        self.server.stop()
        return {"refused": dict(self.viewers.refused)}
