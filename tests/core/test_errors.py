"""Bad arguments raise ValueError naming the argument, and leave the world unchanged."""
import math

import numpy as np
import pytest

import graspcore
from scenes import box_points


@pytest.fixture
def world():
    w = graspcore.World()
    w.add_body(box_points(0.02, 0.02, 0.02), mass=0.1)
    w.add_finger(position=(0.1, 0, 0))
    w.step(1e-3, steps=3)
    return w


def snapshot(w):
    return w.state_hash(), w.body_count, w.finger_count, w.body_poses.tobytes()


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda w: w.add_body(box_points(0.01, 0.01, 0.01), mass=0.0), "mass"),
        (lambda w: w.add_body(box_points(0.01, 0.01, 0.01), mass=-1.0), "mass"),
        (lambda w: w.add_body(box_points(0.01, 0.01, 0.01), mass=math.nan), "mass"),
        (lambda w: w.add_body([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], mass=1.0), "points"),  # coplanar
        (lambda w: w.add_body([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]], mass=1.0), "points"),  # collinear
        (lambda w: w.add_body([[0, 0, 0]] * 5, mass=1.0), "points"),  # coincident
        (lambda w: w.add_body([[0, 0, math.nan]] * 5, mass=1.0), "points"),
        (lambda w: w.add_body([[0, 0], [1, 1]], mass=1.0), "points"),
        (lambda w: w.add_body(parts=[box_points(0.01, 0.01, 0.01), [[0, 0, 0]] * 4], mass=1.0), "parts"),
        (lambda w: w.add_body(box_points(0.01, 0.01, 0.01), position=(0, math.inf, 0)), "position"),
        (lambda w: w.add_body(box_points(0.01, 0.01, 0.01), orientation=(0, 0, 0, 0)), "orientation"),
        (lambda w: w.add_body(box_points(0.01, 0.01, 0.01), mu_s=0.3, mu_d=0.5), "mu_d"),
        (lambda w: w.add_body(box_points(0.01, 0.01, 0.01), mu_s=-0.1, mu_d=0.0), "mu_s"),
        (lambda w: w.add_body(box_points(0.01, 0.01, 0.01), viscosity=-1), "viscosity"),
        (lambda w: w.add_body(box_points(0.01, 0.01, 0.01), inertia=(1, 1, 5)), "inertia"),  # triangle rule
        (lambda w: w.add_body(box_points(0.01, 0.01, 0.01), inertia=(1, -1, 1)), "inertia"),
        (lambda w: w.add_body(box_points(0.01, 0.01, 0.01), inertia=(1, 2)), "inertia"),
        (lambda w: w.add_finger(radius=-0.001), "radius"),
        (lambda w: w.add_finger(stiffness=0.0), "stiffness"),
        (lambda w: w.add_finger(damping=math.nan), "damping"),
        (lambda w: w.add_finger(position=(0, 0)), "position"),
        (lambda w: w.set_hip(0, (0, math.nan, 0)), "position"),
        (lambda w: w.set_hip(0, (0, 0)), "position"),
        (lambda w: w.set_hip(7, (0, 0, 0)), "finger"),
        (lambda w: w.set_hip(-1, (0, 0, 0)), "finger"),
        (lambda w: w.set_hips(np.zeros((2, 3))), "positions"),
        (lambda w: w.set_body_velocity(3, (0, 0, 0), (0, 0, 0)), "body"),
        (lambda w: w.set_body_velocity(0, (0, 0, math.inf), (0, 0, 0)), "linear"),
        (lambda w: w.set_body_pose(0, (0, 0, 0), (0, 0, 0, 0)), "orientation"),
        (lambda w: w.body_pose(5), "body"),
        (lambda w: w.finger_force(5), "finger"),
        (lambda w: w.step(0.0), "dt"),
        (lambda w: w.step(math.nan), "dt"),
        (lambda w: w.step(-1e-3), "dt"),
        (lambda w: w.attach_serial(9999), "fd"),        # no such descriptor (was accepted)
        (lambda w: w.attach_serial(-1), "fd"),
    ],
)
def test_bad_argument_names_itself_and_changes_nothing(world, call, name):
    before = snapshot(world)
    with pytest.raises(ValueError) as info:
        call(world)
    assert str(info.value).startswith(name), str(info.value)
    assert snapshot(world) == before


def test_capacity_is_reported():
    w = graspcore.World(max_bodies=1, max_fingers=1)
    w.add_body(box_points(0.01, 0.01, 0.01))
    w.add_finger()
    with pytest.raises(ValueError, match="max_bodies"):
        w.add_body(box_points(0.01, 0.01, 0.01))
    with pytest.raises(ValueError, match="max_fingers"):
        w.add_finger()


@pytest.mark.parametrize("kwargs, name", [
    (dict(gravity=(0, 0, math.nan)), "gravity"),
    (dict(max_bodies=0), "max_bodies"),
    (dict(max_fingers=-1), "max_fingers"),
    (dict(max_parts=0), "max_parts"),
    (dict(threads=65), "threads"),
    (dict(max_contacts=-5), "max_contacts"),
])
def test_world_names_just_the_argument_it_refuses(kwargs, name):
    names = {"gravity", "max_bodies", "max_fingers", "max_parts", "threads", "max_contacts"}
    with pytest.raises(ValueError) as info:
        graspcore.World(**kwargs)
    message = str(info.value)
    assert message.startswith(name + ":")
    assert not any(other in message for other in names - {name})


def test_static_body_needs_no_mass_and_refuses_velocity():
    w = graspcore.World()
    b = w.add_body(box_points(0.1, 0.1, 0.01), static=True, mass=0.0)
    with pytest.raises(ValueError, match="static"):
        w.set_body_velocity(b, (1, 0, 0), (0, 0, 0))
    w.step(1e-3, steps=10)
    assert w.body_pose(b) == ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))


def test_spheres_and_capsules_from_one_or_two_points():
    w = graspcore.World(gravity=(0, 0, 0))
    s = w.add_body([[0, 0, 0]], radius=0.01, mass=1.0)
    c = w.add_body([[-0.05, 0, 0], [0.05, 0, 0]], radius=0.01, mass=1.0)
    _, _, inertia = w.body_mass(s)
    np.testing.assert_allclose(np.diag(inertia), [0.4 * 1e-4] * 3, rtol=1e-9)
    _, com, inertia = w.body_mass(c)
    np.testing.assert_allclose(com, (0, 0, 0), atol=1e-12)
    assert inertia[0][0] < inertia[1][1] == pytest.approx(inertia[2][2])
    with pytest.raises(ValueError, match="points"):
        w.add_body([[0, 0, 0]], radius=0.0, mass=1.0)


def test_runtime_errors_carry_the_cores_message():
    """The binding raises with the core's message, never one of its own."""
    w = graspcore.World()
    w.add_finger()
    with pytest.raises(RuntimeError, match=r"^push_hips: the runtime is not running"):
        w.push_hips(np.zeros((1, 3)), 0.0)
    w.start(realtime=False)
    with pytest.raises(ValueError, match=r"^positions: 2 rows given for 1 fingers"):
        w.push_hips(np.zeros((2, 3)), 0.0)
    with pytest.raises(ValueError, match=r"^haptic_rate:"):
        w.stop()
        w.start(haptic_rate=-1.0)
    with pytest.raises(RuntimeError, match=r"^advance: the runtime is not running"):
        w.advance(1)
