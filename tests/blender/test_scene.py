"""Scene -> World conversion: scale & parenting, mass properties vs trimesh, bad meshes."""
import math

import numpy as np
import pytest

import grasp_env



def _describe(bpy):
    convert = grasp_env.submodule("convert")
    scene = grasp_env.submodule("engine.scene")
    bpy.context.view_layer.update()
    desc, links, fingers = convert.scene_description(bpy.context)
    scene.prepare(desc)
    return desc, links, fingers


def _world_trimesh(obj):
    """trimesh of the object's mesh in its rigid frame (scale/parenting applied), computed
    independently from the add-on's own conversion."""
    import trimesh
    me = obj.data
    me.calc_loop_triangles()
    v = np.array([tuple(obj.matrix_world @ vv.co) for vv in me.vertices])
    t = np.array([tuple(lt.vertices) for lt in me.loop_triangles])
    q = obj.matrix_world.to_quaternion()
    r = np.array(q.to_matrix())
    local = (v - np.array(obj.matrix_world.translation)) @ r
    return trimesh.Trimesh(local, t, process=True)


def test_box_scaled_and_parented_mass_properties(bpy):
    import trimesh
    parent = bpy.data.objects.new("Holder", None)
    bpy.context.scene.collection.objects.link(parent)
    parent.scale = (2.0, 2.0, 2.0)
    parent.rotation_euler = (0.3, 0.0, 0.5)
    parent.location = (0.1, 0.2, 0.3)
    box = grasp_env.add_cube(bpy, "Brick", size=1.0, location=(0.01, 0.0, 0.0))
    box.scale = (0.02, 0.03, 0.05)            # world size 0.04 x 0.06 x 0.10 m
    box.rotation_euler = (0.0, 0.2, 0.0)
    box.parent = parent
    box.grasp_lab.role = "DYNAMIC"
    box.grasp_lab.mass_mode = "DENSITY"
    box.grasp_lab.density = 700.0
    desc, links, _ = _describe(bpy)
    b = desc.bodies[0]
    mp = b.mass_properties
    ref = trimesh.creation.box((0.04, 0.06, 0.10))
    ref.density = 700.0
    assert mp.mass == pytest.approx(ref.mass, rel=1e-5)
    assert mp.volume == pytest.approx(0.04 * 0.06 * 0.10, rel=1e-5)
    np.testing.assert_allclose(mp.center_of_mass, 0.0, atol=1e-7)
    np.testing.assert_allclose(mp.inertia, ref.moment_inertia, rtol=1e-4, atol=1e-9)
    # Body frame = world pose of the object without scale.
    np.testing.assert_allclose(b.position, np.array(box.matrix_world.translation), atol=1e-6)
    # Write-back: the rigid pose reproduces the original world matrix (scale kept).
    m = links[0].matrix_world(b.position, b.orientation)
    np.testing.assert_allclose(np.array(m), np.array(box.matrix_world), atol=1e-6)


@pytest.mark.parametrize("kind", ["uv_sphere", "cylinder", "torus"])
def test_sample_meshes_match_trimesh(bpy, kind):
    import bmesh
    me = bpy.data.meshes.new(kind)
    bm = bmesh.new()
    if kind == "uv_sphere":
        bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=0.03)
    elif kind == "cylinder":
        bmesh.ops.create_cone(bm, cap_ends=True, segments=24, radius1=0.02, radius2=0.02, depth=0.1)
    bm.to_mesh(me)
    bm.free()
    if kind == "torus":
        bpy.ops.mesh.primitive_torus_add(major_radius=0.05, minor_radius=0.015)
        obj = bpy.context.active_object
        obj.name = kind
    else:
        obj = bpy.data.objects.new(kind, me)
        bpy.context.scene.collection.objects.link(obj)
    obj.location = (0.2, -0.1, 0.05)
    obj.rotation_euler = (0.4, 0.1, -0.7)
    obj.scale = (1.0, 1.5, 0.8)
    obj.grasp_lab.role = "DYNAMIC"
    obj.grasp_lab.mass_mode = "MASS"
    obj.grasp_lab.mass = 0.25
    desc, _, _ = _describe(bpy)
    mp = desc.bodies[0].mass_properties
    ref = _world_trimesh(obj)
    ref.density = 0.25 / ref.volume
    assert mp.mass == pytest.approx(0.25)
    assert mp.volume == pytest.approx(ref.volume, rel=1e-5)
    np.testing.assert_allclose(mp.center_of_mass, ref.center_mass, atol=1e-6)
    np.testing.assert_allclose(mp.inertia, ref.moment_inertia, rtol=1e-4, atol=1e-10)


def test_child_parts_compound(bpy):
    import trimesh
    root = bpy.data.objects.new("Dumbbell", None)
    bpy.context.scene.collection.objects.link(root)
    a = grasp_env.add_cube(bpy, "Weight A", size=0.04, location=(-0.05, 0, 0))
    b = grasp_env.add_cube(bpy, "Weight B", size=0.04, location=(0.05, 0, 0))
    for c in (a, b):
        c.parent = root
    root.grasp_lab.role = "DYNAMIC"
    root.grasp_lab.shape = "CHILDREN"
    root.grasp_lab.mass_mode = "DENSITY"
    root.grasp_lab.density = 1000.0
    desc, _, _ = _describe(bpy)
    body = desc.bodies[0]
    assert len(body.parts) == 2
    mp = body.mass_properties
    ref = trimesh.util.concatenate([trimesh.creation.box((0.04,) * 3).apply_translation(p)
                                    for p in ((-0.05, 0, 0), (0.05, 0, 0))])
    ref.density = 1000.0
    assert mp.mass == pytest.approx(ref.mass, rel=1e-6)
    np.testing.assert_allclose(mp.inertia, ref.moment_inertia, rtol=1e-5, atol=1e-12)


def test_automatic_decomposition_of_a_ring(bpy):
    bpy.ops.mesh.primitive_torus_add(major_radius=0.05, minor_radius=0.012)
    ring = bpy.context.active_object
    ring.grasp_lab.role = "DYNAMIC"
    ring.grasp_lab.shape = "AUTO"
    desc, _, _ = _describe(bpy)
    parts = desc.bodies[0].parts
    assert 4 <= len(parts) <= 64
    # No part may cover the hole in the middle.
    for p in parts:
        centre = p.mean(axis=0)
        assert np.linalg.norm(centre[:2]) > 0.02


def test_fingers_ordered_by_channel(bpy):
    for i, ch in enumerate((2, 0, 1)):
        f = bpy.data.objects.new(f"F{i}", None)
        bpy.context.scene.collection.objects.link(f)
        f.location = (i * 0.1, 0, 0)
        f.grasp_lab.role = "FINGER"
        f.grasp_lab.channel = ch
    desc, _, _ = _describe(bpy)
    assert [f.name for f in desc.fingers] == ["F1", "F2", "F0"]
    assert desc.fingers[0].position[0] == pytest.approx(0.1)


# --------------------------------------------------------------------------- bad meshes

def _bad(bpy, make):
    obj = make(bpy)
    obj.grasp_lab.role = "DYNAMIC"
    scene = grasp_env.submodule("engine.scene")
    with pytest.raises(scene.SceneError) as info:
        _describe(bpy)
    assert info.value.obj_name == obj.name
    assert obj.name in str(info.value)
    return str(info.value)


def _open_box(bpy):
    import bmesh
    obj = grasp_env.add_cube(bpy, "Open Box", size=0.05)
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    bm.faces.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[bm.faces[0]], context="FACES_ONLY")
    bm.to_mesh(obj.data)
    bm.free()
    return obj


def _flat(bpy):
    obj = grasp_env.add_cube(bpy, "Flat Box", size=0.05)
    obj.scale = (1.0, 1.0, 0.0)
    return obj


def _inverted(bpy):
    import bmesh
    obj = grasp_env.add_cube(bpy, "Inside Out", size=0.05)
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    bmesh.ops.reverse_faces(bm, faces=bm.faces)
    bm.to_mesh(obj.data)
    bm.free()
    return obj


def _huge(bpy):
    return grasp_env.add_cube(bpy, "Huge Box", size=500.0)


def _tiny(bpy):
    return grasp_env.add_cube(bpy, "Tiny Box", size=1e-6)


def _plane(bpy):
    me = bpy.data.meshes.new("Sheet")
    me.from_pydata([(0, 0, 0), (0.1, 0, 0), (0.1, 0.1, 0), (0, 0.1, 0)], [], [(0, 1, 2, 3)])
    obj = bpy.data.objects.new("Sheet", me)
    bpy.context.scene.collection.objects.link(obj)
    return obj


@pytest.mark.multiversion
def test_open_mesh_refused(bpy):
    msg = _bad(bpy, _open_box)
    assert "open" in msg and "boundary edges" in msg


def test_flat_mesh_refused(bpy):
    assert "zero volume" in _bad(bpy, _flat)


def test_plane_refused(bpy):
    assert "zero volume" in _bad(bpy, _plane)


def test_inverted_mesh_refused(bpy):
    assert "inverted" in _bad(bpy, _inverted)


@pytest.mark.parametrize("make", [_huge, _tiny])
def test_absurd_scale_refused(bpy, make):
    assert "absurd scale" in _bad(bpy, make)


def test_mirrored_object_is_not_inverted(bpy):
    obj = grasp_env.add_cube(bpy, "Mirrored", size=0.05)
    obj.scale = (-1.0, 1.0, 1.0)
    obj.grasp_lab.role = "DYNAMIC"
    desc, _, _ = _describe(bpy)
    assert desc.bodies[0].mass_properties.volume == pytest.approx(0.05 ** 3, rel=1e-5)


def test_non_mesh_body_refused(bpy):
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    bpy.context.scene.collection.objects.link(cam)
    cam.grasp_lab.role = "DYNAMIC"
    scene = grasp_env.submodule("engine.scene")
    with pytest.raises(scene.SceneError, match='"Cam": a body must be a mesh object'):
        _describe(bpy)


def test_bad_friction_refused(bpy):
    obj = grasp_env.add_cube(bpy, "Slippery", size=0.05)
    obj.grasp_lab.role = "DYNAMIC"
    obj.grasp_lab.mu_s, obj.grasp_lab.mu_d = 0.3, 0.5
    scene = grasp_env.submodule("engine.scene")
    with pytest.raises(scene.SceneError, match="mu_d <= mu_s"):
        _describe(bpy)


@pytest.mark.multiversion
def test_operator_reports_bad_mesh(bpy, core):
    _inverted(bpy).grasp_lab.role = "DYNAMIC"
    with pytest.raises(RuntimeError, match='"Inside Out": mesh is inverted'):
        bpy.ops.grasp_lab.session()
    with pytest.raises(RuntimeError, match='"Inside Out"'):
        bpy.ops.grasp_lab.validate_scene()


def test_validate_operator_ok(bpy):
    grasp_env.add_cube(bpy, "Good", size=0.05).grasp_lab.role = "DYNAMIC"
    assert bpy.ops.grasp_lab.validate_scene() == {"FINISHED"}


def test_large_mesh_conversion(bpy):
    # A ~100k-triangle sphere converts to one body whose volume is the mesh's own (its speed
    # is benchmarked in bench/bench_blender.py, not timed here).
    import trimesh
    bpy.ops.mesh.primitive_uv_sphere_add(segments=320, ring_count=160, radius=0.05)
    obj = bpy.context.active_object
    obj.grasp_lab.role = "DYNAMIC"
    assert len(obj.data.polygons) * 2 > 100_000 - 1000
    desc, _, _ = _describe(bpy)
    reference = _world_trimesh(obj)
    assert isinstance(reference, trimesh.Trimesh) and reference.is_volume
    assert desc.bodies[0].mass_properties.volume == pytest.approx(reference.volume, rel=1e-6)
    assert reference.volume < 4 / 3 * math.pi * 0.05 ** 3


def test_finger_role_mesh_is_a_convex_finger_of_its_hull(bpy, core):
    """A Finger-role mesh (a scaled, tilted cube: a palm) is a convex finger whose points are its
    corners in its rigid frame, turned as the object is; an Empty stays a sphere of Radius. A plate
    dropped on the palm rests level on it."""
    from mathutils import Quaternion
    scene = grasp_env.submodule("engine.scene")
    palm = grasp_env.add_cube(bpy, "Palm", size=2.0, location=(0.0, 0.0, -0.01))
    palm.scale = (0.045, 0.04, 0.01)                 # 9 x 8 x 2 cm
    palm.rotation_euler = (0.05, 0.0, 0.3)
    palm.grasp_lab.role = "FINGER"
    tip = bpy.data.objects.new("Tip", None)
    bpy.context.scene.collection.objects.link(tip)
    tip.location = (0.3, 0, 0)
    tip.grasp_lab.role = "FINGER"
    tip.grasp_lab.channel = 1
    plate = grasp_env.add_cube(bpy, "Plate", size=2.0, location=(0.0, 0.0, 0.0055))
    plate.scale = (0.1, 0.1, 0.005)
    plate.rotation_euler = (0.05, 0.0, 0.0)
    plate.grasp_lab.role = "DYNAMIC"
    plate.grasp_lab.mass_mode = "MASS"
    plate.grasp_lab.mass = 0.4
    desc, _, fingers = _describe(bpy)
    assert [f.name for f in fingers] == ["Palm", "Tip"]
    p, t = desc.fingers
    assert t.points is None and t.radius == pytest.approx(tip.grasp_lab.radius)
    assert p.radius == 0.0 and len(p.points) == 8
    np.testing.assert_allclose(np.sort(np.abs(p.points), axis=0), [[0.045, 0.04, 0.01]] * 8, atol=1e-7)
    q = palm.matrix_world.to_quaternion()
    np.testing.assert_allclose(p.orientation, (q.w, q.x, q.y, q.z), atol=1e-7)
    handle = scene.build_world(desc, core)
    w = handle.world
    w.step(1e-3, steps=1500)
    pos, quat = w.body_pose(handle.body_ids[0])
    plate_up = np.array(Quaternion(quat).to_matrix())[:, 2]
    palm_up = np.array(palm.matrix_world.to_3x3().normalized())[:, 2]
    assert np.degrees(np.arccos(min(1.0, plate_up @ palm_up))) < 0.2    # lies flat on the tilted palm
    assert len(w.finger_contacts(handle.finger_ids[0])) == 4
