"""graspcore.grasp_quality against qhull (scipy's ConvexHull) as the reference.

The edge wrenches are built here from the documented cone convention, independently of the
core; scipy is a test-only dependency."""
import math

import numpy as np
import pytest
from scipy.spatial import ConvexHull, QhullError

import graspcore

TOLERANCE = 1e-10  # the core's default: relative to the largest wrench norm


def tangent_frame(n):
    """t1 = normalize(n x a), a the world axis of smallest |n.a| (ties: x, y, z); t2 = n x t1."""
    axis = int(np.argmin(np.abs(n)))  # argmin returns the first of equal values: x, then y, then z
    a = np.zeros(3)
    a[axis] = 1.0
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(n, t1)


def edge_wrenches(points, normals, mu, center, radius, edges):
    rows = []
    for p, n, m in zip(points, normals, np.broadcast_to(mu, len(points))):
        n = n / np.linalg.norm(n)
        t1, t2 = tangent_frame(n)
        for j in range(edges if m > 0 else 1):
            angle = 2 * np.pi * j / edges
            f = n + m * (np.cos(angle) * t1 + np.sin(angle) * t2)
            rows.append(np.concatenate([f, np.cross(p - center, f) / radius]))
    return np.array(rows).reshape(-1, 6)


def strictly_inside(points):
    """qhull's answer to: is the origin strictly inside the hull? (False for a flat hull.)"""
    scale = np.linalg.norm(points, axis=1).max()
    try:
        hull = ConvexHull(points)
    except QhullError:
        return False, None
    return bool(hull.equations[:, -1].max() < -TOLERANCE * scale), hull


def reference(points, normals, mu, center, radius, edges):
    w = edge_wrenches(points, normals, mu, center, radius, edges)
    closed, hull = strictly_inside(w)
    force_closed, _ = strictly_inside(w[:, :3])
    torque_closed, _ = strictly_inside(w[:, 3:])
    result = dict(force_closure=closed, force_only_closure=force_closed, torque_closure=torque_closed,
                  volume=hull.volume if hull is not None else 0.0, epsilon=0.0, weakest=np.zeros(6),
                  rank=int(np.linalg.matrix_rank(w, tol=TOLERANCE * np.linalg.norm(w, axis=1).max())))
    if closed:
        nearest = int(np.argmax(hull.equations[:, -1]))
        result["epsilon"] = -hull.equations[nearest, -1]
        result["weakest"] = hull.equations[nearest, :6]
    return result


def random_grasp(rng, contacts):
    """Contacts near a unit sphere, normals roughly inward, random mu in [0.1, 1.5]."""
    d = rng.normal(size=(contacts, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    points = d * rng.uniform(0.6, 1.4, size=(contacts, 1))
    normals = -d + 0.35 * rng.normal(size=(contacts, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    center = 0.1 * rng.normal(size=3)
    return points, normals, rng.uniform(0.1, 1.5, size=contacts), center, float(rng.uniform(1.0, 2.0))


CASES = [(seed, contacts, edges) for edges in (8, 16) for contacts in range(3, 11) for seed in range(4)]


@pytest.mark.parametrize("seed, contacts, edges", CASES)
def test_matches_qhull(seed, contacts, edges):
    rng = np.random.default_rng(1000 * seed + 10 * contacts + edges)
    points, normals, mu, center, radius = random_grasp(rng, contacts)
    got = graspcore.grasp_quality(points, normals, mu, center, radius, edges)
    want = reference(points, normals, mu, center, radius, edges)
    for flag in ("force_closure", "force_only_closure", "torque_closure"):
        assert got[flag] == want[flag], flag
    assert got["rank"] == want["rank"] == 6
    assert got["volume"] == pytest.approx(want["volume"], rel=1e-9)
    assert got["epsilon"] == pytest.approx(want["epsilon"], rel=1e-9, abs=0.0)
    if want["force_closure"]:
        # The nearest facet is unique on random sets: the same direction.
        assert np.allclose(got["weakest"], want["weakest"], atol=1e-9)
        assert got["facets"] > 0


FAST_CASES = [(seed, contacts, edges) for edges in (8, 16) for contacts in range(2, 11) for seed in range(6)]


@pytest.mark.parametrize("seed, contacts, edges", FAST_CASES)
def test_fast_path_matches_full_path_and_qhull(seed, contacts, edges):
    """volume=False (no 6-D hull: the closure LP and the support search) gives the full path's
    flags, rank, epsilon and weakest direction, and qhull's. Friction scaled down at random so
    the sets fall on both sides of closure in all three conditions."""
    rng = np.random.default_rng(7000 + 1000 * seed + 10 * contacts + edges)
    points, normals, mu, center, radius = random_grasp(rng, contacts)
    mu = mu * rng.uniform(0.05, 1.0)
    fast = graspcore.grasp_quality(points, normals, mu, center, radius, edges, volume=False)
    full = graspcore.grasp_quality(points, normals, mu, center, radius, edges)
    want = reference(points, normals, mu, center, radius, edges)
    for flag in ("force_closure", "force_only_closure", "torque_closure"):
        assert fast[flag] == full[flag] == want[flag], flag
    assert fast["rank"] == full["rank"] == want["rank"]
    assert fast["epsilon"] == pytest.approx(want["epsilon"], rel=1e-9, abs=0.0)
    assert fast["epsilon"] == pytest.approx(full["epsilon"], rel=1e-9, abs=0.0)
    assert np.allclose(fast["weakest"], want["weakest"], atol=1e-9)
    assert fast["volume"] == -1.0 and fast["facets"] == -1


def test_fast_path_cases_include_every_answer():
    """The seeded sets above reach closure and miss it, in 6-D and in both 3-D conditions."""
    seen = set()
    for seed, contacts, edges in FAST_CASES:
        rng = np.random.default_rng(7000 + 1000 * seed + 10 * contacts + edges)
        points, normals, mu, center, radius = random_grasp(rng, contacts)
        got = graspcore.grasp_quality(points, normals, mu * rng.uniform(0.05, 1.0), center, radius, edges,
                                      volume=False)
        seen |= {("6", got["force_closure"]), ("f", got["force_only_closure"]), ("t", got["torque_closure"])}
    assert len(seen) == 6, seen


def test_fast_path_near_the_boundary():
    """Sets whose origin lies within a hair of the hull's boundary (mu just above and below a
    set's mu_min), where the LP's margin alone cannot decide: both paths answer alike."""
    rng = np.random.default_rng(41)
    answers = set()
    for _ in range(6):
        points, normals, _, center, radius = random_grasp(rng, 4)
        mu_min = graspcore.grasp_mu_min(points, normals, center, radius, 8)
        if not 0.0 < mu_min < 10.0:
            continue
        for mu in (mu_min - 1e-6, mu_min - 1e-9, mu_min, mu_min + 1e-9, mu_min + 1e-6):
            fast = graspcore.grasp_quality(points, normals, mu, center, radius, 8, volume=False)
            full = graspcore.grasp_quality(points, normals, mu, center, radius, 8)
            assert fast["force_closure"] == full["force_closure"], mu
            assert fast["epsilon"] == pytest.approx(full["epsilon"], rel=1e-6, abs=1e-15)
            answers.add(fast["force_closure"])
    assert answers == {True, False}


def antipodal_grasp(rng, contacts):
    """random_grasp with contacts 0 and 1 opposite each other, normals through the centre: their
    normal wrenches cancel, so at small mu the GWS has facets whose vertices sit in two tiny
    clusters (thin facets), and the origin lies on the hull's boundary below mu_min."""
    points, normals, mu, _, radius = random_grasp(rng, contacts)
    points[1] = -points[0]
    normals[0] = -points[0] / np.linalg.norm(points[0])
    normals[1] = -normals[0]
    return points, normals, mu, np.zeros(3), radius


@pytest.mark.parametrize("volume", [True, False])
@pytest.mark.parametrize("mu", [1e-7, 1e-5, 1e-3])
def test_thin_facets_against_qhull(volume, mu):
    """An antipodal pair and small mu: closure and epsilon as qhull finds them (the hull alone,
    before the support search decided for both paths, called these not closed up to mu ~ 2e-5)."""
    rng = np.random.default_rng(55)
    seen = 0
    for _ in range(8):
        points, normals, _, center, radius = antipodal_grasp(rng, int(rng.integers(4, 6)))
        got = graspcore.grasp_quality(points, normals, mu, center, radius, 8, volume=volume)
        want = reference(points, normals, mu, center, radius, 8)
        assert got["force_closure"] == want["force_closure"]
        assert got["epsilon"] == pytest.approx(want["epsilon"], rel=1e-6, abs=0.0)
        if volume:
            assert got["volume"] == pytest.approx(want["volume"], rel=1e-6)
        seen += want["force_closure"]
    assert seen > 0


def test_mu_min_on_a_plateau_against_qhull():
    """Below mu_min the origin of an antipodal grasp is on the hull's boundary (the LP's margin
    exactly 0 over a range of mu): mu_min still lands within 1e-6 of qhull's closure threshold."""
    rng = np.random.default_rng(77)
    compared = 0
    for _ in range(6):
        points, normals, _, center, radius = antipodal_grasp(rng, 4)
        got = graspcore.grasp_mu_min(points, normals, center, radius, 8, mu_max=10.0)
        if not closed_at(points, normals, center, radius, 10.0):
            assert got == math.inf
            continue
        lo, hi = 0.0, 10.0
        while hi - lo > 1e-7:
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if closed_at(points, normals, center, radius, mid) else (mid, hi)
        assert got == pytest.approx(hi, abs=2e-6)
        assert closed_at(points, normals, center, radius, got)
        compared += 1
    assert compared >= 3


def test_random_cases_include_both_answers():
    """The seeded sets above are not all in closure, nor all out of it."""
    answers = set()
    for seed, contacts, edges in CASES:
        rng = np.random.default_rng(1000 * seed + 10 * contacts + edges)
        answers.add(graspcore.grasp_quality(*random_grasp(rng, contacts), edges)["force_closure"])
    assert answers == {True, False}


def test_force_and_torque_conditions_against_3d_hulls():
    """Sets where the 3-D conditions differ from each other and from 6-D closure."""
    rng = np.random.default_rng(5)
    seen = set()
    for _ in range(60):
        contacts = int(rng.integers(2, 6))
        points, normals, mu, center, radius = random_grasp(rng, contacts)
        mu = mu * rng.uniform(0.05, 1.0)
        got = graspcore.grasp_quality(points, normals, mu, center, radius, 8)
        want = reference(points, normals, mu, center, radius, 8)
        assert (got["force_only_closure"], got["torque_closure"], got["force_closure"]) == (
            want["force_only_closure"], want["torque_closure"], want["force_closure"])
        seen.add((got["force_only_closure"], got["torque_closure"]))
    assert len(seen) >= 3, seen


@pytest.mark.parametrize("volume", [True, False])
def test_never_nan_and_rank_deficient_sets(volume):
    no_volume = 0.0 if volume else -1.0
    antipodal = graspcore.grasp_quality([[1, 0, 0], [-1, 0, 0]], [[-1, 0, 0], [1, 0, 0]], 0.7, [0, 0, 0], 1.0,
                                        volume=volume)
    assert antipodal["rank"] == 5 and not antipodal["force_closure"]
    assert antipodal["epsilon"] == 0.0 and antipodal["volume"] == no_volume and antipodal["weakest"] == (0.0,) * 6
    one = graspcore.grasp_quality([[0, 0, 1]], [[0, 0, -1]], 1.0, [0, 0, 0], 1.0, volume=volume)
    assert one["rank"] == 3 and not one["force_only_closure"] and not one["force_closure"]
    same = graspcore.grasp_quality([[0, 0, 1]] * 4, [[0, 0, -1]] * 4, [0.5, 0.0, 0.5, 1.0], [0, 0, 0], 1.0, 16,
                                   volume=volume)
    assert all(math.isfinite(v) for v in (same["epsilon"], same["volume"], *same["weakest"]))
    assert not same["force_closure"]
    empty = graspcore.grasp_quality(np.zeros((0, 3)), np.zeros((0, 3)), 0.5, [0, 0, 0], 1.0, volume=volume)
    assert empty["rank"] == 0 and not empty["force_closure"] and empty["volume"] == no_volume
    # Frictionless contacts in one plane, normals through the centre: forces in the plane, no torque.
    flat = graspcore.grasp_quality([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]],
                                   [[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0]], 0.0, [0, 0, 0], 1.0,
                                   volume=volume)
    assert flat["rank"] == 2 and not flat["force_closure"] and not flat["force_only_closure"]


def test_volume_flag_is_a_bool():
    with pytest.raises(ValueError, match=r"^volume\b"):
        graspcore.grasp_quality(**GOOD, volume=1)
    with pytest.raises(ValueError, match=r"^volume\b"):
        graspcore.grasp_quality_batch(np.array(GOOD["points"], float), np.array(GOOD["normals"], float), 0.5, [3],
                                      np.zeros((1, 3)), [1.0], volume="no")


def test_batch_equals_single_calls():
    rng = np.random.default_rng(9)
    sets = [random_grasp(rng, int(rng.integers(1, 8))) for _ in range(25)]
    counts = [len(s[0]) for s in sets]
    table = graspcore.grasp_quality_batch(
        np.concatenate([s[0] for s in sets]), np.concatenate([s[1] for s in sets]),
        np.concatenate([s[2] for s in sets]), counts, np.array([s[3] for s in sets]), [s[4] for s in sets], 8)
    assert table.dtype == graspcore.GRASP_QUALITY_DTYPE and len(table) == len(sets)
    for row, s in zip(table, sets):
        one = graspcore.grasp_quality(*s, 8)
        for name in graspcore.GRASP_QUALITY_DTYPE.names:
            assert np.array_equal(row[name], np.asarray(one[name])), name
    fast = graspcore.grasp_quality_batch(
        np.concatenate([s[0] for s in sets]), np.concatenate([s[1] for s in sets]),
        np.concatenate([s[2] for s in sets]), counts, np.array([s[3] for s in sets]), [s[4] for s in sets], 8,
        volume=False)
    for row, s in zip(fast, sets):
        one = graspcore.grasp_quality(*s, 8, volume=False)
        for name in graspcore.GRASP_QUALITY_DTYPE.names:
            assert np.array_equal(row[name], np.asarray(one[name])), name
    assert (fast["volume"] == -1.0).all() and (fast["facets"] == -1).all()
    assert np.array_equal(fast["force_closure"], table["force_closure"])
    assert table["force_closure"].any() and not table["force_closure"].all()
    assert len(graspcore.grasp_quality_batch(np.zeros((0, 3)), np.zeros((0, 3)), 0.5, [], np.zeros((0, 3)), [])) == 0


def closed_at(points, normals, center, radius, mu, edges=8):
    return strictly_inside(edge_wrenches(points, normals, mu, center, radius, edges))[0]


@pytest.mark.parametrize("seed", range(6))
def test_mu_min_against_bisection_on_qhull(seed):
    rng = np.random.default_rng(300 + seed)
    points, normals, _, center, radius = random_grasp(rng, int(rng.integers(3, 6)))
    got = graspcore.grasp_mu_min(points, normals, center, radius, 8, mu_max=10.0)
    if closed_at(points, normals, center, radius, 0.0):
        assert got == 0.0
    elif not closed_at(points, normals, center, radius, 10.0):
        assert got == math.inf
    else:
        lo, hi = 0.0, 10.0
        while hi - lo > 1e-7:
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if closed_at(points, normals, center, radius, mid) else (mid, hi)
        assert got == pytest.approx(hi, abs=2e-6)
        assert closed_at(points, normals, center, radius, got)


def test_mu_min_closed_forms():
    # Two contacts are never in closure (rank 5): inf. Frictionless closure: 0.
    assert graspcore.grasp_mu_min([[1, 0, 0], [-1, 0, 0]], [[-1, 0, 0], [1, 0, 0]], [0, 0, 0], 1.0) == math.inf
    cube_points = [[0, -1, 0.5], [-0.5, 0, -1], [-0.5, 1, 0.5], [0.5, 0.5, 1], [1, -0.5, 0.5], [-0.5, -1, -0.5],
                   [-1, 0, -0.5]]
    cube_normals = [[0, 1, 0], [0, 0, 1], [0, -1, 0], [0, 0, -1], [-1, 0, 0], [0, 1, 0], [1, 0, 0]]
    assert graspcore.grasp_mu_min(cube_points, cube_normals, [0, 0, 0], math.sqrt(3)) == 0.0


GOOD = dict(points=[[1, 0, 0], [-1, 0, 0], [0, 1, 0]], normals=[[-1, 0, 0], [1, 0, 0], [0, -1, 0]], mu=0.5,
            center=[0, 0, 0], radius=1.0, edges=8)


@pytest.mark.parametrize("change, name", [
    (dict(points=[[1, 0, 0], [math.nan, 0, 0], [0, 1, 0]]), "points"),
    (dict(points=[[1, 0], [0, 1], [1, 1]]), "points"),
    (dict(normals=[[-1, 0, 0], [0, 0, 0], [0, -1, 0]]), "normals"),
    (dict(normals=[[-1, 0, 0], [1, 0, 0]]), "normals"),
    (dict(normals=[[-1, 0, 0], [math.inf, 0, 0], [0, -1, 0]]), "normals"),
    (dict(mu=-0.1), "mu"),
    (dict(mu=math.nan), "mu"),
    (dict(mu=[0.5, 0.5]), "mu"),
    (dict(mu="much"), "mu"),
    (dict(center=[0, 0]), "center"),
    (dict(center=[0, math.nan, 0]), "center"),
    (dict(radius=0.0), "radius"),
    (dict(radius=-2.0), "radius"),
    (dict(radius=math.inf), "radius"),
    (dict(radius="big"), "radius"),
    (dict(edges=2), "edges"),
    (dict(edges=8.5), "edges"),
])
def test_bad_input_names_the_argument(change, name):
    args = dict(GOOD, **change)
    with pytest.raises(ValueError, match=rf"^{name}\b"):
        graspcore.grasp_quality(**args)


def test_batch_bad_input_names_the_argument():
    p, n = np.array(GOOD["points"], float), np.array(GOOD["normals"], float)
    with pytest.raises(ValueError, match=r"^counts\b"):
        graspcore.grasp_quality_batch(p, n, 0.5, [2, 2], np.zeros((2, 3)), [1.0, 1.0])
    with pytest.raises(ValueError, match=r"^counts\b"):
        graspcore.grasp_quality_batch(p, n, 0.5, [4, -1], np.zeros((2, 3)), [1.0, 1.0])
    with pytest.raises(ValueError, match=r"^centers\b"):
        graspcore.grasp_quality_batch(p, n, 0.5, [2, 1], np.zeros((3, 3)), [1.0, 1.0])
    with pytest.raises(ValueError, match=r"^radii\b"):
        graspcore.grasp_quality_batch(p, n, 0.5, [2, 1], np.zeros((2, 3)), [1.0])
    with pytest.raises(ValueError, match=r"^set 1: radius\b"):
        graspcore.grasp_quality_batch(p, n, 0.5, [2, 1], np.zeros((2, 3)), [1.0, 0.0])
    with pytest.raises(ValueError, match=r"^mu_max\b"):
        graspcore.grasp_mu_min(p, n, [0, 0, 0], 1.0, mu_max=-1.0)


@pytest.mark.parametrize("tilt", [1.6452892242769884e-10, 1e-12, 3e-9, 1e-7, 1e-5])
def test_mu_min_on_a_nearly_antipodal_pair_agrees_with_closure(tilt):
    # A pinch recorded by the analysis: two contacts whose normals are antipodal up to a tilt of
    # rounding size. The closure LP stalled on it (1250 pivots, ValueError); mu_min must answer
    # what grasp_quality says at the same friction.
    points = [[0.2809765885849599, 0.0, 0.2990585384659764], [0.2209765885849599, 0.0, 0.2990585384758482]]
    normals = [[-1.0, 0.0, tilt], [1.0, 0.0, -tilt]]
    center = [0.25097658858495986, 0.0, 0.2990584767858975]
    radius = 0.05196152422706632
    mu = graspcore.grasp_mu_min(points, normals, center, radius, mu_max=10.0)
    at_max = graspcore.grasp_quality(points, normals, 10.0, center, radius, volume=False)
    if math.isinf(mu):
        assert not at_max["force_closure"]
    else:
        assert graspcore.grasp_quality(points, normals, mu, center, radius)["force_closure"]
        if mu > 2e-6:
            assert not graspcore.grasp_quality(points, normals, mu - 2e-6, center, radius)["force_closure"]


# ---- symmetric and near-planar grasps (the live session's held box) --------------------------

HALF = 0.03         # a 6 cm box
FACES = {"+x": ([HALF, 0, 0], [-1, 0, 0]), "-x": ([-HALF, 0, 0], [1, 0, 0]),
         "+y": ([0, HALF, 0], [0, -1, 0]), "-y": ([0, -HALF, 0], [0, 1, 0]),
         "+z": ([0, 0, HALF], [0, 0, -1]), "-z": ([0, 0, -HALF], [0, 0, 1])}
# Fingertips on face centres, and (second entry) on the faces but off their centres along the
# face, as the held-box scene's 3- and 5-finger grasps have them (two fingers side by side on -x).
BOX_GRASPS = {
    2: (["+x", "-x"], [[0, 0, 0], [0, 0, 0]]),
    3: (["+x", "-x", "-x"], [[0, 0, 0], [0, -0.015, 0], [0, 0.015, 0]]),
    4: (["+x", "-x", "+y", "-y"], [[0, 0.01, 0], [0, -0.01, 0], [0.012, 0, 0], [-0.012, 0, 0]]),
    5: (["+x", "-x", "-x", "+y", "-y"], [[0, 0, 0], [0, -0.015, 0], [0, 0.015, 0], [0, 0, 0], [0, 0, 0]]),
    6: (["+x", "-x", "+y", "-y", "+z", "-z"], [[0, 0, 0.01], [0, 0, -0.01], [0.01, 0, 0], [-0.01, 0, 0],
                                               [0, 0.01, 0], [0, -0.01, 0]]),
}


def box_grasp(fingers, off_centre, tilt=0.0, seed=0):
    """A box held by fingertips on its faces; normals tilted by `tilt` radians about random axes."""
    faces, shifts = BOX_GRASPS[fingers]
    points = np.array([FACES[f][0] for f in faces], float) + (np.array(shifts, float) if off_centre else 0.0)
    normals = np.array([FACES[f][1] for f in faces], float)
    if tilt:
        rng = np.random.default_rng(seed)
        for i, n in enumerate(normals):
            axis = np.cross(n, rng.normal(size=3))
            axis /= np.linalg.norm(axis)
            normals[i] = np.cos(tilt) * n + np.sin(tilt) * np.cross(axis, n)
    return points, normals, np.sqrt(3) * HALF


def three_at_120(tilt=0.0):
    """Three fingers at 120 degrees round the equator of a unit sphere, normals to its centre."""
    angles = 2 * np.pi * np.arange(3) / 3
    points = np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], axis=1)
    normals = -points.copy()
    normals[:, 2] += tilt * np.array([1.0, -1.0, 0.5])
    return points, normals / np.linalg.norm(normals, axis=1)[:, None], 1.0


def supports_at(weakest, w, epsilon):
    """weakest is a unit facet normal of the hull of w at distance epsilon: max_i weakest.w_i."""
    return abs(np.linalg.norm(weakest) - 1.0) < 1e-9 and np.max(w @ np.asarray(weakest)) == \
        pytest.approx(epsilon, rel=1e-9, abs=1e-12)


def check_symmetric(points, normals, mu, center, radius, edges=8, volume=True):
    """Fast path = full path = qhull on a set whose nearest facet may be one of several mirror
    images (ties): epsilon and the flags must agree; the weakest direction must be a facet normal
    at distance epsilon, not necessarily qhull's."""
    fast = graspcore.grasp_quality(points, normals, mu, center, radius, edges, volume=False)
    full = graspcore.grasp_quality(points, normals, mu, center, radius, edges)
    want = reference(points, normals, mu, center, radius, edges)
    for flag in ("force_closure", "force_only_closure", "torque_closure"):
        assert fast[flag] == full[flag] == want[flag], flag
    assert fast["rank"] == full["rank"] == want["rank"]
    assert fast["epsilon"] == pytest.approx(want["epsilon"], rel=1e-9, abs=0.0)
    assert full["epsilon"] == pytest.approx(want["epsilon"], rel=1e-9, abs=0.0)
    if volume:
        assert full["volume"] == pytest.approx(want["volume"], rel=1e-9)
    if want["force_closure"]:
        w = edge_wrenches(points, normals, mu, center, radius, edges)
        assert supports_at(fast["weakest"], w, fast["epsilon"])
        assert supports_at(full["weakest"], w, full["epsilon"])
    return fast


@pytest.mark.parametrize("fingers", sorted(BOX_GRASPS))
@pytest.mark.parametrize("off_centre", [False, True])
@pytest.mark.parametrize("tilt", [0.0, 1e-3, 1e-6, 1e-8, 1e-10])
@pytest.mark.parametrize("mu", [0.3, 0.8])
def test_held_box_against_qhull(fingers, off_centre, tilt, mu):
    """Boxes held by 2 to 6 fingertips on face centres and off them, normals exact and tilted:
    contacts in one plane or nearly, symmetric normals, many equal support values."""
    points, normals, radius = box_grasp(fingers, off_centre, tilt, seed=fingers)
    # The full path's volume is wrong on some of the nearly flat ones (test below).
    check_symmetric(points, normals, mu, np.zeros(3), radius, volume=tilt == 0.0 or tilt >= 1e-6)


@pytest.mark.xfail(strict=True, reason="known bug: the full hull's volume on normals tilted by 1e-10..1e-8")
@pytest.mark.parametrize("fingers, tilt", [(4, 1e-10), (5, 1e-8), (6, 1e-10)])
def test_held_box_volume_with_tilts_of_rounding_size(fingers, tilt):
    """The volume is continuous in the wrenches: tilting the normals by 1e-10 must change it by
    about that much. qhull does; the full path gives 0.2676 for 0.2656 (4 fingers, mu 0.8), as
    if some simplices were counted twice."""
    points, normals, radius = box_grasp(fingers, False, tilt, seed=fingers)
    got = graspcore.grasp_quality(points, normals, 0.8, np.zeros(3), radius)["volume"]
    want = reference(points, normals, 0.8, np.zeros(3), radius, 8)["volume"]
    level = graspcore.grasp_quality(*box_grasp(fingers, False)[:2], 0.8, np.zeros(3), radius)["volume"]
    assert want == pytest.approx(level, rel=1e-6)
    assert got == pytest.approx(want, rel=1e-9)


@pytest.mark.parametrize("edges", [8, 16])
@pytest.mark.parametrize("tilt", [0.0, 1e-3, 1e-7, 1e-10])
def test_three_fingers_at_120_degrees_against_qhull(edges, tilt):
    points, normals, radius = three_at_120(tilt)
    check_symmetric(points, normals, 0.6, np.zeros(3), radius, edges)


def test_held_box_cases_include_both_answers():
    """The box grasps above are in closure (4 to 6 fingers, and 3 at mu 0.8) and not (the pinch)."""
    answers = {graspcore.grasp_quality(*box_grasp(f, True)[:2], 0.8, np.zeros(3), box_grasp(f, True)[2],
                                       volume=False)["force_closure"] for f in BOX_GRASPS}
    assert answers == {True, False}


def test_recorded_held_box_against_qhull():
    """The live session's 5-finger held box (contacts 0.4 mm off the centre's plane, normals
    tilted by 4e-3), the set that took the fast path 300 µs: epsilon 0.3306 as qhull has it."""
    points = np.array([[0.0305997, 0.0, -0.00054295], [-0.02939982, -0.015, -0.00030271],
                       [-0.02939982, 0.015, -0.00030271], [0.00059994, 0.03, -0.00042283],
                       [0.00059994, -0.03, -0.00042283]])
    normals = np.array([[-0.99999198, 0.0, 0.00400405], [0.99999198, 0.0, -0.00400405],
                        [0.99999198, 0.0, -0.00400405], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    got = check_symmetric(points, normals, 0.8, np.array([0.00059994, 0.0, -0.00042283]), 0.05196152)
    assert got["force_closure"] and got["epsilon"] == pytest.approx(0.3306, abs=1e-4)


def dithered(a, rng, ulps=4):
    """a with every entry moved by up to `ulps` units in the last place (a still hand in the
    threaded session: the haptic loop dithers the contacts in the last bits)."""
    out = a.copy()
    for _ in range(ulps):
        out = np.where(rng.random(a.shape) < 0.5, np.nextafter(out, np.inf), np.nextafter(out, -np.inf))
    return out


RECORDED_HELD_BOX = (np.array([[0.0305997, 0.0, -0.00054295], [-0.02939982, -0.015, -0.00030271],
                                [-0.02939982, 0.015, -0.00030271], [0.00059994, 0.03, -0.00042283],
                                [0.00059994, -0.03, -0.00042283]]) - [0.00059994, 0.0, -0.00042283],
                     np.array([[-0.99999198, 0.0, 0.00400405], [0.99999198, 0.0, -0.00400405],
                               [0.99999198, 0.0, -0.00400405], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0]]), 0.05196152)


def held_box_sets():
    yield RECORDED_HELD_BOX         # mu_min 1e-6: closed at any friction, flat without
    yield box_grasp(5, False, 4e-3, seed=3)
    yield box_grasp(4, True, 1e-8, seed=4)
    yield three_at_120(1e-3)
    rng = np.random.default_rng(17)
    for _ in range(3):
        p, n, _, c, r = random_grasp(rng, 6)
        yield p - c, n, r


def test_reuse_answers_as_a_fresh_call():
    """reuse=True: a set within rounding of one answered before gets its facet re-certified; the
    answers must be a fresh call's to 1e-12 (epsilon, flags), the weakest direction a facet normal
    at epsilon. Sets moved further (1e-7), or out of closure, must get exactly a fresh call's
    answer. Two sets alternate (the live view's two bodies in one batch)."""
    rng = np.random.default_rng(3)
    sets = list(held_box_sets())
    for (p, n, r), (q, m, s) in zip(sets, sets[1:] + sets[:1]):
        for step in range(6):
            for pts, nrm, rad in ((p, n, r), (q, m, s)):
                if step in (3, 5):
                    pts = pts + 1e-7 * rng.normal(size=pts.shape)
                elif step:
                    pts, nrm = dithered(pts, rng), dithered(nrm, rng)
                mu = 0.8 if step != 5 else 0.02
                got = graspcore.grasp_quality(pts, nrm, mu, np.zeros(3), rad, volume=False, reuse=True)
                fresh = graspcore.grasp_quality(pts, nrm, mu, np.zeros(3), rad, volume=False)
                for flag in ("force_closure", "force_only_closure", "torque_closure", "rank"):
                    assert got[flag] == fresh[flag], flag
                assert got["epsilon"] == pytest.approx(fresh["epsilon"], rel=1e-12, abs=0.0)
                if step in (3, 5):
                    assert got == fresh     # no remembered set this close: a search, as without reuse
                elif fresh["force_closure"]:
                    w = edge_wrenches(pts, nrm, mu, np.zeros(3), rad, 8)
                    assert supports_at(got["weakest"], w, got["epsilon"])
    batch = graspcore.grasp_quality_batch(np.concatenate([sets[0][0], sets[1][0]]),
                                          np.concatenate([sets[0][1], sets[1][1]]), 0.8,
                                          [len(sets[0][0]), len(sets[1][0])],
                                          np.zeros((2, 3)), [sets[0][2], sets[1][2]], volume=False, reuse=True)
    for row, (p, n, r) in zip(batch, sets[:2]):
        assert row["epsilon"] == pytest.approx(graspcore.grasp_quality(p, n, 0.8, np.zeros(3), r,
                                                                       volume=False)["epsilon"], rel=1e-12)


def test_reuse_is_a_bool_and_leaves_the_full_path_alone():
    p, n, r = box_grasp(5, True)
    with pytest.raises(ValueError, match=r"^reuse\b"):
        graspcore.grasp_quality(p, n, 0.8, np.zeros(3), r, volume=False, reuse=1)
    assert graspcore.grasp_quality(p, n, 0.8, np.zeros(3), r, reuse=True) == \
        graspcore.grasp_quality(p, n, 0.8, np.zeros(3), r)


def test_mu_min_reuse_answers_as_a_search():
    """grasp_mu_min(reuse=True) on contacts within rounding of ones it answered: an answer the
    search could have given (closed there as grasp_quality decides, not closed 2e-6 below, within
    2e-6 of a fresh search's); contacts moved by 1e-7: exactly a fresh search's. Includes a pinch
    that never closes (inf) and a frictionless closure (0)."""
    rng = np.random.default_rng(8)
    p, n, _, c, r = random_grasp(np.random.default_rng(0), 12)      # closed without friction
    sets = [s for s in held_box_sets()] + [box_grasp(2, False), (p - c, n, r)]
    answers = set()
    for p, n, r in sets:
        first = graspcore.grasp_mu_min(p, n, np.zeros(3), r, reuse=True)
        for step in range(4):
            q, m = (p + 1e-7 * rng.normal(size=p.shape), n) if step == 3 else (dithered(p, rng), dithered(n, rng))
            got = graspcore.grasp_mu_min(q, m, np.zeros(3), r, reuse=True)
            fresh = graspcore.grasp_mu_min(q, m, np.zeros(3), r)
            if step == 3:
                assert got == fresh
            elif math.isinf(fresh):
                assert math.isinf(got)
            else:
                assert got == pytest.approx(fresh, abs=2e-6)
                assert graspcore.grasp_quality(q, m, got, np.zeros(3), r, volume=False)["force_closure"]
                if got > 2e-6:
                    assert not graspcore.grasp_quality(q, m, got - 2e-6, np.zeros(3), r, volume=False)["force_closure"]
        answers.add("inf" if math.isinf(first) else "0" if first == 0 else "mu")
    assert answers == {"inf", "0", "mu"}


def test_three_fingers_at_120_degrees_dithered_at_large_mu():
    """Three fingers at 120 degrees tilted by 1e-3, in the last bits dithered, mu 10 (t* 0.04, well
    inside): the closure LP stopped phase 1 on a rounding artefact ("unbounded") and read it as
    "far outside" for 16 of 200 such sets; closure and epsilon as qhull has them, and mu_min
    finite."""
    p, n, r = three_at_120(1e-3)
    rng = np.random.default_rng(8)
    for _ in range(40):
        q, m = dithered(p, rng), dithered(n, rng)
        check_symmetric(q, m, 10.0, np.zeros(3), r, volume=False)
        assert graspcore.grasp_mu_min(q, m, np.zeros(3), r) < 0.01


SOFT_SEEDS = range(16)


def soft_grasp(seed):
    """Odd seeds: a nearly antipodal pair (closed by its torsion alone); even: 3-4 random
    contacts. About one contact in five has no torsion."""
    rng = np.random.default_rng(100 + seed)
    if seed % 2:
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        points = np.array([d, -d]) + 0.05 * rng.normal(size=(2, 3))
        normals = -np.array([d, -d]) + 0.05 * rng.normal(size=(2, 3))
        mu, center, radius = rng.uniform(0.3, 1.0, size=2), 0.05 * rng.normal(size=3), 1.0
    else:
        points, normals, mu, center, radius = random_grasp(rng, int(rng.integers(3, 5)))
    rho = rng.uniform(0.05, 0.3, size=len(points)) * (rng.random(len(points)) < 0.8)
    return points, normals, mu, center, radius, rho


@pytest.mark.parametrize("seed", SOFT_SEEDS)
def test_soft_contacts_against_qhull(seed):
    """Soft contacts (torsion rho): each contact's cone edges and its two generators (n, ((p - c) x n
    +- mu rho n) / radius), as docs/api.md defines them, through Qhull give the core's closure,
    epsilon, weakest direction and volume, on the full path and the fast path; mu_min is where
    that set closes (grasp_quality at mu_min closed, 2e-6 below open)."""
    points, normals, mu, center, radius, rho = soft_grasp(seed)
    w = edge_wrenches(points, normals, mu, center, radius, 8)
    unit = normals / np.linalg.norm(normals, axis=1)[:, None]
    extra = [np.concatenate([n, (np.cross(p - center, n) + s * m * r * n) / radius])
             for p, n, m, r in zip(points, unit, mu, rho) if m * r > 0 for s in (-1, 1)]
    w = np.vstack([w] + ([np.array(extra)] if extra else []))
    closed, hull = strictly_inside(w)
    for volume in (True, False):
        q = graspcore.grasp_quality(points, normals, mu, center, radius, volume=volume, torsion=rho)
        assert q["force_closure"] == closed
        if closed:
            nearest = int(np.argmax(hull.equations[:, -1]))
            assert q["epsilon"] == pytest.approx(-hull.equations[nearest, -1], rel=1e-7, abs=1e-12)
            if volume:
                assert q["volume"] == pytest.approx(hull.volume, rel=1e-7)
    point = graspcore.grasp_quality(points, normals, mu, center, radius)
    assert not point["force_closure"] or closed     # torsion only adds wrenches
    m = graspcore.grasp_mu_min(points, normals, center, radius, torsion=rho)
    if np.isfinite(m) and m > 0:
        assert graspcore.grasp_quality(points, normals, m, center, radius, torsion=rho)["force_closure"]
        assert not graspcore.grasp_quality(points, normals, max(m - 2e-6, 0.0), center, radius,
                                           torsion=rho)["force_closure"]


def test_soft_contact_cases_include_closure_by_torsion_alone():
    """The antipodal pairs above are closed with their torsion and open without it."""
    closed_by_torsion = 0
    for seed in SOFT_SEEDS[1::2]:
        points, normals, mu, center, radius, rho = soft_grasp(seed)
        soft = graspcore.grasp_quality(points, normals, mu, center, radius, torsion=rho)["force_closure"]
        hard = graspcore.grasp_quality(points, normals, mu, center, radius)["force_closure"]
        closed_by_torsion += soft and not hard
    assert closed_by_torsion >= 6


def test_soft_contacts_bad_torsion_names_it():
    p, n = [[1, 0, 0], [-1, 0, 0]], [[-1, 0, 0], [1, 0, 0]]
    with pytest.raises(ValueError, match="torsion: expected finite numbers >= 0"):
        graspcore.grasp_quality(p, n, 0.5, [0, 0, 0], 1.0, torsion=[0.1, -0.1])
    with pytest.raises(ValueError, match=r"torsion: expected a number or shape \(2,\)"):
        graspcore.grasp_quality_batch(p, n, 0.5, [2], [[0, 0, 0]], [1.0], torsion=[0.1, 0.1, 0.1])
    with pytest.raises(ValueError, match="torsion"):
        graspcore.grasp_mu_min(p, n, [0, 0, 0], 1.0, torsion=[np.nan, 0.1])
