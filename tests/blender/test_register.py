"""Install, enable, and register/unregister leaving nothing behind."""
import pytest

import grasp_env

OUR_TYPES = ("GRASPLAB_",)


def _our_types(bpy):
    return sorted(n for n in dir(bpy.types) if n.startswith(OUR_TYPES))


def _our_handlers(bpy):
    out = []
    for name in dir(bpy.app.handlers):
        lst = getattr(bpy.app.handlers, name)
        if isinstance(lst, list):
            out += [f"{name}:{fn.__module__}" for fn in lst if "grasp_lab" in (fn.__module__ or "")]
    return out


@pytest.mark.multiversion
def test_installed_and_enabled(bpy, ext):
    assert ext in bpy.context.preferences.addons
    assert hasattr(bpy.types.Object, "grasp_lab")
    assert hasattr(bpy.types.Scene, "grasp_lab")
    ops = set(dir(bpy.ops.grasp_lab))
    assert {"session", "stop_session", "add_finger", "set_role", "validate_scene", "reset",
            "clear_display"} <= ops
    panels = [n for n in _our_types(bpy) if "_PT_" in n]
    assert "GRASPLAB_PT_main" in panels
    assert bpy.types.GRASPLAB_PT_main.bl_category == "Grasp"
    prefs = bpy.context.preferences.addons[ext].preferences
    assert prefs is not None and prefs.finger_stiffness == 1000.0


@pytest.mark.multiversion
def test_unregister_leaves_nothing_behind(bpy, ext, sample, core):
    import addon_utils
    sample.build(bpy)
    bpy.ops.grasp_lab.session(duration=0.2)      # leaves display objects and data around
    handlers_before = _our_handlers(bpy)
    assert handlers_before, "load handlers should be registered while enabled"
    addon_utils.disable(ext, default_set=True)
    try:
        assert ext not in bpy.context.preferences.addons
        assert _our_types(bpy) == []
        assert not hasattr(bpy.types.Object, "grasp_lab")
        assert not hasattr(bpy.types.Scene, "grasp_lab")
        assert list(dir(bpy.ops.grasp_lab)) == []
        assert _our_handlers(bpy) == []
        display = grasp_env.submodule("display")
        assert not display.overlay_active()
        assert grasp_env.submodule("session").active_session() is None
    finally:
        addon_utils.enable(ext, default_set=True)
    assert hasattr(bpy.types.Object, "grasp_lab")


def test_enable_disable_cycles(bpy, ext):
    import addon_utils
    for _ in range(3):
        addon_utils.disable(ext, default_set=True)
        addon_utils.enable(ext, default_set=True)
    assert hasattr(bpy.types.Object, "grasp_lab")
    assert len(_our_handlers(bpy)) == 7   # load_pre (session, robustness), load_post (session, device_fit), undo_pre, redo_pre, undo_post


def test_operators_have_tooltips(bpy, ext):
    for name in dir(bpy.ops.grasp_lab):
        rna = getattr(bpy.ops.grasp_lab, name).get_rna_type()
        assert rna.description.strip(), name


@pytest.mark.multiversion
def test_core_and_wheels_come_with_the_extension(ext, core):
    import trimesh
    import serial
    if grasp_env.source() == "zip":
        assert core.__name__ == f"{ext}.engine.graspcore"    # vendored abi3 core
    assert hasattr(core, "World")
    assert trimesh.__version__ and serial.VERSION
