"""Convex fingers and area contacts (docs/physics.md "Area contacts") against closed forms.

A convex finger is a hull in its own frame driven by a pose HIP; each hull vertex is a point of
contact with a god-object of its own, and each body vertex inside the finger a reversed one. The
patch of god-objects is the chapter's pressure integral taken as a sum: its resultant acts at the
pressure centroid, its moment is the pressure torque."""
import time

import numpy as np
import pytest

import graspcore
from scenes import box_points, prism_points, quat_to_matrix

DT = 1e-3
G = 9.81


def tilt_deg(w, body):
    R = quat_to_matrix(w.body_pose(body)[1])
    return float(np.degrees(np.arccos(np.clip(R[2, 2], -1.0, 1.0))))


def min_jerk(u):
    u = min(max(u, 0.0), 1.0)
    return 10 * u**3 - 15 * u**4 + 6 * u**5


# ---- the finger definition -------------------------------------------------------------------

def test_convex_finger_keeps_its_hull_vertices_and_pose():
    w = graspcore.World(gravity=(0, 0, 0))
    inner = np.array([[0.0, 0.0, 0.0]])  # an interior point is dropped from the vertices
    f = w.add_finger(radius=0.0, points=np.vstack([box_points(0.02, 0.03, 0.005), inner]),
                     position=(1, 2, 3), orientation=(2, 0, 0, 0))
    pos, q = w.finger_pose(f)
    assert pos == (1, 2, 3) and q == (1, 0, 0, 0)  # normalised
    s = np.sin(np.radians(30) / 2)
    w.set_finger_pose(f, (0, 0, 0.5), (np.cos(np.radians(30) / 2), 0, 0, s))
    np.testing.assert_allclose(w.finger_pose(f)[1], (np.cos(np.radians(30) / 2), 0, 0, s))
    assert w.finger_torque(f) == (0, 0, 0) and w.finger_contacts(f) == []
    sphere = w.add_finger()
    assert w.finger_pose(sphere)[1] == (1, 0, 0, 0) and w.finger_torque(sphere) == (0, 0, 0)


@pytest.mark.parametrize("points, message", [
    (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float), "points: their convex hull is degenerate"),
    (np.zeros((3, 3)), "points: a convex finger needs at least 4"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.nan]]), "points"),
    (np.array([[np.cos(a) * np.cos(b), np.sin(a) * np.cos(b), np.sin(b)]
               for a in np.linspace(0, 2 * np.pi, 12, endpoint=False) for b in (-0.5, 0.0, 0.5)]),
     "points: their hull has 36 vertices, a convex finger takes at most 32"),
])
def test_bad_convex_finger_is_refused_naming_points(points, message):
    w = graspcore.World()
    with pytest.raises(ValueError, match=message):
        w.add_finger(points=np.ascontiguousarray(points))
    assert w.finger_count == 0


def test_bad_orientation_is_refused():
    w = graspcore.World()
    with pytest.raises(ValueError, match="orientation: must be a non-zero quaternion"):
        w.add_finger(points=box_points(0.01, 0.01, 0.01), orientation=(0, 0, 0, 0))
    f = w.add_finger(points=box_points(0.01, 0.01, 0.01))
    with pytest.raises(ValueError, match="orientation"):
        w.set_finger_pose(f, (0, 0, 0), (np.nan, 0, 0, 1))
    assert w.finger_pose(f)[1] == (1, 0, 0, 0)


# ---- a plate on a flat pad under a tilting moment ---------------------------------------------

PAD = 0.03          # pad half width (m), 4 top vertices at (+-PAD, +-PAD)
PLATE_H = 0.005     # plate half thickness
PLATE_M = 0.4
K = 1000.0


def plate_on_pad(offset, seconds=3.0, ramp=1.0):
    """A 20 x 20 x 1 cm plate whose centre of mass is `offset` (m) off the pad's centre along x,
    on a 6 x 6 cm pad, gravity ramped in over `ramp` s (quasi-static loading)."""
    w = graspcore.World(gravity=(0, 0, 0))
    pad = w.add_finger(radius=0.0, stiffness=K, damping=2.0, position=(0, 0, -0.005),
                       points=box_points(PAD, PAD, 0.005))
    plate = w.add_body(box_points(0.1, 0.1, PLATE_H), mass=PLATE_M, position=(0, 0, PLATE_H),
                       center_of_mass=(offset, 0, 0))
    tilts = []
    for i in range(int(round(seconds / DT))):
        w.set_gravity((0, 0, -G * min((i + 1) * DT / ramp, 1.0)))
        w.step(DT)
        tilts.append(tilt_deg(w, plate))
    return w, pad, plate, np.array(tilts)


@pytest.mark.parametrize("fraction", [0.5, 0.9, 0.98])
def test_plate_below_the_tipping_limit_rests_at_the_static_tilt(fraction):
    d = fraction * PAD
    w, pad, plate, tilts = plate_on_pad(d)
    W = PLATE_M * G
    # Four springs k at (+-a, +-a): tilt stiffness 4 k a^2, less the weight's lever W h as the
    # centre of mass (h above the pad's face) swings over: theta = W d / (4 k a^2 - W h).
    h = PLATE_H + W / (4 * K)  # the plate sinks W / 4k into the springs
    expected = np.degrees(W * d / (4 * K * PAD**2 - W * h))
    np.testing.assert_allclose(tilts[-1], expected, rtol=0.01)
    assert tilts.max() < 1.2 * expected
    # The point-equivalent force: the weight, at the pressure centroid, under the centre of mass.
    force = np.array(w.finger_force(pad))
    np.testing.assert_allclose(force, [0, 0, -W], atol=5e-5)  # the last of the settling swing
    pos, q = w.body_pose(plate)
    com = np.array(pos) + quat_to_matrix(q) @ [d, 0, 0]
    np.testing.assert_allclose(w.god_object(pad)[:2], com[:2], atol=1e-5)
    # Its moment about the HIP is the weight's: (c - hip) x F, the centroid c weighted by depth
    # (the normal forces; the small tangential parts of the tilted springs leave 1e-5 of it).
    torque = np.array(w.finger_torque(pad))
    np.testing.assert_allclose(torque, np.cross(np.array(w.god_object(pad)) - w.finger_pose(pad)[0], force),
                               rtol=1e-4, atol=1e-9)
    assert torque[1] == pytest.approx(W * com[0], rel=1e-3)
    contacts = w.finger_contacts(pad)
    assert len(contacts) == 4 and all(c["state"] == "stick" and not c["reversed"] for c in contacts)
    # Each point carries F/4 + (moment share): the two near the load more than the two far.
    fz = sorted(-c["force"][2] for c in contacts)
    np.testing.assert_allclose(fz, [W / 4 * (1 - com[0] / PAD)] * 2 + [W / 4 * (1 + com[0] / PAD)] * 2,
                               rtol=2e-3)
    np.testing.assert_allclose([c["normal"] for c in contacts], [-quat_to_matrix(q)[:, 2]] * 4, atol=1e-9)  # out of the plate's bottom face


@pytest.mark.parametrize("fraction", [1.02, 1.1])
def test_plate_beyond_the_tipping_limit_tips_over(fraction):
    """Past the pad's edge the far springs cannot pull: the pressure centroid has reached the
    edge and the plate turns over it."""
    _, _, _, tilts = plate_on_pad(fraction * PAD)
    assert tilts.max() > 45.0


def test_pad_twisted_on_a_table_slips_at_the_torsional_limit():
    """Torsion about the normal: each of the 4 points sticks until its friction circle, mu_s k
    depth, is reached at radius r = a sqrt 2, i.e. at mu_s F_n r, then slides at mu_d F_n r."""
    mu_s, mu_d, depth, a = 0.5, 0.3, 0.002, 0.02
    w = graspcore.World(gravity=(0, 0, 0))
    w.add_body(box_points(0.2, 0.2, 0.05, center=(0, 0, -0.05)), static=True, mu_s=mu_s, mu_d=mu_d)
    pad = w.add_finger(radius=0.0, stiffness=K, position=(0, 0, 0.01), points=box_points(a, a, 0.005, center=(0, 0, 0.005)))
    for i in range(1, 21):
        w.set_hip(pad, (0, 0, 0.01 + (-depth - 0.01) * i / 20))
        w.step(DT)
    Fn, r = 4 * K * depth, a * np.sqrt(2)
    np.testing.assert_allclose(w.finger_force(pad), [0, 0, Fn], atol=1e-9)
    peak, states = 0.0, []
    for deg in np.arange(0.1, 6.0, 0.1):
        phi = np.radians(deg)
        w.set_finger_pose(pad, (0, 0, -depth), (np.cos(phi / 2), 0, 0, np.sin(phi / 2)))
        w.step(DT)
        tz = -w.finger_torque(pad)[2]
        states.append(w.finger_state(pad))
        if states[-1] == "stick":
            assert tz == pytest.approx(4 * K * r * r * np.sin(phi), rel=1e-6)  # the stuck corners' springs
            assert tz <= mu_s * Fn * r * (1 + 1e-9)
        peak = max(peak, tz)
    assert states[0] == "stick" and states[-1] == "slip"
    assert peak > 0.97 * mu_s * Fn * r
    assert tz == pytest.approx(mu_d * Fn * r, rel=1e-3)


# ---- a box carried sideways at rising acceleration --------------------------------------------

def test_box_on_a_pad_tips_where_statics_says():
    """A 6 x 6 x 12 cm box on a 4 x 4 cm pad (half width b = 2 cm, centre of mass h = 6 cm up),
    the pad accelerated sideways (smoothly over 1 s, then held 1 s). Statics on a rigid pad: it
    tips at a = g b / h. On the springs the back edge sinks first: at lift-off the back pair
    carries W, sinks W / 2k, the box has turned theta = W / (4 k b) and tips at
    a = g (b - h theta) / (h + b theta) (2 % below the rigid value here)."""
    k, b, h, m = 10000.0, 0.02, 0.06, 0.5
    theta = m * G / (4 * k * b)
    a_tip = G * (b - h * theta) / (h + b * theta)
    assert a_tip == pytest.approx(G * b / h, rel=0.03)

    def carry(accel):
        w = graspcore.World()
        pad = w.add_finger(radius=0.0, stiffness=k, damping=20.0, position=(0, 0, -0.005),
                           points=box_points(b, b, 0.005))
        box = w.add_body(box_points(0.03, 0.03, h), mass=m, position=(0, 0, h))
        w.step(DT, steps=500)
        x = v = 0.0
        worst = 0.0
        for i in range(2000):
            u = min((i + 1) * DT / 1.0, 1.0)
            v += accel * (3 * u * u - 2 * u**3) * DT
            x += v * DT
            w.set_hip(pad, (x, 0, -0.005))
            w.step(DT)
            worst = max(worst, tilt_deg(w, box))
        return worst

    assert carry(0.95 * a_tip) < 1.0
    assert carry(1.05 * a_tip) > 45.0


# ---- a body smaller than the finger's face, push-through, energy, creep ------------------------

def test_small_box_rests_on_a_wider_palm():
    """The palm's vertices are all outside the box: the box's corners inside the palm carry it
    (reversed contacts), each W/4, sunk W/4k, level and stuck."""
    w = graspcore.World()
    palm = w.add_finger(radius=0.0, stiffness=K, damping=2.0, position=(0, 0, -0.01),
                        points=box_points(0.05, 0.05, 0.01))
    box = w.add_body(box_points(0.01, 0.01, 0.01), mass=0.1, position=(0.005, 0, 0.0105))
    w.step(DT, steps=2000)
    W = 0.1 * G
    contacts = w.finger_contacts(palm)
    assert len(contacts) == 4 and all(c["reversed"] and c["state"] == "stick" for c in contacts)
    np.testing.assert_allclose([c["force"][2] for c in contacts], [-W / 4] * 4, rtol=1e-6)
    np.testing.assert_allclose(w.body_pose(box)[0], [0.005, 0, 0.01 - W / (4 * K)], atol=1e-7)
    assert tilt_deg(w, box) < 1e-6
    np.testing.assert_allclose(w.god_object(palm), [0.005, 0, -W / (4 * K)], atol=1e-7)


PALM = dict(radius=0.0, stiffness=K, damping=2.0)


@pytest.mark.parametrize("kind", ["pencil", "can"])
def test_long_body_across_a_palm_rests_on_points_along_its_edge(kind):
    """A 15 cm pencil (a capsule) and a 12 cm can (a 16-sided prism) lying across a 9 cm palm: no
    vertex of either is over the palm, nor any palm vertex under them. Points along the body's
    edge, no further apart than the palm is thick (2 cm), carry it: it rests on the palm's face
    (sunk W / n k over its n points), level and still."""
    w = graspcore.World()
    palm = w.add_finger(position=(0, 0, -0.01), points=box_points(0.045, 0.04, 0.01), **PALM)
    if kind == "pencil":
        body = w.add_body(np.array([[-0.075, 0, 0], [0.075, 0, 0]]), radius=0.004, mass=0.01, position=(0, 0, 0.004))
        rest, mass = 0.004, 0.01
    else:  # on a face (on an edge it would balance on one line of points and roll over)
        rest, mass = 0.033 * np.cos(np.pi / 16), 0.35
        half = np.pi / 32
        body = w.add_body(prism_points(0.033, 0.06, sides=16), mass=mass, position=(0, 0, rest),
                          orientation=(np.cos(half), np.sin(half), 0, 0))
    w.step(DT, steps=2000)
    contacts = w.finger_contacts(palm)
    n = 5 if kind == "pencil" else 10  # five along each edge of the bottom face
    assert len(contacts) == n and all(c["reversed"] for c in contacts)
    xs = sorted(c["point"][0] for c in contacts)
    assert xs[0] > -0.045 and xs[-1] < 0.045 and np.all(np.diff(xs) <= 0.02 + 1e-9)
    np.testing.assert_allclose(w.finger_force(palm), [0, 0, -mass * G], atol=1e-6)
    assert w.body_pose(body)[0][2] == pytest.approx(rest - mass * G / (n * K), abs=1e-6)
    start = (1, 0, 0, 0) if kind == "pencil" else (np.cos(np.pi / 32), np.sin(np.pi / 32), 0, 0)
    turned = quat_to_matrix(w.body_pose(body)[1]) @ quat_to_matrix(start).T
    assert np.degrees(np.arccos(np.clip((np.trace(turned) - 1) / 2, -1, 1))) < 0.01


def test_can_in_a_power_grasp_of_palm_and_fingers():
    """A 0.35 kg can (radius 3.3 cm, 12 cm tall, upright) between a palm (on its side, 9 x 8 cm,
    shorter than the can: no vertex of either inside the other) and three fingertips wrapping the
    other side, squeezed 3 mm and lifted 5 cm: it rises with the hand, upright."""
    r, squeeze = 0.033, 0.003
    apothem = r * np.cos(np.pi / 16)
    w = graspcore.World(gravity=(0, 0, 0))
    c = np.cos(np.pi / 4)
    can = w.add_body(prism_points(r, 0.06, sides=16), mass=0.35, orientation=(c, 0, -c, 0))  # axis along z
    palm = w.add_finger(position=(-apothem - 0.01 + squeeze, 0, 0), points=box_points(0.01, 0.04, 0.045), **PALM)
    for deg, z in ((-50, 0.03), (0, 0.0), (50, -0.03)):
        a, d = np.radians(deg), apothem + 0.008 - squeeze
        w.add_finger(radius=0.008, stiffness=K, damping=2.0, position=(d * np.cos(a), d * np.sin(a), z))
    hips = np.array([w.finger_pose(i)[0] for i in range(4)])
    w.step(DT, steps=200)
    w.set_gravity((0, 0, -G))
    for i in range(2000):
        w.set_hips(hips + [0, 0, 0.05 * min(i / 1000, 1.0)])
        w.step(DT)
    pos, q = w.body_pose(can)
    assert pos[2] == pytest.approx(0.05, abs=0.002)
    assert abs(pos[0]) < 0.003 and abs(pos[1]) < 0.003
    axis = quat_to_matrix(q) @ [1, 0, 0]
    assert np.degrees(np.arccos(axis[2])) < 3.0
    assert all(w.finger_state(f) == "stick" for f in range(4))
    palm_points = w.finger_contacts(palm)
    assert len(palm_points) >= 3 and all(p["reversed"] for p in palm_points)


@pytest.mark.parametrize("pad_half", [0.01, 0.05])  # pad smaller, and larger, than the plate's face
def test_pad_driven_through_a_thin_plate_stays_on_its_face(pad_half):
    """The HIP goes 3 cm down through a 4 mm static plate: every contact keeps pushing the finger
    back up (no push-through), the pad's own god-objects stay on the top face, and the force is at
    least the springs' k x depth. (A pad wider than the plate, driven deeper than the plate is
    thick, also takes up the plate's bottom corners, on the same side: a stiffer spring.)"""
    w = graspcore.World(gravity=(0, 0, 0))
    w.add_body(box_points(0.03, 0.03, 0.002, center=(0, 0, -0.002)), static=True)
    pad = w.add_finger(radius=0.0, stiffness=K, position=(0, 0, 0.01),
                       points=box_points(pad_half, pad_half, 0.003, center=(0, 0, 0.003)))
    for i in range(1, 401):
        z = 0.01 - 0.04 * i / 400
        w.set_hip(pad, (0, 0, z))
        w.step(DT)
        contacts = w.finger_contacts(pad)
        if z < -0.001:
            assert contacts, f"no contact with the HIP {z * 1000:.1f} mm down"
            assert all(c["normal"][2] > 0.999 and c["force"][2] >= 0.0 for c in contacts)
            tops = [c["point"][2] for c in contacts if not c["reversed"] or c["point"][2] > -0.001]
            assert tops and min(tops) > -1e-9 and max(tops) < 1e-9
            assert w.finger_force(pad)[2] >= K * -z * 0.999


def test_rocking_plate_never_gains_energy():
    """A plate rocking on a pad (no finger damping): kinetic + gravity + spring energy never
    rises above its start (backward Euler and the friction circle only dissipate)."""
    w = graspcore.World()
    pad = w.add_finger(radius=0.0, stiffness=K, position=(0, 0, -0.005), points=box_points(PAD, PAD, 0.005))
    plate = w.add_body(box_points(0.1, 0.1, PLATE_H), mass=PLATE_M, position=(0, 0, PLATE_H - PLATE_M * G / (4 * K)))
    w.step(DT, steps=200)
    w.set_body_velocity(plate, (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    m, _, inertia_local = w.body_mass(plate)

    def energy():
        pos, q = w.body_pose(plate)
        v, om = (np.array(x) for x in w.body_velocity(plate))
        R = quat_to_matrix(q)
        I = R @ np.asarray(inertia_local).reshape(3, 3) @ R.T
        springs = sum(np.dot(c["force"], c["force"]) / (2 * K) for c in w.finger_contacts(pad))
        return 0.5 * m * v @ v + 0.5 * om @ I @ om + m * G * pos[2] + springs

    w.step(DT)
    e0 = energy()
    history = []
    for _ in range(3000):
        w.step(DT)
        history.append(energy())
    assert max(history) <= e0 + 1e-9
    assert tilt_deg(w, plate) < 1.0


def test_plate_on_a_tilted_pad_does_not_creep():
    """Pad tilted 15 deg (tan 15 = 0.27 < mu_s 0.8): once settled the plate stays put on it."""
    w = graspcore.World()
    ang = np.radians(15.0)
    q = (np.cos(ang / 2), np.sin(ang / 2), 0.0, 0.0)
    pad = w.add_finger(radius=0.0, stiffness=K, damping=2.0, position=(0, 0, 0), orientation=q,
                       points=box_points(PAD, PAD, 0.005, center=(0, 0, -0.005)))
    R = quat_to_matrix(q)
    plate = w.add_body(box_points(0.06, 0.06, PLATE_H), mass=PLATE_M, orientation=q,
                       position=tuple(R @ [0, 0, PLATE_H]))
    w.step(DT, steps=1000)
    p0 = np.array(w.body_pose(plate)[0])
    w.step(DT, steps=5000)
    assert np.linalg.norm(np.array(w.body_pose(plate)[0]) - p0) < 1e-6
    assert w.finger_state(pad) == "stick"


# ---- the target: a plate on a palm, lifted and carried ---------------------------------

def carry_plate(area: bool):
    """A 0.4 kg, 20 x 20 x 1 cm plate on a 9 x 8 cm palm (or, area off, on a 1 cm sphere finger at
    the palm's centre: one point contact), lifted 10 cm over 1 s and carried 10 cm over the next
    (minimum-jerk), then held 1 s. Returns the largest tilt (deg) and slide on the palm (m)."""
    w = graspcore.World()
    if area:
        palm = w.add_finger(radius=0.0, stiffness=K, damping=2.0, position=(0, 0, -0.01),
                            points=box_points(0.045, 0.04, 0.01))
    else:
        palm = w.add_finger(radius=0.01, stiffness=K, damping=2.0, position=(0, 0, -0.01))
    plate = w.add_body(box_points(0.1, 0.1, PLATE_H), mass=PLATE_M, position=(0, 0, PLATE_H))
    w.step(DT, steps=300)
    hip0 = np.array(w.finger_pose(palm)[0])
    rel0 = np.array(w.body_pose(plate)[0]) - hip0
    worst_tilt = worst_slide = 0.0
    for i in range(3000):
        t = (i + 1) * DT
        hip = hip0 + [0.1 * min_jerk(t - 1.0), 0, 0.1 * min_jerk(t)]
        w.set_hip(palm, hip)
        w.step(DT)
        worst_tilt = max(worst_tilt, tilt_deg(w, plate))
        worst_slide = max(worst_slide, float(np.linalg.norm((np.array(w.body_pose(plate)[0]) - hip - rel0)[:2])))
    return worst_tilt, worst_slide


def test_plate_rests_level_on_a_palm_while_carried():
    tilt, slide = carry_plate(area=True)
    assert tilt < 2.0 and slide < 0.005


def test_plate_on_a_point_contact_tips_when_carried():
    tilt, _ = carry_plate(area=False)
    assert tilt > 45.0


def test_runtime_carries_a_convex_finger_as_the_synchronous_step_does():
    """The manual-clock runtime (haptic loop adopting the plate while the palm holds it) gives the
    synchronous steps' state bit for bit: the finger's hull and orientation reach its shadows."""
    def scene():
        w = graspcore.World()
        q = (np.cos(0.05), np.sin(0.05), 0.0, 0.0)  # a palm tilted 5.7 deg
        w.add_finger(radius=0.0, stiffness=K, damping=2.0, position=(0, 0, -0.01), orientation=q,
                     points=box_points(0.045, 0.04, 0.01))
        w.add_body(box_points(0.1, 0.1, PLATE_H), mass=PLATE_M, orientation=q,
                   position=tuple(quat_to_matrix(q) @ [0, 0, PLATE_H]))
        return w

    def hips(i):
        return np.array([[0.0, 0.0, -0.01 + 0.05 * min(i / 500, 1.0)]])

    ref = scene()
    for i in range(800):
        ref.set_hips(hips(i))
        ref.step(DT)
    w = scene()
    w.start(realtime=False, object_rate=1000)
    for i in range(800):
        assert w.push_hips(hips(i), i * DT)
        w.advance(1)
    running = w.snapshot()      # the display channel's, from the haptic loop
    w.stop()
    assert w.state_hash() == ref.state_hash()
    assert tilt_deg(ref, 0) == pytest.approx(np.degrees(0.1), abs=0.2)  # resting on the tilted palm
    # The palm's patch for the analysis, as the stopped world reports it: its four top corners
    # (about the pressure centroid, which the tilt moves off the palm's centre): 8 x 9 cm.
    np.testing.assert_array_equal(running["patches"], ref.snapshot()["patches"])
    corners = running["patches"][0]
    np.testing.assert_allclose(np.sort(np.ptp(corners, axis=0)), [0.08, 0.09], atol=1e-6)


# ---- soft fingertips: torsional friction about the normal (sphere fingers) ---------------------

def test_soft_fingertip_twisted_on_a_table_slips_at_its_torsional_limit():
    """A sphere fingertip with a pressed patch of radius rho, pressed F_n = k depth on a table and
    turned about the normal: the torque is k rho^2 phi while it sticks, up to mu_s F_n rho
    (phi = mu_s depth / rho), then it slides at mu_d F_n rho."""
    mu_s, mu_d, depth, rho = 0.5, 0.3, 0.002, 0.01
    w = graspcore.World(gravity=(0, 0, 0))
    w.add_body(box_points(0.2, 0.2, 0.05, center=(0, 0, -0.05)), static=True, mu_s=mu_s, mu_d=mu_d)
    f = w.add_finger(radius=0.008, stiffness=K, position=(0, 0, 0.02), torsion=rho)
    for i in range(1, 21):
        w.set_hip(f, (0, 0, 0.02 + (0.008 - depth - 0.02) * i / 20))
        w.step(DT)
    Fn = K * depth
    peak, states = 0.0, []
    for deg in np.arange(0.1, 12.0, 0.1):
        phi = np.radians(deg)
        w.set_finger_pose(f, (0, 0, 0.008 - depth), (np.cos(phi / 2), 0, 0, np.sin(phi / 2)))
        w.step(DT)
        tz = -w.finger_torque(f)[2]
        states.append(tz)
        if phi <= mu_s * depth / rho:
            assert tz == pytest.approx(K * rho**2 * phi, rel=1e-9)
        peak = max(peak, tz)
    assert peak <= mu_s * Fn * rho * (1 + 1e-9) and peak > 0.97 * mu_s * Fn * rho
    assert states[-1] == pytest.approx(mu_d * Fn * rho, rel=1e-9)
    np.testing.assert_allclose(w.finger_force(f), [0, 0, Fn], atol=1e-9)   # the push is untouched


def pinched_bar(torsion, seconds=8.0):
    """A 0.1 kg bar (20 x 2 x 2 cm) pinched across its width 5 cm from its centre by two
    fingertips (3000 N/m, squeezed 4 mm): its weight twists it about the pinch axis."""
    w = graspcore.World()
    bar = w.add_body(box_points(0.1, 0.01, 0.01), mass=0.1, position=(0.05, 0, 0))
    for s in (-1, 1):
        w.add_finger(radius=0.008, stiffness=3000.0, damping=2.0, position=(0, s * (0.01 + 0.008 - 0.004), 0),
                     torsion=torsion)
    largest = 0.0
    for _ in range(int(seconds / 0.01)):
        w.step(DT, steps=10)
        R = quat_to_matrix(w.body_pose(bar)[1])
        theta = -np.arctan2(R[2, 0], R[0, 0])   # the bar's turn about the pinch axis, down positive
        largest = max(largest, abs(theta))
    return theta, largest, w


def test_soft_fingertips_hold_a_pinched_bar_against_its_twist():
    """Point contacts leave the rotation about the pinch axis free: the bar swings down. Soft
    fingertips (rho 1 cm) hold it where their twist springs carry its weight's moment,
    2 k rho^2 theta = m g d cos theta; with rho 2 mm their limit 2 mu_s F_n rho is below that
    moment and it swings down again."""
    _, largest, _ = pinched_bar(0.0, seconds=2.0)
    assert np.degrees(largest) > 90.0
    theta, largest, w = pinched_bar(0.01)
    from scipy.optimize import brentq
    expected = brentq(lambda t: 2 * 3000.0 * 0.01**2 * t - 0.1 * G * 0.05 * np.cos(t), 0.0, 1.0)
    assert theta == pytest.approx(expected, rel=0.03)
    assert all(w.finger_state(f) == "stick" for f in range(2))
    assert largest < 2.2 * expected   # the swing from rest overshoots at most to twice
    _, largest, _ = pinched_bar(0.002, seconds=2.0)
    assert 2 * 0.8 * 3000.0 * 0.004 * 0.002 < 0.1 * G * 0.05
    assert np.degrees(largest) > 45.0


def test_torsion_is_refused_on_a_convex_finger_and_when_negative():
    w = graspcore.World()
    with pytest.raises(ValueError, match="torsion"):
        w.add_finger(torsion=-0.01)
    with pytest.raises(ValueError, match="torsion"):
        w.add_finger(torsion=0.01, points=box_points(0.01, 0.01, 0.01))
    assert w.finger_count == 0


def test_contact_patch_is_refused_while_the_runtime_runs():
    """The runtime's snapshots carry one god-object per finger, not the patch: finger_contacts and
    finger_torque say so while it runs (rather than answer from the start), and answer after stop."""
    w = graspcore.World()
    palm = w.add_finger(position=(0, 0, -0.01), points=box_points(0.045, 0.04, 0.01), **PALM)
    w.add_body(box_points(0.1, 0.1, PLATE_H), mass=PLATE_M, position=(0, 0, PLATE_H))
    w.start(realtime=False)
    w.advance(200)
    with pytest.raises(RuntimeError, match="finger_contacts: the runtime's snapshots do not carry"):
        w.finger_contacts(palm)
    with pytest.raises(RuntimeError, match="finger_torque"):
        w.finger_torque(palm)
    w.stop()
    assert len(w.finger_contacts(palm)) == 4


# ---- a palm's orientation driven by the runtime's HIP track -------------------------------------

TILT = np.radians(10.0)
TRACK_DT = 0.02  # 50 Hz samples: most ticks fall between two and are interpolated


def tilt_track():
    """A palm held level 0.3 s, tilted 10 deg about x over 1 s, then held 0.4 s; every other
    sample given as -q (the same rotation: the interpolation must take the shorter arc)."""
    times = np.arange(0.0, 1.7 + TRACK_DT / 2, TRACK_DT)
    ang = TILT * np.array([min_jerk((t - 0.3) / 1.0) for t in times])
    q = np.stack([np.cos(ang / 2), np.sin(ang / 2), np.zeros_like(ang), np.zeros_like(ang)], axis=1)
    q[1::2] *= -1.0
    positions = np.tile([0.0, 0.0, -0.01], (len(times), 1))
    return times, positions[:, None, :], q[:, None, :]


def track_sample(times, values, t, shorter_arc=False):
    """The track's position or orientation at t as the core computes it, operation for operation:
    the lerp of the samples around t (for a quaternion the second's sign taken into the first's
    hemisphere), before the normalisation that set_finger_pose does."""
    if t <= times[0]:
        return values[0]
    if t >= times[-1]:
        return values[-1]
    lo = int(np.searchsorted(times, t, side="right")) - 1
    a = (t - times[lo]) / (times[lo + 1] - times[lo])
    s = -a if shorter_arc and float(values[lo] @ values[lo + 1]) < 0.0 else a
    return np.array([(1.0 - a) * values[lo][k] + s * values[lo + 1][k] for k in range(len(values[lo]))])


def palm_under_plate():
    w = graspcore.World()
    palm = w.add_finger(radius=0.0, stiffness=K, damping=2.0, position=(0, 0, -0.01),
                        points=box_points(0.045, 0.04, 0.01))
    plate = w.add_body(box_points(0.1, 0.1, PLATE_H), mass=PLATE_M, position=(0, 0, PLATE_H))
    return w, palm, plate


def test_runtime_track_tilts_a_palm_as_set_finger_pose_does_bit_for_bit():
    times, positions, q = tilt_track()
    ticks = 1800
    ref, palm, plate = palm_under_plate()
    for i in range(ticks):
        t = (i + 1) * DT
        ref.set_finger_pose(palm, track_sample(times, positions[:, 0], t),
                            track_sample(times, q[:, 0], t, shorter_arc=True))
        ref.step(DT)
    w, _, _ = palm_under_plate()
    w.set_hip_track(times, positions, orientations=q)
    w.start(realtime=False, object_rate=1000)
    w.advance(ticks)
    w.stop()
    assert w.state_hash() == ref.state_hash()
    assert w.finger_pose(palm) == ref.finger_pose(palm)
    # The palm turned the whole 10 deg (the last sample, -q's sign normalised away) and the
    # plate tilted with it, resting on it.
    np.testing.assert_allclose(np.abs(w.finger_pose(palm)[1]), np.abs(q[-1, 0]), atol=1e-15)
    assert tilt_deg(w, plate) == pytest.approx(10.0, abs=0.2)


def test_threaded_runtime_track_tilts_a_palm():
    times, positions, q = tilt_track()
    w, palm, plate = palm_under_plate()
    w.set_hip_track(times, positions, orientations=q)
    w.start(object_rate=500)
    try:
        t0 = time.monotonic()  # a loaded machine runs late, never fast: wait for simulated time
        while w.snapshot()["time"] < 1.9 and time.monotonic() - t0 < 30.0:
            time.sleep(0.05)
    finally:
        w.stop()
    assert w.time >= 1.9
    np.testing.assert_allclose(np.abs(w.finger_pose(palm)[1]), np.abs(q[-1, 0]), atol=1e-15)
    assert tilt_deg(w, plate) == pytest.approx(10.0, abs=0.3)


def test_track_orientations_are_refused_naming_what_is_wrong():
    times, positions, q = tilt_track()
    w, _, _ = palm_under_plate()
    with pytest.raises(ValueError, match=r"orientations \(86, 1, 4\)"):
        w.set_hip_track(times, positions, orientations=q[:, :, :3])
    bad = q.copy()
    bad[5, 0] = 0.0
    with pytest.raises(ValueError, match="sample 5, finger 0: not a finite non-zero quaternion"):
        w.set_hip_track(times, positions, orientations=bad)
    bad[5, 0] = (np.nan, 1, 0, 0)
    with pytest.raises(ValueError, match="sample 5, finger 0"):
        w.set_hip_track(times, positions, orientations=bad)
    # Nothing half set: the palm is not moved by a track that was refused.
    w.start(realtime=False)
    w.advance(500)
    w.stop()
    assert w.finger_pose(0)[1] == (1.0, 0.0, 0.0, 0.0)


def test_pushed_orientations_every_tick_tilt_a_palm_as_set_finger_pose_does_bit_for_bit():
    """A caller pushing every tick (a device) gets set_finger_pose + step, bit for bit."""
    times, positions, q = tilt_track()
    ticks = 1800
    poses = [(track_sample(times, positions[:, 0], (i + 1) * DT),
              track_sample(times, q[:, 0], (i + 1) * DT, shorter_arc=True)) for i in range(ticks)]
    ref, palm, plate = palm_under_plate()
    for p, o in poses:
        ref.set_finger_pose(palm, p, o)
        ref.step(DT)
    w, _, _ = palm_under_plate()
    w.start(realtime=False, object_rate=1000)
    for i, (p, o) in enumerate(poses):
        assert w.push_hips([p], i * DT, orientations=[o])
        w.advance(1)
    w.stop()
    assert w.state_hash() == ref.state_hash()
    assert tilt_deg(w, plate) == pytest.approx(10.0, abs=0.2)


def test_slow_pushed_orientations_are_turned_to_smoothly():
    """Samples 20 ticks apart (50 Hz), every other one given as -q: the palm turns along the
    shorter arc, one interval behind, the plate resting on it all the way; a bad quaternion
    rejects its push."""
    times, positions, q = tilt_track()
    w, palm, plate = palm_under_plate()
    w.start(realtime=False, object_rate=1000)
    tilts = []
    for k, t in enumerate(times):
        assert w.push_hips(positions[k], t, orientations=q[k])
        w.advance(20)  # sample k reached at the end of this interval
        pose = w.snapshot()["poses"][plate]
        tilts.append(np.degrees(np.arccos(np.clip(quat_to_matrix(pose[3:])[2, 2], -1.0, 1.0))))
    assert not w.push_hips(positions[-1], times[-1] + 1.0, orientations=[[0.0, 0, 0, 0]])
    assert not w.push_hips(positions[-1], times[-1] + 1.0, orientations=[[np.nan, 1, 0, 0]])
    with pytest.raises(ValueError, match=r"orientations: expected \(1, 4\)"):
        w.push_hips(positions[-1], times[-1] + 1.0, orientations=[1.0, 0, 0])
    assert w.stats()["rejected_inputs"] == 2
    w.stop()
    np.testing.assert_allclose(np.abs(w.finger_pose(palm)[1]), np.abs(q[-1, 0]), atol=1e-15)
    expected = np.degrees(TILT) * np.array([min_jerk((t - 0.3) / 1.0) for t in times])
    np.testing.assert_allclose(tilts, expected, atol=0.25)


def test_device_orientations_tilt_a_palm_under_a_plate():
    """A device read in Python (push_device_hips with orientations) drives the palm's slot: the
    palm turns to each sample as a pushed pose does and the plate resting on it tilts with it,
    to the track's 10 deg; a scaled, zero or NaN quaternion is refused and counted, nothing of
    its sample taken."""
    times, positions, q = tilt_track()
    w, palm, plate = palm_under_plate()
    w.start(realtime=False, object_rate=1000)
    tilts = []
    for k in range(len(times)):
        assert w.push_device_hips(palm, positions[k], q[k])
        w.advance(20)
        tilts.append(tilt_deg_of_pose(w.snapshot()["poses"][plate]))
    for bad in ([[2.0, 0, 0, 0]], [[0.0, 0, 0, 0]], [[np.nan, 1, 0, 0]]):
        assert not w.push_device_hips(palm, np.array([[0.0, 0.0, 0.5]]), np.array(bad))
    with pytest.raises(ValueError, match="orientations: must be a C-contiguous float64 array of 1 wxyz rows"):
        w.push_device_hips(palm, positions[-1], np.array([[1.0, 0, 0]]))
    w.advance(20)
    assert w.stats()["rejected_inputs"] == 3
    w.stop()
    np.testing.assert_allclose(np.abs(w.finger_pose(palm)[1]), np.abs(q[-1, 0]), atol=1e-15)
    assert w.finger_pose(palm)[0] == pytest.approx(tuple(positions[-1, 0]), abs=1e-12)
    expected = np.degrees(TILT) * np.array([min_jerk((t - 0.3) / 1.0) for t in times])
    np.testing.assert_allclose(tilts, expected, atol=0.25)
    assert tilt_deg(w, plate) == pytest.approx(10.0, abs=0.2)


def tilt_deg_of_pose(pose):
    R = quat_to_matrix(pose[3:])
    return float(np.degrees(np.arccos(np.clip(R[2, 2], -1.0, 1.0))))
