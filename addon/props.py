"""Property groups: ``Object.grasp_lab`` (scene description per object) and
``Scene.grasp_lab`` (session settings)."""
from __future__ import annotations

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       IntProperty, PointerProperty, StringProperty)

from .engine import defaults

ROLE_ITEMS = (
    ("NONE", "None", "Not part of the grasp simulation"),
    ("DYNAMIC", "Dynamic", "A rigid body moved by the fingers and gravity"),
    ("STATIC", "Static", "A fixed obstacle (table, wall)"),
    ("FINGER", "Finger", "A fingertip: its position is the HIP of one device channel"),
)

RENDERER_ITEMS = (
    ("XFCA", "God-Objects (xFCA)", "Friction-cone god-objects, one per convex part touched, their forces "
                                   "blended at the seams between parts"),
    ("CURSOR", "Light-Mass Cursor", "A light mass on the finger's spring and damper, kept outside all the "
                                    "convex parts together by a constraint solve: no seams between parts"),
)

SHAPE_ITEMS = (
    ("HULL", "Convex Hull", "Collide with the convex hull of the mesh"),
    ("CHILDREN", "Child Parts", "A compound: the convex hulls of this object's child meshes "
                                "(and of its own mesh, if any)"),
    ("AUTO", "Automatic", "Split the mesh into convex parts automatically (islands, then cuts "
                          "where it is concave)"),
)

MASS_MODE_ITEMS = (
    ("MASS", "Mass", "Give the total mass; density follows from the volume"),
    ("DENSITY", "Density", "Give the density; mass follows from the volume"),
)

INPUT_ITEMS = (
    ("TIMELINE", "Animated Fingertips",
     "Fingertip objects animated on the timeline act as a scripted device"),
)


class GRASPLAB_PG_object(bpy.types.PropertyGroup):
    role: EnumProperty(name="Role", items=ROLE_ITEMS, default="NONE",
                       description="What this object is in the grasp simulation")
    # --- bodies
    mass_mode: EnumProperty(name="Mass From", items=MASS_MODE_ITEMS, default="MASS",
                            description="Give the mass or the density")
    mass: FloatProperty(name="Mass", default=0.1, min=1e-6, soft_max=100.0, unit="MASS",
                        precision=4, description="Total mass of the body, kg")
    density: FloatProperty(name="Density", default=1000.0, min=1e-3, soft_max=20000.0,
                           description="Density, kg/m³ (water = 1000)")
    mu_s: FloatProperty(name="Static Friction", default=defaults.body("mu_s"), min=0.0, soft_max=2.0,
                        description="Static friction coefficient μs (friction cone half angle atan μs)")
    mu_d: FloatProperty(name="Dynamic Friction", default=defaults.body("mu_d"), min=0.0, soft_max=2.0,
                        description="Dynamic (sliding) friction coefficient μd, at most μs")
    viscosity: FloatProperty(name="Viscosity", default=defaults.body("viscosity"), min=0.0, soft_max=1.0, unit="TIME",
                             description="Viscous friction: slip speed is limited to depth / viscosity "
                                         "(0 = pure Coulomb friction)")
    shape: EnumProperty(name="Collision Shape", items=SHAPE_ITEMS, default="HULL",
                        description="How the body's collision shape is made from its mesh")
    # --- fingers
    radius: FloatProperty(name="Radius", default=defaults.finger("radius"), min=0.0, soft_max=0.05, unit="LENGTH",
                          precision=4, description="Fingertip sphere radius (0 = a point)")
    stiffness: FloatProperty(name="Stiffness", default=defaults.finger("stiffness"), min=1.0, soft_max=10000.0,
                             description="Coupling spring between HIP and god-object, N/m")
    damping: FloatProperty(name="Damping", default=defaults.finger("damping"), min=0.0, soft_max=50.0,
                           description="Coupling damping, N·s/m")
    renderer: EnumProperty(name="Renderer", items=RENDERER_ITEMS, default=defaults.renderer().upper(),
                           description="How the finger's force is found")
    cursor_mass: FloatProperty(name="Cursor Mass", default=defaults.finger("cursor_mass"), min=0.0, soft_max=0.05,
                               unit="MASS", precision=4,
                               description="The light-mass cursor's mass (felt as inertia in free space)")
    torsion: FloatProperty(name="Soft Tip Radius", default=0.0, min=0.0, soft_max=0.02, unit="LENGTH", precision=4,
                           description="A soft fingertip: the radius of the patch it presses. It resists a twist "
                                       "about the contact normal up to μs × normal force × this radius, so two "
                                       "fingertips can hold a bar against its weight's twist (0 = a hard point, "
                                       "free to turn). Sphere fingers (an Empty) rendered by god-objects")
    channel: IntProperty(name="Device Channel", default=0, min=0, max=63,
                         description="Which fingertip of the input device drives this finger; "
                                     "fingers are ordered by channel, then by name")
    # --- bookkeeping: world matrix before the last session (for Reset)
    rest_matrix: FloatVectorProperty(size=16, options={"HIDDEN"})
    has_rest: BoolProperty(default=False, options={"HIDDEN"})


class GRASPLAB_PG_scene(bpy.types.PropertyGroup):
    gravity: FloatVectorProperty(name="Gravity", default=(0.0, 0.0, -9.81), subtype="ACCELERATION",
                                 unit="ACCELERATION", size=3, description="Gravity, m/s²")
    gyroscopic: BoolProperty(name="Gyroscopic Term", default=True,
                             description="Keep the −ω×Jω term in Euler's equation (Harwin & "
                                         "Barrow, \"Multi-finger grasps in a dynamic environment\", "
                                         "drop it)")
    haptic_rate: FloatProperty(name="Haptic Rate", default=1000.0, min=100.0, max=10000.0,
                               description="Core step rate, Hz")
    display_rate: FloatProperty(name="Display Rate", default=30.0, min=1.0, max=240.0,
                                description="Live session display updates per second, Hz")
    input_source: EnumProperty(name="Input", items=INPUT_ITEMS, default="TIMELINE",
                               description="Where fingertip positions (HIPs) come from")
    duration: FloatProperty(name="Duration", default=0.0, min=0.0, unit="TIME_ABSOLUTE",
                            description="Session length in seconds (0 = to the end of the animation)")
    loop: BoolProperty(name="Stop at End", default=True,
                       description="Stop a live session when the animation ends")
    bake: BoolProperty(name="Bake Keyframes", default=False,
                       description="Keyframe the bodies (and display objects) every frame of a session")
    display_objects: BoolProperty(name="Display Objects", default=True,
                                  description="Show god-objects and force/torque arrows as real "
                                              "objects in the 'Grasp Lab' collection (they render)")
    force_scale: FloatProperty(name="Force Scale (m/N)", default=0.02, min=0.0, soft_max=1.0, precision=3,
                               description="Force arrow length in metres per newton (0.02: 1 N is a 2 cm arrow)")
    torque_scale: FloatProperty(name="Torque Scale (m/N·m)", default=1.0, min=0.0, soft_max=10.0, precision=3,
                                description="Torque arrow length in metres per newton-metre")
    weakest_scale: FloatProperty(name="Weakest Wrench Size", default=0.5, min=0.0, soft_max=3.0, precision=2,
                                 description="Size of the weakest-wrench display (magenta, drawn around the held "
                                             "body): its arrow is this times twice the body's radius per unit of "
                                             "the wrench's force part, its ring this times the radius beyond the "
                                             "body. 0: not drawn")
    record: BoolProperty(name="Record", default=False,
                         description="Record every haptic tick of each session to the recording folder (.mcap)")
    recording_folder: StringProperty(name="Recording Folder", default="//grasp_recordings/",
                                     subtype="DIR_PATH",
                                     description="Where session recordings are written")
    live_view: BoolProperty(name="Live View", default=False,
                            description="Serve live sessions to Foxglove over WebSocket, watching only "
                                        "(docs/viewers.md)")
    live_view_port: IntProperty(name="Port", default=8765, min=0, max=65535,
                                description="Live view port (0: any free port, shown in the HUD)")
    live_view_bind: StringProperty(name="Bind", default="127.0.0.1",
                                   description="Address the live view listens on (127.0.0.1: this "
                                               "machine only; 0.0.0.0: every interface)")
    finger_target: PointerProperty(name="Finger Target", type=bpy.types.Object,
                                   description="The body Add Finger last put a fingertip beside: the next "
                                               "one goes beside it too while a fingertip is selected")
    # --- live status (read-only in the UI)
    running: BoolProperty(name="Running", default=False)
    status: StringProperty(name="Status", default="")
    last_recording: StringProperty(name="Last Recording", default="", subtype="FILE_PATH")


CLASSES = (GRASPLAB_PG_object, GRASPLAB_PG_scene)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Object.grasp_lab = PointerProperty(type=GRASPLAB_PG_object)
    bpy.types.Scene.grasp_lab = PointerProperty(type=GRASPLAB_PG_scene)


def unregister():
    del bpy.types.Scene.grasp_lab
    del bpy.types.Object.grasp_lab
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
