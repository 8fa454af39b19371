"""Force continuity (issue 20): the seams of a decomposed body in xFCA, and the measure
(addon/engine/continuity.py) that names the cause of every jump."""
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

K, R = 1000.0, 0.005


def _eased(a, b, n):
    s = np.linspace(0.0, 1.0, n)
    e = s * s * (3.0 - 2.0 * s)
    return [np.asarray(a) + (np.asarray(b) - np.asarray(a)) * x for x in e]


def _run(parts, hips, mu=(0.0, 0.0), radius=R, stiffness=K, bodies=None):
    w = graspcore.World()
    for p in (bodies or [parts]):
        w.add_body(parts=p, static=True, mu_s=mu[0], mu_d=mu[1])
    w.add_finger(radius=radius, stiffness=stiffness, damping=0.0, position=hips[0])
    return scenes.run_ticks(w, np.array(hips))


def _flat_seam(mu):
    """A slab made of two boxes sharing the face x = 0; a fingertip pressed 2 mm into its top
    slides from x = -12 mm to +12 mm, across the seam."""
    d = 0.002
    parts = [scenes.box_points(0.01, 0.02, 0.01, (-0.01, 0, 0)), scenes.box_points(0.01, 0.02, 0.01, (0.01, 0, 0))]
    z = 0.01 + R - d
    hips = _eased((-0.012, 0, z + 0.004), (-0.012, 0, z), 200) + [np.array((-0.012, 0, z))] * 100
    hips += _eased((-0.012, 0, z), (0.012, 0, z), 2000)
    return _run(parts, hips, mu), d, slice(301, 2301)


def test_flat_seam_is_felt_as_one_surface():
    # Summed, the two parts' springs doubled the normal force over the seam (2 -> 4 N).
    ticks, d, slide = _flat_seam((0.0, 0.0))
    f = ticks["force"][slide, 0]
    assert set(ticks["parts"][slide, 0].tolist()) >= {1, 3, 2}          # A, both, B
    assert np.all(np.abs(f[:, 2] - K * d) <= 0.07 * K * d), f[:, 2].min()
    assert np.abs(f[:, 0]).max() <= 0.2 * K * d                         # the seam's ridge, frictionless
    r = continuity.finger_continuity(ticks, 0, K, 0.0, threshold=0.02)
    assert r["delta"][slide].max() < 0.02                               # 0.008 N measured
    assert all(j["tick"] < slide.start for j in r["jumps"])             # only while pressing in


def test_flat_seam_with_friction_changes_only_at_stick_slip():
    ticks, d, slide = _flat_seam((0.6, 0.5))
    r = continuity.finger_continuity(ticks, 0, K, 0.0, threshold=0.05)
    assert [j["causes"] for j in r["jumps"]] == [["stick/slip"]]
    # Sliding: the normal force stays within 10 % of k d, friction at mu_d of it (+ the ridge).
    state = ticks["state"][slide, 0]
    f = ticks["force"][slide, 0][state == 2]
    assert np.all(np.abs(f[:, 2] - K * d) <= 0.1 * K * d)
    assert np.all(np.abs(f[:, 0]) <= 0.5 * K * d * 1.6)


@pytest.mark.parametrize("d_floor, d_wall", [(0.002, 0.002), (0.002, 0.001), (0.003, 0.0005)])
def test_concave_crease_adds_both_walls(d_floor, d_wall):
    # An L of two parts; pressed into the corner the two springs add: k (d_wall (-x) + d_floor z).
    parts = [scenes.box_points(0.02, 0.02, 0.005, (-0.01, 0, -0.005)), scenes.box_points(0.005, 0.02, 0.02, (0.005, 0, 0.01))]
    target = np.array([-R + d_wall, 0, R - d_floor])
    hips = _eased(target + [-0.004, 0, 0.004], target, 300) + [target] * 200
    ticks = _run(parts, hips)
    assert ticks["parts"][-1, 0] == 3
    np.testing.assert_allclose(ticks["force"][-1, 0], [-K * d_wall, 0.0, K * d_floor], atol=1e-9)


def test_slot_between_two_parts_of_one_body_adds_both_walls():
    # A 6 mm slot between two walls of one body; a 5 mm fingertip in it touches both: the
    # walls face each other (opposite normals), so nothing is shared and the forces add.
    parts = [scenes.box_points(0.005, 0.02, 0.02, (-0.008, 0, 0)), scenes.box_points(0.005, 0.02, 0.02, (0.008, 0, 0))]
    hip = np.array([0.0005, 0.0, 0.0])                          # 0.5 mm off centre
    ticks = _run(parts, [hip + [0, 0, 0.03]] + _eased(hip + [0, 0, 0.03], hip, 400) + [hip] * 50, mu=(0.0, 0.0))
    # Faces at x = -3 and +3 mm, fingertip from -4.5 to +5.5 mm: 1.5 mm into the left wall
    # (pushing +x), 2.5 mm into the right one (pushing -x).
    assert ticks["parts"][-1, 0] == 3
    np.testing.assert_allclose(ticks["force"][-1, 0], [K * (0.0015 - 0.0025), 0.0, 0.0], atol=1e-9)


def test_mug_handle_slide_has_no_bump():
    # The hooked mug's handle, 16 convex pieces: 60 degrees slid at 4 N in 0.3 s (96 mm/s).
    w, hips = scenes.mug_handle_slide(seconds=0.3)
    ticks = scenes.run_ticks(w, hips)
    k, c = scenes.MUG_FINGER["stiffness"], scenes.MUG_FINGER["damping"]
    r = continuity.finger_continuity(ticks, 0, k, c, threshold=0.1)
    assert continuity.UNEXPLAINED not in {cause for j in r["jumps"] for cause in j["causes"]}
    state = ticks["state"][:, 0]
    transition = np.zeros(len(state), dtype=bool)
    transition[1:] = state[1:] != state[:-1]
    start = 1 + 200 + 300
    sliding = np.zeros(len(state), dtype=bool)
    sliding[start:start + 300] = True
    sliding &= ~(transition | np.roll(transition, 1))
    assert len(set(ticks["parts"][sliding, 0].tolist())) >= 4       # it crosses seams
    assert r["delta"][sliding].max() < 0.25                          # the target; 0.094 N measured


# --------------------------------------------------------------------------- the measure's causes

def _ticks(n=40, force=1.0):
    """Synthetic tick records: one finger in steady contact, force (0, 0, force)."""
    t = np.zeros(n, dtype=graspcore.tick_dtype(1, 1))
    t["tick"] = np.arange(n)
    t["time"] = np.arange(n) * 1e-3
    t["flags"] = 1
    t["force"][:, 0] = (0.0, 0.0, force)
    t["device_force"][:, 0] = (0.0, 0.0, force)
    t["state"][:, 0] = 1
    t["contact"][:, 0] = 0
    t["parts"][:, 0] = 1
    return t


def _jump(t, at, size=0.5):
    t["force"][at:, 0, 2] += size
    t["device_force"][at:, 0, 2] += size


def _causes(t, stiffness=K, damping=0.0):
    r = continuity.finger_continuity(t, 0, stiffness, damping, threshold=0.25)
    assert len(r["jumps"]) == 1, r["jumps"]
    return r["jumps"][0]["causes"]


def test_an_unexplained_jump_is_named_so():
    t = _ticks()
    _jump(t, 20)
    assert _causes(t) == [continuity.UNEXPLAINED]
    r = continuity.finger_continuity(t, 0, K, threshold=0.25)
    assert r["max"] == pytest.approx(0.5) and r["max_tick"] == 20 and r["contact_ticks"] == 39


@pytest.mark.parametrize("cause, edit", [
    ("contact onset", lambda t: t["contact"][:20].__setitem__(slice(None), -1)),
    ("contact end", lambda t: t["contact"][20:].__setitem__(slice(None), -1)),
    ("stick/slip", lambda t: t["state"][19:].__setitem__(slice(None), 2)),
    ("change of convex part", lambda t: t["parts"][20:].__setitem__(slice(None), 3)),
    ("hand-over between threads", lambda t: t["adopted"][20:].__setitem__(slice(None), 1)),
    ("safety gate", lambda t: t["flags"][20:].__setitem__(slice(None), 0)),
])
def test_each_cause_is_named(cause, edit):
    t = _ticks()
    _jump(t, 20)
    edit(t)
    assert cause in _causes(t)


def test_a_transition_long_before_does_not_explain():
    t = _ticks()
    _jump(t, 20)
    t["state"][10:] = 2                                      # 10 ticks earlier: outside the window
    assert _causes(t) == [continuity.UNEXPLAINED]


def test_the_safety_layer_is_named_when_only_the_device_force_jumps():
    t = _ticks()
    t["device_force"][20:, 0, 2] = 0.2                       # clamped/ramped: force itself steady
    assert _causes(t) == ["safety gate"]


def test_the_hand_explains_a_jump_its_spring_and_damper_make():
    # The HIP starts moving at 0.2 m/s into the surface at tick 20: the spring adds k v dt and
    # the damper c v in that tick, the god-object stays put.
    k, c, v = 1000.0, 2.0, 0.2
    t = _ticks()
    step = np.zeros(len(t))
    step[20:] = v * 1e-3
    t["hip"][:, 0, 2] = -np.cumsum(step)
    force = -k * t["hip"][:, 0, 2] + c * np.where(np.arange(len(t)) >= 20, v, 0.0)
    t["force"][:, 0, 2] = 1.0 + force
    t["device_force"][:, 0, 2] = 1.0 + force
    assert _causes(t, k, c) == ["HIP motion"]
    assert _causes(t, k, 0.0) == [continuity.UNEXPLAINED]    # without its damper it does not add up


def test_threshold_must_be_positive():
    with pytest.raises(ValueError, match="threshold"):
        continuity.finger_continuity(_ticks(), 0, K, threshold=0.0)


def test_two_jumps_in_a_row_are_both_unexplained():
    # The second of two equal steps continues the first's trend, but a trend only explains
    # a change after a tick that was no jump.
    t = _ticks()
    _jump(t, 20)
    _jump(t, 21)
    r = continuity.finger_continuity(t, 0, K, threshold=0.25)
    assert [j["causes"] for j in r["jumps"]] == [[continuity.UNEXPLAINED]] * 2


def test_a_carried_body_following_the_hand_is_no_jump():
    # The HIP and the god-object of a carried body both move at 150 mm/s, then 200 mm/s (a
    # key frame of the animation): the spring's stretch stays, the damper steps by c dv.
    # The HIP's own terms alone (k dHIP = 0.2 N a tick) do not account for it; the change
    # against the tick before's does.
    k, c = 1000.0, 4.0
    t = _ticks()
    v = np.where(np.arange(len(t)) >= 20, 0.2, 0.15)
    t["hip"][:, 0, 1] = np.cumsum(v * 1e-3)
    t["force"][:, 0, 1] = -1.0 - c * v
    t["device_force"][:, 0, 1] = t["force"][:, 0, 1]
    r = continuity.finger_continuity(t, 0, k, c, threshold=0.1)
    assert [(j["tick"], j["causes"]) for j in r["jumps"]] == [(20, ["steady change"])]


def test_a_palms_patch_is_m_springs_of_the_hand():
    """A convex finger pressed flat under a slab (a patch of m god-objects, each a spring of K):
    the hand stepping 0.2 mm at once changes the force by m K 0.2 mm. As one spring's hand term
    (a sphere finger's) that is unexplained; with the patch's springs it is the hand."""
    palm = scenes.box_points(0.02, 0.02, 0.002, (0, 0, 0))
    slab = scenes.box_points(0.01, 0.01, 0.01, (0, 0, 0.012))
    w = graspcore.World()
    w.add_body(parts=[slab], static=True)
    w.add_finger(radius=0.0, stiffness=K, damping=0.0, position=(0, 0, -0.001), points=palm)
    # The palm's top face 0.5 mm into the slab's bottom, then the hand 0.2 mm higher at once.
    hips = [np.array((0, 0, 0.0005))] * 50 + [np.array((0, 0, 0.0007))] * 50
    ticks = scenes.run_ticks(w, np.array(hips))
    springs = abs(ticks["force"][49, 0, 2]) / (K * 0.0005)                # the patch's god-objects
    assert springs > 1
    assert abs(ticks["force"][50, 0, 2] - ticks["force"][49, 0, 2]) < 1e-9
    assert abs(ticks["force"][51, 0, 2] - ticks["force"][50, 0, 2]) == pytest.approx(springs * K * 0.0002, rel=1e-6)
    sphere = continuity.finger_continuity(ticks, 0, K, 0.0, threshold=0.1)
    assert [j["causes"] for j in sphere["jumps"] if j["tick"] >= 50] == [[continuity.UNEXPLAINED]]
    patch = continuity.finger_continuity(ticks, 0, K, 0.0, threshold=0.1, springs=continuity.CONVEX_FINGER_SPRINGS)
    assert [j["causes"] for j in patch["jumps"] if j["tick"] >= 50] == [["HIP motion"]]
