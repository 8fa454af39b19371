"""Add-on preferences: defaults applied to new fingers / bodies and live-session options."""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, FloatProperty

from .engine import defaults


class GRASPLAB_AP_preferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    finger_radius: FloatProperty(name="Finger Radius", default=defaults.finger("radius"), min=0.0, unit="LENGTH",
                                 precision=4, description="Radius of new fingers")
    finger_stiffness: FloatProperty(name="Finger Stiffness", default=defaults.finger("stiffness"), min=1.0,
                                    description="Coupling stiffness of new fingers, N/m")
    mu_s: FloatProperty(name="Static Friction", default=defaults.body("mu_s"), min=0.0,
                        description="μs given to objects made dynamic or static")
    mu_d: FloatProperty(name="Dynamic Friction", default=defaults.body("mu_d"), min=0.0,
                        description="μd given to objects made dynamic or static")
    use_runtime: BoolProperty(name="Threaded Runtime", default=True,
                              description="Live sessions run the core on its own haptic thread "
                                          "(otherwise the core is stepped on Blender's main "
                                          "thread, within the step budget)")
    max_hip_speed: FloatProperty(name="Fingertip Speed Limit", default=1.0, min=0.0, soft_max=5.0,
                                 unit="VELOCITY",
                                 description="Fastest a fingertip the user moves (G, drag) is "
                                             "followed by the haptic loop between display "
                                             "updates, m/s (0: no limit)")
    max_step_ms: FloatProperty(name="Step Budget", default=8.0, min=1.0, max=100.0,
                               description="Main-thread time a live session may spend stepping the "
                                           "core per display update, ms; beyond it the session "
                                           "falls behind real time instead of freezing the UI")
    show_hud: BoolProperty(name="Show HUD", default=True,
                           description="Show rates, jitter and contacts in the viewport during a session")
    show_overlay: BoolProperty(name="Show Overlay", default=True,
                               description="Draw HIP-to-god-object springs and finger forces in the "
                                           "viewport during a live session")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(heading="New Objects")
        col.prop(self, "finger_radius")
        col.prop(self, "finger_stiffness")
        col.prop(self, "mu_s")
        col.prop(self, "mu_d")
        col = layout.column(heading="Live Session")
        col.prop(self, "use_runtime")
        col.prop(self, "max_step_ms")
        col.prop(self, "max_hip_speed")
        col.prop(self, "show_hud")
        col.prop(self, "show_overlay")


class _Defaults:
    finger_radius = defaults.finger("radius")
    finger_stiffness = defaults.finger("stiffness")
    mu_s = defaults.body("mu_s")
    mu_d = defaults.body("mu_d")
    use_runtime = True
    max_step_ms = 8.0
    max_hip_speed = 1.0
    show_hud = True
    show_overlay = True


def get_prefs(context=None):
    """The preferences, or class defaults when the add-on is not registered as such."""
    context = context or bpy.context
    addon = context.preferences.addons.get(__package__)
    if addon is None or addon.preferences is None:
        return _Defaults
    return addon.preferences


CLASSES = (GRASPLAB_AP_preferences,)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
