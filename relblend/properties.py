"""The add-on's data: relativity settings of a camera, render settings of a scene.

Every value is an ordinary RNA property, so it is keyframeable with I over the field,
driveable, and evaluated per frame by the depsgraph (read it from the evaluated
camera). Nothing here imports the core.

``bpy.types.Camera.relray`` (:class:`RelrayCameraSettings`), in the camera's Object
Data tab ("Relativity" panel):

==================  ==========================================================================
property            meaning
==================  ==========================================================================
``velocity_input``  "VECTOR": β as a 3-vector; "SPEED": speed |β| and a direction
``beta``            β = v/c, 3 components in [-0.999999, 0.999999] (soft ±0.99); |β| < 1 is
                    checked per frame when rendering (a clear error names the frame)
``speed``           |β| in [0, 0.999999] (soft 0.99), with ``direction``
``direction``       unit direction of motion (normalised when read; zero = at rest)
``axes``            "WORLD": β in world (lab) axes; "CAMERA": in the camera's local axes
                    (x right, y up, -z the view direction), turned into the lab by the
                    camera's world rotation of each frame
``mode``            "SNAPSHOT": each frame is a photo by a camera that has moved at its
                    constant β since ct' = 0 (physics.md); "WORLDLINE": β is integrated
                    over proper time from ct' = 0, frame by frame
``ct``              proper time ct' of the shutter (scene units, c = 1). Snapshot: per
                    frame (any animation). Worldline: read at the scene's start frame
``ct_per_frame``    worldline mode: proper time between frames (read at the start frame)
``gamma``           read-only Lorentz factor of the current β
==================  ==========================================================================

In worldline mode the camera object's own location is its lab position at ct' = 0;
β between integer frames is linear in proper time (the job format's keyframes).

``bpy.types.Object.relray`` (:class:`RelrayObjectSettings`), in the Object tab
("Relativity" panel, meshes): ``velocity``, the object's own constant lab velocity u
(v/c per world axis, |u| < 1, checked when rendering with a message naming the object),
and the read-only ``gamma``. The object's world location at the rendered frame is its
pivot at lab time 0 (physics.md, "Moving objects"): its mesh there is its rest-frame
shape, and it moves at u through the lab. Objects with the same velocity share one rest
frame (one BVH).

``bpy.types.Scene.relray`` (:class:`RelraySceneSettings`), "Relativistic" panels of the
Render tab: samples, seed, max bounces, spectral model, Doppler and searchlight
switches, threads. ``bpy.types.ViewLayer.relray`` (:class:`RelrayViewLayerSettings`):
the Doppler and LabTime passes (Depth is Blender's own Z pass toggle).

The add-on's preferences (:class:`RelrayPreferences`, ``bl_idname`` = the add-on's
package): the Dask scheduler address of "Render on Farm" (empty: this machine), its
connect timeout, and the folder the job is exported to.
"""

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

#: Largest component / speed the UI accepts (|β| must stay below 1: c = 1).
BETA_HARD_MAX = 0.999999
BETA_SOFT_MAX = 0.99
#: The settings of every v/c vector property (the camera's β, an object's velocity).
VELOCITY_VECTOR = dict(size=3, subtype="XYZ", min=-BETA_HARD_MAX, max=BETA_HARD_MAX,
                       soft_min=-BETA_SOFT_MAX, soft_max=BETA_SOFT_MAX, step=1, precision=4,
                       default=(0.0, 0.0, 0.0))


def _gamma_get(self) -> float:
    """γ of the stored β (0 when |β| >= 1: invalid); the core's formula, through
    :mod:`.motion` (imported on first draw: it loads the core)."""
    from .motion import VelocitySettings, beta_local, gamma_or_zero

    return gamma_or_zero(beta_local(VelocitySettings.from_rna(self)))


#: The speed of light in m/s (SI, exact).
C_SI = 299_792_458.0

MOTION_SOURCES = [
    ("VELOCITY", "Velocity", "The velocity typed (and keyed) here; the animated location "
     "only places it"),
    ("ANIMATION", "Animation", "The animated location is the lab worldline, on the scene "
     "clock ct = c · frame / fps (Scene › Relativity › Speed of Light)"),
]


class RelrayCameraSettings(bpy.types.PropertyGroup):
    """Relativistic motion of one camera (see the module docstring)."""

    motion_source: EnumProperty(
        name="Motion", description="Where the camera's motion comes from",
        items=MOTION_SOURCES, default="VELOCITY")
    velocity_input: EnumProperty(
        name="Velocity",
        description="How the camera's velocity is given",
        items=[
            ("VECTOR", "Vector", "β as a 3-vector (v/c per axis)"),
            ("SPEED", "Speed and Direction", "Speed |β| and a direction of motion"),
        ],
        default="VECTOR",
    )
    beta: FloatVectorProperty(
        name="β", description="Camera velocity v/c; |β| must stay below 1 (the speed of light)",
        **VELOCITY_VECTOR)
    speed: FloatProperty(
        name="Speed",
        description="Speed |β| = v/c of the camera",
        min=0.0,
        max=BETA_HARD_MAX,
        soft_max=BETA_SOFT_MAX,
        step=1,
        precision=4,
        default=0.0,
    )
    direction: FloatVectorProperty(
        name="Direction",
        description="Direction of motion (normalised when used)",
        size=3,
        subtype="DIRECTION",
        default=(0.0, 0.0, -1.0),
    )
    axes: EnumProperty(
        name="Axes",
        description="Axes in which β (or the direction) is given",
        items=[
            ("WORLD", "World", "β in world (lab) axes"),
            ("CAMERA", "Camera", "β in the camera's local axes (-Z is the view direction)"),
        ],
        default="WORLD",
    )
    mode: EnumProperty(
        name="Mode",
        description="How the camera's path follows from β",
        items=[
            ("SNAPSHOT", "Snapshot",
             "Each frame: a camera that has moved at the frame's constant β since ct' = 0"),
            ("WORLDLINE", "Worldline",
             "β integrated over proper time frame by frame: the camera really accelerates"),
        ],
        default="SNAPSHOT",
    )
    ct: FloatProperty(
        name="ct'",
        description=(
            "Proper time ct' of the shutter (scene units, c = 1). Snapshot: per frame. "
            "Worldline: the value at the scene's start frame"
        ),
        default=0.0,
        step=10,
        precision=3,
    )
    ct_per_frame: FloatProperty(
        name="ct' per Frame",
        description="Worldline mode: proper time between frames (read at the start frame)",
        min=0.0,
        soft_max=10.0,
        default=0.1,
        step=1,
        precision=4,
    )
    gamma: FloatProperty(
        name="γ",
        description="Lorentz factor of the current β (read-only)",
        get=_gamma_get,
        precision=4,
    )


class RelraySceneSettings(bpy.types.PropertyGroup):
    """Render settings of the Relativistic engine (the job file's [render] table)."""

    samples: IntProperty(name="Samples", description="Samples per pixel", min=1,
                         soft_max=4096, default=64)
    use_adaptive_sampling: BoolProperty(
        name="Noise Threshold", default=False,
        description="Adaptive sampling: stop a pixel once its relative error (and its 3×3 "
                    "neighbourhood's) is below the threshold; Samples is then the cap")
    adaptive_threshold: FloatProperty(
        name="Threshold", description="Relative error at which a pixel stops (the core's "
        "render.noise_threshold)", min=0.0001, soft_max=0.5, default=0.01, precision=4,
        step=0.1)
    clamp: FloatProperty(
        name="Clamp", description="Largest value a path sample may add to a pixel's R, G or "
        "B (the sample is scaled down, its colour kept); removes fireflies at the cost of "
        "bias. 0: off", min=0.0, soft_max=100.0, default=0.0)
    preview_samples: IntProperty(
        name="Viewport Samples", description="Samples per pixel of the Rendered viewport "
        "(it refines progressively up to this count)", min=1, soft_max=1024, default=32)
    max_depth: IntProperty(name="Max Bounces", description="Path segments (max_depth)",
                           min=1, soft_max=64, default=8)
    seed: IntProperty(name="Seed", description="Random seed (the same seed, the same image)",
                      min=0, default=0)
    spectral: EnumProperty(
        name="Spectral Model",
        description="How light is described and seen",
        items=[
            ("cie1931", "CIE 1931", "True spectra, 4 hero wavelengths, CIE 1931 sensor"),
            ("seed-gaussian", "Seed Gaussian", "The seed report's Gaussian eye model"),
            ("rgb", "RGB", "No wavelengths: geometry (aberration) only"),
        ],
        default="cie1931",
    )
    doppler: BoolProperty(name="Doppler Shift", default=True,
                          description="Shift wavelengths by the Doppler factor D")
    searchlight: BoolProperty(name="Searchlight", default=True,
                              description="The D⁵ radiance transform (beaming)")
    threads: IntProperty(name="Threads", description="Render threads (0: all cores)",
                         min=0, soft_max=256, default=0)
    auto_exposure: BoolProperty(
        name="Auto Exposure", default=False,
        description="Meter every frame (log-average luminance onto middle grey 0.18) and "
                    "scale the image by the smoothed exposure, so the searchlight effect's "
                    "orders of magnitude stay visible over a fly-by; the stops applied are "
                    "in the stats line and the file's metadata (relray:exposure)")
    speed_of_light: FloatProperty(
        name="Speed of Light",
        description="c in scene units per second: with the frame rate it fixes the lab "
                    "time of every frame, ct = c · frame / fps, for cameras and objects "
                    "whose motion comes from their animation",
        unit="VELOCITY", min=1e-6, soft_min=0.01, default=C_SI, precision=3, step=100)


def _object_gamma_get(self) -> float:
    """γ of the object's velocity (0 when |u| >= 1: invalid)."""
    b2 = sum(float(x) * float(x) for x in self.velocity)
    return 1.0 / ((1.0 - b2) ** 0.5) if b2 < 1.0 else 0.0


class RelrayObjectSettings(bpy.types.PropertyGroup):
    """A mesh object's own motion (see the module docstring)."""

    motion_source: EnumProperty(
        name="Motion", description="Where the object's motion comes from (Animation: "
        "when the camera's motion comes from its animation too, on the scene clock)",
        items=MOTION_SOURCES, default="ANIMATION")
    velocity: FloatVectorProperty(
        name="Velocity",
        description="The object's own velocity v/c in world axes; |v| must stay below 1 "
                    "(the speed of light). Its location is where it is at lab time 0",
        **VELOCITY_VECTOR)
    gamma: FloatProperty(name="γ", description="Lorentz factor of the velocity",
                         get=_object_gamma_get, precision=6)


class RelrayWorldSettings(bpy.types.PropertyGroup):
    """The world's stars: the job's ``scene.stars`` (job-format.md, "Skies")."""

    use_stars: BoolProperty(
        name="Stars", default=False,
        description="A real star sky (the ESA Hipparcos-2 catalogue) at infinity, each star "
                    "a blackbody point source, aberrated and Doppler-shifted for the camera")
    star_magnitude_limit: FloatProperty(
        name="Magnitude Limit", default=8.0, min=-2.0, max=14.0, soft_max=10.0,
        description="Leave out the stars fainter than this magnitude (as seen at rest)")
    star_brightness: FloatProperty(
        name="Brightness", default=1.0, min=0.0, soft_max=10.0,
        description="Scales every star's flux (1: the photometric zero point of the core)")


class RelrayViewLayerSettings(bpy.types.PropertyGroup):
    """Extra passes of the Relativistic engine."""

    use_pass_doppler: BoolProperty(name="Doppler", default=True,
                                   description="Doppler factor D of the primary rays")
    use_pass_denoising: BoolProperty(
        name="Denoising Data", default=False,
        description="Denoising Albedo and Denoising Normal passes (as Cycles'), for the "
                    "compositor's Denoise node (OpenImageDenoise)")
    use_pass_lab_time: BoolProperty(name="Lab Time", default=True,
                                    description="Lab time of emission of the first hit")


#: The add-on's package: ``bl_ext.<repository>.relray`` installed, ``relray`` in development.
ADDON_PACKAGE = __package__.rpartition(".")[0] or __package__


class RelrayPreferences(bpy.types.AddonPreferences):
    """The add-on's preferences: where "Render on Farm" renders."""

    bl_idname = ADDON_PACKAGE

    scheduler: StringProperty(
        name="Scheduler", default="",
        description="Dask scheduler of Render on Farm, tcp://HOST:8786 (empty: render on "
                    "this machine, in a separate process)")
    connect_timeout: FloatProperty(
        name="Connect Timeout", default=10.0, min=0.1, max=3600.0,
        description="Seconds to reach the scheduler before giving up")
    farm_directory: StringProperty(
        name="Farm Directory", subtype="DIR_PATH", default="",
        description="Where Render on Farm exports the job (frames go to its out/ folder); "
                    "with a scheduler, a folder every worker sees at the same path. Empty: "
                    "relray_farm beside the .blend file (in the temp folder if unsaved)")

    compile_kernels: BoolProperty(
        name="Compile Kernels at Start-up", default=True,
        description="When the add-on is enabled, compile (or load) the render kernels in a "
                    "background process, so the first render does not wait for them")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "compile_kernels")
        layout.prop(self, "scheduler")
        row = layout.row()
        row.enabled = bool(self.scheduler.strip())
        row.prop(self, "connect_timeout")
        layout.prop(self, "farm_directory")


def compile_at_startup() -> bool:
    """The "Compile Kernels at Start-up" preference (True while it cannot be read yet)."""
    prefs = addon_preferences(bpy.context)
    return True if prefs is None else bool(prefs.compile_kernels)


def addon_preferences(context):
    """The add-on's preferences, or None when it is not enabled under ADDON_PACKAGE."""
    addon = context.preferences.addons.get(ADDON_PACKAGE)
    return None if addon is None else addon.preferences


classes = (RelrayCameraSettings, RelraySceneSettings, RelrayObjectSettings,
           RelrayWorldSettings, RelrayViewLayerSettings, RelrayPreferences)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Camera.relray = PointerProperty(type=RelrayCameraSettings)
    bpy.types.Scene.relray = PointerProperty(type=RelraySceneSettings)
    bpy.types.Object.relray = PointerProperty(type=RelrayObjectSettings)
    bpy.types.ViewLayer.relray = PointerProperty(type=RelrayViewLayerSettings)
    bpy.types.World.relray = PointerProperty(type=RelrayWorldSettings)


def unregister() -> None:
    del bpy.types.World.relray
    del bpy.types.ViewLayer.relray
    del bpy.types.Object.relray
    del bpy.types.Scene.relray
    del bpy.types.Camera.relray
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
