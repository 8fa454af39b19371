"""The grasp analysis of area contacts and soft fingertips (docs/analysis.md "Area contacts")
against closed forms, on recordings made by the project's recorder: a convex finger's contact is
its patch (the tick record's ``patch``), whose friction cones stand at its corners in the grasp
wrench space; a soft fingertip adds torsion generators +-mu rho about its normal. Plain Python
(no bpy); scipy's Qhull is the independent reference for the hull."""
import numpy as np
import pytest

import recordings
from addon.engine import analysis, recording, scene

K, MU = 1000.0, (0.8, 0.6)
PLATE_HALF, PLATE_H, PLATE_M = 0.1, 0.005, 0.4
PALM = (0.045, 0.04, 0.01)          # palm half sizes (m): 9 x 8 cm, 2 cm thick, top face at z = 0
SIDE = 0.06                         # pinched box
PAD = 0.01                          # pad half width (square pads, 2 x 2 cm faces)
SQUEEZE = 0.003


def _mesh(half, name, center=(0.0, 0.0, 0.0)):
    import trimesh
    tm = trimesh.creation.box(2 * np.asarray(half, dtype=float))
    return scene.MeshData(np.array(tm.vertices) + center, np.array(tm.faces), source=name)


def _body(d, name, half, position, mass):
    mesh = _mesh(half, name)
    d.bodies.append(scene.BodyDesc(name, False, [mesh.vertices], [mesh], np.array(position, dtype=float),
                                   np.array([1.0, 0, 0, 0]), mass=mass, mu_s=MU[0], mu_d=MU[1]))


def _record(path, desc, hips, seconds):
    import graspcore  # the dev venv's
    recordings.record_scene(path, graspcore, desc, hips, seconds)
    return recording.open_recording(str(path))


def cone_wrenches(points, normals, mu, center, radius, edges=8, torsion=None):
    """The grasp wrench space's generators as docs/analysis.md defines them (numpy, independent of
    the core): k cone edges per contact, and with torsion rho the two generators (n, ((p - c) x n
    +- mu rho n) / radius)."""
    t1, t2 = analysis.tangent_axes(normals)
    out = []
    for i, (p, n) in enumerate(zip(points, normals)):
        for j in range(edges):
            f = n + mu * (np.cos(2 * np.pi * j / edges) * t1[i] + np.sin(2 * np.pi * j / edges) * t2[i])
            out.append(np.concatenate([f, np.cross(p - center, f) / radius]))
        if torsion is not None and torsion[i] > 0:
            for s in (-1, 1):
                out.append(np.concatenate([n, (np.cross(p - center, n) + s * mu * torsion[i] * n) / radius]))
    return np.array(out)


def support(wrenches, direction):
    return float(np.max(wrenches @ np.asarray(direction, dtype=float)))


def ray_exit(wrenches, direction):
    """How far the ray from the origin along the unit ``direction`` stays in the hull (Qhull)."""
    from scipy.spatial import ConvexHull
    hull = ConvexHull(wrenches)
    normal, offset = hull.equations[:, :-1], hull.equations[:, -1]
    along = normal @ direction
    return float(np.min(-offset[along > 1e-12] / along[along > 1e-12])), float(np.min(-offset))


# ---- a plate resting on a palm -----------------------------------------------------------------

@pytest.fixture(scope="module")
def plate_on_palm(tmp_path_factory):
    """A 0.4 kg, 20 x 20 x 1 cm plate dropped onto a still 9 x 8 cm palm (a convex finger), 0.6 s."""
    d = scene.SceneDesc()
    _body(d, "Plate", (PLATE_HALF, PLATE_HALF, PLATE_H), (0, 0, PLATE_H), PLATE_M)
    d.fingers.append(scene.FingerDesc("Palm", np.array([0.0, 0.0, -PALM[2]]), 0.0, K, 2.0, 0,
                                      points=_mesh(PALM, "Palm").vertices))
    desc = scene.prepare(d)
    return _record(tmp_path_factory.mktemp("palm") / "plate.mcap", desc, lambda t: [[0.0, 0.0, -PALM[2]]], 0.6)


def test_the_record_carries_the_palms_patch(plate_on_palm):
    """The palm's four top corners, about the pressure centroid, along the analysis's tangent
    axes of the inward normal +z (t1 = y, t2 = -x): float32 offsets of the corners."""
    last = plate_on_palm.ticks[-1]
    assert last["state"][0] == 1 and last["contact"][0] == 0
    corners = last["patch"][0].astype(np.float64)
    centroid = last["god_object"][0]
    t1, t2 = analysis.tangent_axes(-last["normal"][0])
    np.testing.assert_allclose(t1, [0, 1, 0], atol=1e-9)
    np.testing.assert_allclose(t2, [-1, 0, 0], atol=1e-9)
    world = centroid + corners[:, :1] * t1 + corners[:, 1:] * t2
    want = {(sx * PALM[0], sy * PALM[1]) for sx in (-1, 1) for sy in (-1, 1)}
    got = {tuple(np.round(p[:2], 6)) for p in world}
    assert got == {tuple(np.round(w, 6)) for w in want}
    # on the plate's bottom face, sunk W / 4k into the palm's corner springs
    np.testing.assert_allclose(world[:, 2], last["pose"][0][2] - PLATE_H, atol=1e-9)
    assert last["pose"][0][2] - PLATE_H == pytest.approx(-PLATE_M * 9.81 / (4 * K), rel=1e-3)


def test_plate_on_a_palm_is_held_with_its_pressure_torque_in_the_wrench_space(plate_on_palm):
    """Held (the palm touches it), not in force closure (a palm cannot pull the plate down), but
    in torque closure: the patch resists a tipping torque up to F times its half width about each
    tangential axis, which a point contact at the pressure centroid does not (no torque closure)."""
    table = analysis.analyse_recording(plate_on_palm, rows=[len(plate_on_palm.ticks) - 1])
    (g,) = analysis.body_grasps(table)
    assert g.body == 0 and len(g.contacts) == 1
    assert not g.force_closure and g.torque_closure and g.epsilon == 0.0
    assert g.grip_force == pytest.approx(PLATE_M * 9.81, rel=1e-3)
    t = plate_on_palm.ticks[-1:]
    point = analysis.analyse_arrays(table_models(plate_on_palm), t["pose"], t["god_object"], t["force"], t["normal"],
                                    t["state"], t["contact"], [0.0])
    assert not point.quality["torque_closure"][0] and point.quality["rank"][0] < 6
    # The GWS about the contact point: tipping torque up to F a per unit normal force, a the
    # patch's half width along each tangential axis; a point contact gives none.
    c = g.contacts[0]
    pts, nrm, mu, _, _ = analysis.wrench_contacts(c.point[None], c.normal[None], np.array([c.mu]), np.array([0]),
                                                  t["patch"][:, 0], None)
    assert len(pts) == 4
    w = cone_wrenches(pts, nrm, c.mu, c.point, g.radius)
    for axis, half in ((0, PALM[1]), (1, PALM[0])):
        for sign in (-1, 1):
            u = np.zeros(6)
            u[3 + axis] = sign
            assert support(w, u) == pytest.approx(half / g.radius, rel=1e-6)
            assert support(cone_wrenches(c.point[None], c.normal[None], c.mu, c.point, g.radius), u) == 0.0


def table_models(rec):
    return analysis.body_models(rec.header["scene"])


# ---- a box pinched by two fingers ---------------------------------------------------------------

def _pinch(path, fingers):
    """A 0.2 kg box of side 6 cm without gravity, squeezed along x by two fingers closing over
    0.3 s and holding to 0.6 s; ``fingers`` (name, sign) -> FingerDesc keyword arguments."""
    d = scene.SceneDesc(gravity=(0.0, 0.0, 0.0))
    _body(d, "Box", (SIDE / 2,) * 3, (0, 0, 0), 0.2)
    starts = []
    for i, (sign, kw) in enumerate(fingers):
        reach = kw.pop("reach")
        start = sign * (SIDE / 2 + reach + 0.005)
        starts.append((start, sign * (SIDE / 2 + reach - SQUEEZE)))
        d.fingers.append(scene.FingerDesc(f"Finger {i}", np.array([start, 0.0, 0.0]), stiffness=K, damping=2.0,
                                          channel=i, **kw))
    desc = scene.prepare(d)

    def hips(t):
        u = min(t / 0.3, 1.0)
        return [[a + u * (b - a), 0.0, 0.0] for a, b in starts]
    return _record(path, desc, hips, 0.6)


@pytest.fixture(scope="module")
def pad_pinch(tmp_path_factory):
    pad = _mesh((0.002, PAD, PAD), "Pad").vertices
    return _pinch(tmp_path_factory.mktemp("pads") / "pads.mcap",
                  [(s, dict(radius=0.0, points=pad, reach=0.002)) for s in (1, -1)])


@pytest.fixture(scope="module")
def soft_pinch(tmp_path_factory):
    return _pinch(tmp_path_factory.mktemp("soft") / "soft.mcap",
                  [(s, dict(radius=0.008, torsion=0.005, reach=0.008)) for s in (1, -1)])


def test_two_flat_pads_close_the_pinch_with_the_square_pads_torsional_limit(pad_pinch):
    """Two point contacts leave the rotation about the pinch axis free (never in closure); two
    square pads of half width a resist it up to mu F a sqrt(2) each (their corners' friction,
    docs/physics.md "Area contacts"): epsilon is that torque per unit normal force, mu a sqrt(2) / r,
    in the direction of the pinch axis, and the core's hull is Qhull's."""
    row = len(pad_pinch.ticks) - 1
    table = analysis.analyse_recording(pad_pinch, rows=[row])
    (g,) = analysis.body_grasps(table)
    assert [c.state for c in g.contacts] == [1, 1]
    closed_form = MU[0] * PAD * np.sqrt(2) / g.radius
    assert g.force_closure and g.epsilon == pytest.approx(closed_form, rel=1e-3)
    np.testing.assert_allclose(np.abs(g.weakest), [0, 0, 0, 1, 0, 0], atol=1e-3)
    assert g.mu_min < MU[0]
    # Qhull on the documented generators gives the same epsilon.
    pts, nrm, mu, _, _ = analysis.wrench_contacts(table.point, table.normal, table.mu, table.finger,
                                                  pad_pinch.ticks["patch"][row][table.finger], None)
    w = cone_wrenches(pts, nrm, MU[0], g.center, g.radius)
    reach, nearest = ray_exit(w, np.array([0, 0, 0, 1.0, 0, 0]))
    assert g.epsilon == pytest.approx(nearest, rel=1e-9)
    assert reach == pytest.approx(closed_form, rel=1e-3)
    # The same record read as an older one (no patch): point contacts, never in closure.
    old = analysis.analyse_arrays(table_models(pad_pinch), *(pad_pinch.ticks[[row]][k] for k in
                                  ("pose", "god_object", "force", "normal", "state", "contact")), [0.0, 0.0])
    assert not old.quality["force_closure"][0] and old.quality["rank"][0] == 5


def test_two_soft_fingertips_close_the_pinch_up_to_their_torsional_limit(soft_pinch):
    """Two soft fingertips (rho 5 mm) close the pinch: the torque about the pinch axis they resist
    per unit normal force is mu rho / r (the ray along it leaves the GWS there: their torsional
    friction mu Fn rho); epsilon is Qhull's and no more than that."""
    row = len(soft_pinch.ticks) - 1
    table = analysis.analyse_recording(soft_pinch, rows=[row])
    (g,) = analysis.body_grasps(table)
    torsions = analysis.finger_torsions(soft_pinch.header["scene"])
    np.testing.assert_array_equal(torsions, [0.005, 0.005])
    assert g.force_closure and g.torque_closure
    closed_form = MU[0] * 0.005 / g.radius
    w = cone_wrenches(table.point, table.normal, MU[0], g.center, g.radius, torsion=torsions[table.finger])
    reach, nearest = ray_exit(w, np.array([0, 0, 0, 1.0, 0, 0]))
    assert reach == pytest.approx(closed_form, rel=1e-6)
    assert g.epsilon == pytest.approx(nearest, rel=1e-9) and g.epsilon <= closed_form * (1 + 1e-9)
    # Without the torsion (point contacts, or a recording of fingers without it): not in closure.
    t = soft_pinch.ticks[[row]]
    args = [t[k] for k in ("pose", "god_object", "force", "normal", "state", "contact")]
    point = analysis.analyse_arrays(table_models(soft_pinch), *args, [0.008, 0.008])
    assert not point.quality["force_closure"][0]
    soft = analysis.analyse_arrays(table_models(soft_pinch), *args, [0.008, 0.008], torsions=torsions)
    assert soft.quality["epsilon"][0] == g.epsilon and soft.mu_min[0] == g.mu_min


# ---- recordings of sphere fingers, and those made before the patch --------------------------------

@pytest.fixture(scope="module")
def sphere_pinch(tmp_path_factory):
    return _pinch(tmp_path_factory.mktemp("sphere") / "sphere.mcap",
                  [(s, dict(radius=0.008, reach=0.008)) for s in (1, -1)] + [])


def _without_patch(rec):
    """The recording as one made before the ``patch`` field reads (its records a prefix)."""
    names = [n for n in rec.ticks.dtype.names if n != "patch"]
    old = np.zeros(len(rec.ticks), dtype=[(n, rec.ticks.dtype.fields[n][0]) for n in names])
    for n in names:
        old[n] = rec.ticks[n]
    rec.ticks = old
    return rec


def test_sphere_fingers_are_analysed_as_before_and_older_recordings_still_read(sphere_pinch, pad_pinch, tmp_path):
    """Sphere fingers record a zero patch: the analysis of their recording is bit for bit that of
    the same records without the field (a recording made before it). An older recording of pads
    is analysed with point contacts, and analyze says so."""
    assert not np.any(sphere_pinch.ticks["patch"])
    new = analysis.analyse_recording(sphere_pinch, every=50)
    old = analysis.analyse_recording(_without_patch(recording.open_recording(sphere_pinch.path)), every=50)
    for name in analysis.GraspTable.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(new, name), getattr(old, name), err_msg=name)
    assert analysis.point_contacts_note(sphere_pinch) is None
    pads_old = _without_patch(recording.open_recording(pad_pinch.path))
    note = analysis.point_contacts_note(pads_old)
    assert "Finger 0, Finger 1 analysed as point contacts" in note
    table = analysis.analyse_recording(pads_old, rows=[len(pads_old.ticks) - 1])
    assert not table.quality["force_closure"][0]


def test_bad_patches_and_torsions_are_refused_naming_them(pad_pinch):
    t = pad_pinch.ticks[-1:]
    args = [t[k] for k in ("pose", "god_object", "force", "normal", "state", "contact")]
    models = table_models(pad_pinch)
    with pytest.raises(ValueError, match="patches: expected shape"):
        analysis.analyse_arrays(models, *args, [0.0, 0.0], patches=np.zeros((1, 2, 4)))
    with pytest.raises(ValueError, match="torsions: expected 2 finite radii"):
        analysis.analyse_arrays(models, *args, [0.0, 0.0], torsions=[0.01, -1.0])
    with pytest.raises(scene.SceneError, match="torsion"):
        d = scene.SceneDesc()
        d.fingers.append(scene.FingerDesc("F", np.zeros(3), points=_mesh((0.01,) * 3, "F").vertices, torsion=0.01))
        scene.prepare(d)


def test_the_live_hud_sees_the_patch_as_the_recording_does(tmp_path):
    """One implementation: the session's snapshot (runner.Snapshot.patches, from the core's) through
    the HUD's GraspMonitor gives the plate on the palm the same wrench space as analyze gives the
    recording's last tick (the load differs: the monitor's first update has no acceleration)."""
    import graspcore
    from addon.engine import grasp_display
    d = scene.SceneDesc()
    _body(d, "Plate", (PLATE_HALF, PLATE_HALF, PLATE_H), (0, 0, PLATE_H), PLATE_M)
    d.fingers.append(scene.FingerDesc("Palm", np.array([0.0, 0.0, -PALM[2]]), 0.0, K, 2.0, 0,
                                      points=_mesh(PALM, "Palm").vertices))
    desc = scene.prepare(d)
    run, _ = recordings.record_scene(tmp_path / "live.mcap", graspcore, desc, lambda t: [[0.0, 0.0, -PALM[2]]], 0.3)
    snap = run.snapshot()
    assert snap.patches.shape == (1, 4, 2) and np.count_nonzero(snap.patches) == 8
    monitor = grasp_display.GraspMonitor(analysis.body_models(desc), [f.radius for f in desc.fingers],
                                         gravity=desc.gravity, torsions=analysis.finger_torsions(desc))
    (live,) = monitor.update(snap)
    rec = recording.open_recording(str(tmp_path / "live.mcap"))
    np.testing.assert_array_equal(rec.ticks["patch"][-1], snap.patches)
    (recorded,) = analysis.body_grasps(analysis.analyse_recording(rec, rows=[len(rec.ticks) - 1], volume=False))
    assert live.torque_closure and recorded.torque_closure and not live.force_closure
    assert (live.force_closure, live.torque_closure, live.force_only_closure, live.epsilon, live.mu_min) == \
        (recorded.force_closure, recorded.torque_closure, recorded.force_only_closure, recorded.epsilon,
         recorded.mu_min)


def test_wrench_contacts_takes_each_corner_once_and_zero_patches_as_points():
    """A segment patch records its two ends and repeats the last; a corner at (0, 0) (the
    contact point itself, when the pressure sits at a corner) is a corner like any other; an
    all-zero patch is a point contact; a finger's torsion follows each of its rows."""
    point = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    normal = np.array([[0.0, 0.0, 1.0]] * 3)
    patches = np.array([[[0.01, 0.0], [-0.01, 0.0], [-0.01, 0.0], [-0.01, 0.0]],   # a segment
                        [[0.0, 0.0], [0.02, 0.0], [0.02, 0.03], [0.02, 0.03]],     # a triangle, one corner at p
                        [[0.0, 0.0]] * 4], dtype=np.float32)                     # a point
    pts, nrm, mu, rho, owner = analysis.wrench_contacts(point, normal, np.array([0.5, 0.6, 0.7]), np.array([0, 1, 2]),
                                                        patches, np.array([0.0, 0.0, 0.004]))
    np.testing.assert_array_equal(owner, [0, 0, 1, 1, 1, 2])
    t1, t2 = analysis.tangent_axes(normal[0])                       # n = z: t1 = y, t2 = -x
    np.testing.assert_allclose(t1, [0, 1, 0]) and np.testing.assert_allclose(t2, [-1, 0, 0])
    np.testing.assert_allclose(pts, [[0, 0.01, 0], [0, -0.01, 0], [1, 0, 0], [1, 0.02, 0], [0.97, 0.02, 0], [2, 0, 0]],
                               atol=1e-8)
    np.testing.assert_array_equal(mu, [0.5, 0.5, 0.6, 0.6, 0.6, 0.7])
    np.testing.assert_array_equal(rho, [0, 0, 0, 0, 0, 0.004])
    assert analysis.wrench_contacts(point, normal, np.ones(3), np.arange(3), None, np.zeros(3))[3] is None
