"""Body-body contacts and the contact solver against analytic answers (docs/solver.md)."""
import math

import numpy as np
import pytest

import graspcore
from scenes import box_points

DT = 1e-3
G = 9.81


def table(w, half=0.3, mu_s=0.8, mu_d=0.6, orientation=(1, 0, 0, 0)):
    """A static slab whose top face passes through the origin (normal along the orientation's z)."""
    R = rotation(orientation)
    return w.add_body(box_points(half, half, 0.05), static=True, position=tuple(R @ [0, 0, -0.05]),
                      orientation=orientation, mu_s=mu_s, mu_d=mu_d)


def rotation(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def test_box_rests_on_table_without_drift():
    w = graspcore.World()
    table(w)
    box = w.add_body(box_points(0.03, 0.03, 0.03), mass=0.2, position=(0.01, -0.02, 0.03))
    w.step(DT, steps=200)
    p0 = np.array(w.body_pose(box)[0])
    assert p0[2] == pytest.approx(0.03, abs=1e-5)          # half extent, within the slop
    w.step(DT, steps=10000)                                # 10 s
    p1 = np.array(w.body_pose(box)[0])
    assert np.linalg.norm(p1 - p0) < 1e-6                  # < 1 um over 10 s
    contacts = w.contacts()
    assert len(contacts) == 4                              # a face on a face: 4 points
    assert all(c["sticking"] for c in contacts)
    assert sum(c["normal_impulse"] for c in contacts) / DT == pytest.approx(0.2 * G, rel=1e-9)
    np.testing.assert_allclose(contacts[0]["normal"], (0, 0, 1), atol=1e-12)


def test_static_body_added_after_the_dynamic_ones():
    w = graspcore.World()
    boxes = [w.add_body(box_points(0.02, 0.02, 0.02), mass=0.1, position=(0.1 * i, 0, 0.02)) for i in range(3)]
    table(w)                                               # the static body has the highest id
    w.step(DT, steps=1000)
    for b in boxes:
        assert w.body_pose(b)[0][2] == pytest.approx(0.02, abs=1e-5)
    assert w.chain_count() == 3 and w.body_chain(3) is None


def incline_run(theta, mu_s, mu_d, seconds, box_mu=None):
    """A box on a slab tilted by theta about x; returns (displacement, acceleration) down the slope."""
    q = (math.cos(theta / 2), math.sin(theta / 2), 0.0, 0.0)
    R = rotation(q)
    normal, down = R @ [0, 0, 1], R @ [0, -1, 0]
    w = graspcore.World()
    table(w, half=1.0, mu_s=mu_s, mu_d=mu_d, orientation=q)
    bs, bd = box_mu if box_mu else (mu_s, mu_d)
    box = w.add_body(box_points(0.02, 0.02, 0.02), mass=0.2, position=tuple(0.02 * normal), orientation=q,
                     mu_s=bs, mu_d=bd)
    p0 = np.array(w.body_pose(box)[0])
    steps = int(round(seconds / DT))
    w.step(DT, steps=steps // 4)
    v1 = np.dot(w.body_velocity(box)[0], down)
    w.step(DT, steps=steps - steps // 4)
    v2 = np.dot(w.body_velocity(box)[0], down)
    moved = np.dot(np.array(w.body_pose(box)[0]) - p0, down)
    return moved, (v2 - v1) / ((steps - steps // 4) * DT)


@pytest.mark.parametrize("ratio", [0.5, 0.9, 0.97])
def test_incline_sticks_below_mu_s(ratio):
    mu_s, mu_d = 0.5, 0.3
    moved, accel = incline_run(math.atan(ratio * mu_s), mu_s, mu_d, 1.0)
    assert abs(moved) < 1e-6


@pytest.mark.parametrize("degrees", [30.0, 40.0, 55.0])
def test_incline_slides_with_dynamic_friction(degrees):
    mu_s, mu_d = 0.5, 0.3
    theta = math.radians(degrees)
    moved, accel = incline_run(theta, mu_s, mu_d, 0.4)
    expect = G * (math.sin(theta) - mu_d * math.cos(theta))
    assert accel == pytest.approx(expect, rel=1e-6)
    assert moved == pytest.approx(0.5 * expect * 0.4 ** 2, rel=0.01)


def test_friction_combines_by_geometric_mean():
    # Slab mu (1.0, 0.64), box mu (0.25, 0.16): combined mu_s = 0.5, mu_d = 0.32.
    theta = math.radians(35)
    moved, accel = incline_run(theta, 1.0, 0.64, 0.4, box_mu=(0.25, 0.16))
    assert accel == pytest.approx(G * (math.sin(theta) - 0.32 * math.cos(theta)), rel=1e-6)
    moved, accel = incline_run(math.atan(0.45), 1.0, 0.64, 0.5, box_mu=(0.25, 0.16))
    assert abs(moved) < 1e-6


def stack_world(n=5, threads=1):
    w = graspcore.World(threads=threads)
    table(w)
    ids = [w.add_body(box_points(0.02, 0.02, 0.02), mass=0.2, position=(0.002 * i, 0.0, 0.02 + 0.04 * i))
           for i in range(n)]
    return w, ids


def test_stack_of_five_rests_ten_seconds():
    w, ids = stack_world()
    start = w.body_poses[ids, :3].copy()
    w.step(DT, steps=1000)
    settled = w.body_poses[ids, :3].copy()
    w.step(DT, steps=10000)
    end = w.body_poses[ids, :3]
    assert np.abs(end - start).max() < 1e-4           # the target: < 0.1 mm over the whole run
    assert np.abs(end - settled).max() < 1e-6         # once settled: < 1 um over 10 s
    assert w.chain_count() == 1
    assert len(w.contacts()) == 4 * 5


@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.005, -0.01)])
def test_momentum_conserved_in_zero_gravity_collision(offset):
    w = graspcore.World(gravity=(0, 0, 0))
    a = w.add_body(box_points(0.03, 0.03, 0.03), mass=0.3, position=(-0.1, 0, 0))
    b = w.add_body(box_points(0.02, 0.02, 0.02), mass=0.1, position=(0.1, *offset))
    w.set_body_velocity(a, (1.0, 0, 0), (0, 0, 0))
    w.set_body_velocity(b, (-1.0, 0, 0), (0, 0, 0))
    p0 = 0.3 * np.array([1.0, 0, 0]) + 0.1 * np.array([-1.0, 0, 0])
    touched = False
    for _ in range(300):
        w.step(DT)
        touched |= bool(w.contacts())
    assert touched
    va, vb = np.array(w.body_velocity(a)[0]), np.array(w.body_velocity(b)[0])
    np.testing.assert_allclose(0.3 * va + 0.1 * vb, p0, atol=1e-12)
    if offset == (0.0, 0.0):
        # Perfectly inelastic head-on impact of aligned faces: they move on together.
        np.testing.assert_allclose(va, vb, atol=1e-8)
        assert va[0] == pytest.approx(p0[0] / 0.4, rel=1e-9)


def tray_scene(threads=1):
    """A 20 x 12 x 1 cm tray with six 3 cm cubes, pinched at its two ends by four fingers."""
    w = graspcore.World(threads=threads)
    table(w)
    tx, ty, tz = 0.10, 0.06, 0.005
    tray = w.add_body(box_points(tx, ty, tz), mass=0.2, position=(0, 0, tz), mu_s=0.6, mu_d=0.5)
    cups = [w.add_body(box_points(0.015, 0.015, 0.015), mass=0.05,
                       position=(-0.06 + 0.06 * i, -0.03 + 0.06 * j, 2 * tz + 0.015), mu_s=0.6, mu_d=0.5)
            for i in range(3) for j in range(2)]
    hips = np.array([(sx * (tx + 0.009), y, tz) for sx in (-1, 1) for y in (-0.03, 0.03)])
    fingers = [w.add_finger(radius=0.008, stiffness=3000.0, damping=5.0, position=tuple(p)) for p in hips]
    return w, tray, cups, fingers, hips


def tray_hips(hips, t):
    """Close 4 mm in 50 ms, lift 5 cm (0.2-1.0 s), carry 10 cm sideways (1.2-2.2 s), hold."""
    h = hips.copy()
    h[:, 0] -= np.sign(h[:, 0]) * 0.004 * min(t / 0.05, 1.0)
    h[:, 2] += 0.05 * min(max((t - 0.2) / 0.8, 0.0), 1.0)
    h[:, 1] += 0.10 * min(max((t - 1.2) / 1.0, 0.0), 1.0)
    return h


def test_tray_with_six_objects_is_lifted_and_carried():
    w, tray, cups, fingers, hips = tray_scene()
    rel0 = w.body_poses[cups, :3] - w.body_poses[tray, :3]
    worst = 0.0
    for i in range(2600):
        w.set_hips(tray_hips(hips, i * DT))
        w.step(DT)
        rel = w.body_poses[cups, :3] - w.body_poses[tray, :3]
        worst = max(worst, np.abs(rel - rel0).max())
    pos = np.array(w.body_pose(tray)[0])
    assert pos[2] > 0.05 and pos[1] == pytest.approx(0.10, abs=2e-3)   # lifted and carried
    assert all(w.finger_state(f) != "free" for f in fingers)
    assert worst < 2e-3                                  # nothing slid more than 2 mm on the tray
    # Held still at the end: the objects are at rest on the tray.
    before = w.body_poses[cups, :3].copy()
    for i in range(300):
        w.set_hips(tray_hips(hips, 2.6 + i * DT))
        w.step(DT)
    assert np.abs(w.body_poses[cups, :3] - before).max() < 1e-5
    assert w.chain_count() == 1                          # tray and its load: one chain; the table is not in it


def test_contact_storage_overflow_is_counted_not_fatal():
    w = graspcore.World(max_contacts=2)
    table(w)
    for i in range(4):
        w.add_body(box_points(0.02, 0.02, 0.02), mass=0.1, position=(-0.2 + 0.1 * i, 0, 0.02))
    w.step(DT)
    assert w.contact_overflow() == 2
    with pytest.raises(ValueError, match="threads"):
        graspcore.World(threads=100)
