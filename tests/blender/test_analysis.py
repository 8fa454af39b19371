"""Grasp analysis (addon/engine/analysis.py, grasp-lab analyze) on real recordings made by the
project's recorder, against values derived by hand: a box pinched by two fingers under
gravity, the same box carried up with a known acceleration, a heavier box slipping through
the fingers, a three-finger grasp. Plain Python (no bpy)."""
import csv
import io
import math

import numpy as np
import pytest

import recordings
from addon.engine import analysis, cli, recording, scene

SIDE, MASS, K, R, SQUEEZE = 0.06, 0.2, 1000.0, 0.01, 0.003   # box side, kg, N/m, finger radius, m
G = 9.81
HALF = SIDE / 2
X = HALF + R - SQUEEZE               # HIP x of a finger squeezing a side face by SQUEEZE


def box_scene(fingers, mass=MASS, mu=(0.8, 0.6), damping=2.0):
    """A box of side SIDE at the origin (no table) and fingers with HIPs at ``fingers``."""
    import trimesh  # the dev venv's (this module is not in the multi-version set)
    d = scene.SceneDesc()
    tm = trimesh.creation.box((SIDE,) * 3)
    mesh = scene.MeshData(np.array(tm.vertices), np.array(tm.faces), source="Box")
    d.bodies.append(scene.BodyDesc("Box", False, [mesh.vertices], [mesh], np.zeros(3), np.array([1.0, 0, 0, 0]),
                                   mass=mass, mu_s=mu[0], mu_d=mu[1]))
    for i, p in enumerate(fingers):
        d.fingers.append(scene.FingerDesc(f"Finger {i}", np.array(p, dtype=float), R, K, damping, i))
    return scene.prepare(d)


def record(path, desc, hips, seconds):
    import graspcore  # the dev venv's (this module is not in the multi-version set)
    recordings.record_scene(path, graspcore, desc, hips, seconds)
    return recording.open_recording(str(path))


@pytest.fixture(scope="module")
def pinch(tmp_path_factory):
    """Two fingers squeeze the box's x faces by 3 mm and hold it still for 2 s."""
    desc = box_scene([(X, 0, 0), (-X, 0, 0)])
    return record(tmp_path_factory.mktemp("a") / "pinch.mcap", desc, lambda t: [[X, 0, 0], [-X, 0, 0]], 2.0)


ACC = 2.0                            # m/s^2, upwards from t = 1 s


def lift_z(t):
    return 0.5 * ACC * max(t - 1.0, 0.0) ** 2


@pytest.fixture(scope="module")
def lift(tmp_path_factory):
    """The pinch, then the HIPs accelerate upwards at ACC."""
    desc = box_scene([(X, 0, 0), (-X, 0, 0)])
    return record(tmp_path_factory.mktemp("b") / "lift.mcap", desc,
                  lambda t: [[X, 0, lift_z(t)], [-X, 0, lift_z(t)]], 1.5)


MU_SLIP = (0.3, 0.2)


@pytest.fixture(scope="module")
def slip(tmp_path_factory):
    """A 0.5 kg box (weight 4.9 N) in a 3 N pinch at mu_s 0.3: more than 2 mu_s |Fn| = 1.8 N,
    so it slides down through the fingers (no finger damping)."""
    desc = box_scene([(X, 0, 0), (-X, 0, 0)], mass=0.5, mu=MU_SLIP, damping=0.0)
    return record(tmp_path_factory.mktemp("c") / "slip.mcap", desc, lambda t: [[X, 0, 0], [-X, 0, 0]], 0.06)


def row_of(table, rec, tick):
    rows = np.flatnonzero(rec.ticks["tick"][table.snapshot] == tick)
    assert len(rows) == 1, f"tick {tick}: {len(rows)} held-body rows"
    return analysis.body_grasps(table, rows)[0]


def test_body_model_from_the_recorded_scene(pinch):
    (m,) = analysis.body_models(pinch.header["scene"])
    assert m.name == "Box" and not m.is_static and m.mass == MASS and (m.mu_s, m.mu_d) == (0.8, 0.6)
    np.testing.assert_allclose(m.com, 0.0, atol=1e-15)
    assert m.radius == pytest.approx(HALF * math.sqrt(3), rel=1e-12)    # the cube's half diagonal
    (from_desc,) = analysis.body_models(recording.scene_from_dict(pinch.header["scene"]))
    assert (from_desc.mass, from_desc.radius, from_desc.mu_s) == (m.mass, m.radius, m.mu_s)


def test_pinch_under_gravity(pinch):
    """Held still: each finger presses k * squeeze = 3 N, carries half the weight tangentially
    (symmetry), the load is the weight; the box has sagged until the two sticking springs
    carry it: m g / (2 k) below the HIPs."""
    import graspcore  # the dev venv's (this module is not in the multi-version set)
    table = analysis.analyse_recording(pinch)
    g = row_of(table, pinch, 2000)
    weight = MASS * G
    fn, ft = K * SQUEEZE, weight / 2
    assert [c.finger for c in g.contacts] == [0, 1]
    for c, side in zip(g.contacts, (1, -1)):
        assert c.state == 1 and c.mu == 0.8
        assert c.fn == pytest.approx(fn, rel=1e-9) and c.ft == pytest.approx(ft, rel=1e-6)
        assert c.friction_use == pytest.approx(ft / (0.8 * fn), rel=1e-6)
        assert c.slip_margin == pytest.approx(0.8 * fn - ft, rel=1e-6)
        np.testing.assert_allclose(c.point, (side * HALF, 0, -weight / (2 * K)), atol=1e-9)
        np.testing.assert_allclose(c.normal, (-side, 0, 0), atol=1e-12)
    assert g.grip_force == pytest.approx(2 * fn, rel=1e-9)
    assert g.load_force == pytest.approx(weight, rel=1e-6)
    assert g.grip_ratio == pytest.approx(2 * fn / weight, rel=1e-6)
    assert g.friction_needed == pytest.approx(ft / fn, rel=1e-6)
    assert g.min_slip_margin == pytest.approx(0.8 * fn - ft, rel=1e-6) and g.min_slip_finger in (0, 1)
    np.testing.assert_allclose(g.center, (0, 0, -weight / (2 * K)), atol=1e-9)
    assert g.radius == pytest.approx(HALF * math.sqrt(3))
    # Two point contacts facing each other balance any force but no torque about the line
    # joining them: never in force closure, at any friction.
    assert g.force_only_closure and not g.force_closure
    assert g.epsilon == 0.0 and g.resisted_force == 0.0 and g.mu_min == math.inf
    # The quality is the core routine's on the hand-derived contacts.
    points = np.array([[HALF, 0, -weight / (2 * K)], [-HALF, 0, -weight / (2 * K)]])
    q = graspcore.grasp_quality(points, [[-1, 0, 0], [1, 0, 0]], 0.8, g.center, HALF * math.sqrt(3))
    assert (g.force_closure, g.torque_closure, g.force_only_closure) == \
        (q["force_closure"], q["torque_closure"], q["force_only_closure"])
    assert g.volume == pytest.approx(q["volume"], rel=1e-9, abs=1e-15)


def test_snapshot_and_recording_agree(pinch):
    """analyse (one snapshot, the live HUD's call) gives what analyse_recording gives for that
    tick; without an acceleration the load is the weight."""
    models = analysis.body_models(pinch.header["scene"])
    t = pinch.ticks[1500]
    radii = [f["radius"] for f in pinch.header["scene"]["fingers"]]
    acc = analysis.recorded_accelerations(models, pinch.ticks, [1500])[0]
    (one,) = analysis.analyse(models, t["pose"], t["god_object"], t["force"], t["normal"], t["state"],
                              t["contact"], radii, accelerations=acc)
    same = row_of(analysis.analyse_recording(pinch), pinch, 1500)
    for name in analysis.BodyGrasp.__dataclass_fields__:
        if name != "contacts":
            np.testing.assert_array_equal(getattr(one, name), getattr(same, name), err_msg=name)
    for a, b in zip(one.contacts, same.contacts):
        for name in analysis.FingerContact.__dataclass_fields__:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    (still,) = analysis.analyse(models, t["pose"], t["god_object"], t["force"], t["normal"], t["state"],
                                t["contact"], radii)
    assert still.load_force == pytest.approx(MASS * G, rel=1e-12)


def test_held_body_under_acceleration(lift):
    """Carried up at ACC: the load is m |a - g| = m (g + ACC), which the fingers' reactions
    balance (Newton: their sum is m (a - g)); the grip is unchanged, so grip/load drops."""
    table = analysis.analyse_recording(lift)
    for tick in (1300, 1400, 1500):
        g = row_of(table, lift, tick)
        t = lift.ticks[tick]
        reactions = -t["force"].sum(axis=0)
        assert g.load_force == pytest.approx(np.linalg.norm(reactions), rel=1e-6)
        assert g.load_force == pytest.approx(MASS * (G + ACC), rel=2e-3)
        assert sum(c.ft for c in g.contacts) == pytest.approx(MASS * (G + ACC), rel=2e-3)
        assert g.grip_force == pytest.approx(2 * K * SQUEEZE, rel=1e-9)
        assert g.grip_ratio == pytest.approx(2 * K * SQUEEZE / g.load_force, rel=1e-12)
    before = row_of(table, lift, 900)
    assert before.load_force == pytest.approx(MASS * G, rel=1e-4)


def test_slipping_finger(slip):
    """Sliding: the cone is the mu_d one. Each god-object starts the step on the mu_d circle
    (mu_d * depth from the HIP's surface point) and moves with the box during it, so the force
    the box gets is k (mu_d depth + |dz|), dz the box's drop over the tick: friction use above 1,
    a negative slip margin."""
    table = analysis.analyse_recording(slip)
    slipping = [tick for tick in range(1, len(slip.ticks)) if (slip.ticks["state"][tick] == 2).all()]
    assert len(slipping) > 20
    for tick in slipping[5::10]:
        g = row_of(table, slip, tick)
        dz = slip.ticks["pose"][tick, 0, 2] - slip.ticks["pose"][tick - 1, 0, 2]
        assert dz < 0
        depth = SQUEEZE
        ft = K * (MU_SLIP[1] * depth + abs(dz))
        for c in g.contacts:
            assert c.state == 2 and c.mu == MU_SLIP[1]
            assert c.fn == pytest.approx(K * depth, rel=1e-9)
            assert c.ft == pytest.approx(ft, rel=1e-6)
            assert c.friction_use == pytest.approx(ft / (MU_SLIP[1] * K * depth), rel=1e-6)
            assert c.friction_use > 1 and c.slip_margin == pytest.approx(MU_SLIP[1] * K * depth - ft, rel=1e-6)
        assert g.min_slip_margin < 0 and g.friction_needed == pytest.approx(ft / (K * depth), rel=1e-6)
    # Before it slides, the fingers stick with the mu_s cone.
    g = row_of(table, slip, 1)
    assert all(c.state == 1 and c.mu == MU_SLIP[0] for c in g.contacts)


@pytest.fixture(scope="module")
def three(tmp_path_factory):
    """Two fingers on the +x face at y = +-15 mm, one on the -x face squeezing twice as deep:
    the x forces and the torques about z balance; a grasp in force closure."""
    hips = [(X, 0.015, 0), (X, -0.015, 0), (-(HALF + R - 2 * SQUEEZE), 0, 0)]
    desc = box_scene(hips)
    return record(tmp_path_factory.mktemp("d") / "three.mcap", desc, lambda t: hips, 1.5)


def test_three_finger_grasp_in_closure(three):
    """Statically indeterminate (the box tilts a little under its weight), so the forces are
    checked to the tilt; the quality is the core routine's on the recorded contacts."""
    import graspcore  # the dev venv's (this module is not in the multi-version set)
    table = analysis.analyse_recording(three, every=100)
    g = row_of(table, three, 1500)
    assert [c.finger for c in g.contacts] == [0, 1, 2]
    assert [c.fn for c in g.contacts] == pytest.approx([K * SQUEEZE, K * SQUEEZE, 2 * K * SQUEEZE], rel=5e-3)
    assert g.grip_force == pytest.approx(4 * K * SQUEEZE, rel=5e-3)
    assert g.load_force == pytest.approx(MASS * G, rel=1e-4)
    ideal = np.array([[HALF, 0.015, 0], [HALF, -0.015, 0], [-HALF, 0, 0]])
    np.testing.assert_allclose([c.point for c in g.contacts], ideal, atol=2e-3)
    t = three.ticks[1500]
    points = t["god_object"] - R * t["normal"]        # the fingertip sphere's touching point
    normals = -t["normal"]
    np.testing.assert_allclose([c.point for c in g.contacts], points, rtol=0, atol=1e-15)
    np.testing.assert_allclose(g.center, t["pose"][0, :3], rtol=0, atol=1e-15)    # the box origin: its COM
    center = g.center       # (bit for bit: facets at the same distance tie, and rounding picks one)
    q = graspcore.grasp_quality(points, normals, 0.8, center, HALF * math.sqrt(3))
    assert q["force_closure"] and g.force_closure and g.epsilon > 0
    assert g.epsilon == pytest.approx(q["epsilon"], rel=1e-12)
    assert g.volume == pytest.approx(q["volume"], rel=1e-12)
    # Several facets are nearest (the grasp is symmetric in y) and rounding picks one: on the
    # contacts exactly as the analysis passed them, the same one.
    same = graspcore.grasp_quality(np.array([c.point for c in g.contacts]), np.array([c.normal for c in g.contacts]),
                                   [c.mu for c in g.contacts], g.center, g.radius)
    np.testing.assert_array_equal(g.weakest, same["weakest"])
    assert np.linalg.norm(g.weakest) == pytest.approx(1.0, rel=1e-12)
    assert np.linalg.norm(g.weakest) == pytest.approx(1.0, rel=1e-12)
    assert g.resisted_force == pytest.approx(g.epsilon * g.grip_force, rel=1e-12)
    mu_min = graspcore.grasp_mu_min(points, normals, center, HALF * math.sqrt(3))
    assert g.mu_min == pytest.approx(mu_min, abs=1e-12) and 0 < g.mu_min < 0.8


def run_cli(*argv):
    out, err = io.StringIO(), io.StringIO()
    code = cli.main(list(argv), out=out, err=err)
    return code, out.getvalue(), err.getvalue()


def test_analyze_command(pinch, tmp_path):
    code, out, err = run_cli("analyze", pinch.path, "--csv", str(tmp_path), "--every", "100")
    assert code == 0, err
    assert "Box: held 2.000 s, in force closure 0.000 s" in out
    assert "closest to slipping: Finger" in out
    with open(tmp_path / "grasp.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["time", "body", "contacts", "force_closure", "torque_closure", "force_only_closure",
                       "epsilon", "volume", "weakest_fx", "weakest_fy", "weakest_fz", "weakest_tx", "weakest_ty",
                       "weakest_tz", "mu_min", "friction_needed", "min_slip_margin", "min_slip_finger",
                       "grip_force", "load_force", "center_x", "center_y", "center_z", "radius"]
    # Ticks 100, 200, ..., 2000 (tick 0 is before the first step: no contact yet).
    assert [float(r[0]) for r in rows[1:]] == pytest.approx([k / 10 for k in range(1, 21)])
    last = dict(zip(rows[0], rows[-1]))
    assert last["body"] == "Box" and last["contacts"] == "2" and last["force_closure"] == "0"
    assert last["mu_min"] == "inf" and float(last["grip_force"]) == pytest.approx(6.0, rel=1e-9)
    assert float(last["load_force"]) == pytest.approx(MASS * G, rel=1e-6)
    assert last["min_slip_finger"] in ("Finger 0", "Finger 1")
    with open(tmp_path / "contacts.csv") as fh:
        contacts = list(csv.reader(fh))
    assert contacts[0] == ["time", "body", "finger", "px", "py", "pz", "nx", "ny", "nz", "mu", "fn", "ft",
                           "friction_use", "slip_margin"]
    assert len(contacts) == 1 + 2 * 20
    c = dict(zip(contacts[0], contacts[-1]))
    assert c["finger"] == "Finger 1" and float(c["px"]) == pytest.approx(-HALF, abs=1e-9)
    assert float(c["nx"]) == 1.0 and float(c["ft"]) == pytest.approx(MASS * G / 2, rel=1e-6)
    # The same numbers as the whole recording analysed in memory.
    table = analysis.analyse_recording(pinch)
    assert float(last["min_slip_margin"]) == row_of(table, pinch, 2000).min_slip_margin


def test_analyze_usage_and_errors(pinch, tmp_path):
    assert run_cli("analyze", "--help")[0] == 0
    assert run_cli("analyze", pinch.path, "--edges", "2")[0] == 2
    assert run_cli("analyze", pinch.path, "--every", "0")[0] == 2
    code, _, err = run_cli("analyze", str(tmp_path / "missing.mcap"))
    assert code == 1 and "missing.mcap" in err


def test_analyze_refuses_a_recording_without_normals(tmp_path, monkeypatch):
    """A recording whose ticks carry no contact normals (made before they were recorded)."""
    old = recording.tick_dtype

    def without_normals(nb, nf):
        dt = old(nb, nf)
        names = [n for n in dt.names if n != "normal"]
        return np.dtype([(n, dt.fields[n][0]) for n in names])
    monkeypatch.setattr(recording.writer, "tick_dtype", without_normals)
    desc = box_scene([(X, 0, 0), (-X, 0, 0)])
    header = recording.make_header(desc, mode="exec", haptic_rate=1000.0)
    w = recording.RecordingWriter(str(tmp_path / "old.mcap"), header)
    ticks = np.zeros(3, w.dtype)
    ticks["tick"] = [0, 1, 2]
    ticks["time"] = [0.0, 0.001, 0.002]
    w.write_ticks(ticks)
    w.close()
    monkeypatch.undo()
    code, out, err = run_cli("analyze", str(tmp_path / "old.mcap"))
    assert code == 1 and "older version" in err and "normals" in err, err


def test_thinned_read_gives_the_same_numbers(lift):
    """analyze --every N reads only ticks N k and the tick before each: the same accelerations,
    so the same numbers as the whole recording analysed, bit for bit."""
    full = analysis.analyse_recording(lift)
    thin_rec = recording.open_recording(lift.path, every=50)
    thin = analysis.analyse_recording(thin_rec, every=50)
    ticks = thin_rec.ticks["tick"][thin.snapshot]
    assert len(ticks) > 20 and np.all(ticks % 50 == 0)
    rows = np.searchsorted(lift.ticks["tick"][full.snapshot], ticks)
    for name in ("load_force", "grip_force", "min_slip_margin", "mu_min", "friction_needed"):
        np.testing.assert_array_equal(getattr(thin, name), getattr(full, name)[rows], err_msg=name)
    np.testing.assert_array_equal(thin.quality, full.quality[rows])


def test_cone_edges(three):
    """--edges K: the contacts' cones of K edges, as the core routine builds them."""
    import graspcore  # the dev venv's (this module is not in the multi-version set)
    for k in (3, 16):
        table = analysis.analyse_recording(three, every=500, edges=k)
        g = row_of(table, three, 1500)
        points = np.array([c.point for c in g.contacts])
        normals = np.array([c.normal for c in g.contacts])
        q = graspcore.grasp_quality(points, normals, [c.mu for c in g.contacts], g.center, g.radius, edges=k)
        assert g.epsilon == q["epsilon"] and g.volume == q["volume"] and g.force_closure == q["force_closure"]
    eight = row_of(analysis.analyse_recording(three, every=500), three, 1500)
    sixteen = row_of(analysis.analyse_recording(three, every=500, edges=16), three, 1500)
    assert sixteen.epsilon > eight.epsilon         # a finer cone spans more of the true one


def test_a_contact_set_the_core_refuses_is_located(pinch):
    """Bad numbers in a snapshot (a NaN god-object) come back as an error naming the snapshot
    and the body, and in a recording the tick and its time."""
    models = analysis.body_models(pinch.header["scene"])
    t = pinch.ticks[1000].copy()
    t["god_object"][1, 0] = np.nan
    radii = [f["radius"] for f in pinch.header["scene"]["fingers"]]
    with pytest.raises(analysis.GraspAnalysisError, match=r"snapshot 0, body Box: points: .*not finite") as err:
        analysis.analyse(models, t["pose"], t["god_object"], t["force"], t["normal"], t["state"], t["contact"],
                         radii)
    assert err.value.snapshot == 0
    broken = recording.Recording(pinch.path, pinch.header, pinch.dtype, pinch.ticks.copy())
    broken.ticks["god_object"][1000, 1, 0] = np.nan
    with pytest.raises(ValueError, match=r"tick 1000 \(t = 1 s\), body Box: points"):
        analysis.analyse_recording(broken, every=100)


def test_live_options_and_rotation(three):
    """volume=False (the live view's fast path): the same measures but the volume (-1, not
    computed); the centres of mass rotate as the runner's quat_rotate does."""
    from addon.engine.runner import quat_rotate
    models = analysis.body_models(three.header["scene"])
    t = three.ticks[1500]
    radii = [f["radius"] for f in three.header["scene"]["fingers"]]
    args = (models, t["pose"], t["god_object"], t["force"], t["normal"], t["state"], t["contact"], radii)
    (full,) = analysis.analyse(*args)
    (fast,) = analysis.analyse(*args, volume=False)
    assert full.volume > 0 and fast.volume == -1.0
    assert (fast.force_closure, fast.epsilon, fast.mu_min) == (full.force_closure, full.epsilon, full.mu_min)
    np.testing.assert_allclose(fast.weakest, full.weakest, rtol=0, atol=1e-12)
    rng = np.random.default_rng(1)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    v = rng.normal(size=3)
    np.testing.assert_allclose(analysis._rotate(q, v), quat_rotate(q, v), rtol=0, atol=1e-15)


def test_memo_gives_the_same_answers(three, lift):
    """analyse_arrays with a memo kept between calls (the live view's): the same tables bit for
    bit as without it, over snapshots that repeat (a still grasp) and change (a lift), two at a
    time; the memo then holds the last call's sets, and a set the core refuses among remembered
    ones is still located."""
    memo = {}
    for rec, ticks in ((three, [(1400, 1401), (1400, 1401), (1401, 1402), (1400, 1400)]),
                       (lift, [(1200, 1201), (1201, 1400), (1200, 1400), (1200, 1201)])):
        models = analysis.body_models(rec.header["scene"])
        radii = [f["radius"] for f in rec.header["scene"]["fingers"]]
        for pair in ticks:
            t = rec.ticks[np.searchsorted(rec.ticks["tick"], pair)]
            assert list(t["tick"]) == list(pair)
            args = (models, t["pose"], t["god_object"], t["force"], t["normal"], t["state"], t["contact"], radii)
            want = analysis.analyse_arrays(*args, volume=False)
            got = analysis.analyse_arrays(*args, volume=False, memo=memo)
            assert len(got.quality) == 2
            np.testing.assert_array_equal(got.quality, want.quality)
            np.testing.assert_array_equal(got.mu_min, want.mu_min)
            (s0, s1), (c0, c1) = want.first, want.count
            same = c0 == c1 and np.array_equal(want.center[0], want.center[1]) and all(
                np.array_equal(a[s0:s0 + c0], a[s1:s1 + c1]) for a in (want.point, want.normal, want.mu))
            assert len(memo) == (1 if same else 2)
    t = lift.ticks[np.searchsorted(lift.ticks["tick"], [1200, 1201])].copy()
    t["god_object"][1, 1, 0] = np.nan
    with pytest.raises(analysis.GraspAnalysisError, match=r"snapshot 1, body Box: points: .*not finite"):
        analysis.analyse_arrays(models, t["pose"], t["god_object"], t["force"], t["normal"], t["state"],
                                t["contact"], radii, volume=False, memo=memo)
