"""Rigid-body dynamics against closed forms, and grasps held by god-object fingers."""
import numpy as np
import pytest

import graspcore
from scenes import box_points, prism_points, quat_to_matrix

DT = 1e-3


def test_free_fall_matches_semi_implicit_euler_and_closed_form():
    g = 9.81
    w = graspcore.World(gravity=(0, 0, -g))
    b = w.add_body(box_points(0.02, 0.02, 0.02), mass=0.1, position=(0, 0, 1.0))
    n = 1000
    w.step(DT, steps=n)
    z = w.body_pose(b)[0][2]
    # v_k = -g k dt, z_n = 1 - g dt^2 n (n + 1) / 2 exactly for v += a dt; x += v dt.
    assert z == pytest.approx(1.0 - g * DT * DT * n * (n + 1) / 2, rel=1e-12)
    assert z == pytest.approx(1.0 - 0.5 * g * (n * DT) ** 2, abs=g * DT * n * DT)
    assert w.body_velocity(b)[0][2] == pytest.approx(-g * n * DT, rel=1e-12)
    force, torque = w.residual_wrench(b)
    np.testing.assert_allclose(force, (0, 0, -g * 0.1), rtol=1e-12)
    np.testing.assert_allclose(torque, (0, 0, 0), atol=1e-15)


def test_mass_properties_of_a_box_from_its_hull():
    a, b_, c = 0.1, 0.04, 0.02
    w = graspcore.World()
    b = w.add_body(box_points(a / 2, b_ / 2, c / 2, center=(0.01, 0.02, 0.03)), mass=2.0)
    mass, com, inertia = w.body_mass(b)
    assert mass == 2.0
    np.testing.assert_allclose(com, (0.01, 0.02, 0.03), atol=1e-12)
    expected = np.diag([b_ * b_ + c * c, a * a + c * c, a * a + b_ * b_]) * mass / 12
    np.testing.assert_allclose(inertia, expected, rtol=1e-9, atol=1e-15)


def test_spin_about_a_principal_axis_matches_the_closed_form():
    w = graspcore.World(gravity=(0, 0, 0))
    b = w.add_body(box_points(0.05, 0.03, 0.01), mass=1.0)
    omega = np.array([0.0, 0.0, 3.0])
    w.set_body_velocity(b, (0, 0, 0), omega)
    w.step(DT, steps=1000)
    q = np.array(w.body_pose(b)[1])
    angle = 3.0 * 1.0
    expected = np.array([np.cos(angle / 2), 0, 0, np.sin(angle / 2)])
    np.testing.assert_allclose(q, expected, atol=1e-12)


def test_world_frame_rotation_update_order():
    """A body already rotated about z, spun about world x: R(t) = Rx(wt) Rz(a), not Rz Rx."""
    a = 0.7
    w = graspcore.World(gravity=(0, 0, 0))
    b = w.add_body(box_points(0.05, 0.05, 0.05), mass=1.0,  # a cube: every axis principal
                   orientation=(np.cos(a / 2), 0, 0, np.sin(a / 2)))
    w.set_body_velocity(b, (0, 0, 0), (2.0, 0, 0))
    w.step(DT, steps=500)
    t = 2.0 * 0.5
    rx = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    np.testing.assert_allclose(quat_to_matrix(w.body_pose(b)[1]), rx @ rz, atol=1e-9)


def test_torque_free_asymmetric_body_conserves_angular_momentum():
    w = graspcore.World(gravity=(0, 0, 0), gyroscopic=True)
    b = w.add_body(box_points(0.1, 0.04, 0.01), mass=1.0)
    w.set_body_velocity(b, (0, 0, 0), (0.3, 4.0, 0.2))  # near the intermediate axis: tumbles

    def angular_momentum():
        _, com, inertia = w.body_mass(b)
        R = quat_to_matrix(w.body_pose(b)[1])
        omega = np.array(w.body_velocity(b)[1])
        return R @ np.array(inertia) @ R.T @ omega

    L0 = angular_momentum()
    w.step(DT, steps=2000)
    L1 = angular_momentum()
    np.testing.assert_allclose(L1, L0, rtol=0, atol=1e-6 * np.linalg.norm(L0))
    # Dropping the gyroscopic term (the simplification of the source chapter, Harwin & Barrow,
    # docs/physics.md) does not conserve it.
    w2 = graspcore.World(gravity=(0, 0, 0), gyroscopic=False)
    b2 = w2.add_body(box_points(0.1, 0.04, 0.01), mass=1.0)
    w2.set_body_velocity(b2, (0, 0, 0), (0.3, 4.0, 0.2))
    w2.step(DT, steps=2000)
    omega2 = np.array(w2.body_velocity(b2)[1])
    np.testing.assert_allclose(omega2, (0.3, 4.0, 0.2), rtol=1e-12)  # w stays constant in the world


@pytest.mark.parametrize("gyroscopic", [True, False])
def test_untouched_and_touched_bodies_integrate_alike(gyroscopic):
    """A body no finger touches is integrated with its block-diagonal mass directly; a touched
    one through the 6x6 factor with the finger coupling. With a negligible finger (1e-6 N/m)
    both must give the same tumbling motion."""
    def tumble(with_finger):
        w = graspcore.World(gravity=(0, 0, 0), gyroscopic=gyroscopic)
        b = w.add_body(box_points(0.1, 0.04, 0.01), mass=1.0)
        w.set_body_velocity(b, (0, 0, 0), (0.3, 4.0, 0.2))
        if with_finger:
            f = w.add_finger(radius=0.0, stiffness=1e-6, damping=0.0, position=(0.0, 0.0, 0.05))
            w.set_hip(f, (0.0, 0.0, 0.005))  # 5 mm from the centre: inside however the box turns
        states = []
        for _ in range(300):
            w.step(DT)
            if with_finger:
                states.append(w.finger_state(f))
        return np.array(w.body_velocity(b)[1]), quat_to_matrix(w.body_pose(b)[1]), states

    omega_free, R_free, _ = tumble(False)
    omega_touched, R_touched, states = tumble(True)
    assert "free" not in states  # the coupled path ran on every step
    np.testing.assert_allclose(omega_touched, omega_free, rtol=0, atol=1e-6)
    np.testing.assert_allclose(R_touched, R_free, rtol=0, atol=1e-7)


def test_angular_response_is_r_cross_f_over_j():
    """A finger pushing off-centre: residual torque r x F, and w_dot = J^-1 (r x F)."""
    k = 10.0  # soft, so the implicit correction k dt^2 r^2 / J is negligible
    w = graspcore.World(gravity=(0, 0, 0))
    b = w.add_body(box_points(0.05, 0.02, 0.02), mass=0.5)
    f = w.add_finger(radius=0.0, stiffness=k, position=(0.03, 0.0, 0.03))
    w.set_hip(f, (0.03, 0.0, 0.019))  # 1 mm into the top face at x = 0.03
    w.step(DT)
    force, torque = w.residual_wrench(b)
    F = np.array([0, 0, -k * 0.001])
    r = np.array([0.03, 0.0, 0.02])
    np.testing.assert_allclose(force, F, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(torque, np.cross(r, F), rtol=1e-4, atol=1e-8)  # implicit spring: k dt v off
    _, _, inertia = w.body_mass(b)
    expected_omega = np.linalg.solve(np.array(inertia), np.cross(r, F)) * DT
    np.testing.assert_allclose(w.body_velocity(b)[1], expected_omega, rtol=2e-3, atol=1e-12)


def pinch_world(depth, mass=0.2, mu_s=0.8, mu_d=0.6, damping=2.0):
    w = graspcore.World()
    b = w.add_body(box_points(0.03, 0.03, 0.03), mass=mass, mu_s=mu_s, mu_d=mu_d)
    r = 0.008
    x = 0.03 + r - depth
    f1 = w.add_finger(radius=r, stiffness=1000.0, damping=damping, position=(-x, 0, 0))
    f2 = w.add_finger(radius=r, stiffness=1000.0, damping=damping, position=(x, 0, 0))
    return w, b, (f1, f2), x


def test_pinched_box_is_held_and_lifted_with_enough_grip():
    # Two fingers at depth d hold m g when 2 mu_s k d > m g: here 2*0.8*1000*0.003 = 4.8 N > 1.96 N.
    w, b, (f1, f2), x = pinch_world(depth=0.003)
    for i in range(3000):
        lift = 0.05 * min(max(i * DT - 1.0, 0.0), 1.0)
        w.set_hip(f1, (-x, 0, lift))
        w.set_hip(f2, (x, 0, lift))
        w.step(DT)
    z = w.body_pose(b)[0][2]
    # Sag of the two tangential springs: m g / (2 k).
    assert z == pytest.approx(0.05 - 0.2 * 9.81 / 2000, abs=2e-5)
    assert w.finger_state(f1) == w.finger_state(f2) == "stick"
    assert w.finger_contact(f1) == w.finger_contact(f2) == b
    # The fingers carry the weight: vertical finger forces sum to -m g.
    fz = w.finger_forces[:, 2].sum()
    assert fz == pytest.approx(-0.2 * 9.81, rel=1e-3)


def test_pinched_box_slides_out_without_enough_grip():
    # 2*0.8*1000*0.0005 = 0.8 N < 1.96 N: it slips and falls.
    w, b, (f1, f2), x = pinch_world(depth=0.0005)
    for _ in range(1000):
        w.step(DT)
    assert w.body_pose(b)[0][2] < -0.05
    assert w.finger_state(f1) == "free"


def test_held_box_does_not_creep():
    w, b, (f1, f2), x = pinch_world(depth=0.003)
    w.step(DT, steps=3000)  # settle
    z0 = w.body_pose(b)[0][2]
    w.step(DT, steps=10000)
    assert abs(w.body_pose(b)[0][2] - z0) < 1e-6
    assert np.linalg.norm(w.body_velocity(b)[0]) < 1e-6


def test_finger_damping_damps_the_held_object():
    def oscillation(damping):
        w, b, fingers, x = pinch_world(depth=0.003, damping=damping)
        w.step(DT, steps=1000)
        return np.std([w.step(DT) or w.body_pose(b)[0][2] for _ in range(200)])

    assert oscillation(5.0) < 0.2 * oscillation(0.0)


def test_pencil_tripod_is_stable_for_ten_seconds():
    """A 10 g pencil in a three-finger grasp at 1 kHz with 1000 N/m fingers, kicked in roll.

    Its roll mode (3 k r^2 / J with J = 7e-8 kg m^2) is near 1.2 kHz: explicit coupling at
    1 kHz diverges; the implicit coupling must hold it."""
    w = graspcore.World()
    radius, half_length = 0.0035, 0.075
    b = w.add_body(prism_points(radius, half_length), mass=0.01, mu_s=0.9, mu_d=0.7)
    tip, depth = 0.006, 0.001
    fingers = []
    for k in range(3):  # thumb above, two fingers below, in one cross-section
        angle = 2 * np.pi * k / 3 + np.pi / 2
        reach = radius * np.cos(np.pi / 6) + tip - depth  # the prism's flat faces sit at r cos 30
        hip = (0.0, reach * np.cos(angle), reach * np.sin(angle))
        fingers.append(w.add_finger(radius=tip, stiffness=1000.0, damping=0.5, position=hip))
    w.step(DT, steps=1000)
    w.set_body_velocity(b, (0, 0, 0), (20.0, 0, 0))  # a sharp roll kick
    speeds = []
    for i in range(9000):
        w.step(DT)
        if i % 100 == 0:
            speeds.append(np.linalg.norm(w.body_velocity(b)[1]))
    pos, q = w.body_pose(b)
    assert np.all(np.isfinite(pos)) and np.all(np.isfinite(q))
    assert np.linalg.norm(pos) < 0.001  # held where it was grasped
    assert max(speeds[10:]) < 1e-3  # the kick died out, no spin-up
    assert all(w.finger_state(f) == "stick" for f in fingers)
    # Sag under gravity is a fraction of the finger springs' give: m g / (3 k) scale.
    assert abs(pos[2]) < 0.01 * 9.81 / 1000


def test_identical_inputs_give_bit_identical_states():
    def run():
        w, b, (f1, f2), x = pinch_world(depth=0.003)
        for i in range(1500):
            s = np.sin(i * 0.01) * 0.01
            w.set_hip(f1, (-x, s, 0.01 * s))
            w.set_hip(f2, (x, s, 0.01 * s))
            w.step(DT)
        return w.state_hash(), w.body_poses.tobytes()

    assert run() == run()


def test_views_are_zero_copy_and_read_only():
    w = graspcore.World()
    b = w.add_body(box_points(0.01, 0.01, 0.01), mass=0.1)
    f = w.add_finger(position=(1, 2, 3))
    poses, hips = w.body_poses, w.hips
    assert poses.shape == (1, 7) and hips.shape == (1, 3)
    w.step(DT, steps=10)
    assert poses[0, 2] == w.body_pose(b)[0][2] < 0  # the old view sees the new state
    w.set_hip(f, (4, 5, 6))
    np.testing.assert_array_equal(hips[0], (4, 5, 6))
    with pytest.raises(ValueError):
        poses[0, 0] = 1.0
    del w  # views keep the world alive
    assert poses[0, 3] == 1.0


def test_velocity_is_set_and_read_at_the_body_origin():
    w = graspcore.World(gravity=(0, 0, 0))
    b = w.add_body(box_points(0.02, 0.02, 0.02, center=(0.1, 0, 0)), mass=1.0,
                   linear_velocity=(0, 0.5, 0), angular_velocity=(0, 0, 2.0))
    lin, ang = w.body_velocity(b)
    np.testing.assert_allclose(lin, (0, 0.5, 0), atol=1e-15)
    w.set_body_velocity(b, (0.1, 0.2, 0.3), (1.0, 0, 0))
    lin, ang = w.body_velocity(b)
    np.testing.assert_allclose(lin, (0.1, 0.2, 0.3), atol=1e-15)
    np.testing.assert_allclose(ang, (1.0, 0, 0))


def test_residual_wrench_vanishes_for_a_box_carried_at_constant_speed():
    w, b, (f1, f2), x = pinch_world(depth=0.003)
    w.step(DT, steps=1000)
    for i in range(2000):
        lift = 0.1 * i * DT  # 10 cm/s
        w.set_hip(f1, (-x, 0, lift))
        w.set_hip(f2, (x, 0, lift))
        w.step(DT)
    force, torque = w.residual_wrench(b)
    assert np.linalg.norm(force) < 1e-3  # was k dt v = 0.2 N when springs were read at step start
    assert w.body_velocity(b)[0][2] == pytest.approx(0.1, rel=1e-3)


def test_fingers_carrying_a_box_at_constant_speed_feel_its_weight():
    """Device forces are read on the poses the step moved the body to: no k v dt lag."""
    w, b, (f1, f2), x = pinch_world(depth=0.003)
    w.step(DT, steps=1000)
    for i in range(1500):
        lift = 0.1 * i * DT  # 10 cm/s up
        w.set_hip(f1, (-x, 0, lift))
        w.set_hip(f2, (x, 0, lift))
        w.step(DT)
    carried = -w.finger_forces[:, 2].sum()
    assert carried == pytest.approx(0.2 * 9.81, rel=1e-3)
