"""Scene description: what a grasp scene is, independent of Blender.

The Blender side (``..convert``) fills these dataclasses from objects; everything
here is plain Python + numpy (+ trimesh for mass properties), so it is tested
without bpy. ``build_world`` turns a description into a ``graspcore.World``.

Frames: a body's *frame* is its object's world matrix with scale and shear removed
(translation + rotation). Mesh points are given in that frame with scale, shear and
parenting already applied, so the core only ever sees rigid poses.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import defaults

# Limits for the "absurd scale" check, in metres (largest bounding-box extent).
MIN_SIZE = 1e-4     # 0.1 mm
MAX_SIZE = 100.0    # 100 m
MAX_DISTANCE = 1e4  # m from the origin, for a body or a fingertip
# A body whose volume is below this fraction of its bounding box is "zero volume".
MIN_VOLUME_FRACTION = 1e-9


class SceneError(ValueError):
    """A scene that cannot be simulated. The message names the object and the problem."""

    def __init__(self, obj_name: str, problem: str):
        self.obj_name = obj_name
        self.problem = problem
        super().__init__(f'"{obj_name}": {problem}')


@dataclass
class MeshData:
    """A triangle mesh in a body frame (metres)."""
    vertices: np.ndarray            # (V, 3) float64
    triangles: np.ndarray           # (T, 3) int
    source: str = ""                # object the mesh came from (for messages)


@dataclass
class MassProperties:
    mass: float
    volume: float
    center_of_mass: np.ndarray      # (3,) body frame
    inertia: np.ndarray             # (3, 3) about the centre of mass, body axes


@dataclass
class BodyDesc:
    name: str
    static: bool
    parts: list                     # list of (N_i, 3) arrays: convex parts, body frame
    meshes: list                    # list of MeshData: the solid(s), for mass properties
    position: np.ndarray            # (3,) world
    orientation: np.ndarray         # (4,) w, x, y, z
    mass: float | None = None       # kg; None: use density
    density: float = 1000.0         # kg/m^3
    mu_s: float = field(default_factory=lambda: defaults.body("mu_s"))
    mu_d: float = field(default_factory=lambda: defaults.body("mu_d"))
    viscosity: float = field(default_factory=lambda: defaults.body("viscosity"))
    mass_properties: MassProperties | None = None


@dataclass
class FingerDesc:
    name: str
    position: np.ndarray            # (3,) world, initial HIP
    radius: float = field(default_factory=lambda: defaults.finger("radius"))
    stiffness: float = field(default_factory=lambda: defaults.finger("stiffness"))
    damping: float = field(default_factory=lambda: defaults.finger("damping"))
    channel: int = 0
    # A convex finger (a Finger-role mesh: a pad, a palm): its hull's points in the finger's
    # frame (m, scale applied), and that frame's orientation (w, x, y, z). None: a sphere of radius.
    points: np.ndarray | None = None
    orientation: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    renderer: str = field(default_factory=defaults.renderer)      # "xfca" or "cursor" (sphere fingers)
    cursor_mass: float = field(default_factory=lambda: defaults.finger("cursor_mass"))
    # A soft sphere fingertip (docs/physics.md "Soft fingertips"): the radius rho (m) of the patch it
    # presses, its torsional friction up to mu Fn rho; 0: none.
    torsion: float = 0.0


@dataclass
class SceneDesc:
    gravity: tuple = field(default_factory=lambda: tuple(defaults.world("gravity")))
    gyroscopic: bool = field(default_factory=lambda: bool(defaults.world("gyroscopic")))
    haptic_rate: float = field(default_factory=lambda: float(defaults.runtime("haptic_rate")))
    display_rate: float = 30.0
    bodies: list = field(default_factory=list)
    fingers: list = field(default_factory=list)

    def body_index(self, name: str) -> int:
        for i, b in enumerate(self.bodies):
            if b.name == name:
                return i
        raise KeyError(name)


# Collision hulls are given to the core with at most this many points: the extreme
# points of the part along as many evenly spread directions. The hull shrinks by at
# most ~0.2 % of the part's size (0.15 mm on a 10 cm sphere, the worst case: every
# vertex on the hull); mass properties always use the full mesh.
HULL_MAX_POINTS = 1024
# A convex finger's hull has at most this many vertices (the core's GC_MAX_FINGER_VERTICES):
# a mesh with more is reduced to the extreme points along as many directions.
FINGER_MAX_POINTS = 32


def _sphere_directions(k: int) -> np.ndarray:
    i = np.arange(k) + 0.5
    phi = np.arccos(1.0 - 2.0 * i / k)
    theta = np.pi * (1.0 + 5.0 ** 0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)


def reduce_hull_points(points: np.ndarray, max_points: int = HULL_MAX_POINTS) -> np.ndarray:
    """At most ``max_points`` of ``points`` (plus the 6 axis extremes) spanning nearly the
    same convex hull: the extreme point along each of ``max_points`` directions."""
    if len(points) <= max_points:
        return points
    centred = (points - points.mean(axis=0)).astype(np.float32)
    dirs = np.vstack([np.eye(3), -np.eye(3), _sphere_directions(max_points - 6)]).astype(np.float32)
    best_val = np.full(len(dirs), -np.inf, dtype=np.float32)
    best_idx = np.zeros(len(dirs), dtype=np.int64)
    chunk = 16384
    for start in range(0, len(points), chunk):
        proj = dirs @ centred[start:start + chunk].T          # (K, chunk)
        j = np.argmax(proj, axis=1)
        v = proj[np.arange(len(dirs)), j]
        better = v > best_val
        best_val[better] = v[better]
        best_idx[better] = j[better] + start
    return points[np.unique(best_idx)]


# --------------------------------------------------------------------------- checks

def _as_points(name: str, pts) -> np.ndarray:
    a = np.asarray(pts, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise SceneError(name, f"expected (N, 3) points, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise SceneError(name, "has non-finite vertex coordinates (NaN or infinity)")
    return a


def check_scale(name: str, points: np.ndarray) -> None:
    """Refuse sizes that are almost certainly a unit or scale mistake."""
    if len(points) == 0:
        raise SceneError(name, "has no vertices")
    check_distance(name, points)
    extent = float(np.max(points.max(axis=0) - points.min(axis=0)))
    if extent > MAX_SIZE or extent < MIN_SIZE:
        raise SceneError(
            name,
            f"absurd scale: largest extent is {extent:.3g} m (expected {MIN_SIZE:g} m to "
            f"{MAX_SIZE:g} m); apply or fix the object's scale (units are metres)")


def check_distance(name: str, points) -> None:
    """Within MAX_DISTANCE of the origin: farther out, millimetre geometry loses its precision
    (and its volume reads as zero)."""
    far = float(np.max(np.abs(np.asarray(points, dtype=np.float64)))) if np.size(points) else 0.0
    if not far <= MAX_DISTANCE:
        raise SceneError(name, f"is {far:.3g} m from the origin (at most {MAX_DISTANCE:g} m); move it "
                               f"near the origin")


def check_hull_points(name: str, points: np.ndarray) -> None:
    """A convex part needs >= 4 points spanning a volume (not flat, not a line)."""
    if len(points) < 4:
        raise SceneError(name, f"convex part has {len(points)} vertices; at least 4 are needed")
    centred = points - points.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    if s[0] <= 0 or s[-1] < 1e-9 * s[0]:
        raise SceneError(name, "has zero volume: its vertices are flat (coplanar) or collinear; give it "
                                 "thickness (Solidify modifier, or extrude it)")


def mesh_to_trimesh(mesh: MeshData):
    """Validated trimesh.Trimesh of a closed, outward-facing, non-degenerate mesh."""
    import trimesh

    name = mesh.source
    v = _as_points(name, mesh.vertices)
    t = np.asarray(mesh.triangles, dtype=np.int64).reshape(-1, 3)
    if len(t) == 0:
        raise SceneError(name, "mesh has no faces")
    check_scale(name, v)
    tm = trimesh.Trimesh(v, t, process=True, validate=False)
    if not tm.is_watertight:
        # Count edges used by exactly one face: the holes' borders.
        edges = np.sort(tm.edges, axis=1)
        _, counts = np.unique(edges, axis=0, return_counts=True)
        n_open = int(np.sum(counts == 1))
        n_bad = int(np.sum(counts > 2))
        detail = f"{n_open} boundary edges" if n_open else f"{n_bad} edges shared by more than two faces"
        raise SceneError(name, f"mesh is open (not watertight: {detail}); close the holes or "
                               f"use the convex hull of a closed mesh")
    if not tm.is_winding_consistent:
        raise SceneError(name, "mesh has inconsistent face winding; recalculate normals")
    extent = float(np.max(tm.extents))
    volume = float(tm.volume)
    if abs(volume) <= MIN_VOLUME_FRACTION * extent ** 3:
        raise SceneError(name, "has zero volume (flat or degenerate mesh); give it thickness (Solidify "
                               "modifier, or extrude it)")
    if volume < 0:
        raise SceneError(name, "mesh is inverted (normals point inward, negative volume); "
                               "recalculate normals outside")
    return tm


def mass_properties(name: str, meshes, mass: float | None, density: float) -> MassProperties:
    """Mass, centre of mass and inertia about it of the union of closed meshes.

    With ``mass`` given, the density is derived from the total volume; otherwise the
    mass is ``density * volume``. Each mesh is validated first.
    """
    if not meshes:
        raise SceneError(name, "has no solid mesh to compute its mass from")
    if mass is None and not (density > 0 and np.isfinite(density)):
        raise SceneError(name, f"density must be > 0, got {density}")
    if mass is not None and not (mass > 0 and np.isfinite(mass)):
        raise SceneError(name, f"mass must be > 0, got {mass}")
    tms = [mesh_to_trimesh(m) for m in meshes]
    vols = np.array([tm.volume for tm in tms])
    volume = float(vols.sum())
    rho = density if mass is None else mass / volume
    total = rho * volume
    coms = np.array([tm.center_mass for tm in tms])
    com = (vols[:, None] * coms).sum(axis=0) / volume
    inertia = np.zeros((3, 3))
    for tm, vol, c in zip(tms, vols, coms):
        # trimesh: inertia about the mesh's own centre of mass for density 1.
        i_c = np.asarray(tm.moment_inertia) * rho
        d = c - com
        m_i = rho * vol
        inertia += i_c + m_i * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return MassProperties(mass=total, volume=volume, center_of_mass=com, inertia=inertia)


def torsion_problem(f: FingerDesc) -> str:
    """Why a finger's ``torsion`` (the add-on's Soft Tip Radius) cannot be, or ''. The core takes
    it on a sphere finger rendered by god-objects only."""
    if not (np.isfinite(f.torsion) and f.torsion >= 0):
        return f"Soft Tip Radius (torsion, m) must be a finite number >= 0, got {f.torsion}"
    if f.torsion and f.points is not None:
        return (f"Soft Tip Radius (torsion) is for a fingertip sphere (an Empty): a mesh finger's patch "
                f"resists twisting of its own; set it to 0 (got {f.torsion})")
    if f.torsion and f.renderer == "cursor":
        return (f"Soft Tip Radius (torsion) needs the God-Objects (xFCA) renderer: the light-mass cursor "
                f"has no torsional friction; set the renderer to xfca or the Soft Tip Radius to 0 (got {f.torsion})")
    return ""


def check_ranges(desc: SceneDesc) -> None:
    """Every value of the scene in the legal range of its ``--set`` key (engine/limits.py): a
    scene's own 5 m fingertip is refused as ``--set radius=5`` is. Raises SceneError."""
    from .limits import check_set_value

    def check(name, key, value):
        if why := check_set_value(key, float(value)):
            raise SceneError(name, f"{why} (the range of --set {key})")
    check("scene", "haptic_rate", desc.haptic_rate)
    for g in desc.gravity:
        check("scene", "gravity", g)
    for b in desc.bodies:
        for key in ("mu_s", "mu_d", "viscosity"):
            check(b.name, key, getattr(b, key))
        if b.mass is not None and not b.static:
            check(b.name, "mass", b.mass)
    for f in desc.fingers:
        for key in ("stiffness", "damping", "cursor_mass") + (("radius",) if f.points is None else ()):
            check(f.name, key, getattr(f, key))


def prepare(desc: SceneDesc) -> SceneDesc:
    """Validate every body and finger; fill in mass properties. Raises SceneError."""
    check_ranges(desc)
    seen = set()
    for b in desc.bodies:
        if b.name in seen:
            raise SceneError(b.name, "duplicate body name")
        seen.add(b.name)
        check_distance(b.name, b.position)
        if not b.parts:
            raise SceneError(b.name, "has no collision shape (no mesh and no child mesh parts)")
        parts = []
        for p in b.parts:
            p = _as_points(b.name, p)
            check_scale(b.name, p)
            check_hull_points(b.name, p)
            parts.append(reduce_hull_points(p))
        b.parts = parts
        if not (0 <= b.mu_d <= b.mu_s):
            raise SceneError(b.name, f"friction must satisfy 0 <= mu_d <= mu_s (mu_s={b.mu_s}, mu_d={b.mu_d})")
        if b.viscosity < 0:
            raise SceneError(b.name, f"viscosity must be >= 0, got {b.viscosity}")
        if not b.static:
            b.mass_properties = mass_properties(b.name, b.meshes, b.mass, b.density)
    for f in desc.fingers:
        if not (f.radius >= 0 and f.stiffness > 0 and f.damping >= 0):
            raise SceneError(f.name, f"finger needs radius >= 0, stiffness > 0, damping >= 0 "
                                     f"(got {f.radius}, {f.stiffness}, {f.damping})")
        if not np.all(np.isfinite(f.position)):
            raise SceneError(f.name, "finger position is not finite")
        if f.renderer not in defaults.renderers() or not f.cursor_mass >= 0:
            renderers = " or ".join(map(repr, defaults.renderers()))
            raise SceneError(f.name, f"finger needs renderer {renderers} and cursor mass >= 0 "
                                     f"(got {f.renderer!r}, {f.cursor_mass})")
        if why := torsion_problem(f):
            raise SceneError(f.name, why)
        if f.points is not None:
            if f.renderer == "cursor":
                raise SceneError(f.name, "a mesh finger is a convex finger, rendered by its god-objects (xFCA): "
                                         "the light-mass cursor takes a sphere finger (an Empty)")
            p = _as_points(f.name, f.points)
            check_scale(f.name, p)
            check_hull_points(f.name, p)
            f.points = reduce_hull_points(p, FINGER_MAX_POINTS)
            q = np.asarray(f.orientation, dtype=np.float64)
            if q.shape != (4,) or not np.all(np.isfinite(q)) or not np.linalg.norm(q) > 0:
                raise SceneError(f.name, f"finger orientation must be a non-zero quaternion, got {f.orientation}")
            f.orientation = q / np.linalg.norm(q)
    return desc


# --------------------------------------------------------------------------- world

@dataclass
class WorldHandle:
    """A built world and the mapping from description order to core ids."""
    world: object
    body_ids: list
    finger_ids: list
    desc: SceneDesc


DEFAULT_MAX_CONTACTS = 2048     # graspcore.World's (graspcore.h)


def build_world(desc: SceneDesc, graspcore, exact: bool = False) -> WorldHandle:
    """Create a ``graspcore.World`` from a prepared description. ``exact``: capacities for just
    this scene (a world made a thousand times over by a sweep: the default contact storage is
    most of a world's making); contact pairs are capped as by default, so a run is the same
    bit for bit (part pairs, the most there can be, or the default cap if that is fewer)."""
    n_b, n_f = len(desc.bodies), len(desc.fingers)
    size = {}
    if exact:
        parts = sum(len(b.parts) for b in desc.bodies)
        size = {"max_parts": max(1, parts),
                "max_contacts": max(1, min(DEFAULT_MAX_CONTACTS, parts * (parts - 1) // 2))}
    world = graspcore.World(gravity=tuple(float(g) for g in desc.gravity),
                            gyroscopic=bool(desc.gyroscopic),
                            max_bodies=max(256, n_b) if not exact else max(1, n_b),
                            max_fingers=max(32, n_f) if not exact else max(1, n_f), **size)
    body_ids, finger_ids = [], []
    for b in desc.bodies:
        kw = dict(position=tuple(map(float, b.position)),
                  orientation=tuple(map(float, b.orientation)),
                  static=bool(b.static), mu_s=float(b.mu_s), mu_d=float(b.mu_d),
                  viscosity=float(b.viscosity))
        if len(b.parts) == 1:
            kw["points"] = b.parts[0]
        else:
            kw["points"] = None
            kw["parts"] = list(b.parts)
        if b.static:
            kw["mass"] = 1.0
        else:
            mp = b.mass_properties
            kw.update(mass=float(mp.mass), inertia=np.asarray(mp.inertia, dtype=np.float64),
                      center_of_mass=tuple(map(float, mp.center_of_mass)))
        try:
            points = kw.pop("points")
            body_ids.append(world.add_body(points, **kw))
        except ValueError as ex:
            raise SceneError(b.name, f"rejected by the core: {ex}") from ex
    for f in desc.fingers:
        convex = {} if f.points is None else dict(points=np.ascontiguousarray(f.points, dtype=np.float64),
                                                   orientation=tuple(map(float, f.orientation)))
        if f.torsion:
            convex["torsion"] = float(f.torsion)
        try:
            finger_ids.append(world.add_finger(radius=float(f.radius), stiffness=float(f.stiffness),
                                               damping=float(f.damping),
                                               position=tuple(map(float, f.position)), **convex,
                                               renderer=str(f.renderer), cursor_mass=float(f.cursor_mass)))
        except ValueError as ex:
            raise SceneError(f.name, f"rejected by the core: {ex}") from ex
    return WorldHandle(world=world, body_ids=body_ids, finger_ids=finger_ids, desc=desc)
