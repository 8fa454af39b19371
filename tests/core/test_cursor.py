"""The light-mass cursor renderer (native/src/cursor.c, issue 20): against analytic results
and beside xFCA: one surface across a seam of parts, the walls of a crease add, stiction and
Coulomb sliding, no push-through of thin walls however fast the HIP, no energy gain, stable at
1 kHz with device stiffnesses, a box lifted as xFCA lifts it, the hooked mug's handle slid
without a bump, and its arguments checked."""
import os
import sys

import numpy as np
import pytest

import graspcore

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.dirname(os.path.dirname(HERE)))

import scenes  # noqa: E402
from addon.engine import continuity  # noqa: E402

K, R, DT = 1000.0, 0.005, 1e-3


def _run(bodies, hips, renderer="cursor", stiffness=K, damping=0.0, mass=0.002, radius=R):
    """bodies: [(parts, kwargs)]; one finger; tick records, one per step."""
    w = graspcore.World(gravity=(0.0, 0.0, 0.0))
    for parts, kw in bodies:
        w.add_body(parts=parts, **kw)
    w.add_finger(radius=radius, stiffness=stiffness, damping=damping, position=hips[0], renderer=renderer,
                 cursor_mass=mass)
    return w, scenes.run_ticks(w, np.asarray(hips, float))


def _eased(a, b, n):
    s = np.linspace(0.0, 1.0, n)
    e = s * s * (3.0 - 2.0 * s)
    return [np.asarray(a, float) + (np.asarray(b, float) - np.asarray(a, float)) * x for x in e]


def _static(parts, mu=(0.0, 0.0)):
    return (parts, dict(static=True, mu_s=mu[0], mu_d=mu[1]))


def test_defaults_and_arguments():
    assert graspcore.FINGER_DEFAULTS["renderer"] == "xfca"
    assert graspcore.FINGER_DEFAULTS["cursor_mass"] == 0.002
    w = graspcore.World()
    with pytest.raises(ValueError, match="renderer: must be 'xfca' or 'cursor'"):
        w.add_finger(renderer="lcp")
    with pytest.raises(ValueError, match="cursor_mass: must be a finite number >= 0"):
        w.add_finger(renderer="cursor", cursor_mass=-1.0)
    with pytest.raises(ValueError, match="cursor_mass"):
        w.add_finger(renderer="cursor", cursor_mass=float("nan"))
    assert w.finger_count == 0


def test_seam_of_two_parts_is_one_flat_surface():
    # A slab of two boxes sharing x = 0, the fingertip pressed 2 mm and slid across: exactly
    # k d normal and no sideways force (frictionless, no damping: the light mass alone).
    d = 0.002
    parts = [scenes.box_points(0.01, 0.02, 0.01, (-0.01, 0, 0)), scenes.box_points(0.01, 0.02, 0.01, (0.01, 0, 0))]
    z = 0.01 + R - d
    hips = _eased((-0.012, 0, z + 0.004), (-0.012, 0, z), 200) + [np.array((-0.012, 0, z))] * 100
    hips += _eased((-0.012, 0, z), (0.012, 0, z), 2000)
    _, t = _run([_static(parts)], hips)
    f = t["force"][301:, 0]
    np.testing.assert_allclose(f[:, 2], K * d, rtol=1e-9)
    assert np.abs(f[:, 0]).max() < 1e-3                # the 2 g cursor's inertia at 18 mm/s
    assert set(t["parts"][301:, 0].tolist()) >= {1, 2}                  # one part, then the other


@pytest.mark.parametrize("d_floor, d_wall", [(0.002, 0.002), (0.003, 0.0005)])
def test_concave_crease_adds_both_walls(d_floor, d_wall):
    parts = [scenes.box_points(0.02, 0.02, 0.005, (-0.01, 0, -0.005)), scenes.box_points(0.005, 0.02, 0.02, (0.005, 0, 0.01))]
    target = np.array([-R + d_wall, 0, R - d_floor])
    _, t = _run([_static(parts)], _eased(target + [-0.004, 0, 0.004], target, 300) + [target] * 300)
    np.testing.assert_allclose(t["force"][-1, 0], [-K * d_wall, 0.0, K * d_floor], atol=1e-9)
    assert t["parts"][-1, 0] == 3


def test_stiction_then_coulomb_sliding():
    # 2 N normal on a box (mu_s 0.6, mu_d 0.5), the HIP moved sideways slowly: the cursor
    # stays put and the sideways force is k times the HIP's offset up to mu_s Fn = 1.2 N;
    # then it slides at mu_d Fn = 1.0 N.
    d = 0.002
    z = 0.01 + R - d
    hips = _eased((0, 0, z + 0.004), (0, 0, z), 200) + [np.array((0, 0, z))] * 100
    hips += [np.array((x, 0, z)) for x in np.linspace(0.0, 0.004, 4000)]
    _, t = _run([_static([scenes.box_points(0.02, 0.02, 0.01)], (0.6, 0.5))], hips, damping=2.0)
    fx, fz, state = t["force"][301:, 0, 0], t["force"][301:, 0, 2], t["state"][301:, 0]
    x_hip, go = t["hip"][301:, 0, 0], t["god_object"][301:, 0, 0]
    np.testing.assert_allclose(fz, K * d, rtol=1e-9)
    stuck = state == 1
    first_slip = int(np.argmax(state == 2))
    assert first_slip > 0 and stuck[:first_slip].all()
    assert np.all(go[:first_slip] == 0.0)                            # the contact point stays
    v_hip = np.diff(t["hip"][300:, 0, 0]) / DT
    np.testing.assert_allclose(fx[:first_slip], -K * x_hip[:first_slip] - 2.0 * v_hip[:first_slip], atol=1e-9)
    assert abs(fx[first_slip - 1]) <= 0.6 * K * d + 1e-9 < abs(fx[first_slip - 1]) + K * 1e-6 + 1e-3
    sliding = fx[first_slip + 200:]
    np.testing.assert_allclose(sliding, -(0.5 * K * d + 2.0 * 1e-3), atol=2e-3)


@pytest.mark.parametrize("speed", [1.0, 100.0])
def test_no_push_through_a_thin_wall(speed):
    # A 1 mm plate; the HIP crosses it at 1 m/s (a tick is 1 mm: the plate's thickness) and
    # at 100 m/s (10 cm in a tick): the cursor stays on the near side, the force grows.
    plate = [scenes.box_points(0.05, 0.05, 0.0005)]
    start, end = np.array([0, 0, 0.02]), np.array([0, 0, -0.05])
    n = max(2, int(np.linalg.norm(end - start) / (speed * DT)) + 1)
    hips = [start + (end - start) * s for s in np.linspace(0, 1, n)] + [end] * 50
    _, t = _run([_static(plate)], hips)
    top = 0.0005 + R
    assert t["god_object"][:, 0, 2].min() >= top - 1e-9
    np.testing.assert_allclose(t["force"][-1, 0], [0.0, 0.0, K * (top + 0.05)], rtol=1e-9)


def test_no_energy_gain_free_or_touching():
    # The cursor's energy, 1/2 m v^2 + 1/2 k |x - HIP|^2 (v from its positions), never grows
    # from one tick to the next: after the HIP jumps 5 mm away from it in free space, and
    # after the HIP, pressed 3 mm into a box, jumps out of it.
    m = 0.002
    for bodies, hips in (
            ([], [np.zeros(3)] * 10 + [np.array([0.005, 0, 0])] * 500),
            ([_static([scenes.box_points(0.02, 0.02, 0.01)])],
             _eased((0, 0, 0.02), (0, 0, 0.01 + R - 0.003), 300) + [np.array((0, 0, 0.03))] * 500)):
        _, t = _run(bodies, hips, mass=m)
        x, hip = t["god_object"][:, 0], t["hip"][:, 0]
        v = np.zeros_like(x)
        v[1:] = np.diff(x, axis=0) / DT
        e = 0.5 * m * np.einsum("ij,ij->i", v, v) + 0.5 * K * np.einsum("ij,ij->i", x - hip, x - hip)
        jump = int(np.argmax(np.linalg.norm(np.diff(hip, axis=0), axis=1) > 0.004)) + 1
        after = e[jump:]
        assert after[0] > 1e-3
        assert np.all(np.diff(after) <= 1e-12 * after[0]), np.diff(after).max()
        assert after[-1] < 1e-3 * after[0]                   # and it settles


@pytest.mark.parametrize("stiffness", [500.0, 2000.0, 5000.0])
@pytest.mark.parametrize("mass", [0.0, 0.0005, 0.01])
@pytest.mark.parametrize("damping", [0.0, 3.0])
def test_stable_at_1khz(stiffness, mass, damping):
    # Pressed 2 mm into a box and held 2 s at 1 kHz: finite, bounded by its start, and at
    # rest on k d.
    d = 0.002
    z = 0.01 + R - d
    hips = _eased((0, 0, z + 0.004), (0, 0, z), 50) + [np.array((0, 0, z))] * 2000
    _, t = _run([_static([scenes.box_points(0.02, 0.02, 0.01)], (0.6, 0.5))], hips, stiffness=stiffness,
                mass=mass, damping=damping)
    f = t["force"][:, 0]
    assert np.all(np.isfinite(f))
    assert np.abs(f).max() <= stiffness * 0.004 + 1e-9
    np.testing.assert_allclose(f[-1], [0.0, 0.0, stiffness * d], atol=1e-6 * stiffness)


def test_lifts_a_box_as_xfca_does():
    # Two fingertips squeeze a 100 g box (3 mm, 1000 N/m), lift it 8 cm and hold: each
    # carries half its weight; the cursor's reaction reaches the box as xFCA's does.
    def lift(renderer):
        w = graspcore.World()
        w.add_body(points=scenes.box_points(0.2, 0.2, 0.01, (0, 0, -0.01)), static=True)
        b = w.add_body(points=scenes.box_points(0.025, 0.025, 0.025), mass=0.1, position=(0, 0, 0.025),
                       mu_s=0.8, mu_d=0.6)
        r, sq = 0.008, 0.003
        for s in (-1, 1):
            w.add_finger(radius=r, stiffness=1000.0, damping=2.0, position=(s * 0.048, 0, 0.025), renderer=renderer)

        def hips(opening, up):
            return np.array([[s * (0.025 + r - sq + opening), 0, 0.025 + up] for s in (-1, 1)])
        for i in range(300):
            w.set_hips(hips(0.015 * (1 - i / 299), 0.0))
            w.step(DT)
        for i in range(1000):
            w.set_hips(hips(0.0, 0.08 * i / 999))
            w.step(DT)
        for _ in range(1000):
            w.set_hips(hips(0.0, 0.08))
            w.step(DT)
        return w.body_pose(b)[0], np.array(w.finger_forces)
    (p_x, f_x), (p_c, f_c) = lift("xfca"), lift("cursor")
    assert p_c[2] == pytest.approx(0.025 + 0.08 - 0.1 * 9.81 / 2 / (2 * 1000.0 * 0.8), abs=6e-4)
    np.testing.assert_allclose(p_c, p_x, atol=1e-6)
    np.testing.assert_allclose(f_c[:, 2], [-0.1 * 9.81 / 2] * 2, atol=1e-6)


def test_deterministic():
    w1, t1 = _run([_static([scenes.box_points(0.02, 0.02, 0.01)], (0.6, 0.5))],
                  _eased((0, 0, 0.02), (0.003, 0, 0.013), 500))
    w2, t2 = _run([_static([scenes.box_points(0.02, 0.02, 0.01)], (0.6, 0.5))],
                  _eased((0, 0, 0.02), (0.003, 0, 0.013), 500))
    assert np.array_equal(t1["state_hash"], t2["state_hash"])


def test_mug_handle_slide_is_smooth():
    # The hooked mug's handle, its 16 convex pieces: 60 degrees slid at 4 N in 2 s. The
    # issue's target for the cursor: under 0.1 N a tick while sliding, stick/slip transitions
    # (the friction law's own (mu_s - mu_d) |Fn| step) aside; every jump named.
    w, hips = scenes.mug_handle_slide(seconds=2.0, renderer="cursor")
    t = scenes.run_ticks(w, hips)
    k, c = scenes.MUG_FINGER["stiffness"], scenes.MUG_FINGER["damping"]
    r = continuity.finger_continuity(t, 0, k, c, threshold=0.05)
    assert continuity.UNEXPLAINED not in {cause for j in r["jumps"] for cause in j["causes"]}
    state = t["state"][:, 0]
    transition = np.zeros(len(state), dtype=bool)
    transition[1:] = state[1:] != state[:-1]
    near = transition.copy()
    for lag in range(1, continuity.WINDOW + 1):
        near[lag:] |= transition[:-lag]
    start = 1 + 200 + 300
    sliding = np.zeros(len(state), dtype=bool)
    sliding[start:start + 2000] = True
    assert (t["contact"][sliding, 0] == 0).all()
    assert len(set(t["parts"][sliding, 0].tolist())) >= 2
    assert r["delta"][sliding & ~near].max() < 0.1                  # 0.068 N measured


@pytest.mark.parametrize("renderer", ["xfca", "cursor"])
def test_along_the_crease_between_two_parts(renderer):
    # Pressed 2 mm into both walls of an L of two parts and slid 20 mm along the crease
    # (frictionless): both walls push, k d each, all the way, and nothing else.
    parts = [scenes.box_points(0.02, 0.03, 0.005, (-0.01, 0, -0.005)), scenes.box_points(0.005, 0.03, 0.02, (0.005, 0, 0.01))]
    d = 0.002
    p0 = np.array([-R + d, -0.01, R - d])
    hips = _eased(p0 + [-0.004, 0, 0.004], p0, 300) + [p0] * 100 + _eased(p0, p0 + [0, 0.02, 0], 1500)
    _, t = _run([_static(parts)], hips, renderer=renderer)
    f = t["force"][400:, 0]
    np.testing.assert_allclose(f[:, 0], -K * d, atol=1e-6)
    np.testing.assert_allclose(f[:, 2], K * d, atol=1e-6)
    assert np.abs(f[:, 1]).max() < 1e-3


def test_bowl_traced_inside_without_a_bump():
    # A hemispherical bowl decomposed into 20 convex parts, a fingertip pressed 3 N into it
    # and traced 120 degrees through the bottom in 1.5 s: the cursor renderer's every change
    # above 0.1 N is named and, stick/slip aside, none reaches 0.1 N (0.094 N measured; xFCA
    # with the seam blend: 1.67 N where a part's god-object slides round its rounded edge,
    # docs/benchmarks.md).
    w, hips = scenes.bowl_trace(renderer="cursor")
    t = scenes.run_ticks(w, hips)
    r = continuity.finger_continuity(t, 0, 1000.0, 2.0, threshold=0.1)
    assert continuity.unexplained({"fingers": [dict(r, name="f")]}) == []
    state = t["state"][:, 0]
    transition = np.zeros(len(state), dtype=bool)
    transition[1:] = state[1:] != state[:-1]
    near = transition.copy()
    for lag in range(1, continuity.WINDOW + 1):
        near[lag:] |= transition[:-lag]
    sliding = np.zeros(len(state), dtype=bool)
    sliding[401:1901] = True
    assert (t["contact"][sliding, 0] == 0).all()
    assert len(set(t["parts"][sliding, 0].tolist())) >= 8
    assert r["delta"][sliding & ~near].max() < 0.1
