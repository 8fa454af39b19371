"""The live view's grasp logic (addon/engine/grasp_display.py), in plain Python: colours by
friction use, the acceleration the load's inertial part is taken from, the HUD text, the
weakest-wrench geometry, wrapping, and the analysis of a real pinch."""
import math
import os
import sys
from types import SimpleNamespace

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from addon.engine import analysis, grasp_display, inputs, runner, scene  # noqa: E402


# ---------------------------------------------------------------- colours

def test_friction_colour_runs_green_yellow_red_and_saturates():
    green, yellow, red = (grasp_display.friction_color(u)[:3] for u in (0.0, 0.5, 1.0))
    assert green[1] > 0.8 and green[0] < 0.2                 # far from slip
    assert yellow[0] == 1.0 and yellow[1] > 0.8              # half way
    assert red[0] == 1.0 and red[1] < 0.2 and red[2] < 0.2   # at slip
    uses = np.linspace(0.0, 1.0, 21)
    reds = [grasp_display.friction_color(u)[0] for u in uses]
    greens = [grasp_display.friction_color(u)[1] for u in uses[10:]]
    assert all(np.diff(reds) >= 0) and all(np.diff(greens) <= 0)
    for beyond in (1.5, math.inf, math.nan):                 # past the cone, or no normal force
        assert grasp_display.friction_color(beyond) == grasp_display.friction_color(1.0)
    assert grasp_display.friction_color(-0.1) == grasp_display.friction_color(0.0)


def test_finger_colours_free_fingers_keep_the_god_object_blue():
    grasps = [SimpleNamespace(contacts=[SimpleNamespace(finger=2, friction_use=1.0),
                                        SimpleNamespace(finger=0, friction_use=0.0)])]
    colors = grasp_display.finger_colors(grasps, 4)
    assert colors[1] == colors[3] == grasp_display.FREE_COLOR
    assert colors[2] == grasp_display.friction_color(1.0) and colors[0] == grasp_display.friction_color(0.0)


def test_friction_colours_are_friction_color_elementwise():
    uses = np.array([[0.0, 0.2, 0.5], [0.75, 1.0, 1.5], [math.inf, math.nan, -0.1]])
    got = grasp_display.friction_colors(uses)
    assert got.shape == (3, 3, 4)
    for idx in np.ndindex(uses.shape):
        np.testing.assert_allclose(got[idx], grasp_display.friction_color(float(uses[idx])), atol=1e-15)


def test_finger_color_series_is_finger_colors_per_record():
    """Per record, the colours finger_colors gives that record's sets; a record with no set:
    all free; a finger in two sets takes the last, as finger_colors does."""
    table = SimpleNamespace(snapshot=np.array([3, 3, 7]), count=np.array([2, 1, 1]), first=np.array([0, 2, 3]),
                            finger=np.array([0, 2, 2, 1]), friction_use=np.array([0.1, 0.9, 0.3, math.nan]))
    rows = np.array([1, 3, 7])
    got = grasp_display.finger_color_series(table, rows, 3)
    by_record = {3: [SimpleNamespace(contacts=[SimpleNamespace(finger=0, friction_use=0.1),
                                               SimpleNamespace(finger=2, friction_use=0.9)]),
                     SimpleNamespace(contacts=[SimpleNamespace(finger=2, friction_use=0.3)])],
                 7: [SimpleNamespace(contacts=[SimpleNamespace(finger=1, friction_use=math.nan)])]}
    for k, row in enumerate(rows):
        np.testing.assert_allclose(got[k], grasp_display.finger_colors(by_record.get(row, []), 3), atol=1e-15)


# ---------------------------------------------------------------- accelerations

def _snap(t, velocities, poses):
    return SimpleNamespace(time=t, velocities=np.asarray(velocities, float), poses=np.asarray(poses, float),
                           contacts=np.array([-1]))


def test_centre_of_mass_acceleration_between_display_updates():
    """A body whose centre of mass is 0.1 m off its frame origin, spinning at 2 rad/s about
    z: its centre moves at v_origin + w x (R com). The acceleration is the change of that
    over the snapshots' time; a repeated snapshot time keeps the last one."""
    model = analysis.BodyModel("B", 1.0, np.array([0.1, 0, 0]), 0.8, 0.6, 0.1, False)
    m = grasp_display.GraspMonitor([model], [])
    s0 = _snap(1.0, [[0, 0, 0, 0, 0, 2.0]], [[0, 0, 0, 1, 0, 0, 0]])                   # centre moves at (0, 0.2, 0)
    np.testing.assert_array_equal(m.accelerations(s0), [[0, 0, 0]])          # first update
    quarter = [[0, 0, 0, math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)]]           # turned 90° about z
    s1 = _snap(1.25, [[0, 0, 0.5, 0, 0, 2.0]], quarter)                       # centre: (-0.2, 0, 0.5)
    np.testing.assert_allclose(m.accelerations(s1), [[-0.8, -0.8, 2.0]], atol=1e-12)
    np.testing.assert_allclose(m.accelerations(s1), [[-0.8, -0.8, 2.0]], atol=1e-12)    # same tick again
    s2 = _snap(1.5, [[0, 0, 0.5, 0, 0, 2.0]], quarter)
    np.testing.assert_allclose(m.accelerations(s2), [[0, 0, 0]], atol=1e-12)


def test_monitor_survives_a_refused_contact_set(monkeypatch):
    def refuse(*args, **kwargs):
        raise ValueError("normals: row 1 is not a unit vector")
    monkeypatch.setattr(grasp_display.analysis, "analyse", refuse)
    model = analysis.BodyModel("B", 1.0, np.zeros(3), 0.8, 0.6, 0.1, False)
    m = grasp_display.GraspMonitor([model], [0.01])
    snap = SimpleNamespace(time=0.0, velocities=np.zeros((1, 6)), poses=np.array([[0, 0, 0, 1, 0, 0, 0.]]),
                           contacts=np.array([0]), god_objects=np.zeros((1, 3)),
                           spring_forces=np.zeros((1, 3)), normals=np.zeros((1, 3)),
                           finger_states=np.array([1]))
    assert m.update(snap) == [] and "row 1" in m.error and len(m.costs) == 1


# ---------------------------------------------------------------- text

def _grasp(body=0, closure=True):
    contacts = [SimpleNamespace(finger=0, state=1, friction_use=0.25),
                SimpleNamespace(finger=1, state=2, friction_use=1.0)]
    return SimpleNamespace(body=body, contacts=contacts, force_closure=closure, epsilon=0.1234,
                           resisted_force=0.617, grip_force=5.0, load_force=1.962, grip_ratio=5.0 / 1.962,
                           min_slip_margin=0.0, min_slip_finger=1 if closure else -1)


def test_grasp_lines_lead_with_closure_and_name_the_finger_closest_to_slip():
    lines = grasp_display.grasp_lines([_grasp()], ["Box"], ["Thumb", "Index Tip"])
    assert [x.replace(grasp_display.NBSP, " ") for x in lines] == [
        "Box: slipping; Index Tip slips first (100% of its friction)",
        "Box: closure yes  ε 0.123  resists 0.62 N",
        "  grip 5.00 N / load 1.96 N = 2.5×",
        "  slip margin 0.00 N at Index Tip",
        "  Thumb stick 25%   Index Tip slip 100%"]
    # Wrapped narrow, a value stays with its unit and a finger's entry stays whole.
    narrow = grasp_display.wrap(lines, 14)
    assert "0.62\u00a0N" in " ".join(narrow) and any(x.strip() == "Index\u00a0Tip\u00a0slip\u00a0100%"
                                                        for x in narrow), narrow
    open_ = grasp_display.grasp_lines([_grasp(closure=False)], ["Box"], ["Thumb", "Index"])
    assert open_[1].startswith("Box: closure no") and not any("slip margin" in x for x in open_)
    weightless = _grasp()
    weightless.grip_ratio = math.inf
    assert grasp_display.grasp_lines([weightless], ["Box"], ["T", "I"])[2].endswith("= ∞")
    assert grasp_display.grasp_lines([], ["Box"], ["T"]) == ["No finger on a body"]


def _contacts(*uses_states):
    return [SimpleNamespace(finger=k, state=state, friction_use=use) for k, (use, state) in enumerate(uses_states)]


def test_verdict_says_in_words_whether_held_how_firmly_and_who_slips_first():
    names = ["Thumb", "Index"]

    def words(contacts, closure=True, ratio=3.0):
        g = SimpleNamespace(body=0, contacts=contacts, force_closure=closure, grip_ratio=ratio)
        return grasp_display.verdict(g, "Pencil", names).replace(grasp_display.NBSP, " ")
    # in closure, every contact under half its friction: firmly; the larger use slips first
    assert words(_contacts((0.2, 1), (0.4, 1))) == "Pencil: held firmly; Index slips first (40% of its friction)"
    # in closure but one contact at 60 %: held, not firmly
    assert words(_contacts((0.6, 1), (0.1, 1))).startswith("Pencil: held; Thumb slips first (60%")
    # a two-finger pinch out of closure (free to turn about the line of its fingertips)
    assert words(_contacts((0.2, 1), (0.3, 1)), closure=False).startswith(
        "Pencil: held, but free to turn (not in force closure); Index")
    # close to the cone: barely; sliding: slipping; grip under the load: not held
    assert words(_contacts((0.85, 1), (0.1, 1))).startswith("Pencil: held, barely; Thumb")
    assert words(_contacts((0.3, 1), (1.0, 2))).startswith("Pencil: slipping; Index")
    assert words(_contacts((0.3, 1), (0.3, 1)), ratio=0.4).startswith("Pencil: not held (grip below load)")
    assert words(_contacts((0.3, 1), (0.3, 1)), ratio=math.nan).startswith("Pencil: not held")
    # squeezed with no load to carry (a body resting on a table): nobody to name
    assert words(_contacts((0.0, 1), (0.005, 1))) == "Pencil: held firmly; no finger near slipping"
    # a contact with no normal force (use not a number) is the first to slip
    assert words(_contacts((0.3, 1), (math.nan, 1))) == "Pencil: held, barely; Index slips first (— of its friction)"


def test_verdict_lines_one_per_touched_body_before_the_numbers():
    a, b = _grasp(body=0), _grasp(body=1)
    lines = grasp_display.grasp_lines([a, b], ["Box", "Lid"], ["T", "I"])
    assert lines[0].startswith("Box: slipping") and lines[1].startswith("Lid: slipping")
    assert lines[2].startswith("Box: closure yes") and grasp_display.verdict_lines([], [], []) == ["No finger on a body"]


def test_a_baked_frame_gets_the_same_verdict():
    bodies = [("Pencil", 1.0, 1.0, 45.0), ("Cup", 0.0, 0.0, 0.0)]       # the cup is not held
    fingers = [("Thumb", 1.0, 0.2), ("Index", 1.0, 0.45), ("Middle", 0.0, 0.0)]
    assert [x.replace(grasp_display.NBSP, " ") for x in grasp_display.baked_verdict_lines(bodies, fingers)] == [
        "Pencil: held firmly; Index slips first (45% of its friction)"]
    fingers[1] = ("Index", 2.0, 1.0)                                       # sliding at that frame
    assert grasp_display.baked_verdict_lines(bodies, fingers)[0].startswith("Pencil: slipping; Index")
    assert grasp_display.baked_verdict_lines([("Pencil", 0.0, 0.0, 0.0)], fingers) == ["No finger on a body"]
    # friction use keyed -1 (not bounded: no normal force) is the first to slip
    line = grasp_display.baked_verdict_lines(bodies, [("Thumb", 1.0, 0.1), ("Index", 1.0, -1.0)])[0]
    assert line.startswith("Pencil: held, barely; Index")


def test_force_output_is_one_statement_of_what_reaches_the_hand():
    assert grasp_display.force_output(True) == "forces on"
    assert grasp_display.force_output(True, [False, True]) == "forces on"
    assert grasp_display.force_output(True, [False]) == "forces off (no device enabled)"
    assert grasp_display.force_output(False, [True]).startswith("forces held at zero")


def test_wrap_breaks_at_words_within_the_width():
    lines = ["Box: closure yes  ε 0.123  resists 0.62 N", "  Thumb stick 25%   Index slip 100%   Middle free"]
    for width in (14, 20, 33, 200):
        out = grasp_display.wrap(lines, width)
        assert all(len(x) <= width for x in out)
        assert " ".join(out).split() == " ".join(lines).split()        # no word cut or lost
    # A word longer than the width stays whole on its own line rather than being cut.
    assert grasp_display.wrap(["ab Fingertip_of_the_thumb cd"], 12) == ["ab", "  Fingertip_of_the_thumb", "  cd"]
    # Measured in pixels by a font's measure (here 5 px a character, 9 for "W").
    px = lambda t: 5 * len(t) + 4 * t.count("W")  # noqa: E731
    assert grasp_display.wrap(["WWW aaa bbb"], 38, px) == ["WWW", "  aaa", "  bbb"]
    assert grasp_display.wrap(["WWW aaa bbb"], 38, lambda t: 5 * len(t)) == ["WWW aaa", "  bbb"]
    out = grasp_display.wrap(lines, 20)
    assert [x for x in out if "Index" in x][0].startswith("    ")     # continuations indented


# ---------------------------------------------------------------- weakest wrench geometry

def test_weakest_geometry_arrow_along_the_force_ring_about_the_torque():
    w = np.array([0.0, 0.6, 0.0, 0.0, 0.0, 0.8])                      # unit 6-vector
    g = SimpleNamespace(force_closure=True, weakest=w, center=np.array([1.0, 2.0, 3.0]), radius=0.05)
    geo = grasp_display.weakest_geometry(g)
    start, end = geo["arrow"]
    np.testing.assert_allclose(start, [1, 2, 3])
    np.testing.assert_allclose(end - start, [0, 2 * 0.05 * 0.6, 0])   # twice the radius per unit
    ring = geo["ring"] - g.center
    np.testing.assert_allclose(np.linalg.norm(ring, axis=1), 0.05 * 0.8)   # lever arm of the torque
    np.testing.assert_allclose(ring[:, 2], 0.0, atol=1e-15)           # in the plane normal to the axis
    np.testing.assert_allclose(ring[0], ring[-1])                      # closed
    tip, tangent = geo["ring_tip"]
    turn = np.cross(tip - g.center, tangent)
    assert turn[2] > 0 and abs(turn[0]) < 1e-12                        # right hand about +z
    # the viewport's way: around the body, not over it, at the user's scale
    geo = grasp_display.weakest_geometry(g, scale=0.5, outside=True)
    start, end = geo["arrow"]
    np.testing.assert_allclose(start, [1, 2 + 0.05, 3])                # on the bounding sphere
    np.testing.assert_allclose(end - start, [0, 0.5 * 2 * 0.05 * 0.6, 0])
    np.testing.assert_allclose(np.linalg.norm(geo["ring"] - g.center, axis=1), 0.05 + 0.5 * 0.05 * 0.8)
    g.weakest = np.array([0.0, 0, 1, 0, 0, 0])
    assert grasp_display.weakest_geometry(g)["ring"] is None           # no torque part
    g.force_closure = False
    assert grasp_display.weakest_geometry(g) is None                   # not in closure: nothing


# ---------------------------------------------------------------- a real pinch

def _core():
    try:
        import graspcore
    except ImportError as ex:
        if os.environ.get("GRASP_LAB_REQUIRE_CORE"):
            raise
        pytest.skip(f"graspcore not available: {ex}")
    return graspcore


def test_monitor_on_a_held_box_gives_the_contacts_the_core_reports():
    """A 100 g box pinched between two fingers at rest: one held body, both fingers in
    contact with inward normals +x/-x, normal forces the springs' components along them, and
    a load of m g (the box does not accelerate)."""
    import trimesh
    gc = _core()
    m = trimesh.creation.box((0.05, 0.05, 0.05))
    body = scene.BodyDesc("Box", False, [np.array(m.vertices)],
                          [scene.MeshData(np.array(m.vertices), np.array(m.faces))], np.zeros(3),
                          np.array([1.0, 0, 0, 0]), mass=0.1)
    desc = scene.prepare(scene.SceneDesc(bodies=[body], fingers=[
        scene.FingerDesc("F0", np.array([-0.030, 0, 0])), scene.FingerDesc("F1", np.array([0.030, 0, 0]))]))
    h = scene.build_world(desc, gc)
    r = runner.SessionRunner(h, inputs.StaticInput([[-0.022, 0, 0], [0.022, 0, 0]]))
    monitor = grasp_display.GraspMonitor(analysis.body_models(desc), [f.radius for f in desc.fingers])
    for k in range(1, 31):
        r.advance_to(0.02 * k)
        grasps = monitor.update(r.snapshot())
    snap = r.snapshot()
    np.testing.assert_allclose(snap.normals, [[-1, 0, 0], [1, 0, 0]], atol=1e-9)   # out of the box
    assert len(grasps) == 1 and grasps[0].body == 0
    g = grasps[0]
    assert sorted(c.finger for c in g.contacts) == [0, 1]
    for c in g.contacts:
        np.testing.assert_allclose(c.normal, -snap.normals[c.finger], atol=1e-9)  # inward
        assert c.fn == pytest.approx(abs(snap.spring_forces[c.finger][0]), rel=1e-9)
    assert g.load_force == pytest.approx(0.1 * 9.81, rel=0.02)
    assert g.grip_force == pytest.approx(sum(c.fn for c in g.contacts), rel=1e-12)
    assert len(monitor.costs) == 30 and monitor.error == ""


def test_the_update_times_kept_are_bounded(monkeypatch):
    """A session of any length keeps at most COSTS_KEPT update times, the latest ones."""
    monkeypatch.setattr(grasp_display, "COSTS_KEPT", 4)
    monitor = grasp_display.GraspMonitor([], [])
    snap = type("Snap", (), {"time": 0.0, "contacts": np.full(0, -1)})()
    for k in range(10):
        snap.time = 0.01 * k
        monitor.update(snap)
    assert len(monitor.costs) == 4
