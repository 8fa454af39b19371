"""Shared scene builders for the core tests (imported as a plain module)."""
import numpy as np


def box_points(hx, hy, hz, center=(0.0, 0.0, 0.0)):
    """The 8 corners of a box with half extents (hx, hy, hz)."""
    c = np.asarray(center, dtype=float)
    return np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)]) + c


def prism_points(radius, half_length, sides=6):
    """A regular prism along x (a pencil)."""
    angles = 2 * np.pi * np.arange(sides) / sides
    ring = np.stack([np.zeros(sides), radius * np.cos(angles), radius * np.sin(angles)], axis=1)
    return np.concatenate([ring + [-half_length, 0, 0], ring + [half_length, 0, 0]])


def quat_to_matrix(q):
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


# --------------------------------------------------------------------------- the hooked mug's handle
# The sample scene mug_hook's mug (sample_scenes/library.py), decomposed as the add-on's Collision
# Shape Automatic does it, held still: a finger pressed up into the inside of its handle slides
# along it across the seams between the handle's convex parts.

def mug_parts():
    """(parts, ring centre, ring major radius, ring minor radius): the mug's convex parts,
    body frame, and its handle ring (in the x-z plane)."""
    import os
    import sys
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    sys.path.insert(0, root)
    from sample_scenes import library
    from addon.engine.decompose import decompose
    mug = next(b for b in library.mug_hook().bodies if b.name == "Mug")
    verts, faces = library._shape_geometry(mug.shape)
    tris = [(f[0], f[k], f[k + 1]) for f in faces for k in range(1, len(f) - 1)]
    parts = decompose(np.array(verts), np.array(tris))
    ring_shape, offset = mug.shape.shapes[1]
    return parts, np.array(offset, float), ring_shape.major, ring_shape.minor


MUG_FINGER = dict(radius=0.007, stiffness=1500.0, damping=3.0)   # mug_hook's finger


def mug_handle_slide(load=4.0, start_deg=20.0, end_deg=80.0, seconds=2.0, hold=0.3, dt=1e-3, renderer="xfca"):
    """(world, hips): the static mug at the origin and one finger whose HIP presses ``load``
    newtons outward into the inside of the handle, then slides along the ring's inner arc from
    ``start_deg`` to ``end_deg`` (angle about the ring centre in the x-z plane, 90 = top) in
    ``seconds`` with an eased start and end. ``hips`` is (ticks, 3), one HIP per step."""
    import graspcore
    parts, centre, major, minor = mug_parts()
    w = graspcore.World()
    w.add_body(parts=parts, static=True, mu_s=0.6, mu_d=0.5)
    k = MUG_FINGER["stiffness"]
    r_hip = major - minor - MUG_FINGER["radius"] + load / k

    def at(deg):
        a = np.radians(deg)
        return centre + r_hip * np.array([np.cos(a), 0.0, np.sin(a)])

    # Approach along the radius from the ring's centre, then hold, then slide.
    start = at(start_deg)
    below = centre + (start - centre) * 0.4
    approach = [below + (start - below) * s for s in np.linspace(0.0, 1.0, int(0.2 / dt))]
    held = [start] * int(hold / dt)
    n = int(seconds / dt)
    s = np.linspace(0.0, 1.0, n)
    ease = s * s * (3.0 - 2.0 * s)
    slide = [at(start_deg + (end_deg - start_deg) * e) for e in ease]
    hips = np.array(approach + held + slide + [at(end_deg)] * int(hold / dt))
    w.add_finger(position=below, renderer=renderer, **MUG_FINGER)
    return w, hips


def run_ticks(w, hips, dt=1e-3):
    """Steps the world along the HIPs, one tick record per step (tick 0: the start)."""
    ticks = np.zeros(len(hips) + 1, dtype=w.tick_dtype())
    ticks[0] = w.tick_record(tick=0)
    for t, h in enumerate(hips, start=1):
        w.set_hips(np.asarray(h, float).reshape(1, 3))
        w.step(dt)
        ticks[t] = w.tick_record(tick=t)
    return ticks


def bowl_parts(outer=0.04, wall=0.006, rings=8, segments=24):
    """A hemispherical bowl (opening up, rim at z = 0, centre of its sphere at the origin) as a
    closed mesh, decomposed as the add-on's Collision Shape Automatic does it: its convex parts."""
    import os
    import sys
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    sys.path.insert(0, root)
    from addon.engine.decompose import decompose
    inner = outer - wall
    verts, tris = [], []

    def ring(radius, k):                      # k = 0 at the rim ... rings at the bottom pole
        a = 0.5 * np.pi * k / rings
        return [(radius * np.cos(a) * np.cos(2 * np.pi * j / segments), radius * np.cos(a) * np.sin(2 * np.pi * j / segments),
                 -radius * np.sin(a)) for j in range(segments)]

    for surface, radius in ((0, outer), (1, inner)):
        for k in range(rings):
            verts += ring(radius, k)
        verts.append((0.0, 0.0, -radius))     # pole
    n_side = rings * segments + 1
    for surface in (0, 1):
        base = surface * n_side
        pole = base + rings * segments
        for k in range(rings):
            for j in range(segments):
                a, b = base + k * segments + j, base + k * segments + (j + 1) % segments
                if k + 1 < rings:
                    c, d = base + (k + 1) * segments + (j + 1) % segments, base + (k + 1) * segments + j
                    quad = [(a, d, c), (a, c, b)] if surface == 0 else [(a, c, d), (a, b, c)]
                    tris += quad
                else:
                    tris.append((a, pole, b) if surface == 0 else (a, b, pole))
    for j in range(segments):                 # the rim joins the two surfaces
        a, b = j, (j + 1) % segments
        c, d = n_side + (j + 1) % segments, n_side + j
        tris += [(a, b, c), (a, c, d)]
    return decompose(np.array(verts), np.array(tris)), outer, inner


def bowl_trace(renderer="xfca", load=3.0, seconds=1.5, radius=0.006, stiffness=1000.0, damping=2.0,
               mu=(0.6, 0.5)):
    """(world, hips): a fingertip pressed ``load`` N into the inside of the static bowl traced
    from one side of it through the bottom to the other (a 120 degree arc)."""
    import graspcore
    parts, outer, inner = bowl_parts()
    w = graspcore.World()
    w.add_body(parts=parts, static=True, mu_s=mu[0], mu_d=mu[1])
    r_hip = inner - radius + load / stiffness

    def at(deg):                               # angle from straight down, in the x-z plane
        a = np.radians(deg)
        return r_hip * np.array([np.sin(a), 0.0, -np.cos(a)])

    start = at(-60.0)
    approach = [start * s for s in np.linspace(0.5, 1.0, 200)]
    n = int(seconds / 1e-3)
    s = np.linspace(0.0, 1.0, n)
    ease = s * s * (3.0 - 2.0 * s)
    hips = np.array(approach + [start] * 200 + [at(-60.0 + 120.0 * e) for e in ease] + [at(60.0)] * 200)
    w.add_finger(radius=radius, stiffness=stiffness, damping=damping, position=hips[0], renderer=renderer)
    return w, hips
