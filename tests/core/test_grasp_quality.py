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
