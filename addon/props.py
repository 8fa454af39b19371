"""Property groups: ``Object.grasp_lab`` (scene description per object),
``PoseBone.grasp_lab`` (a bone as a finger) and ``Scene.grasp_lab`` (session settings)."""
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


BONE_ROLE_ITEMS = (
    ("NONE", "None", "Not part of the grasp simulation: follows the input pose"),
    ("FINGER", "Finger", "A capsule from head to tail with the bone's radius; its pose is a finger's HIP"),
)


class GRASPLAB_PG_bone(bpy.types.PropertyGroup):
    """A pose bone as a finger: the same parameters as a Finger object (docs/hands.md)."""
    role: EnumProperty(name="Role", items=BONE_ROLE_ITEMS, default="NONE",
                       description="What this bone is in the grasp simulation")
    radius: FloatProperty(name="Radius", default=defaults.finger("radius"), min=0.0, soft_max=0.05, unit="LENGTH",
                          precision=4, description="Capsule radius around the bone from head to tail")
    stiffness: FloatProperty(name="Stiffness", default=defaults.finger("stiffness"), min=1.0, soft_max=10000.0,
                             description="Coupling spring between the input pose and the god-pose, N/m")
    damping: FloatProperty(name="Damping", default=defaults.finger("damping"), min=0.0, soft_max=50.0,
                           description="Coupling damping, N·s/m")
    channel: IntProperty(name="Device Channel", default=0, min=0, max=63,
                         description="Orders the fingers (by channel, then by name) like a Finger object's")


class GRASPLAB_PG_scene(bpy.types.PropertyGroup):
    gravity: FloatVectorProperty(name="Gravity", default=tuple(defaults.world("gravity")), subtype="ACCELERATION",
                                 unit="ACCELERATION", size=3, description="Gravity, m/s²")
    gyroscopic: BoolProperty(name="Gyroscopic Term", default=True,
                             description="Keep the −ω×Jω term in Euler's equation (Harwin & "
                                         "Barrow, \"Multi-finger grasps in a dynamic environment\", "
                                         "drop it)")
    haptic_rate: FloatProperty(name="Haptic Rate", default=defaults.runtime("haptic_rate"), min=100.0, max=10000.0,
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
    sound: BoolProperty(name="Sound", default=True,
                        description="Hear the grasp in live sessions through Blender's audio: a click at each "
                                    "touch, a tone whose pitch follows the squeeze, a scrape while a finger "
                                    "slips, a beep when a held body is close to slipping (off in background "
                                    "mode)")
    sound_volume: FloatProperty(name="Volume", default=0.5, min=0.0, max=1.0, subtype="FACTOR",
                                description="Loudness of the live sound")
    # The tone's pitch against the normal force (docs/sound.md): live and baked sound alike.
    sound_pitch_low: FloatProperty(name="Pitch at 0 N", default=220.0, min=20.0, max=8000.0, unit="NONE",
                                   description="The tone's frequency (Hz) at a light touch")
    sound_pitch_high: FloatProperty(name="Pitch at Full", default=880.0, min=20.0, max=8000.0,
                                    description="The tone's frequency (Hz) at Full Force and above")
    sound_force_full: FloatProperty(name="Full Force", default=10.0, min=1e-3, soft_max=100.0,
                                    description="The normal force (N) of the highest pitch")
    sound_curve: FloatProperty(name="Curve", default=0.5, min=0.05, max=5.0,
                               description="Exponent on force / Full Force: below 1 the pitch moves most at "
                                           "light forces, 1 evenly (in musical steps), above 1 most near Full")
    live_view: BoolProperty(name="Live View", default=False,
                            description="Show live sessions in a viewer while they run: served to Foxglove "
                                        "over WebSocket (watching only) or streamed to Rerun (docs/viewers.md)")
    live_view_viewer: EnumProperty(name="Viewer", default="FOXGLOVE",
                                   items=[("FOXGLOVE", "Foxglove", "Serve the session over Foxglove's WebSocket "
                                                                   "protocol; Foxglove connects to it"),
                                          ("RERUN", "Rerun", "Stream the session to a Rerun viewer running on "
                                                             "this machine (start it with: rerun)")],
                                   description="Which viewer the live view is for (docs/viewers.md)")
    live_view_port: IntProperty(name="Port", default=8765, min=0, max=65535,
                                description="Live view port (0: any free port, shown in the HUD)")
    live_view_rerun_port: IntProperty(name="Rerun Port", default=9876, min=1, max=65535,
                                      description="The port the Rerun viewer on this machine listens on "
                                                  "(its default: 9876)")
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


CLASSES = (GRASPLAB_PG_object, GRASPLAB_PG_bone, GRASPLAB_PG_scene)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Object.grasp_lab = PointerProperty(type=GRASPLAB_PG_object)
    bpy.types.PoseBone.grasp_lab = PointerProperty(type=GRASPLAB_PG_bone)
    bpy.types.Scene.grasp_lab = PointerProperty(type=GRASPLAB_PG_scene)


def unregister():
    del bpy.types.Scene.grasp_lab
    del bpy.types.PoseBone.grasp_lab
    del bpy.types.Object.grasp_lab
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
