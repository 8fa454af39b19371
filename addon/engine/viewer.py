"""Viewer channels: a session as Foxglove shows it (docs/viewers.md).

``grasp-lab export REC.mcap --foxglove OUT.mcap`` writes, at the recording's display rate,
the channels a robotics viewer (Foxglove, Lichtblick) draws and plots without any Grasp Lab
code: ``foxglove.SceneUpdate`` (bodies as triangle meshes of their convex parts,
fingertips, god-objects, HIP-god-object springs coloured by stick/slip, finger force and
residual force/torque arrows), ``foxglove.FrameTransforms`` (body frames), JSON channels of
numbers per finger and per body for plots, and the events as ``foxglove.Log``.

bpy-free. The geometry and the numbers are plain numpy (``ViewerFrame``); only writing
needs ``foxglove-sdk``, imported when a copy is written, so nothing else depends on it.
"""
from __future__ import annotations

import json
import os
import re
import shutil
from dataclasses import dataclass

import numpy as np

from . import analysis
from .measures import body_grip, finger_measures
from .outputs import AtomicFile, OutputError, write_whole
from .recording import STATE_NAMES, Recording
from .runner import quat_rotate

WORLD_FRAME = "world"
TOPIC_SCENE = "/grasp_lab/scene"            # fingertips, god-objects, springs, arrows: every frame
TOPIC_BODIES = "/grasp_lab/bodies"          # body meshes, locked to their frames: at the start, then every second
TOPIC_TRANSFORMS = "/grasp_lab/transforms"  # world -> body frames: every frame
TOPIC_LOG = "/grasp_lab/log"                # events
FINGER_TOPIC = "/grasp_lab/finger/"         # + topic-safe finger name: numbers for plots
BODY_TOPIC = "/grasp_lab/body/"             # + topic-safe body name
BODIES_REPEAT = 1.0         # s: body meshes again, so a viewer that seeks or joins late has them
FORCE_SCALE = 0.02          # m per N (the extension's default Force Scale)
TORQUE_SCALE = 1.0          # m per N m (its default Torque Scale)
ARROW_DIAMETER = 0.008      # m, arrow shaft (Blender's arrows: 4 mm radius)
HIP_DIAMETER = 0.006        # m, the fingertip (HIP) marker
SPRING_WIDTH = 0.002        # m
MIN_GO_RADIUS = 0.002       # m: god-objects of point fingers are still visible
# RGBA. Stick/slip as the HUD shows them; force red, torque green, god-objects blue as in Blender.
STATE_COLORS = {0: (0.6, 0.6, 0.6, 1.0), 1: (0.1, 0.8, 0.2, 1.0), 2: (1.0, 0.45, 0.0, 1.0)}
GO_COLOR = (0.10, 0.45, 1.00, 1.0)
HIP_COLOR = (0.9, 0.9, 0.9, 0.8)
FINGER_FORCE_COLOR = (1.0, 0.85, 0.1, 1.0)
FORCE_COLOR = (1.0, 0.15, 0.10, 1.0)
TORQUE_COLOR = (0.10, 0.85, 0.25, 1.0)
WEAKEST_COLOR = (1.00, 0.20, 0.90, 1.0)   # magenta, as the viewport's (grasp_display.WEAKEST_COLOR)
WEAKEST_TORQUE_COLOR = (0.65, 0.10, 1.00, 1.0)
BODY_COLOR = (0.55, 0.6, 0.7, 0.6)
STATIC_BODY_COLOR = (0.35, 0.35, 0.38, 0.8)
SDK_HINT = "pip install foxglove-sdk (the version in requirements.txt)"


# --------------------------------------------------------------------------- geometry

def hull_triangles(points: np.ndarray) -> np.ndarray:
    """The convex hull of ``points`` (N, 3) as outward-wound triangles (T, 3, 3): incremental,
    every point either inside the hull so far or joined to the edges around what it sees.
    ValueError for fewer than 4 points or points that span no volume."""
    pts = np.unique(np.asarray(points, dtype=np.float64).reshape(-1, 3), axis=0)
    if len(pts) < 4 or not np.all(np.isfinite(pts)):
        raise ValueError(f"a convex hull needs at least 4 finite points, got {len(pts)}")
    eps = 1e-12 * max(1.0, float(np.abs(pts).max())) + 1e-9 * float(np.ptp(pts, axis=0).max())
    a = int(np.argmin(pts[:, 0]))
    b = int(np.argmax(np.linalg.norm(pts - pts[a], axis=1)))
    ab = pts[b] - pts[a]
    c = int(np.argmax(np.linalg.norm(np.cross(pts - pts[a], ab), axis=1)))
    normal = np.cross(ab, pts[c] - pts[a])
    d = int(np.argmax(np.abs((pts - pts[a]) @ normal)))
    if abs((pts[d] - pts[a]) @ normal) <= eps * np.linalg.norm(normal) or np.linalg.norm(normal) <= eps * eps:
        raise ValueError("the points span no volume (coplanar or collinear)")
    inside = pts[[a, b, c, d]].mean(axis=0)
    faces = []

    def add(i, j, k):
        n = np.cross(pts[j] - pts[i], pts[k] - pts[i])
        if n @ (pts[i] - inside) < 0:
            i, j = j, i
            n = -n
        faces.append((i, j, k, n / np.linalg.norm(n)))

    for i, j, k in ((a, b, c), (a, b, d), (a, c, d), (b, c, d)):
        add(i, j, k)
    tri = np.array([f[:3] for f in faces])
    normals = np.array([f[3] for f in faces])
    for p in range(len(pts)):
        if p in (a, b, c, d):
            continue
        seen = np.einsum("ij,ij->i", normals, pts[p] - pts[tri[:, 0]]) > eps
        if not seen.any():
            continue
        edges = {(int(u), int(v)) for t in tri[seen] for u, v in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
        horizon = [(u, v) for u, v in edges if (v, u) not in edges]
        new = np.array([(u, v, p) for u, v in horizon])
        n = np.cross(pts[new[:, 1]] - pts[new[:, 0]], pts[new[:, 2]] - pts[new[:, 0]])
        keep = np.linalg.norm(n, axis=1) > 0
        tri = np.concatenate([tri[~seen], new[keep]])
        normals = np.concatenate([normals[~seen], n[keep] / np.linalg.norm(n[keep], axis=1)[:, None]])
    return pts[tri]


def arrows(tails: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Foxglove arrows (a Foxglove arrow points along +x of its pose) from tails and vectors
    (..., 3): (..., 8) tail x y z, orientation x y z w turning +x onto the vector, length
    (0 for a vector shorter than 1e-6 m: not drawn)."""
    length = np.sqrt(np.einsum("...k,...k->...", vectors, vectors))
    shown = length > 1e-6
    d = vectors / np.where(shown, length, 1.0)[..., None]
    q = np.stack([np.zeros_like(length), -d[..., 2], d[..., 1], 1.0 + d[..., 0]], axis=-1)
    back = d[..., 0] < -1.0 + 1e-12                 # half a turn about z
    q[back] = (0.0, 0.0, 1.0, 0.0)
    q /= np.linalg.norm(q, axis=-1)[..., None]
    return np.concatenate([tails, q, np.where(shown, length, 0.0)[..., None]], axis=-1)


def topic_name(name: str, taken: set) -> str:
    """``name`` as a topic segment a plot path can name (letters, digits, _), unique in ``taken``."""
    base = re.sub(r"[^A-Za-z0-9_]", "_", name) or "_"
    out, k = base, 2
    while out in taken:
        out, k = f"{base}_{k}", k + 1
    taken.add(out)
    return out


# --------------------------------------------------------------------------- what a frame shows

@dataclass
class ViewerFrame:
    """One display frame of a session, as plain Python numbers (world frame, SI), ready for
    messages: lists, not arrays (building a message from numpy scalars costs several times more)."""
    time: float
    pose: list                  # nb x [x y z qw qx qy qz]
    hip: list                   # nf x [x y z]
    god_object: list            # nf x [x y z]
    state: list                 # nf: 0 free, 1 stick, 2 slip
    finger_arrow: list          # nf x [tail xyz, quat xyzw, length]: the push on the body, head at the god-object
    force_arrow: list           # nb x [...]: residual force at the centre of mass
    torque_arrow: list          # nb x [...]: residual torque
    weakest_force_arrow: list   # nb x [...]: the weakest wrench's force part (length 0: not in closure)
    weakest_torque_arrow: list  # nb x [...]: its torque part, along the axis it turns about
    fingers: list               # nf plot dicts
    bodies: list                # nb plot dicts


class SceneModel:
    """What the viewer channels show of a recording's scene: names, topics, hull meshes, radii."""

    def __init__(self, header: dict, force_scale: float = FORCE_SCALE, torque_scale: float = TORQUE_SCALE):
        scene = header["scene"]
        self.header = header
        self.body_names = list(header["body_names"])
        self.finger_names = list(header["finger_names"])
        self.static = [bool(b["static"]) for b in scene["bodies"]]
        self.com_local = np.array([b["center_of_mass"] if b.get("center_of_mass") is not None else [0.0] * 3
                                   for b in scene["bodies"]], dtype=np.float64).reshape(-1, 3)
        self.radii = np.array([max(float(f["radius"]), MIN_GO_RADIUS) for f in scene["fingers"]])
        self.meshes = [[hull_triangles(np.asarray(p, dtype=np.float64).reshape(-1, 3)) for p in b["parts"]]
                       for b in scene["bodies"]]
        self.display_rate = float(header["rates"].get("display_hz") or scene.get("display_rate") or 30.0)
        self.force_scale, self.torque_scale = float(force_scale), float(torque_scale)
        taken = set()
        self.body_frames = [n if n != WORLD_FRAME else f"{n} (body)" for n in self.body_names]
        self.body_topics = [BODY_TOPIC + topic_name(n, taken) for n in self.body_names]
        taken = set()
        self.finger_topics = [FINGER_TOPIC + topic_name(n, taken) for n in self.finger_names]

    def frame_times(self, rec: Recording, rate: float | None = None) -> np.ndarray:
        """The display updates of a recording at ``rate`` (default: its display rate), s."""
        rate = float(rate or self.display_rate)
        t = rec.ticks["time"]
        first, last = int(np.ceil(t[0] * rate - 1e-9)), int(np.floor(t[-1] * rate + 1e-9))
        return np.arange(first, last + 1) / rate

    def batches(self, rec: Recording, times: np.ndarray, batch: int = 512):
        """FrameBatches at ``times`` (each frame the last tick at or before its time), ``batch``
        frames at a time (a long session's frames are never all in memory)."""
        with_normals = "normal" in (rec.ticks.dtype.names or ())
        for start in range(0, len(times), batch):
            part = times[start:start + batch]
            rows = rec.sample(part)
            grasp = self.grasp_numbers(rec, rows) if with_normals else None
            yield frame_batch(self, rec, rec.ticks[rows], part, normals=with_normals, grasp=grasp)

    def frames(self, rec: Recording, times: np.ndarray, batch: int = 512):
        """ViewerFrames at ``times`` (``batches``, one frame at a time)."""
        for b in self.batches(rec, times, batch):
            yield from viewer_frames(self, b)

    def grasp_numbers(self, rec, rows) -> dict:
        """The grasp analysis (analysis.analyse_recording without the volume: the viewer does
        not show it) at the records ``rows``, per row and body: grasp_arrays's answer."""
        unique, back = np.unique(rows, return_inverse=True)
        table = analysis.analyse_recording(rec, rows=unique, volume=False)
        return {k: v[back] for k, v in grasp_arrays(table, np.searchsorted(unique, table.snapshot),
                                                    len(unique), len(self.body_names)).items()}


GRASP_IDLE = {"held": 0.0, "closure": 0.0, "epsilon": 0.0, "resisted_force": 0.0, "mu_min": analysis.NONE,
              "slip_margin": 0.0, "slip_finger": -1, "load": 0.0, "grip_load": 0.0}


def grasp_arrays(table, snapshots, n: int, n_bodies: int) -> dict:
    """A GraspTable's per-body numbers as (n, nb) arrays (GRASP_IDLE where a body is not
    held; analysis.NONE for a value with no finite answer) and the weakest wrench as
    (n, nb, 6) with its centre (n, nb, 3) and torque radius (n, nb): zero out of closure.
    ``snapshots``: the table's sets' snapshot indices in 0..n-1."""
    q = table.quality
    values = {"held": np.ones(len(table.body)), "closure": q["force_closure"].astype(np.float64),
              "epsilon": q["epsilon"], "resisted_force": table.resisted_force, "mu_min": table.mu_min,
              "slip_margin": table.min_slip_margin, "slip_finger": table.min_slip_finger,
              "load": table.load_force, "grip_load": table.grip_ratio}
    out = {}
    for name, v in values.items():
        a = np.full((n, n_bodies), GRASP_IDLE[name], dtype=np.int64 if name == "slip_finger" else np.float64)
        v = np.asarray(v)
        a[snapshots, table.body] = np.where(np.isfinite(v), v, analysis.NONE) if a.dtype.kind == "f" else v
        out[name] = a
    weakest = np.zeros((n, n_bodies, 6))
    closed = q["force_closure"].astype(bool) & np.all(np.isfinite(q["weakest"]), axis=1)
    weakest[snapshots[closed], table.body[closed]] = q["weakest"][closed]
    center, radius = np.zeros((n, n_bodies, 3)), np.zeros((n, n_bodies))
    center[snapshots, table.body] = table.center
    radius[snapshots, table.body] = table.radius
    out.update(weakest=weakest, center=center, radius=radius)
    return out


def grasp_arrays_of(grasps, n_bodies: int) -> dict:
    """grasp_arrays's answer (n = 1) from one snapshot's BodyGrasp list (the live grasp
    monitor's: engine.grasp_display.GraspMonitor.grasps), so the live view shows the analysis
    the display update already made instead of making it again."""
    out = {name: np.full((1, n_bodies), v, dtype=np.int64 if name == "slip_finger" else np.float64)
           for name, v in GRASP_IDLE.items()}
    out.update(weakest=np.zeros((1, n_bodies, 6)), center=np.zeros((1, n_bodies, 3)), radius=np.zeros((1, n_bodies)))
    for g in grasps:
        b = g.body
        values = {"held": 1.0, "closure": float(g.force_closure), "epsilon": g.epsilon,
                  "resisted_force": g.resisted_force, "mu_min": g.mu_min, "slip_margin": g.min_slip_margin,
                  "load": g.load_force, "grip_load": g.grip_ratio}
        for name, v in values.items():
            out[name][0, b] = v if np.isfinite(v) else analysis.NONE
        out["slip_finger"][0, b] = g.min_slip_finger
        if g.force_closure and np.all(np.isfinite(g.weakest)):
            out["weakest"][0, b] = g.weakest
        out["center"][0, b], out["radius"][0, b] = g.center, g.radius
    return out


@dataclass
class FrameBatch:
    """What the display frames of a stretch of a session show, as arrays (n frames first; world
    frame, SI): the one computation behind every viewer (the Foxglove channels, the Rerun
    recording, both live views). Arrow vectors are scaled to metres (``SceneModel``'s force
    and torque scales); a zero vector is an arrow not drawn."""
    time: np.ndarray            # (n,) s
    tick: np.ndarray            # (n,) the haptic tick each frame shows
    pose: np.ndarray            # (n, nb, 7) x y z qw qx qy qz
    com: np.ndarray             # (n, nb, 3) centre of mass, world
    hip: np.ndarray             # (n, nf, 3)
    god_object: np.ndarray      # (n, nf, 3)
    orientation: np.ndarray     # (n, nf, 4) the finger's orientation qw qx qy qz (a convex finger's god-pose)
    state: np.ndarray           # (n, nf) 0 free, 1 stick, 2 slip
    contact: np.ndarray         # (n, nf) body index, -1 free
    force: np.ndarray           # (n, nf, 3) coupling force, N
    push_tail: np.ndarray       # (n, nf, 3) the finger's push on the body: its tail ...
    push: np.ndarray            # (n, nf, 3) ... and vector, its head at the god-object
    residual_force: np.ndarray  # (n, nb, 3) scaled residual force at the centre of mass
    residual_torque: np.ndarray  # (n, nb, 3) scaled residual torque
    weakest_center: np.ndarray  # (n, nb, 3)
    weakest_force: np.ndarray   # (n, nb, 3) the weakest wrench's force part (zero out of closure)
    weakest_torque: np.ndarray  # (n, nb, 3) its torque part, along the axis it turns about
    fingers: dict               # name -> (n, nf) numbers for plots (FINGER_SCHEMA's numbers)
    bodies: dict                # name -> (n, nb) numbers for plots (BODY_SCHEMA's numbers)
    normals: bool               # the records carry contact normals (the numbers that need one are there)
    grasp: bool                 # the grasp analysis is there (bodies' GRASP_IDLE numbers)


def frame_batch(model: SceneModel, rec, ticks: np.ndarray, times, normals: bool = True,
                grasp: dict | None = None) -> FrameBatch:
    """The FrameBatch of tick records (one per frame time), computed for all of them at once.
    ``normals=False``: the records carry no contact normals, so the finger numbers that need
    one (normal and tangential force, friction use, grip) are left out. ``grasp``:
    grasp_arrays's answer for these records (the analysis's per-body numbers and the
    weakest-wrench arrows), or None to leave them out."""
    m = finger_measures(rec, ticks)
    grip = body_grip(ticks["contact"], m["gl_normal_force"], len(model.body_names))
    pose, force, go, wrench = ticks["pose"], ticks["force"], ticks["god_object"], ticks["wrench"]
    com = pose[..., :3] + quat_rotate(pose[..., 3:], model.com_local[None])
    push = -force * model.force_scale
    n, nb = len(ticks), len(model.body_names)
    if grasp is not None:
        # The weakest wrench as the viewport draws it (grasp_display.weakest_geometry): its force
        # part from the centre of mass, twice the torque radius per unit; its torque part (a
        # ring there) as a second arrow along its axis, the same length per unit.
        reach = 2.0 * grasp["radius"][..., None]
        center = grasp["center"]
        weakest_force, weakest_torque = reach * grasp["weakest"][..., :3], reach * grasp["weakest"][..., 3:]
    else:
        center = weakest_force = weakest_torque = np.zeros((n, nb, 3))
    contact, state = ticks["contact"], ticks["state"]
    on = contact[:, None, :] == np.arange(nb)[None, :, None]       # (n, nb, nf)
    fingers = {"force_norm": m["gl_force"]}
    if normals:
        fingers.update({"normal_force": m["gl_normal_force"], "tangential_force": m["gl_tangential_force"],
                        "friction_use": m["gl_friction_use"]})
    fingers["penetration"] = np.linalg.norm(go - ticks["hip"], axis=-1)
    bodies = {"grip": grip} if normals else {}
    bodies.update({"residual_force": np.linalg.norm(wrench[..., :3], axis=-1),
                   "residual_torque": np.linalg.norm(wrench[..., 3:], axis=-1),
                   "fingers_in_contact": on.sum(axis=2),
                   "fingers_slipping": (on & (state[:, None, :] == 2)).sum(axis=2)})
    if grasp is not None:
        bodies.update({name: grasp[name] for name in GRASP_IDLE})
    names = ticks.dtype.names
    orientation = (ticks["orientation"] if "orientation" in names
                   else np.broadcast_to(np.array([1.0, 0.0, 0.0, 0.0]), go.shape[:-1] + (4,)))
    return FrameBatch(time=np.asarray(times, dtype=np.float64), tick=ticks["tick"].astype(np.int64), pose=pose,
                      com=com, hip=ticks["hip"], god_object=go, orientation=orientation, state=state,
                      contact=contact, force=force, push_tail=go - push, push=push,
                      residual_force=wrench[..., :3] * model.force_scale,
                      residual_torque=wrench[..., 3:] * model.torque_scale, weakest_center=center,
                      weakest_force=weakest_force, weakest_torque=weakest_torque, fingers=fingers, bodies=bodies,
                      normals=bool(normals), grasp=grasp is not None)


def frames_of(model: SceneModel, rec, ticks: np.ndarray, times, normals: bool = True,
              grasp: dict | None = None) -> list:
    """ViewerFrames of tick records (one per frame time): frame_batch's numbers as messages take them."""
    return viewer_frames(model, frame_batch(model, rec, ticks, times, normals, grasp))


def viewer_frames(model: SceneModel, b: FrameBatch) -> list:
    """A FrameBatch as ViewerFrames (Foxglove's arrows, plain Python numbers)."""
    finger_arrow = arrows(b.push_tail, b.push)
    force_arrow, torque_arrow = arrows(b.com, b.residual_force), arrows(b.com, b.residual_torque)
    weakest_force, weakest_torque = arrows(b.weakest_center, b.weakest_force), arrows(b.weakest_center,
                                                                                      b.weakest_torque)
    finger_names = np.array(model.finger_names + [""], dtype=object)
    names = np.array(model.body_names + [""], dtype=object)
    contact_name = names[np.where(b.contact >= 0, b.contact, len(model.body_names))]
    per_finger = {key: v for key, v in b.fingers.items() if key != "penetration"}
    per_body = {key: b.bodies[key] for key in ("grip", "residual_force", "residual_torque", "fingers_in_contact",
                                               "fingers_slipping") if key in b.bodies}
    out = []
    for k, t in enumerate(b.time.tolist()):
        f, st, cn = b.force[k].tolist(), b.state[k].tolist(), contact_name[k].tolist()
        meas = {key: v[k].tolist() for key, v in per_finger.items()}
        pen = b.fingers["penetration"][k].tolist()
        fingers = [{"time": t, "force": {"x": f[j][0], "y": f[j][1], "z": f[j][2]},
                    **{key: v[j] for key, v in meas.items()},
                    "state": st[j], "state_name": STATE_NAMES[st[j]] if 0 <= st[j] < 3 else str(st[j]),
                    "contact": cn[j], "penetration": pen[j]} for j in range(len(st))]
        p = b.pose[k].tolist()
        nums = {key: v[k].tolist() for key, v in per_body.items()}
        bodies = [{"time": t, "position": {"x": p[i][0], "y": p[i][1], "z": p[i][2]},
                   **{key: v[i] for key, v in nums.items()}} for i in range(len(p))]
        if b.grasp:
            for i, body in enumerate(bodies):
                if model.static[i]:
                    continue
                body.update({name: b.bodies[name][k, i].item() for name in GRASP_IDLE})
                body["slip_finger_name"] = str(finger_names[body["slip_finger"]])
        out.append(ViewerFrame(time=t, pose=p, hip=b.hip[k].tolist(), god_object=b.god_object[k].tolist(),
                               state=st, finger_arrow=finger_arrow[k].tolist(), force_arrow=force_arrow[k].tolist(),
                               torque_arrow=torque_arrow[k].tolist(),
                               weakest_force_arrow=weakest_force[k].tolist(),
                               weakest_torque_arrow=weakest_torque[k].tolist(), fingers=fingers, bodies=bodies))
    return out


# --------------------------------------------------------------------------- Foxglove messages

def _sdk():
    try:
        import foxglove
        import foxglove.messages
    except ImportError as ex:
        raise ImportError(f"the Foxglove channels need foxglove-sdk ({SDK_HINT}): {ex}") from None
    return foxglove


class FoxgloveChannels:
    """The viewer channels on one foxglove-sdk context (an MCAP file or a live server)."""

    def __init__(self, model: SceneModel, context):
        foxglove = _sdk()
        from foxglove import channels as ch
        self.fm = foxglove.messages
        self.model = model
        meta = {"grasp_lab_fingerprint": str(model.header.get("fingerprint", ""))}
        self.scene = ch.SceneUpdateChannel(TOPIC_SCENE, context=context, metadata=meta)
        self.bodies = ch.SceneUpdateChannel(TOPIC_BODIES, context=context, metadata=meta)
        self.transforms = ch.FrameTransformsChannel(TOPIC_TRANSFORMS, context=context, metadata=meta)
        self.log = ch.LogChannel(TOPIC_LOG, context=context, metadata=meta)
        self.fingers = [foxglove.Channel(t, schema=FINGER_SCHEMA, context=context) for t in model.finger_topics]
        self.body_plots = [foxglove.Channel(t, schema=BODY_SCHEMA, context=context) for t in model.body_topics]
        self._bodies_at = None
        self._body_entities = None
        self.time_offset = 0.0      # s added to session time in stamps (live: the wall clock)
        fm = self.fm
        c = lambda rgba: fm.Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])  # noqa: E731
        self._state_colors = {k: c(v) for k, v in STATE_COLORS.items()}
        self._colors = {name: c(v) for name, v in (("go", GO_COLOR), ("hip", HIP_COLOR), ("push", FINGER_FORCE_COLOR),
                                                   ("force", FORCE_COLOR), ("torque", TORQUE_COLOR),
                                                   ("body", BODY_COLOR), ("static", STATIC_BODY_COLOR),
                                                   ("weakest", WEAKEST_COLOR),
                                                   ("weakest_torque", WEAKEST_TORQUE_COLOR))}
        self._origin = self._pose((0.0, 0.0, 0.0))
        self._go_size = [fm.Vector3(x=2 * r, y=2 * r, z=2 * r) for r in model.radii.tolist()]
        self._hip_size = fm.Vector3(x=HIP_DIAMETER, y=HIP_DIAMETER, z=HIP_DIAMETER)
        self._strip = fm.LinePrimitiveLineType.LineStrip

    # ---- building blocks
    def _ns(self, t: float) -> int:
        return max(0, int(round((t + self.time_offset) * 1e9)))

    def _ts(self, t: float):
        ns = self._ns(t)
        return self.fm.Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)

    def _point(self, p):
        return self.fm.Point3(x=p[0], y=p[1], z=p[2])

    def _pose(self, p, q_xyzw=(0.0, 0.0, 0.0, 1.0)):
        fm = self.fm
        return fm.Pose(position=fm.Vector3(x=p[0], y=p[1], z=p[2]),
                       orientation=fm.Quaternion(x=q_xyzw[0], y=q_xyzw[1], z=q_xyzw[2], w=q_xyzw[3]))

    def _arrow(self, a, color):
        """An ``arrows`` row (tail, orientation, length) as a primitive; [] when not drawn."""
        length = a[7]
        if length <= 0.0:
            return []
        head = min(0.25 * length, 4 * ARROW_DIAMETER)
        return [self.fm.ArrowPrimitive(pose=self._pose(a[:3], a[3:7]), shaft_length=length - head,
                                       shaft_diameter=ARROW_DIAMETER, head_length=head,
                                       head_diameter=2.5 * ARROW_DIAMETER, color=color)]

    def _body_entities_of(self, stamp):
        fm, model = self.fm, self.model
        if self._body_entities is None:
            self._body_entities = []
            for i, parts in enumerate(model.meshes):
                color = self._colors["static" if model.static[i] else "body"]
                triangles = [fm.TriangleListPrimitive(
                    pose=self._origin, points=[self._point(v) for v in tri.reshape(-1, 3).tolist()],
                    color=color) for tri in parts]
                self._body_entities.append((model.body_frames[i], f"body/{model.body_names[i]}", triangles))
        return [fm.SceneEntity(timestamp=stamp, frame_id=frame, id=eid, frame_locked=True, triangles=tris,
                               metadata=[fm.KeyValuePair(key="kind", value="body")])
                for frame, eid, tris in self._body_entities]

    # ---- messages of a frame
    def scene_update(self, fr: ViewerFrame):
        fm, model, colors = self.fm, self.model, self._colors
        stamp = self._ts(fr.time)
        entities = []
        for j, name in enumerate(model.finger_names):
            s = fr.state[j]
            go, hip = fr.god_object[j], fr.hip[j]
            entities.append(fm.SceneEntity(
                timestamp=stamp, frame_id=WORLD_FRAME, id=f"finger/{name}",
                metadata=[fm.KeyValuePair(key="state", value=STATE_NAMES[s] if 0 <= s < 3 else str(s))],
                spheres=[fm.SpherePrimitive(pose=self._pose(go), size=self._go_size[j], color=colors["go"]),
                         fm.SpherePrimitive(pose=self._pose(hip), size=self._hip_size, color=colors["hip"])],
                lines=[fm.LinePrimitive(type=self._strip, pose=self._origin, thickness=SPRING_WIDTH,
                                        points=[self._point(hip), self._point(go)],
                                        color=self._state_colors.get(s, self._state_colors[0]))],
                arrows=self._arrow(fr.finger_arrow[j], colors["push"])))
        for i, name in enumerate(model.body_names):
            if model.static[i]:
                continue
            entities.append(fm.SceneEntity(
                timestamp=stamp, frame_id=WORLD_FRAME, id=f"residual/{name}",
                arrows=self._arrow(fr.force_arrow[i], colors["force"]) + self._arrow(fr.torque_arrow[i],
                                                                                    colors["torque"])))
            weakest = (self._arrow(fr.weakest_force_arrow[i], colors["weakest"])
                       + self._arrow(fr.weakest_torque_arrow[i], colors["weakest_torque"]))
            # Always sent (empty out of closure), so a viewer drops the last frame's arrow.
            entities.append(fm.SceneEntity(timestamp=stamp, frame_id=WORLD_FRAME, id=f"weakest/{name}",
                                           arrows=weakest))
        return fm.SceneUpdate(entities=entities)

    def frame_transforms(self, fr: ViewerFrame):
        fm = self.fm
        stamp = self._ts(fr.time)
        return fm.FrameTransforms(transforms=[
            fm.FrameTransform(timestamp=stamp, parent_frame_id=WORLD_FRAME, child_frame_id=frame,
                              translation=fm.Vector3(x=p[0], y=p[1], z=p[2]),
                              rotation=fm.Quaternion(x=p[4], y=p[5], z=p[6], w=p[3]))
            for frame, p in zip(self.model.body_frames, fr.pose)])

    def resend_bodies(self) -> None:
        """The body meshes go out again with the next frame (a viewer joined)."""
        self._bodies_at = None

    def log_frame(self, fr: ViewerFrame) -> None:
        """Everything a display update shows, stamped with its session time."""
        ns = self._ns(fr.time)
        if self._bodies_at is None or fr.time >= self._bodies_at + BODIES_REPEAT - 1e-9:
            self.bodies.log(self.fm.SceneUpdate(entities=self._body_entities_of(self._ts(fr.time))),
                            log_time=ns)
            self._bodies_at = fr.time
        self.transforms.log(self.frame_transforms(fr), log_time=ns)
        self.scene.log(self.scene_update(fr), log_time=ns)
        for channel, numbers in zip(self.fingers, fr.fingers):
            channel.log(numbers, log_time=ns)
        for channel, numbers in zip(self.body_plots, fr.bodies):
            channel.log(numbers, log_time=ns)

    def log_event(self, e: dict) -> None:
        fm = self.fm
        t = float(e.get("time", 0.0))
        kind = str(e.get("kind", ""))
        level = (fm.LogLevel.Warning if kind in WARNING_EVENTS else
                 fm.LogLevel.Error if kind in ERROR_EVENTS else fm.LogLevel.Info)
        text = " ".join(str(x) for x in (kind, e.get("subject", ""), e.get("detail", "")) if x != "")
        self.log.log(fm.Log(timestamp=self._ts(t), level=level, message=text, name="grasp_lab",
                            file=self.model.header.get("source", "") or "", line=max(0, int(e.get("tick", 0)))),
                     log_time=self._ns(t))


WARNING_EVENTS = {"slip", "forces_off", "clamp_begin", "device_lost", "device_stall", "device_dropped"}
ERROR_EVENTS = {"overflow", "device_estop"}
_XYZ = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
FINGER_SCHEMA = {"type": "object", "title": "grasp_lab.FingerNumbers", "properties": {
    "time": {"type": "number", "description": "session time, s"},
    "force": {**_XYZ, "description": "coupling force k (GO - HIP) + damping, N, world"},
    "force_norm": {"type": "number", "description": "|force|, N"},
    "normal_force": {"type": "number", "description": "|Fn| along the contact normal, N"},
    "tangential_force": {"type": "number", "description": "|Ft|, N"},
    "friction_use": {"type": "number", "description": "|Ft| / (mu |Fn|), mu of the current cone (mu_s sticking, mu_d slipping): 1 at its edge, -1 a finger pulling"},
    "state": {"type": "integer", "description": "0 free, 1 stick, 2 slip"},
    "state_name": {"type": "string"},
    "contact": {"type": "string", "description": "the body touched, empty when free"},
    "penetration": {"type": "number", "description": "|GO - HIP|, m"}}}
BODY_SCHEMA = {"type": "object", "title": "grasp_lab.BodyNumbers", "properties": {
    "time": {"type": "number", "description": "session time, s"},
    "position": {**_XYZ, "description": "body frame origin, m, world"},
    "grip": {"type": "number", "description": "sum of |Fn| of the fingers touching it, N"},
    "residual_force": {"type": "number", "description": "|residual force|, N"},
    "residual_torque": {"type": "number", "description": "|residual torque| about the centre of mass, N m"},
    "fingers_in_contact": {"type": "integer"},
    "fingers_slipping": {"type": "integer"},
    # The grasp analysis (docs/analysis.md), dynamic bodies of recordings with contact normals:
    "held": {"type": "number", "description": "1 while a finger touches it, else 0"},
    "closure": {"type": "number", "description": "1 in force closure, else 0"},
    "epsilon": {"type": "number", "description": "radius of the largest ball about 0 inside the grasp wrench space (0 out of closure)"},
    "resisted_force": {"type": "number", "description": "force the grasp resists in its weakest direction, N"},
    "mu_min": {"type": "number", "description": "least friction coefficient that closes the grasp (-1: none up to 10, or not held)"},
    "slip_margin": {"type": "number", "description": "smallest mu |Fn| - |Ft| of its fingers, N"},
    "slip_finger": {"type": "integer", "description": "index of the finger with that margin, -1 none"},
    "slip_finger_name": {"type": "string"},
    "load": {"type": "number", "description": "m |a - g|: the weight plus the inertial force the grip must balance, N"},
    "grip_load": {"type": "number", "description": "grip force / load force (-1: no load)"}}}


# --------------------------------------------------------------------------- layout

def layout_json(model: SceneModel) -> str:
    """A Foxglove layout for the copy of a recording of this scene: the 3-D scene beside force,
    friction-use and grip plots, the fingers' stick/slip states and the event log."""
    _sdk()
    import foxglove.layouts as fl
    fingers = list(zip(model.finger_names, model.finger_topics))
    bodies = [(n, t) for n, t, static in zip(model.body_names, model.body_topics, model.static) if not static]

    def plot(title, series, y_min=None):
        return fl.PlotPanel(title=title, config=fl.PlotConfig(
            paths=[fl.PlotSeries(value=v, label=label, enabled=True) for label, v in series],
            show_legend=True, legend_display="top", min_y_value=y_min, is_synced=True))

    # The camera on the first moving body, far enough back to see a hand around it.
    scene = model.header["scene"]["bodies"]
    moving = [b for b in scene if not b["static"]] or scene
    target = tuple(round(float(x), 4) for x in moving[0]["position"]) if moving else (0.0, 0.0, 0.0)
    size = max((float(np.ptp(np.asarray(p, dtype=np.float64).reshape(-1, 3), axis=0).max())
                for p in (moving[0]["parts"] if moving else [])), default=0.1)
    distance = round(max(0.3, 8.0 * size), 3)
    three_d = fl.ThreeDeePanel(title="Grasp", config=fl.ThreeDeeConfig(
        follow_tf=WORLD_FRAME, fixed_frame=WORLD_FRAME,
        camera_state=fl.ThreeDeeCameraState(distance=distance, perspective=True, phi=60.0, theta_offset=45.0,
                                            target=target),
        topics={TOPIC_SCENE: fl.BaseRendererSceneUpdateTopicSettings(visible=True),
                TOPIC_BODIES: fl.BaseRendererSceneUpdateTopicSettings(visible=True)}))
    forces = plot("Finger forces (N): normal, tangential",
                  [(f"{n} |Fn|", f"{t}.normal_force") for n, t in fingers]
                  + [(f"{n} |Ft|", f"{t}.tangential_force") for n, t in fingers], y_min=0)
    use = plot("Friction use |Ft| / (mu |Fn|): slip at 1", [(n, f"{t}.friction_use") for n, t in fingers], y_min=0)
    grip = plot("Bodies: grip (N) and residual force (N)",
                [(f"{n} grip", f"{t}.grip") for n, t in bodies]
                + [(f"{n} residual", f"{t}.residual_force") for n, t in bodies], y_min=0)
    closure = plot("Grasp: force closure (0/1) and epsilon",
                   [(f"{n} closure", f"{t}.closure") for n, t in bodies]
                   + [(f"{n} epsilon", f"{t}.epsilon") for n, t in bodies], y_min=0)
    states = fl.StateTransitionsPanel(title="Finger states", config=fl.StateTransitionsConfig(
        paths=[fl.StateTransitionsSeries(value=f"{t}.state_name", label=n) for n, t in fingers], is_synced=True))
    log = fl.LogPanel(title="Events", config=fl.LogConfig(topic_to_render=TOPIC_LOG, show_time=True))
    item = fl.SplitItem
    content = fl.SplitContainer(direction="row", items=[
        item(proportion=3, content=fl.SplitContainer(direction="column", items=[
            item(proportion=3, content=three_d), item(proportion=1, content=log)])),
        item(proportion=2, content=fl.SplitContainer(direction="column", items=[
            item(content=forces), item(content=use), item(content=grip), item(content=closure),
            item(content=states)]))])
    return json.dumps(json.loads(fl.Layout(content=content).to_json()), indent=1) + "\n"


# --------------------------------------------------------------------------- export

def export_foxglove(rec: Recording, path: str, rate: float | None = None, force_scale: float = FORCE_SCALE,
                    torque_scale: float = TORQUE_SCALE) -> dict:
    """A viewer-ready copy of ``rec`` at ``path`` (MCAP, Foxglove's schemas), written to a
    temporary file beside it and renamed when complete, and its layout (``layout_path``).
    Returns {"frames", "events", "bytes", "rate", "layout"}."""
    if os.path.exists(path) and os.path.exists(rec.path) and os.path.samefile(path, rec.path):
        raise ValueError(f"{path}: that is the recording itself; write the copy to another file")
    foxglove = _sdk()
    from foxglove.mcap import MCAPWriteOptions
    model = SceneModel(rec.header, force_scale, torque_scale)
    times = model.frame_times(rec, rate)
    if not len(times):
        raise ValueError(f"{rec.path}: the recording is shorter than one display frame")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise OutputError(f"{path}: its folder {folder} is missing")
    out = AtomicFile(path)          # a folder, a busy or unwritable path refused here, naming it
    context = foxglove.Context()
    try:
        writer = foxglove.open_mcap(out.file, context=context, writer_options=MCAPWriteOptions(profile=""))
        channels = FoxgloveChannels(model, context)
        events = sorted(rec.events, key=lambda e: float(e.get("time", 0.0)))
        k = 0
        for fr in model.frames(rec, times):     # events interleaved: the file is in log-time order
            while k < len(events) and float(events[k].get("time", 0.0)) <= fr.time:
                channels.log_event(events[k])
                k += 1
            channels.log_frame(fr)
        for e in events[k:]:
            channels.log_event(e)
        writer.close()
    except Exception as ex:         # the SDK's own error type too (a write that failed: a full disk)
        out.discard()
        why = getattr(ex, "strerror", None) or f"{type(ex).__name__}: {ex}"
        if not isinstance(ex, OSError):     # the SDK's error hides the errno: the free space says it
            free = shutil.disk_usage(os.path.dirname(out.path)).free
            why += f"; {free:,} bytes free there"
        raise OutputError(f"{out.path}: could not be written ({why}); it is as it was") from None
    except BaseException:
        out.discard()
        raise
    out.commit()
    layout = write_whole(layout_path(path), layout_json(model))
    return {"frames": len(times), "events": len(events), "bytes": os.path.getsize(path),
            "rate": float(rate or model.display_rate), "layout": layout}


def layout_path(path: str) -> str:
    """Where the layout of a copy at ``path`` goes: beside it, OUT.layout.json."""
    return os.path.splitext(path)[0] + ".layout.json"
