"""xFCA god-object behaviour against analytic results, on static bodies."""
import numpy as np
import pytest

import graspcore
from scenes import box_points

K = 1000.0
DT = 1e-3


def table_world(mu_s=0.5, mu_d=0.3, viscosity=0.0, radius=0.0):
    """A static slab whose top face is z = 0, and one finger just above it."""
    w = graspcore.World(gravity=(0, 0, 0))
    w.add_body(box_points(0.2, 0.2, 0.05, center=(0, 0, -0.05)), static=True, mu_s=mu_s, mu_d=mu_d,
               viscosity=viscosity)
    f = w.add_finger(radius=radius, stiffness=K, position=(0, 0, radius + 0.01))
    return w, f


def press(w, f, depth, radius=0.0, steps=20):
    """Lower the HIP straight down to `depth` below the surface the fingertip centre sees."""
    start = radius + 0.01
    for i in range(1, steps + 1):
        z = start + (radius - depth - start) * i / steps
        w.set_hip(f, (0, 0, z))
        w.step(DT)


@pytest.mark.parametrize("radius", [0.0, 0.008])
def test_normal_force_is_spring_on_depth(radius):
    w, f = table_world(radius=radius)
    press(w, f, 0.002, radius)
    force = np.array(w.finger_force(f))
    assert w.finger_state(f) == "stick"
    assert w.finger_contact(f) == 0
    np.testing.assert_allclose(force, [0, 0, K * 0.002], atol=1e-9)
    np.testing.assert_allclose(w.god_object(f), [0, 0, radius], atol=1e-9)


@pytest.mark.parametrize("radius", [0.0, 0.008])
def test_stick_below_mu_s_depth_then_slip_at_mu_d(radius):
    mu_s, mu_d, depth = 0.5, 0.3, 0.002
    w, f = table_world(mu_s, mu_d, radius=radius)
    press(w, f, depth, radius)
    z = radius - depth
    limit = mu_s * depth
    # Stick: the GO stays put, the tangential force is the spring on the offset.
    for x in np.linspace(0, 0.95 * limit, 12)[1:]:
        w.set_hip(f, (x, 0, z))
        w.step(DT)
        assert w.finger_state(f) == "stick"
        fx, _, fz = w.finger_force(f)
        assert fx == pytest.approx(-K * x, rel=1e-9)
        assert fz == pytest.approx(K * depth, rel=1e-9)
    # Past mu_s * depth: slip, and while sliding |Ft| / |Fn| is mu_d.
    ratios = []
    for x in np.linspace(1.05 * limit, 5 * limit, 30):
        w.set_hip(f, (x, 0, z))
        w.step(DT)
        assert w.finger_state(f) == "slip"
        fx, fy, fz = w.finger_force(f)
        ratios.append(np.hypot(fx, fy) / fz)
    np.testing.assert_allclose(ratios, mu_d, rtol=1e-9)
    # Stopping inside the mu_d circle returns to stick.
    w.step(DT)
    assert w.finger_state(f) == "stick"


def test_slip_direction_follows_the_hip():
    w, f = table_world(0.5, 0.3)
    press(w, f, 0.002)
    direction = np.array([0.6, -0.8, 0.0])
    for s in np.linspace(0, 0.01, 40)[1:]:
        w.set_hip(f, tuple(direction * s + [0, 0, -0.002]))
        w.step(DT)
    force = np.array(w.finger_force(f))
    tangential = force[:2] / np.linalg.norm(force[:2])
    np.testing.assert_allclose(tangential, -direction[:2], atol=1e-9)


def trailing_slope(speed, viscosity, depth=0.002):
    """d(tangential force)/dt while sliding at `speed`."""
    w, f = table_world(0.5, 0.3, viscosity=viscosity)
    press(w, f, depth)
    forces, times = [], []
    x = 0.0
    for i in range(400):
        x += speed * DT
        w.set_hip(f, (x, 0, -depth))
        w.step(DT)
        if i >= 200:
            forces.append(-w.finger_force(f)[0])
            times.append(w.time)
    return np.polyfit(times, forces, 1)[0], forces[-1]


def test_viscous_friction_rises_with_sliding_speed():
    # The GO may slide at most depth / viscosity per second (the viscous radius of the
    # source chapter, Harwin & Barrow, docs/physics.md: depth*dt/viscosity per step);
    # faster, it trails, and the force grows at
    # K * (speed - depth / viscosity).
    viscosity, depth = 0.05, 0.002
    v_limit = depth / viscosity  # 0.04 m/s
    finals = []
    for speed in (0.02, 0.06, 0.1):
        slope, final = trailing_slope(speed, viscosity, depth)
        expected = K * max(speed - v_limit, 0.0)
        assert slope == pytest.approx(expected, rel=1e-6, abs=1e-6)
        finals.append(final)
    assert finals[0] == pytest.approx(K * 0.3 * depth, rel=1e-9)  # below the limit: Coulomb only
    assert finals[0] < finals[1] < finals[2]
    # Without viscosity the same slides are pure Coulomb.
    assert trailing_slope(0.1, 0.0, depth)[1] == pytest.approx(K * 0.3 * depth, rel=1e-9)


@pytest.mark.parametrize("radius", [0.0, 0.008])
def test_contact_lost_when_hip_leaves(radius):
    w, f = table_world(radius=radius)
    press(w, f, 0.002, radius)
    assert w.finger_state(f) == "stick"
    w.set_hip(f, (0, 0, radius + 0.0001))
    w.step(DT)
    assert w.finger_state(f) == "free"
    assert w.finger_contact(f) is None
    assert w.finger_force(f) == (0.0, 0.0, 0.0)
    np.testing.assert_allclose(w.god_object(f), (0, 0, radius + 0.0001))


@pytest.mark.parametrize("radius", [0.0, 0.008])
@pytest.mark.parametrize("per_step", [0.0002, 0.05])
def test_no_push_through_thin_plate(radius, per_step):
    """A 2 mm plate: whether the HIP crawls or jumps through it, the GO stays on top."""
    w = graspcore.World(gravity=(0, 0, 0))
    w.add_body(box_points(0.1, 0.1, 0.001), static=True)
    f = w.add_finger(radius=radius, stiffness=K, position=(0.01, 0.02, 0.03))
    z = 0.03
    while z > -0.05:
        z -= per_step
        w.set_hip(f, (0.01, 0.02, z))
        w.step(DT)
        if z < 0.001 + radius:
            assert w.finger_state(f) != "free"
            go = w.god_object(f)
            assert go[2] == pytest.approx(0.001 + radius, abs=1e-6)
            assert w.finger_force(f)[2] == pytest.approx(K * (0.001 + radius - z), rel=1e-6)
    # And sliding sideways while pushed through keeps it on top too.
    for x in np.linspace(0.01, 0.09, 50):
        w.set_hip(f, (x, 0.02, -0.05))
        w.step(DT)
        assert w.god_object(f)[2] == pytest.approx(0.001 + radius, abs=1e-6)


def test_go_follows_a_curved_surface():
    """Sliding over a sphere keeps the GO on it (the push toward the HIP is enough)."""
    w = graspcore.World(gravity=(0, 0, 0))
    R = 0.05
    w.add_body(np.zeros((1, 3)), radius=R, static=True, mu_s=0.1, mu_d=0.05)
    f = w.add_finger(radius=0.0, stiffness=K, position=(0, 0, R + 0.01))
    for z in np.linspace(R + 0.01, R - 0.003, 20):
        w.set_hip(f, (0, 0, z))
        w.step(DT)
    for angle in np.linspace(0, 1.0, 200):
        r = R - 0.003
        w.set_hip(f, (r * np.sin(angle), 0, r * np.cos(angle)))
        w.step(DT)
        assert w.finger_state(f) != "free"
        assert np.linalg.norm(w.god_object(f)) == pytest.approx(R, abs=1e-6)


def test_compound_body_has_a_god_object_per_part():
    """Pressing into the inner corner of an L made of two boxes touches both parts."""
    w = graspcore.World(gravity=(0, 0, 0))
    floor = box_points(0.06, 0.05, 0.01, center=(-0.01, 0, -0.01))  # runs under the wall
    wall = box_points(0.01, 0.05, 0.05, center=(-0.06, 0, 0.04))
    w.add_body(parts=[floor, wall], static=True, mu_s=0.0, mu_d=0.0)  # frictionless: forces are normal
    f = w.add_finger(radius=0.0, stiffness=K, position=(-0.045, 0, 0.01))
    for i in range(1, 21):
        s = 0.007 * i / 20
        w.set_hip(f, (-0.045 - s, 0, 0.01 - 0.012 * i / 20))
        w.step(DT)
    fx, fy, fz = w.finger_force(f)
    # Both the floor (pushes up) and the wall (pushes +x) act on the finger, each by its own depth.
    assert fz == pytest.approx(K * 0.002, rel=1e-6)
    assert fx == pytest.approx(K * 0.002, rel=1e-6)
