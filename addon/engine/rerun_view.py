"""A session in Rerun (docs/viewers.md): ``grasp-lab export REC.mcap --rerun OUT.rrd``,
``grasp-lab view REC.mcap`` and the live view ``grasp-lab run --realtime --live-view rerun``.

What is shown is viewer.py's FrameBatch, the numbers the Foxglove channels and the bake show
(one computation, engine/viewer.py's frame sampler over engine/analysis); this module only
says it in Rerun's words: ``Mesh3D`` bodies (their convex parts, logged once) under a
``Transform3D`` per frame, the fingers' HIPs, god-objects (a convex finger's god-pose: its hull
under a transform), springs coloured by stick/slip and force arrows, the residual and weakest
wrench arrows, ``Scalars`` plots, the events as a ``TextLog`` and a saved blueprint (layout).
A copy's frames go out as whole columns (``send_columns``: a few calls per entity for a
batch of frames), a live update's single frame as plain ``log`` calls.

bpy-free. ``rerun-sdk`` is imported only here, when one of these commands runs.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import uuid

import numpy as np

from .live_view import LiveLoop
from .recording import Recording
from .viewer import (BODY_COLOR, FINGER_FORCE_COLOR, FORCE_COLOR, GO_COLOR, HIP_COLOR, HIP_DIAMETER,
                     STATE_COLORS, STATIC_BODY_COLOR, TORQUE_COLOR, WEAKEST_COLOR, WEAKEST_TORQUE_COLOR,
                     ERROR_EVENTS, WARNING_EVENTS, FrameBatch, SceneModel, hull_triangles)

RERUN_VERSION = "0.23.1"
SDK_HINT = (f"pip install rerun-sdk=={RERUN_VERSION} pyarrow==22.0.0 (the versions in requirements.txt; "
            f"make test installs them into .venv)")
APPLICATION_ID = "grasp_lab"
TIME = "session_time"       # timeline: session time (a duration from the start), s
TICK = "tick"               # timeline: the haptic tick each frame shows
ARROW_RADIUS = 0.002        # m
BACKGROUND = (24, 24, 28)   # the 3-D view's background, RGB
SPRING_RADIUS = 0.001       # m
# Plots, each a time-series view of the blueprint: root path, title.
PLOTS = (("plots/finger_force", "Finger forces (N): normal, tangential"),
         ("plots/friction_use", "Friction use |Ft| / (mu |Fn|): slip at 1"),
         ("plots/grip", "Bodies: grip and load (N)"),
         ("plots/grip_load", "Grip / load"),
         ("plots/closure", "Grasp: force closure (0/1) and epsilon"),
         ("plots/slip_margin", "Slip margin (N): smallest mu |Fn| - |Ft|"))


def _sdk():
    try:
        import rerun
        import rerun.blueprint  # noqa: F401
    except ImportError as ex:
        raise ImportError(f"Rerun needs rerun-sdk ({SDK_HINT}): {ex}") from None
    return rerun


def _rgba8(rgba) -> list:
    return [int(round(255 * c)) for c in rgba]


def drawn(vectors: np.ndarray) -> np.ndarray:
    """Which arrows are drawn: longer than 1e-6 m (as the Foxglove channels' arrows)."""
    return np.einsum("ij,ij->i", vectors, vectors) > 1e-12


def part(name: str) -> str:
    """An object's name as one entity path part (Rerun escapes spaces and slashes)."""
    return _sdk().escape_entity_path_part(name)


class RerunPaths:
    """The entity paths of a scene's fingers and bodies."""

    def __init__(self, model: SceneModel):
        self.model = model
        f = [part(n) for n in model.finger_names]
        b = [part(n) for n in model.body_names]
        self.body = [f"world/bodies/{n}" for n in b]
        self.finger = [f"world/fingers/{n}" for n in f]
        self.residual = [f"world/residual/{n}" for n in b]
        self.weakest = [f"world/weakest/{n}" for n in b]
        self.normal_force = [f"plots/finger_force/{n}/normal" for n in f]
        self.tangential_force = [f"plots/finger_force/{n}/tangential" for n in f]
        self.friction_use = [f"plots/friction_use/{n}" for n in f]
        self.grip = [f"plots/grip/{n}/grip" for n in b]
        self.load = [f"plots/grip/{n}/load" for n in b]
        self.grip_load = [f"plots/grip_load/{n}" for n in b]
        self.closure = [f"plots/closure/{n}/closure" for n in b]
        self.epsilon = [f"plots/closure/{n}/epsilon" for n in b]
        self.slip_margin = [f"plots/slip_margin/{n}" for n in b]
        self.events = "events"


def blueprint(model: SceneModel):
    """The layout saved with the recording: the 3-D view beside the plots, the events below."""
    _sdk()
    import rerun.blueprint as rrb
    plots = [rrb.TimeSeriesView(origin=f"/{root}", name=title, plot_legend=rrb.PlotLegend(visible=True))
             for root, title in PLOTS]
    # Rerun 0.23 has no camera setting in a blueprint: the view frames what it shows.
    three_d = rrb.Spatial3DView(origin="/world", name="Grasp", background=list(BACKGROUND))
    events = rrb.TextLogView(origin="/events", name="Events")
    return rrb.Blueprint(rrb.Horizontal(rrb.Vertical(three_d, events, row_shares=[4, 1]), rrb.Vertical(*plots),
                                        column_shares=[3, 2]), collapse_panels=True)


class RerunLogger:
    """The scene of a SceneModel logged to one Rerun recording stream: ``static()`` once,
    ``log_batch(batch)`` for each FrameBatch, ``log_event(e)`` for each event."""

    def __init__(self, model: SceneModel, stream):
        self.rr = _sdk()
        self.model = model
        self.stream = stream
        self.paths = RerunPaths(model)
        self.time_offset = 0.0      # s added to session time on the session_time timeline
        scene = model.header["scene"]
        self.convex = [f.get("points") is not None for f in scene["fingers"]]
        # packed 0xRRGGBBAA: one colour per row of a column
        self.state_colors = np.array([int.from_bytes(bytes(_rgba8(STATE_COLORS[k])), "big") for k in range(3)],
                                     dtype=np.uint32)

    def _mesh(self, tris, rgba):
        """Hull triangles (T, 3, 3) as a flat-shaded mesh."""
        rr = self.rr
        n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        return rr.Mesh3D(vertex_positions=tris.reshape(-1, 3),
                         triangle_indices=np.arange(3 * len(tris)).reshape(-1, 3),
                         vertex_normals=np.repeat(n, 3, axis=0), albedo_factor=_rgba8(rgba))

    def static(self) -> None:
        """What does not change: the body meshes, the finger markers' sizes and colours, the
        plot series' names and colours."""
        rr, s, p, model = self.rr, self.stream, self.paths, self.model
        s.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for i, parts in enumerate(model.meshes):
            color = STATIC_BODY_COLOR if model.static[i] else BODY_COLOR
            for k, tris in enumerate(parts):
                s.log(f"{p.body[i]}/part_{k}", self._mesh(tris, color), static=True)
        scene = model.header["scene"]
        for j, name in enumerate(model.finger_names):
            base = p.finger[j]
            if self.convex[j]:
                hull = hull_triangles(np.asarray(scene["fingers"][j]["points"], dtype=np.float64).reshape(-1, 3))
                s.log(f"{base}/god_pose/hull", self._mesh(hull, GO_COLOR), static=True)
            else:
                s.log(f"{base}/god_object", rr.Points3D.from_fields(radii=[float(model.radii[j])],
                                                                    colors=[_rgba8(GO_COLOR)]), static=True)
            s.log(f"{base}/hip", rr.Points3D.from_fields(radii=[HIP_DIAMETER / 2], colors=[_rgba8(HIP_COLOR)]),
                  static=True)
            s.log(f"{base}/spring", rr.LineStrips3D.from_fields(radii=[SPRING_RADIUS]), static=True)
            s.log(f"{base}/force", rr.Arrows3D.from_fields(radii=[ARROW_RADIUS],
                                                           colors=[_rgba8(FINGER_FORCE_COLOR)]), static=True)
            s.log(p.normal_force[j], rr.SeriesLines(names=[f"{name} |Fn|"]), static=True)
            s.log(p.tangential_force[j], rr.SeriesLines(names=[f"{name} |Ft|"]), static=True)
            s.log(p.friction_use[j], rr.SeriesLines(names=[name]), static=True)
        for i, name in enumerate(model.body_names):
            if model.static[i]:
                continue
            for path, color in ((f"{p.residual[i]}/force", FORCE_COLOR), (f"{p.residual[i]}/torque", TORQUE_COLOR),
                                (f"{p.weakest[i]}/force", WEAKEST_COLOR),
                                (f"{p.weakest[i]}/torque", WEAKEST_TORQUE_COLOR)):
                s.log(path, rr.Arrows3D.from_fields(radii=[ARROW_RADIUS], colors=[_rgba8(color)]), static=True)
            for path, label in ((p.grip[i], "grip"), (p.load[i], "load"), (p.grip_load[i], "grip / load"),
                                (p.closure[i], "closure"), (p.epsilon[i], "epsilon"),
                                (p.slip_margin[i], "slip margin")):
                s.log(path, rr.SeriesLines(names=[f"{name} {label}"]), static=True)

    def items(self, b: FrameBatch):
        """What a FrameBatch shows, entity by entity: (path, archetype, {field: array with the
        frames first}). An arrow's zero vector is a frame without it."""
        rr, p, model = self.rr, self.paths, self.model
        for i in range(len(model.body_names)):
            yield p.body[i], rr.Transform3D, {"translation": b.pose[:, i, :3],
                                              "quaternion": b.pose[:, i][:, [4, 5, 6, 3]]}
        for j in range(len(model.finger_names)):
            base = p.finger[j]
            go, hip = b.god_object[:, j], b.hip[:, j]
            if self.convex[j]:
                yield f"{base}/god_pose", rr.Transform3D, {"translation": go,
                                                           "quaternion": b.orientation[:, j][:, [1, 2, 3, 0]]}
            else:
                yield f"{base}/god_object", rr.Points3D, {"positions": go}
            yield f"{base}/hip", rr.Points3D, {"positions": hip}
            yield f"{base}/spring", rr.LineStrips3D, {"strips": np.stack([hip, go], axis=1),
                                                      "colors": self.state_colors[np.clip(b.state[:, j], 0, 2)]}
            yield f"{base}/force", rr.Arrows3D, {"origins": b.push_tail[:, j], "vectors": b.push[:, j]}
            if b.normals:
                yield p.normal_force[j], rr.Scalars, {"scalars": b.fingers["normal_force"][:, j]}
                yield p.tangential_force[j], rr.Scalars, {"scalars": b.fingers["tangential_force"][:, j]}
                yield p.friction_use[j], rr.Scalars, {"scalars": b.fingers["friction_use"][:, j]}
        for i in range(len(model.body_names)):
            if model.static[i]:
                continue
            yield f"{p.residual[i]}/force", rr.Arrows3D, {"origins": b.com[:, i], "vectors": b.residual_force[:, i]}
            yield f"{p.residual[i]}/torque", rr.Arrows3D, {"origins": b.com[:, i], "vectors": b.residual_torque[:, i]}
            yield f"{p.weakest[i]}/force", rr.Arrows3D, {"origins": b.weakest_center[:, i],
                                                         "vectors": b.weakest_force[:, i]}
            yield f"{p.weakest[i]}/torque", rr.Arrows3D, {"origins": b.weakest_center[:, i],
                                                          "vectors": b.weakest_torque[:, i]}
            if b.normals:
                yield p.grip[i], rr.Scalars, {"scalars": b.bodies["grip"][:, i]}
            if b.grasp:
                for path, name in ((p.load, "load"), (p.grip_load, "grip_load"), (p.closure, "closure"),
                                   (p.epsilon, "epsilon"), (p.slip_margin, "slip_margin")):
                    yield path[i], rr.Scalars, {"scalars": b.bodies[name][:, i]}

    def log_batch(self, b: FrameBatch) -> None:
        """A batch of frames as columns (``send_columns``: a few calls per entity for any number
        of frames, what a recording's copy needs); one frame (a live update) as plain ``log``
        calls, which cost a tenth of a one-row column."""
        rr, s = self.rr, self.stream
        if len(b.time) == 1:
            s.set_time(TIME, duration=float(b.time[0]) + self.time_offset)
            s.set_time(TICK, sequence=int(b.tick[0]))
            for path, archetype, fields in self.items(b):
                if archetype is rr.Arrows3D and not drawn(fields["vectors"][:1])[0]:
                    s.log(path, rr.Arrows3D(origins=np.zeros((0, 3)), vectors=np.zeros((0, 3))))
                elif archetype is rr.Transform3D:
                    s.log(path, rr.Transform3D(**{k: v[0] for k, v in fields.items()}))
                else:
                    s.log(path, archetype(**{k: v[:1] for k, v in fields.items()}))
            return
        indexes = [rr.TimeColumn(TIME, duration=b.time + self.time_offset), rr.TimeColumn(TICK, sequence=b.tick)]
        for path, archetype, fields in self.items(b):
            if archetype is rr.Arrows3D:
                shown = drawn(fields["vectors"])
                columns = archetype.columns(**{k: v[shown] for k, v in fields.items()}).partition(
                    shown.astype(np.int32))
            elif archetype is rr.LineStrips3D:
                columns = archetype.columns(strips=list(fields["strips"]), colors=fields["colors"])
            else:
                columns = archetype.columns(**fields)
            s.send_columns(path, indexes=indexes, columns=columns, strict=True)

    def log_event(self, e: dict) -> None:
        rr = self.rr
        kind = str(e.get("kind", ""))
        level = "WARN" if kind in WARNING_EVENTS else "ERROR" if kind in ERROR_EVENTS else "INFO"
        text = " ".join(str(x) for x in (kind, e.get("subject", ""), e.get("detail", "")) if x != "")
        self.stream.set_time(TIME, duration=float(e.get("time", 0.0)) + self.time_offset)
        self.stream.set_time(TICK, sequence=max(0, int(e.get("tick", 0))))
        self.stream.log(self.paths.events, rr.TextLog(text, level=level))


# --------------------------------------------------------------------------- export

def export_rerun(rec: Recording, path: str, rate: float | None = None, every_tick: bool = False) -> dict:
    """``rec`` as a Rerun recording at ``path`` (.rrd with its blueprint), at the display rate
    (``rate``) or every recorded tick (``every_tick``), written to a temporary file beside it
    and renamed when complete. Returns {"frames", "events", "bytes", "rate"}."""
    if os.path.exists(path) and os.path.exists(rec.path) and os.path.samefile(path, rec.path):
        raise ValueError(f"{path}: that is the recording itself; write the Rerun copy to another file")
    rr = _sdk()
    model = SceneModel(rec.header)
    if every_tick:
        times, shown_rate = rec.ticks["time"].astype(np.float64), rec.haptic_rate
    else:
        times = model.frame_times(rec, rate)
        shown_rate = float(rate or model.display_rate)
    if not len(times):
        raise ValueError(f"{rec.path}: the recording is shorter than one display frame")
    tmp = f"{path}.partial"
    with open(tmp, "wb"):       # ours first, so a path that cannot be written fails naming it
        pass
    stream = rr.RecordingStream(APPLICATION_ID, recording_id=str(rec.header.get("fingerprint") or uuid.uuid4()),
                                send_properties=False)
    try:
        stream.save(tmp)
        logger = RerunLogger(model, stream)
        logger.static()
        for b in model.batches(rec, times, batch=4096):
            logger.log_batch(b)
        events = sorted(rec.events, key=lambda e: float(e.get("time", 0.0)))
        for e in events:
            logger.log_event(e)
        # The layout last and active: a viewer that has made up a layout of its own while the
        # data streamed in (it does when the data comes first) switches to this one.
        stream.send_blueprint(blueprint(model), make_active=True, make_default=True)
        stream.flush(blocking=True)
        stream.disconnect()
    except BaseException:
        try:
            stream.disconnect()
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)
        raise
    os.replace(tmp, path)
    return {"frames": len(times), "events": len(events), "bytes": os.path.getsize(path), "rate": shown_rate}


# --------------------------------------------------------------------------- the viewer

def viewer_binary() -> str:
    """The Rerun viewer inside the rerun-sdk wheel (the venv's ``rerun`` is a Python wrapper
    around it)."""
    rr = _sdk()
    base = os.path.dirname(os.path.dirname(os.path.abspath(rr.__file__)))
    for candidate in (os.path.join(base, "rerun_cli", "rerun"),
                      os.path.join(os.path.dirname(base), "rerun_cli", "rerun")):
        if os.access(candidate, os.X_OK):
            return candidate
    found = shutil.which("rerun")
    if found:
        return found
    raise ImportError(f"the Rerun viewer is not in the rerun-sdk package found ({SDK_HINT})")


def cached_copy(rec_path: str, fingerprint: str, every_tick: bool = False) -> str:
    """Where ``view`` keeps the Rerun copy of a recording: beside it, named by the recording's
    fingerprint and its size and time (a recording re-made or grown gets a new copy)."""
    st = os.stat(rec_path)
    key = hashlib.sha256(f"{fingerprint}:{st.st_size}:{st.st_mtime_ns}:{int(every_tick)}:{RERUN_VERSION}"
                         .encode()).hexdigest()[:12]
    stem = os.path.splitext(rec_path)[0]
    return f"{stem}.{key}.rrd"


def stale_copies(rec_path: str, keep: str) -> list:
    """Earlier cached copies of the same recording (other keys), to be removed."""
    folder = os.path.dirname(os.path.abspath(rec_path))
    stem = os.path.basename(os.path.splitext(rec_path)[0])
    out = []
    for name in os.listdir(folder):
        rest = name[len(stem) + 1:] if name.startswith(stem + ".") else ""
        if rest.endswith(".rrd") and len(rest) == 16 and all(c in "0123456789abcdef" for c in rest[:12]):
            full = os.path.join(folder, name)
            if os.path.abspath(full) != os.path.abspath(keep):
                out.append(full)
    return out


def view_recording(rec_path: str, screenshot: str | None = None, size: str = "1600x900", every_tick: bool = False,
                   warn=None, launch: bool = True) -> dict:
    """``grasp-lab view`` and Blender's *Open in Rerun*: the recording's Rerun copy (made once,
    kept beside it as ``cached_copy`` names it, older copies of it removed), then the viewer
    on it as a separate process (not waited for), or with ``screenshot`` its picture.
    ``warn(line)`` hears what a damaged recording lost; ``launch=False``: the copy alone.
    Returns {"rrd", "converted", "pid"}."""
    from .recording import RecordingError, open_recording, summarize
    _sdk()
    try:
        fingerprint = summarize(rec_path)["fingerprint"]
    except (KeyError, TypeError):
        fingerprint = ""
    rrd = cached_copy(rec_path, fingerprint, every_tick)
    converted = not os.path.exists(rrd)
    if converted:
        rec = open_recording(rec_path)
        for line in rec.warnings():
            if warn is not None:
                warn(line)
        if len(rec.ticks) == 0:
            raise RecordingError(f"{rec_path}: no tick was recorded")
        export_rerun(rec, rrd, every_tick=every_tick)
        for old in stale_copies(rec_path, rrd):
            os.remove(old)
    if screenshot:
        take_screenshot(rrd, screenshot, size)
        return {"rrd": rrd, "converted": converted, "pid": None}
    return {"rrd": rrd, "converted": converted, "pid": open_viewer(rrd).pid if launch else None}


def viewer_command(rrd: str, screenshot: str | None = None, size: str = "1600x900") -> list:
    """The viewer's command line for a file: its own gRPC port on 127.0.0.1, any free one
    (several viewers may run at once), and with ``screenshot`` its picture then exit."""
    cmd = [viewer_binary(), "--bind", "127.0.0.1", "--port", "0", "--web-viewer-port", "0"]
    if screenshot:
        cmd += ["--screenshot-to", screenshot, "--window-size", size]
    return cmd + [rrd]


def open_viewer(rrd: str) -> subprocess.Popen:
    """The viewer on ``rrd`` as a separate process, not waited for (Blender, the shell go on)."""
    return subprocess.Popen(viewer_command(rrd), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)


def take_screenshot(rrd: str, png: str, size: str = "1600x900", timeout: float = 300.0) -> str:
    """The viewer's own picture of ``rrd`` at ``png`` (``--screenshot-to``; it needs a display:
    Xvfb with -extension Composite headless). Written beside ``png`` and renamed; the viewer
    may exit non-zero after writing it (0.23 does on its way out), so the picture decides.
    Returns the viewer's output (its log)."""
    tmp = f"{png}.partial.png"
    if os.path.exists(tmp):
        os.remove(tmp)
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        raise OSError("the Rerun viewer needs a display (headless: Xvfb :N -extension Composite, then DISPLAY=:N)")
    env = dict(os.environ)
    env.setdefault("XDG_RUNTIME_DIR", _runtime_dir())
    try:
        done = subprocess.run(viewer_command(rrd, tmp, size), stdin=subprocess.DEVNULL, capture_output=True,
                              text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        raise OSError(f"{png}: the Rerun viewer did not write its picture in {timeout:g} s") from None
    log = done.stdout + done.stderr
    if not os.path.exists(tmp) or not _is_png(tmp):
        if os.path.exists(tmp):
            os.remove(tmp)
        tail = "; ".join(line for line in log.splitlines() if "ERROR" in line or "panicked" in line)[-400:]
        raise OSError(f"{png}: the Rerun viewer wrote no picture (exit {done.returncode}{': ' + tail if tail else ''})")
    os.replace(tmp, png)
    return log


def _runtime_dir() -> str:
    path = os.path.join("/tmp", f"grasp-lab-runtime-{os.getuid()}")
    os.makedirs(path, mode=0o700, exist_ok=True)
    return path


def _is_png(path: str) -> bool:
    with open(path, "rb") as fh:
        head = fh.read(8)
    if head != b"\x89PNG\r\n\x1a\n":
        return False
    with open(path, "rb") as fh:
        fh.seek(-12, os.SEEK_END)
        return fh.read(12)[4:8] == b"IEND"


# --------------------------------------------------------------------------- live

DEFAULT_LIVE_PORT = 9876        # the Rerun viewer's own default


def live_url(spec: str) -> str:
    """``rerun`` (a viewer on this machine, its default port), ``rerun:PORT`` or
    ``rerun:HOST:PORT`` as the viewer's gRPC address."""
    kind, _, rest = spec.partition(":")
    if kind != "rerun":
        raise ValueError(f"--live-view {spec}: expected PORT (Foxglove), rerun, rerun:PORT or rerun:HOST:PORT")
    host, _, port = rest.rpartition(":")
    try:
        p = int(port) if rest else DEFAULT_LIVE_PORT
    except ValueError:
        raise ValueError(f"--live-view {spec}: expected rerun, rerun:PORT or rerun:HOST:PORT") from None
    if not 0 < p < 65536:
        raise ValueError(f"--live-view {spec}: a port is 1..65535")
    return f"rerun+http://{host or '127.0.0.1'}:{p}/proxy"


class RerunLiveView(LiveLoop):
    """A live session streamed to a Rerun viewer over its own protocol (gRPC; the SDK buffers
    and sends from its own threads): the same entities as a recording's copy, with the
    blueprint, stamped with the wall clock. Never on the haptic thread (engine/live_view.py's
    loop). The viewer is started by the user (``rerun``, on this machine by default). Its
    session_time timeline is session time (Rerun's own log_time is the wall clock); its tick
    timeline counts display updates."""

    hint = "Rerun: start the viewer (rerun) on that address; it shows the session as it runs"

    def __init__(self, header: dict, spec: str = "rerun"):
        rr = _sdk()
        super().__init__(header)
        self.url = live_url(spec)
        self.stream = rr.RecordingStream(APPLICATION_ID, recording_id=str(uuid.uuid4()), send_properties=False)
        try:
            self.stream.connect_grpc(self.url, default_blueprint=blueprint(self.model))
        except Exception as ex:         # the SDK's own error type: say what could not be reached
            raise OSError(f"live view: cannot stream to {self.url} ({ex})") from None
        self.logger = RerunLogger(self.model, self.stream)
        self.logger.static()
        self._start()

    @property
    def address(self) -> str:
        return self.url

    def status(self) -> str:
        return (f"live view {self.url}: {self.updates} updates, {self.dropped} skipped"
                + (f"; {self.error}" if self.error else ""))

    def publish(self, batch, events, time_offset) -> None:
        self.logger.log_batch(batch)
        for e in events:
            self.logger.log_event(e)

    def _close_viewer(self) -> dict:
        self.stream.flush(blocking=True)
        self.stream.disconnect()
        return {"refused": {}}
