"""Seeded random fuzzing of the Python API: random scenes and call sequences with extreme but
legal values (1 g bodies, 1e5 N/m fingers, 1 m HIP jumps, spins to 2,000 rad/s, steps from
0.1 ms to 10 ms, stepped directly and on the runtime's manual clock). Nothing may crash,
raise, or leave a non-finite number in any output. A body the non-finite guard had to stop
is allowed only if it was reported (RuntimeWarning and stopped_bodies())."""
import warnings

import numpy as np
import pytest

import graspcore
from scenes import box_points

SCENES = 40
CALLS = 60


def log_uniform(rng, lo, hi):
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def random_unit_quaternion(rng):
    q = rng.standard_normal(4)
    return tuple(q / np.linalg.norm(q))


def random_body(rng, w):
    size = log_uniform(rng, 0.003, 0.15)
    kind = rng.integers(4)
    common = dict(
        mass=log_uniform(rng, 1e-3, 10.0),
        position=tuple(rng.uniform(-0.2, 0.2, 3)),
        orientation=random_unit_quaternion(rng),
        mu_s=float(rng.uniform(0.0, 1.5)),
        linear_velocity=tuple(rng.uniform(-10, 10, 3) * (rng.random() < 0.3)),
        angular_velocity=tuple(rng.uniform(-2000, 2000, 3) * (rng.random() < 0.3)),
    )
    common["mu_d"] = float(rng.uniform(0.0, common["mu_s"]))
    if kind == 0:  # a box, flat to cubic
        half = size * np.array([1.0, log_uniform(rng, 0.05, 1.0), log_uniform(rng, 0.05, 1.0)])
        return w.add_body(box_points(*half), **common)
    if kind == 1:  # a sphere
        return w.add_body([[0, 0, 0]], radius=size, **common)
    if kind == 2:  # a capsule
        return w.add_body([[-size, 0, 0], [size, 0, 0]], radius=size * log_uniform(rng, 0.05, 1.0), **common)
    # a random hull: points on a sphere, so never degenerate
    p = rng.standard_normal((int(rng.integers(8, 24)), 3))
    p = size * p / np.linalg.norm(p, axis=1, keepdims=True)
    return w.add_body(p, **common)


def all_outputs(w):
    arrays = [w.body_poses, w.god_objects, w.finger_forces, w.hips]
    for b in range(w.body_count):
        arrays += [np.array(v) for v in w.body_velocity(b)] + [np.array(v) for v in w.residual_wrench(b)]
    for c in w.contacts():
        arrays += [np.array(c["point"]), np.array(c["normal"]), np.array(c["friction_impulse"]),
                   np.array([c["separation"], c["normal_impulse"]])]
    return arrays


def assert_finite(w, where):
    for a in all_outputs(w):
        assert np.all(np.isfinite(a)), f"non-finite output after {where}"


def build_scene(rng):
    w = graspcore.World(gravity=(0, 0, -9.81) if rng.random() < 0.7 else tuple(rng.uniform(-20, 20, 3)),
                        gyroscopic=bool(rng.random() < 0.8), threads=int(rng.integers(1, 3)))
    if rng.random() < 0.6:
        w.add_body(box_points(0.5, 0.5, 0.05), static=True, position=(0, 0, -0.3))
    bodies = [random_body(rng, w) for _ in range(int(rng.integers(1, 6)))]
    fingers = [w.add_finger(radius=float(rng.choice([0.0, log_uniform(rng, 0.001, 0.02)])),
                            stiffness=log_uniform(rng, 10.0, 1e5), damping=float(rng.uniform(0, 50)),
                            position=tuple(rng.uniform(-0.3, 0.3, 3)))
               for _ in range(int(rng.integers(0, 6)))]
    return w, bodies, fingers


def random_call(rng, w, bodies, fingers, stopped):
    r = rng.random()
    dynamic = list(bodies)
    if r < 0.35 and fingers:
        f = int(rng.choice(fingers))
        here = np.array(w.body_pose(int(rng.choice(bodies)))[0])
        jump = rng.uniform(-1, 1, 3) if rng.random() < 0.2 else rng.uniform(-0.03, 0.03, 3)
        w.set_hip(f, tuple(here + jump))
    elif r < 0.45 and fingers:
        w.set_hips(np.array(w.hips) + rng.uniform(-0.01, 0.01, (len(fingers), 3)))
    elif r < 0.55:
        w.set_body_velocity(int(rng.choice(dynamic)), tuple(rng.uniform(-10, 10, 3)),
                            tuple(rng.uniform(-2000, 2000, 3)))
    elif r < 0.6:
        w.set_body_pose(int(rng.choice(dynamic)), tuple(rng.uniform(-0.2, 0.2, 3)), random_unit_quaternion(rng))
    elif r < 0.62:
        w.set_gravity(tuple(rng.uniform(-30, 30, 3)))
    elif r < 0.65:
        mu_s = float(rng.uniform(0.0, 2.0))
        w.set_body_friction(int(rng.choice(dynamic)), mu_s, float(rng.uniform(0.0, mu_s)),
                            float(rng.choice([0.0, log_uniform(rng, 1e-4, 1.0)])))
    else:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            w.step(log_uniform(rng, 1e-4, 1e-2), steps=int(rng.integers(1, 20)))
        stopped += [str(c.message) for c in caught if issubclass(c.category, RuntimeWarning)]


@pytest.mark.parametrize("seed", range(SCENES))
def test_random_scene_and_calls_stay_finite(seed):
    rng = np.random.default_rng(seed)
    w, bodies, fingers = build_scene(rng)
    stopped = []
    for call in range(CALLS):
        random_call(rng, w, bodies, fingers, stopped)
        assert_finite(w, f"call {call}")
        chains = [w.body_chain(b) for b in bodies]
        assert all(c is None or 0 <= c < w.chain_count() for c in chains)
    assert w.stopped_bodies() >= len(stopped)  # every warning counted; a count without one is impossible
    assert (w.stopped_bodies() > 0) == (len(stopped) > 0)
    for message in stopped:
        assert message.startswith("body ") and "non-finite" in message


@pytest.mark.parametrize("seed", range(10))
def test_random_runtime_sessions_stay_finite(seed):
    """The same on the runtime's manual clock: pushes with jumps, stalls, snapshots."""
    rng = np.random.default_rng(1000 + seed)
    w, bodies, fingers = build_scene(rng)
    if not fingers:
        fingers.append(w.add_finger(stiffness=1e5, position=(0, 0, 0)))
    w.start(realtime=False, max_adopted_bodies=int(rng.integers(0, 4)))
    t = 0.0
    for _ in range(CALLS):
        r = rng.random()
        if r < 0.5:
            t += log_uniform(rng, 1e-4, 1e-2)
            hips = np.array(w.snapshot()["hips"]) + rng.uniform(-1, 1, (len(fingers), 3)) * (rng.random() < 0.2)
            w.push_hips(hips + rng.uniform(-0.01, 0.01, hips.shape), t)
        else:
            w.advance(int(rng.integers(1, 30)), delay=float(rng.choice([0.0, log_uniform(rng, 1e-4, 0.02)])))
        snap = w.snapshot()
        for key in ("poses", "residual_forces", "residual_torques", "god_objects", "hips", "forces",
                    "spring_forces"):
            assert np.all(np.isfinite(snap[key])), key
        stats = w.stats()
        assert all(np.isfinite(v) for v in stats.values() if isinstance(v, float))
    w.stop()
    assert_finite(w, "stop")
    assert w.stopped_bodies() == stats["stopped_bodies"]


def test_a_body_that_would_turn_non_finite_is_stopped_and_reported():
    """A finite but absurd velocity (1e308 m/s on 10 kg: the momentum overflows) cannot be
    integrated. The body goes back to where it was, at rest, the step says so, the count
    goes up, and a finger holding another body never sees it."""
    w = graspcore.World(gravity=(0, 0, -9.81))
    bad = w.add_body(box_points(0.02, 0.02, 0.02), mass=10.0, position=(1.0, 0, 0))
    good = w.add_body(box_points(0.03, 0.03, 0.03), mass=0.2)
    left = w.add_finger(radius=0.008, stiffness=1000.0, position=(-0.035, 0, 0))
    right = w.add_finger(radius=0.008, stiffness=1000.0, position=(0.035, 0, 0))
    ref = graspcore.World(gravity=(0, 0, -9.81))
    ref.add_body(box_points(0.02, 0.02, 0.02), mass=10.0, position=(1.0, 0, 0))
    ref.add_body(box_points(0.03, 0.03, 0.03), mass=0.2)
    ref.add_finger(radius=0.008, stiffness=1000.0, position=(-0.035, 0, 0))
    ref.add_finger(radius=0.008, stiffness=1000.0, position=(0.035, 0, 0))
    for world in (w, ref):
        world.step(1e-3, steps=100)
    before = w.body_pose(bad)
    w.set_body_velocity(bad, (1e308, 0, 0), (0, 0, 0))
    with pytest.warns(RuntimeWarning, match=r"^body 0: its state would have become non-finite"):
        w.step(1e-3)
    assert w.stopped_bodies() == 1
    assert w.body_pose(bad) == before
    assert w.body_velocity(bad) == ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    ref.step(1e-3)
    assert w.body_pose(good) == ref.body_pose(good)          # the neighbour stepped as if nothing happened
    np.testing.assert_array_equal(w.finger_forces, ref.finger_forces)
    assert_finite(w, "the stopped step")
    w.step(1e-3, steps=10)                                    # and it carries on from rest
    assert w.stopped_bodies() == 1
    assert w.body_velocity(bad)[0][2] == pytest.approx(-9.81 * 10e-3, rel=1e-9)


@pytest.mark.parametrize("seed", range(20))
def test_random_convex_finger_scenes_stay_finite(seed):
    """Random scenes with convex fingers (pads, random hulls up to 32 vertices, 1 mm to 20 cm,
    radius 0 to 1 cm) turned to random orientations and jumping through the bodies: every
    output, the fingers' torques and contact patches included, stays finite."""
    rng = np.random.default_rng(2000 + seed)
    w, bodies, fingers = build_scene(rng)
    convex = []
    for _ in range(int(rng.integers(1, 4))):
        size = log_uniform(rng, 0.001, 0.2)
        if rng.random() < 0.5:
            pts = box_points(size, size * log_uniform(rng, 0.1, 1.0), size * log_uniform(rng, 0.02, 1.0))
        else:
            p = rng.standard_normal((int(rng.integers(4, 40)), 3))
            pts = size * p / np.linalg.norm(p, axis=1, keepdims=True)
        try:
            f = w.add_finger(radius=float(rng.choice([0.0, log_uniform(rng, 1e-4, 0.01)])),
                             stiffness=log_uniform(rng, 10.0, 1e5), damping=float(rng.uniform(0, 50)),
                             position=tuple(rng.uniform(-0.3, 0.3, 3)), points=pts,
                             orientation=random_unit_quaternion(rng))
        except ValueError as ex:  # a random hull of more than 32 vertices
            assert "at most 32" in str(ex)
            continue
        convex.append(f)
    fingers = fingers + convex
    stopped = []
    for call in range(CALLS):
        if convex and rng.random() < 0.3:
            f = int(rng.choice(convex))
            here = np.array(w.body_pose(int(rng.choice(bodies)))[0])
            w.set_finger_pose(f, tuple(here + rng.uniform(-0.05, 0.05, 3)), random_unit_quaternion(rng))
        else:
            random_call(rng, w, bodies, fingers, stopped)
        assert_finite(w, f"call {call}")
        for f in convex:
            assert np.all(np.isfinite(w.finger_torque(f)))
            for c in w.finger_contacts(f):
                assert np.all(np.isfinite(np.concatenate([c["point"], c["normal"], c["force"]])))
    assert (w.stopped_bodies() > 0) == (len(stopped) > 0)
