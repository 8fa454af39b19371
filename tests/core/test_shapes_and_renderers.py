"""How finger shapes and renderers compose (docs/physics.md "Renderers and finger shapes"): the
seam blend weights a sphere finger's god-objects (and a soft fingertip's twist with them), a
convex finger's patch is not blended, the cursor renders sphere fingers only, and the tick
record carries both `parts` and `orientation`."""
import numpy as np
import pytest

import graspcore
from scenes import box_points

DT = 1e-3
K = 1000.0
R = 0.008
SLAB = [box_points(0.01, 0.02, 0.01, (-0.01, 0, 0)), box_points(0.01, 0.02, 0.01, (0.01, 0, 0))]


def test_cursor_takes_sphere_fingers_without_torsion_only():
    w = graspcore.World()
    with pytest.raises(ValueError, match="renderer.*convex finger"):
        w.add_finger(renderer="cursor", points=box_points(0.01, 0.01, 0.002))
    with pytest.raises(ValueError, match="renderer.*torsion"):
        w.add_finger(renderer="cursor", torsion=0.01)
    assert w.finger_count == 0
    # Each alone is accepted.
    w.add_finger(renderer="cursor")
    w.add_finger(points=box_points(0.01, 0.01, 0.002))
    w.add_finger(torsion=0.01)


def _soft_tip_twisted(parts, x, phi):
    """A soft fingertip (rho 1 cm) pressed 2 mm into the top of a static body at x, then turned
    by phi about the normal: (finger force, twist torque about z)."""
    depth, rho = 0.002, 0.01
    w = graspcore.World(gravity=(0, 0, 0))
    w.add_body(parts=parts, static=True, mu_s=0.5, mu_d=0.3)
    z = 0.01 + R - depth
    f = w.add_finger(radius=R, stiffness=K, position=(x, 0, z + 0.01), torsion=rho)
    for i in range(1, 21):
        w.set_hip(f, (x, 0, z + 0.01 * (1 - i / 20)))
        w.step(DT)
    w.set_finger_pose(f, (x, 0, z), (np.cos(phi / 2), 0, 0, np.sin(phi / 2)))
    w.step(DT)
    return np.array(w.finger_force(f)), -w.finger_torque(f)[2], w.tick_record(tick=1)


def test_soft_fingertip_on_a_seam_twists_as_one_surface():
    """On the seam of two boxes making one flat slab, the fingertip has a god-object on each, and
    the seam blend gives each half the spring: the push is k d, not 2 k d, and the twist torque
    k rho^2 phi, as on one box, not twice it."""
    phi, rho, depth = np.radians(0.5), 0.01, 0.002
    force, torque, record = _soft_tip_twisted(SLAB, 0.0, phi)
    assert record["parts"][0] == 3                                   # both boxes touched
    np.testing.assert_allclose(force, [0, 0, K * depth], atol=1e-9)
    assert torque == pytest.approx(K * rho**2 * phi, rel=1e-9)
    one_force, one_torque, one = _soft_tip_twisted([box_points(0.02, 0.02, 0.01)], 0.0, phi)
    assert one["parts"][0] == 1
    assert torque == pytest.approx(one_torque, rel=1e-9)
    np.testing.assert_allclose(force, one_force, atol=1e-9)


def test_pad_on_a_decomposed_body_keeps_every_point_whole():
    """A flat pad (1.2 cm square) pressed 1 mm on the slab of two boxes, across its seam: its points
    on both parts are a patch, each spring whole (k d on every point, not blended), and the points'
    forces add up to the finger's. Its 4 bottom vertices touch the top faces; the slab's seam edges
    inside the pad are reversed points of their own (each also k d: the limit named in
    docs/physics.md). The record names both parts and the pad's orientation."""
    depth = 0.001
    w = graspcore.World(gravity=(0, 0, 0))
    w.add_body(parts=SLAB, static=True)
    q = (np.cos(0.15), 0, 0, np.sin(0.15))                           # turned 17 deg about z
    pad = box_points(0.006, 0.006, 0.002)
    f = w.add_finger(radius=0.0, stiffness=K, points=pad, position=(0, 0, 0.02), orientation=q)
    for i in range(1, 41):
        w.set_finger_pose(f, (0, 0, 0.02 + (0.012 - depth - 0.02) * i / 40), q)
        w.step(DT)
    contacts = w.finger_contacts(f)
    assert sum(not c["reversed"] for c in contacts) == 4
    assert {c["body"] for c in contacts} == {0}
    total = np.sum([c["force"] for c in contacts], axis=0)
    np.testing.assert_allclose(total, w.finger_force(f), atol=1e-12)
    np.testing.assert_allclose([c["force"][2] for c in contacts], K * depth, rtol=1e-6)
    np.testing.assert_allclose(w.finger_force(f), [0, 0, len(contacts) * K * depth], rtol=1e-6, atol=1e-9)
    r = w.tick_record(tick=1)
    assert r["parts"][0] == 3
    np.testing.assert_allclose(r["orientation"][0], q, atol=1e-15)


def test_record_field_order_is_the_cores():
    names = graspcore.tick_dtype(2, 3).names
    assert names[-7:] == ("state", "contact", "parts", "orientation", "patch", "object_tick", "object_reads")
