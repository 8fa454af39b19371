"""Grasp Lab: multi-finger grasp simulation with friction-cone god-objects.

Blender-facing modules (``props``, ``prefs``, ``ops``, ``session``, ``display``,
``ui``) are imported only when the add-on registers; the bpy-free logic lives in
``engine`` (scene description, decomposition, input sources, session runner).
"""

_MODULES = ("props", "prefs", "ops", "hand_add", "session", "ui", "devices_ui", "device_fit", "recording_ops",
            "robustness", "cli_blender")


def _modules():
    import importlib
    return [importlib.import_module(f".{name}", __package__) for name in _MODULES]


def register():
    for mod in _modules():
        mod.register()


def unregister():
    for mod in reversed(_modules()):
        mod.unregister()
