"""Device profiles: what a haptic device can render, one TOML file per device (docs/devices.md,
"Can this device do this task?").

The built-in profiles are ``profiles/*.toml`` beside this file, each citing its maker's data sheet;
a user's own device is one more such file, named by its path (``--device my_rig.toml``) or put in a
folder listed in ``GRASP_LAB_PROFILES`` (``:``-separated). A profile's name is its file's stem.
"""
from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass

import numpy as np

BUILTIN_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "profiles")
PROFILES_ENV = "GRASP_LAB_PROFILES"
SHAPES = {"box": ("size",), "cylinder": ("radius", "height"), "sphere": ("radius",)}
POSITIVE = ("peak_force", "continuous_force", "stable_stiffness", "effector_radius", "duty_time")
# Most end-effectors a profile may have (a glove-like rig has five a hand; two hands ten).
MAX_EFFECTORS = 10


class ProfileError(ValueError):
    """A profile that is not there or not valid: the message names the file and the field."""


@dataclass
class Workspace:
    """The volume an end-effector reaches, in the device frame (x right, y away from the user, z up),
    centred on ``center``: a box (full extents ``size``), an upright cylinder or a sphere."""
    shape: str
    center: np.ndarray
    size: np.ndarray | None = None      # box: full extents x, y, z
    radius: float = 0.0                 # cylinder, sphere
    height: float = 0.0                 # cylinder: along z

    def margin(self, q: np.ndarray) -> np.ndarray:
        """Signed distance inside the volume of each point q (N, 3) in the device frame: positive
        inside, 0 on the boundary, negative outside (per axis for a box: the smallest slack)."""
        d = q - self.center
        if self.shape == "box":
            return np.min(self.size / 2 - np.abs(d), axis=-1)
        if self.shape == "cylinder":
            return np.minimum(self.radius - np.hypot(d[..., 0], d[..., 1]), self.height / 2 - np.abs(d[..., 2]))
        return self.radius - np.linalg.norm(d, axis=-1)


@dataclass
class Profile:
    name: str
    title: str
    source: str
    path: str
    end_effectors: int
    workspaces: list                    # a Workspace per end-effector
    peak_force: float                   # N
    continuous_force: float             # N
    stable_stiffness: float             # N/m, at 1 kHz
    effector_radius: float              # m
    can_cross: bool
    duty_time: float                    # s: the thermal time constant of the duty check

    def line(self) -> str:
        """One line for ``grasp-lab fit --list``: the name first."""
        w = self.workspaces[0]
        if w.shape == "box":
            vol = "box " + " x ".join(f"{v * 1000:g}" for v in w.size) + " mm"
        elif w.shape == "cylinder":
            vol = f"cylinder {w.radius * 2000:g} across x {w.height * 1000:g} mm"
        else:
            vol = f"sphere {w.radius * 2000:g} mm across"
        n = self.end_effectors
        return (f"{self.name}  {self.title}: {n} end-effector{'s' if n > 1 else ''}, {vol}"
                f"{' each' if n > 1 else ''}, {self.peak_force:g} N peak, {self.continuous_force:g} N continuous, "
                f"{self.stable_stiffness:g} N/m, crossing {'yes' if self.can_cross else 'no'}")


def search_dirs() -> list:
    extra = [d for d in os.environ.get(PROFILES_ENV, "").split(os.pathsep) if d]
    return [BUILTIN_DIR] + extra


def available() -> dict:
    """Every profile found, {name: path}; a user's folder may override a built-in name."""
    found = {}
    for folder in search_dirs():
        if not os.path.isdir(folder):
            continue
        for entry in sorted(os.listdir(folder)):
            if entry.endswith(".toml"):
                found[entry[:-5]] = os.path.join(folder, entry)
    return found


def find(name_or_path: str) -> Profile:
    """A profile by name (built-in or in GRASP_LAB_PROFILES) or by the path of its file."""
    if name_or_path.endswith(".toml") or os.sep in name_or_path:
        if not os.path.isfile(name_or_path):
            raise ProfileError(f"device profile {name_or_path}: no such file")
        return load(name_or_path)
    known = available()
    if name_or_path not in known:
        raise ProfileError(f"unknown device profile {name_or_path!r} (known: {', '.join(sorted(known))}; "
                           f"or give the path of a .toml profile)")
    return load(known[name_or_path])


def load_all() -> list:
    return [load(p) for p in available().values()]


def _number(path, data, key, positive=True):
    if key not in data:
        raise ProfileError(f"device profile {path}: field {key!r} is missing")
    v = data[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ProfileError(f"device profile {path}: field {key!r} must be a number, got {v!r}")
    if positive and v <= 0:
        raise ProfileError(f"device profile {path}: field {key!r} must be positive, got {v!r}")
    return float(v)


def _vector(path, key, v):
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ProfileError(f"device profile {path}: {key} must be three numbers, got {v!r}")
    return a


def load(path: str) -> Profile:
    """A profile file read and checked: every field there, numbers positive, one line naming
    the file and the field otherwise."""
    try:
        with open(path, "rb") as f:
            text = f.read().decode("utf-8")
    except OSError as ex:
        raise ProfileError(f"device profile {path}: {ex.strerror}") from None
    except UnicodeDecodeError:
        raise ProfileError(f"device profile {path}: not UTF-8 text") from None
    return loads(text, path)


def loads(text: str, path: str) -> Profile:
    """A profile from its file's text (``path`` names it: its stem is the profile's name); what a
    sweep's workers get, which may have no copy of the file."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as ex:
        raise ProfileError(f"device profile {path}: not valid TOML ({ex})") from None
    for key in ("title", "source"):
        if not isinstance(data.get(key), str) or not data[key].strip():
            raise ProfileError(f"device profile {path}: field {key!r} is missing (a text)")
    n = data.get("end_effectors")
    if n is None:
        raise ProfileError(f"device profile {path}: field 'end_effectors' is missing")
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_EFFECTORS:
        raise ProfileError(f"device profile {path}: field 'end_effectors' must be a whole number in "
                           f"1 .. {MAX_EFFECTORS}, got {n!r}")
    values = {k: _number(path, data, k) for k in POSITIVE}
    if values["continuous_force"] > values["peak_force"]:
        raise ProfileError(f"device profile {path}: continuous_force {values['continuous_force']:g} N is above "
                           f"peak_force {values['peak_force']:g} N")
    if not isinstance(data.get("can_cross"), bool):
        raise ProfileError(f"device profile {path}: field 'can_cross' is missing (true or false)")
    ws = data.get("workspace")
    if not isinstance(ws, dict):
        raise ProfileError(f"device profile {path}: field 'workspace' is missing "
                           f"(e.g. workspace = {{ shape = \"box\", size = [0.16, 0.07, 0.12] }})")
    shape = ws.get("shape")
    if shape not in SHAPES:
        raise ProfileError(f"device profile {path}: workspace shape must be one of {', '.join(SHAPES)}, got {shape!r}")
    size = None
    radius = height = 0.0
    if shape == "box":
        if "size" not in ws:
            raise ProfileError(f"device profile {path}: field 'workspace.size' is missing")
        size = _vector(path, "workspace.size", ws["size"])
        if np.any(size <= 0):
            raise ProfileError(f"device profile {path}: workspace.size must be positive, got {ws['size']!r}")
    else:
        radius = _number(path, {f"workspace.{k}": v for k, v in ws.items()}, "workspace.radius")
        if shape == "cylinder":
            height = _number(path, {f"workspace.{k}": v for k, v in ws.items()}, "workspace.height")
    centers = data.get("effector_centers", [[0.0, 0.0, 0.0]] * n)
    if not isinstance(centers, list) or len(centers) != n:
        raise ProfileError(f"device profile {path}: effector_centers must list {n} centre(s), one an end-effector")
    workspaces = [Workspace(shape, _vector(path, "effector_centers", c), size, radius, height) for c in centers]
    name = os.path.splitext(os.path.basename(path))[0]
    return Profile(name=name, title=data["title"].strip(), source=data["source"].strip(), path=path,
                   end_effectors=n, workspaces=workspaces, can_cross=data["can_cross"], **values)
