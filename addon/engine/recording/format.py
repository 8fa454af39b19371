"""The recording format (docs/recording-format.md): topics, the tick record's layout (the
core's, stored in the file's schema), the header with the scene, and the version check.
Plain Python + numpy; the layout alone comes from the core."""
from __future__ import annotations

import hashlib
import json
import os
import platform
import sys
import time

import numpy as np

FORMAT_VERSION = 1
PROFILE = "grasp_lab"
TOPIC_HEADER = "/grasp_lab/header"
TOPIC_TICKS = "/grasp_lab/ticks"
TOPIC_EVENTS = "/grasp_lab/events"
TOPIC_END = "/grasp_lab/end"
TICK_SCHEMA = "grasp_lab.TickBlock"
TICK_ENCODING = "grasp_lab.tick_records"    # message: whole records, back to back
JSON_SCHEMA = {"type": "object"}
BLOCK_TICKS = 256           # ticks per message at most
STATE_NAMES = ("free", "stick", "slip")  # the file's state codes: graspcore.FINGER_STATES (test_recording.py)
UNITS = {"length": "m", "mass": "kg", "time": "s", "force": "N", "torque": "N m",
         "velocity": "m/s", "angular_velocity": "rad/s (world)", "orientation": "quaternion w x y z",
         "stiffness": "N/m", "damping": "N s/m", "rate": "Hz", "period_us": "us", "work_us": "us"}
# The tick record's layout is the core's (graspcore.tick_dtype, checked against
# gc_tick_record_size): the writer takes it from there and stores it in the file's schema,
# which readers build their record type from (a recording opens without the core). The
# fields every reader needs:
REQUIRED_FIELDS = ("tick", "time", "object_time", "state_hash", "period_us", "work_us", "flags", "adopted",
                   "log_us")
FLAG_FORCES_ENABLED = 1  # the file's flags bit: graspcore.TICK_FORCES_ENABLED (test_recording.py)


class RecordingError(ValueError):
    """A file that cannot be read as a recording. The message names the file and the problem."""


def tick_dtype(n_bodies: int, n_fingers: int) -> np.dtype:
    """The core's tick record type (graspcore.tick_dtype): what a recording is written with."""
    from .. import core_loader
    return core_loader.load().tick_dtype(n_bodies, n_fingers)


def schema_of(dtype: np.dtype) -> dict:
    """The tick schema stored in the file: every field with its type, shape and offset."""
    fields = []
    for name in dtype.names:
        sub, offset = dtype.fields[name][:2]
        base, shape = (sub.base, list(sub.shape)) if sub.shape else (sub, [])
        fields.append({"name": name, "type": base.str, "shape": shape, "offset": offset})
    return {"record_size": dtype.itemsize, "byte_order": "little", "fields": fields,
            "message": "a whole number of records back to back, in tick order"}


def dtype_of(schema: dict) -> np.dtype:
    try:
        spec = {"names": [f["name"] for f in schema["fields"]],
                "formats": [np.dtype((f["type"], tuple(f["shape"]))) if f["shape"] else np.dtype(f["type"])
                            for f in schema["fields"]],
                "offsets": [int(f["offset"]) for f in schema["fields"]],
                "itemsize": int(schema["record_size"])}
        dtype = np.dtype(spec)
    except (KeyError, TypeError, ValueError) as ex:
        raise ValueError(f"tick schema is malformed ({ex})") from None
    missing = set(REQUIRED_FIELDS) - set(dtype.names)
    if missing:
        raise ValueError(f"tick schema lacks {sorted(missing)}")
    return dtype


def addon_version() -> str:
    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))    # addon/
    for folder in (here, os.path.dirname(here)):
        path = os.path.join(folder, "blender_manifest.toml")
        if os.path.exists(path):
            with open(path) as fh:
                for line in fh:
                    if line.startswith("version"):
                        return line.split("=", 1)[1].strip().strip('"')
    return "unknown"


def scene_to_dict(desc) -> dict:
    """A prepared ``engine.scene.SceneDesc`` as JSON-able data, exact (floats round-trip)."""
    def arr(a):
        return np.asarray(a, dtype=np.float64).tolist()
    bodies = []
    for b in desc.bodies:
        mp = b.mass_properties
        bodies.append({
            "name": b.name, "static": bool(b.static), "parts": [arr(p) for p in b.parts],
            "position": arr(b.position), "orientation": arr(b.orientation),
            "mu_s": float(b.mu_s), "mu_d": float(b.mu_d), "viscosity": float(b.viscosity),
            "mass": None if mp is None else float(mp.mass),
            "volume": None if mp is None else float(mp.volume),
            "center_of_mass": None if mp is None else arr(mp.center_of_mass),
            "inertia": None if mp is None else arr(mp.inertia)})
    fingers = []
    for f in desc.fingers:
        finger = {"name": f.name, "position": arr(f.position), "radius": float(f.radius),
                  "stiffness": float(f.stiffness), "damping": float(f.damping), "channel": int(f.channel),
                  "renderer": str(f.renderer), "cursor_mass": float(f.cursor_mass)}
        if f.points is not None:  # a convex finger; a sphere's entry has no points
            finger.update(points=arr(f.points), orientation=arr(f.orientation))
        if f.torsion:             # a soft fingertip; others have no entry (their fingerprints unchanged)
            finger["torsion"] = float(f.torsion)
        fingers.append(finger)
    return {"gravity": [float(g) for g in desc.gravity], "gyroscopic": bool(desc.gyroscopic),
            "haptic_rate": float(desc.haptic_rate), "display_rate": float(desc.display_rate),
            "bodies": bodies, "fingers": fingers}


def scene_from_dict(data: dict):
    """The ``SceneDesc`` a recording was made with (prepared: mass properties included)."""
    from ..scene import BodyDesc, FingerDesc, MassProperties, SceneDesc
    bodies = []
    for b in data["bodies"]:
        mp = None if b.get("mass") is None else MassProperties(
            mass=b["mass"], volume=b["volume"], center_of_mass=np.array(b["center_of_mass"]),
            inertia=np.array(b["inertia"]))
        bodies.append(BodyDesc(name=b["name"], static=b["static"],
                               parts=[np.array(p, dtype=np.float64).reshape(-1, 3) for p in b["parts"]],
                               meshes=[], position=np.array(b["position"]),
                               orientation=np.array(b["orientation"]), mass=b.get("mass"),
                               mu_s=b["mu_s"], mu_d=b["mu_d"], viscosity=b["viscosity"], mass_properties=mp))
    fingers = [FingerDesc(name=f["name"], position=np.array(f["position"]), radius=f["radius"],
                          stiffness=f["stiffness"], damping=f["damping"], channel=f.get("channel", 0),
                          points=None if f.get("points") is None else np.array(f["points"], dtype=np.float64).reshape(-1, 3),
                          orientation=np.array(f.get("orientation", (1.0, 0.0, 0.0, 0.0)), dtype=np.float64),
                          **{k: f[k] for k in ("renderer", "cursor_mass", "torsion") if k in f})
               for f in data["fingers"]]
    return SceneDesc(gravity=tuple(data["gravity"]), gyroscopic=data["gyroscopic"],
                     haptic_rate=data["haptic_rate"], display_rate=data.get("display_rate", 30.0),
                     bodies=bodies, fingers=fingers)


def fingerprint(scene: dict) -> str:
    """sha256 of the scene as recorded (geometry, masses, friction, fingers, gravity)."""
    text = json.dumps(scene, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def make_header(desc, *, mode: str, haptic_rate: float, source: str = "", fps: float | None = None,
                device: dict | None = None, runtime: dict | None = None, extra: dict | None = None) -> dict:
    """Everything needed to read, bake and re-simulate a recording."""
    import mcap
    scene = scene_to_dict(desc)
    versions = {"grasp_lab": addon_version(), "python": platform.python_version(),
                "numpy": np.__version__, "mcap": getattr(mcap, "__version__", "")}
    try:
        import graspcore
        versions["graspcore"] = getattr(graspcore, "__version__", "present")
    except ImportError:
        pass
    bpy = sys.modules.get("bpy")       # only when running inside Blender (never imported here)
    if bpy is not None:
        versions["blender"] = bpy.app.version_string
    header = {
        "format": "grasp_lab recording", "format_version": FORMAT_VERSION,
        "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "mode": mode, "source": source, "versions": versions, "units": UNITS,
        "rates": {"haptic_hz": float(haptic_rate), "display_hz": float(desc.display_rate),
                  "fps": None if fps is None else float(fps)},
        "device": device or {}, "runtime": runtime or {},
        "body_names": [b.name for b in desc.bodies], "finger_names": [f.name for f in desc.fingers],
        "fingerprint": fingerprint(scene), "scene": scene,
    }
    header.update(extra or {})
    return header


def check_version(path, header):
    if header.get("format") != "grasp_lab recording":
        raise RecordingError(f"{path}: not a Grasp Lab recording (its header says format "
                             f"{header.get('format')!r})")
    version = header.get("format_version")
    if not isinstance(version, int):
        raise RecordingError(f"{path}: header has no format version")
    if version > FORMAT_VERSION:
        raise RecordingError(f"{path}: recording format version {version} is newer than this Grasp Lab "
                             f"reads (version {FORMAT_VERSION}); open it with a newer Grasp Lab")
