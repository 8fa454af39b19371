"""The bpy-free half of the extension (addon/engine), tested in plain Python."""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from addon.engine import decompose, inputs, runner, scene  # noqa: E402


class FakeWorld:
    """Records what the runner asks of the core."""

    def __init__(self, n_fingers=2, threaded=False):
        self.hips_log = []
        self.dts = []
        self.n = n_fingers
        self.body_poses = np.array([[0, 0, 0, 1, 0, 0, 0]], dtype=float)
        if threaded:
            self.start = lambda haptic_rate: setattr(self, "started", haptic_rate)

    def set_hips(self, hips):
        self.hips_log.append(np.array(hips))

    def step(self, dt):
        self.dts.append(dt)

    def snapshot(self):
        """The stopped world's snapshot, as graspcore.World.snapshot lays it out."""
        gos = np.array(self.hips_log[-1], dtype=float) if self.hips_log else np.zeros((self.n, 3))
        return {"poses": self.body_poses, "residual_forces": np.array([[0, 0, -1.0]]),
                "residual_torques": np.zeros((1, 3)), "god_objects": gos, "spring_forces": np.zeros((self.n, 3)),
                "finger_states": np.zeros(self.n, np.int32), "contact_bodies": np.full(self.n, -1, np.int32),
                "normals": np.zeros((self.n, 3)), "linear_velocities": np.zeros((1, 3)),
                "angular_velocities": np.zeros((1, 3)), "patches": np.zeros((self.n, 4, 2), np.float32)}


def _handle(world, n_fingers=2):
    box = scene.BodyDesc("B", False, [np.eye(3)], [], np.zeros(3), np.array([1, 0, 0, 0.]))
    box.mass_properties = scene.MassProperties(1.0, 1.0, np.zeros(3), np.eye(3))
    desc = scene.SceneDesc(bodies=[box], fingers=[scene.FingerDesc(f"F{i}", np.zeros(3))
                                                  for i in range(n_fingers)])
    return scene.WorldHandle(world, [0], list(range(n_fingers)), desc)


def test_sampled_trajectory_interpolates_and_holds():
    src = inputs.SampledTrajectory([0.0, 1.0, 2.0],
                                   np.array([[[0, 0, 0]], [[1, 0, 0]], [[1, 2, 0]]], dtype=float))
    np.testing.assert_allclose(src.hips_at(0.25), [[0.25, 0, 0]])
    np.testing.assert_allclose(src.hips_at(1.5), [[1, 1, 0]])
    np.testing.assert_allclose(src.hips_at(5.0), [[1, 2, 0]])
    np.testing.assert_allclose(src.hips_at(-1.0), [[0, 0, 0]])
    assert src.duration == 2.0


@pytest.mark.parametrize("times, pos, word", [
    ([0.0, 0.0], np.zeros((2, 1, 3)), "increasing"),
    ([0.0, 1.0], np.zeros((3, 1, 3)), "positions"),
    ([0.0, 1.0], np.full((2, 1, 3), np.nan), "non-finite"),
])
def test_sampled_trajectory_rejects_bad_input(times, pos, word):
    with pytest.raises(ValueError, match=word):
        inputs.SampledTrajectory(times, pos)


def test_runner_substeps_at_haptic_rate_with_end_of_step_hips():
    w = FakeWorld()
    src = inputs.CallableInput(2, lambda t: [[t, 0, 0], [0, t, 0]])
    r = runner.SessionRunner(_handle(w), src, haptic_rate=1000.0)
    assert r.advance_to(1 / 24) == 41
    assert r.advance_to(2 / 24) == 42
    assert len(w.dts) == 83 and all(dt == 1e-3 for dt in w.dts)
    np.testing.assert_allclose(w.hips_log[0][0], [1e-3, 0, 0])
    np.testing.assert_allclose(w.hips_log[-1][1], [0, 83e-3, 0])
    snap = r.snapshot()
    assert snap.poses.shape == (1, 7) and snap.n_contacts == 0
    np.testing.assert_allclose(snap.force, [[0, 0, -1]])


def test_runner_falls_behind_within_its_wall_time_budget_then_catches_up():
    w = FakeWorld()
    r = runner.SessionRunner(_handle(w), inputs.StaticInput(np.zeros((2, 3))), haptic_rate=1000.0)
    assert r.advance_to(1.0, budget=0.0) == 8        # the budget is checked every 8 steps
    assert r.lag == pytest.approx(0.992) and r.time == pytest.approx(0.008)
    assert r.advance_to(1.0, budget=10.0) == 992     # a generous budget: back on time
    assert r.lag == 0.0 and r.time == pytest.approx(1.0)


def test_runner_checks_finger_count():
    with pytest.raises(ValueError, match="3 fingertips"):
        runner.SessionRunner(_handle(FakeWorld()), inputs.StaticInput(np.zeros((3, 3))))


def test_quat_rotate():
    q = np.array([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)])      # 90 deg about z
    np.testing.assert_allclose(runner.quat_rotate(q, [1, 0, 0]), [0, 1, 0], atol=1e-12)


def _core():
    try:
        import graspcore
    except ImportError as ex:        # not built, or mid-rebuild
        pytest.skip(f"graspcore not importable: {ex}")
    return graspcore


def _box_mesh(ext=(0.04, 0.06, 0.1), name="box"):
    import trimesh
    b = trimesh.creation.box(ext)
    return scene.MeshData(np.array(b.vertices), np.array(b.faces), source=name), b


def test_mass_properties_box_and_offset_compound():
    import trimesh
    m1, ref = _box_mesh()
    mp = scene.mass_properties("b", [m1], mass=None, density=500.0)
    ref.density = 500.0
    assert mp.mass == pytest.approx(ref.mass)
    np.testing.assert_allclose(mp.inertia, ref.moment_inertia, rtol=1e-9)
    a = trimesh.creation.box((0.02,) * 3).apply_translation((0.05, 0, 0))
    b = trimesh.creation.box((0.02,) * 3).apply_translation((-0.01, 0.02, 0))
    meshes = [scene.MeshData(np.array(x.vertices), np.array(x.faces), "p") for x in (a, b)]
    mp = scene.mass_properties("c", meshes, mass=2.0, density=1.0)
    both = trimesh.util.concatenate([a, b])
    both.density = 2.0 / both.volume
    np.testing.assert_allclose(mp.center_of_mass, both.center_mass, atol=1e-12)
    np.testing.assert_allclose(mp.inertia, both.moment_inertia, rtol=1e-9, atol=1e-15)


def test_scene_errors_name_object_and_problem():
    m, _ = _box_mesh(name="Cup")
    inv = scene.MeshData(m.vertices, m.triangles[:, ::-1], "Cup")
    with pytest.raises(scene.SceneError, match='"Cup": mesh is inverted'):
        scene.mass_properties("Cup", [inv], None, 1000.0)
    opened = scene.MeshData(m.vertices, m.triangles[2:], "Cup")
    with pytest.raises(scene.SceneError, match='"Cup": mesh is open'):
        scene.mass_properties("Cup", [opened], None, 1000.0)
    with pytest.raises(scene.SceneError, match="absurd scale"):
        scene.check_scale("Cup", m.vertices * 1e4)
    with pytest.raises(scene.SceneError, match="zero volume"):
        scene.check_hull_points("Cup", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]]))
    with pytest.raises(scene.SceneError, match="mass must be > 0"):
        scene.mass_properties("Cup", [m], 0.0, 1000.0)


def test_decompose_box_islands_and_ring():
    import trimesh
    box = trimesh.creation.box((1, 1, 1))
    assert len(decompose.decompose(box.vertices, box.faces)) == 1
    two = trimesh.util.concatenate([box, box.copy().apply_translation((3, 0, 0))])
    assert len(decompose.decompose(two.vertices, two.faces)) == 2
    ring = trimesh.creation.annulus(r_min=0.5, r_max=1.0, height=0.3, sections=32)
    parts = decompose.decompose(ring.vertices, ring.faces)
    assert 4 <= len(parts) <= 64
    for p in parts:                      # no part bridges the hole
        assert np.linalg.norm(p.mean(axis=0)[:2]) > 0.4
    # Together the parts cover the ring's vertices.
    allp = np.vstack(parts)
    for v in ring.vertices[::7]:
        assert np.min(np.linalg.norm(allp - v, axis=1)) < 1e-9


def test_build_world_with_core():
    gc = _core()
    m, ref = _box_mesh((0.05, 0.05, 0.05))
    body = scene.BodyDesc("Box", False, [m.vertices], [m], np.zeros(3), np.array([1.0, 0, 0, 0]),
                          mass=0.1)
    desc = scene.prepare(scene.SceneDesc(bodies=[body], fingers=[
        scene.FingerDesc("F0", np.array([-0.030, 0, 0])), scene.FingerDesc("F1", np.array([0.030, 0, 0]))]))
    h = scene.build_world(desc, gc)
    mass, com, inertia = h.world.body_mass(h.body_ids[0])
    assert mass == pytest.approx(0.1)
    ref.density = 0.1 / ref.volume
    np.testing.assert_allclose(np.array(inertia).reshape(3, 3), ref.moment_inertia, rtol=1e-9)
    r = runner.SessionRunner(h, inputs.StaticInput([[-0.030, 0, 0], [0.030, 0, 0]]))
    r.advance_to(0.2)
    snap = r.snapshot()
    assert snap.n_contacts == 2
    assert abs(snap.poses[0, 2]) < 0.002        # held against gravity


def test_build_world_reports_core_rejection():
    gc = _core()
    body = scene.BodyDesc("Needle", True, [np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])],
                          [], np.zeros(3), np.array([1.0, 0, 0, 0]))
    with pytest.raises(scene.SceneError, match='"Needle": rejected by the core'):
        scene.build_world(scene.SceneDesc(bodies=[body]), gc)


def test_reduce_hull_points_keeps_the_hull():
    import trimesh
    s = trimesh.creation.icosphere(subdivisions=6, radius=0.05)     # 40962 vertices
    p = np.array(s.vertices)
    q = scene.reduce_hull_points(p, 1024)
    assert len(q) <= 1024
    assert set(map(tuple, q)) <= set(map(tuple, p))
    # The reduced hull supports every direction within 0.2 % of the size.
    d = scene._sphere_directions(4000)
    gap = (p @ d.T).max(axis=0) - (q @ d.T).max(axis=0)
    assert gap.max() < 2e-4          # 0.2 % of the 10 cm diameter
    small = p[:100]
    assert scene.reduce_hull_points(small) is small


def test_runtime_driver_hands_the_script_over_whole_and_pushes_only_live_fingers(core):
    """Two fingers: one animated (its track goes to the core once), one the user moves
    (pushed at every call with its time stamp). The haptic loop, not the caller, samples
    the track: after 250 manual ticks finger 0 is where the track is at 0.25 s."""
    w = core.World()
    w.add_finger(position=(0.0, 0.0, 0.0))
    w.add_finger(position=(1.0, 0.0, 0.0))
    handle = scene.WorldHandle(world=w, desc=scene.SceneDesc(fingers=[scene.FingerDesc("a", (0, 0, 0)),
                                                                       scene.FingerDesc("b", (1, 0, 0))]),
                               body_ids=[], finger_ids=[0, 1])
    times = np.array([0.0, 1.0])
    pos = np.array([[[0, 0, 0], [1, 0, 0]], [[0, 0, 1.0], [1, 0, 0]]])
    src = inputs.TimelineInput(inputs.SampledTrajectory(times, pos), scripted=[True, False])
    assert src.interactive and src.duration == 1.0
    r = runner.SessionRunner(handle, src, haptic_rate=1000.0, use_runtime=True,
                             runtime_options={"realtime": False})
    src.set_live([[9, 9, 9], [1.0, 0.5, 0.0]])      # the user dragged finger b; a is scripted
    assert r.advance_to(0.0) == 0 and r.threaded
    w.advance(250)
    snap = r.snapshot()
    np.testing.assert_allclose(snap.hips, [[0, 0, 0.25], [1.0, 0.5, 0.0]], atol=1e-12)
    assert r.time == pytest.approx(0.25)
    assert r.stats()["steps"] == 250
    r.stop()
    assert not w.running and r.stats()["steps"] == 250   # the last run's numbers stay


def test_timeline_input_with_nothing_animated_is_open_ended():
    track = inputs.SampledTrajectory([0.0, 1.0], np.zeros((2, 2, 3)))
    src = inputs.TimelineInput(track, scripted=[False, False])
    assert src.script() is None and src.duration is None and src.interactive
    with pytest.raises(ValueError, match="non-finite"):
        src.set_live([[np.nan, 0, 0], [0, 0, 0]])


def test_convex_finger_desc_builds_a_convex_finger_and_round_trips_in_recordings():
    """A FingerDesc with points (a Finger-role mesh) becomes a convex finger of their hull, reduced
    to the core's 32 vertices; the recorded scene keeps its points and orientation, and a
    sphere finger's entry is unchanged (older recordings read as spheres)."""
    import graspcore
    from addon.engine import recording
    ring = np.array([[0.04 * np.cos(a), 0.04 * np.sin(a), z]
                     for a in np.linspace(0, 2 * np.pi, 40, endpoint=False) for z in (-0.01, 0.01)])
    s = np.sin(0.1)
    palm = scene.FingerDesc("Palm", np.array([0.0, 0.0, -0.01]), points=ring,
                            orientation=np.array([2 * np.cos(0.1), 2 * s, 0, 0]))
    tip = scene.FingerDesc("Tip", np.array([0.1, 0.0, 0.0]))
    desc = scene.prepare(scene.SceneDesc(fingers=[palm, tip]))
    assert len(desc.fingers[0].points) <= scene.FINGER_MAX_POINTS
    np.testing.assert_allclose(desc.fingers[0].orientation, [np.cos(0.1), s, 0, 0])
    handle = scene.build_world(desc, graspcore)
    w = handle.world
    np.testing.assert_allclose(w.finger_pose(0)[1], [np.cos(0.1), s, 0, 0])
    assert w.finger_pose(1)[1] == (1, 0, 0, 0)

    data = recording.scene_to_dict(desc)
    assert set(data["fingers"][1]) == {"name", "position", "radius", "stiffness", "damping", "channel",
                                       "renderer", "cursor_mass"}                  # a sphere: no points
    assert data["fingers"][0]["renderer"] == "xfca"
    back = recording.scene_from_dict(data)
    np.testing.assert_array_equal(back.fingers[0].points, desc.fingers[0].points)
    np.testing.assert_array_equal(back.fingers[0].orientation, desc.fingers[0].orientation)
    assert back.fingers[1].points is None
    assert recording.scene_to_dict(back) == data


@pytest.mark.parametrize("points, problem", [
    (np.array([[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0], [0.05, 0.05, 0]]), "zero volume"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.inf]]), "non-finite"),
])
def test_bad_convex_finger_desc_names_the_finger(points, problem):
    with pytest.raises(scene.SceneError, match=f'"Palm": .*{problem}'):
        scene.prepare(scene.SceneDesc(fingers=[scene.FingerDesc("Palm", np.zeros(3), points=points)]))


def test_convex_finger_with_the_cursor_renderer_is_refused_naming_it():
    """The light-mass cursor renders sphere fingers; a Finger-role mesh is rendered by its
    god-objects (docs/physics.md "Renderers and finger shapes"), and a sphere keeps the cursor."""
    pad = np.array([[x, y, z] for x in (-0.01, 0.01) for y in (-0.01, 0.01) for z in (-0.002, 0.002)])
    with pytest.raises(scene.SceneError, match='"Pad": .*cursor'):
        scene.prepare(scene.SceneDesc(fingers=[scene.FingerDesc("Pad", np.zeros(3), points=pad, renderer="cursor")]))
    desc = scene.prepare(scene.SceneDesc(fingers=[scene.FingerDesc("Pad", np.zeros(3), points=pad),
                                                  scene.FingerDesc("Tip", np.ones(3), renderer="cursor")]))
    assert [f.renderer for f in desc.fingers] == ["xfca", "cursor"]
