"""Panels of the Relativistic engine, and Blender's own panels it reuses.

Our panels: Relativity (camera Object Data tab: motion, β, ct', switches, γ and the D
range of the view, presets, velocity keyframes), Sampling, Relativity summary (with
Export for Farm, Render on Farm and the farm run's status) and Film (Render tab),
Passes (View Layer tab), Light (light Object Data tab).

Blender's panels are reused as Cycles does: "RELRAY" is added to the
``COMPAT_ENGINES`` of every built-in panel open to any engine ("BLENDER_RENDER" in
its set) except those for features the engine lacks, plus the EEVEE node panels for
materials and the world (they draw the node tree, which the exporter reads).
"""

from __future__ import annotations

import bpy

ENGINE = "RELRAY"

#: Built-in panels open to any engine that do not apply (or are replaced by ours).
EXCLUDED_PANELS = {
    "DATA_PT_camera_dof", "DATA_PT_camera_dof_aperture", "DATA_PT_light", "NODE_DATA_PT_light",
    "DATA_PT_preview", "MATERIAL_PT_preview", "OBJECT_PT_visibility",
    "VIEWLAYER_PT_layer_passes", "RENDER_PT_simplify", "DATA_PT_lightprobe",
    "DATA_PT_lightprobe_visibility", "DATA_PT_lightprobe_display", "DATA_PT_context_lightprobe",
    "DATA_PT_lightprobe_parallax", "EEVEE_MATERIAL_PT_viewport_settings",
}
#: Engine-specific built-in panels that draw what the exporter reads.
EXTRA_PANELS = ("EEVEE_MATERIAL_PT_context_material", "EEVEE_MATERIAL_PT_surface",
                "EEVEE_WORLD_PT_surface")

_added_to: list[type] = []


def compat_panels() -> list[type]:
    """The built-in panels the engine shows."""
    panels = [p for p in bpy.types.Panel.__subclasses__()
              if "BLENDER_RENDER" in getattr(p, "COMPAT_ENGINES", ())
              and p.__name__ not in EXCLUDED_PANELS]
    panels += [getattr(bpy.types, name) for name in EXTRA_PANELS if hasattr(bpy.types, name)]
    return panels


class RelrayPanel:
    """Common poll: only for the Relativistic engine."""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = {ENGINE}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


def _camera_object(context, cam_data):
    """An object using this camera data (the scene camera first)."""
    obj = context.scene.camera
    if obj is not None and obj.data == cam_data:
        return obj
    ob = getattr(context, "object", None)
    if ob is not None and ob.data == cam_data:
        return ob
    return None


def view_readout(context, cam_data) -> str:
    """'|β| 0.5  D 0.577–1.73' for the camera as it stands (or why not)."""
    try:
        from . import export, motion

        obj = _camera_object(context, cam_data)
        if obj is None:
            return "D range: the camera is not used by an object"
        m = export.matrix_np(obj.matrix_world)
        beta = motion.camera_beta(cam_data.relray, m)
        speed = float((beta @ beta) ** 0.5)
        if speed >= 1.0:
            return f"|β| = {speed:.4g} ≥ 1: not renderable"
        w, h = export.render_size(context.scene.render)
        cam = export.camera_settings(obj, w, h)
        lo, hi = motion.view_doppler_range(cam, beta, w, h)
        return f"|β| {speed:.4f}   D {lo:.3f} – {hi:.3f}"
    except Exception as e:  # noqa: BLE001 - a panel must draw whatever happens
        return f"D range unavailable: {e}"


class RELRAY_PT_camera_relativity(RelrayPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Relativity"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return context.camera is not None and super().poll(context)

    def draw(self, context):
        layout = self.layout
        cam = context.camera
        s = cam.relray
        rs = context.scene.relray
        row = layout.row(align=True)
        row.menu("RELRAY_MT_motion_presets", icon="PRESET")
        row.operator("relray.add_velocity_keyframe", icon="KEY_HLT", text="Key Velocity")
        layout.use_property_split = True
        layout.use_property_decorate = True
        layout.prop(s, "motion_source", expand=True)
        if s.motion_source == "ANIMATION":
            draw_animation_source(layout, context)
            return
        layout.prop(s, "mode", expand=True)
        layout.prop(s, "velocity_input", expand=True)
        if s.velocity_input == "VECTOR":
            layout.prop(s, "beta")
        else:
            layout.prop(s, "speed")
            layout.prop(s, "direction")
        layout.prop(s, "axes", expand=True)
        if s.mode == "WORLDLINE":
            layout.prop(s, "ct", text="ct' at Start Frame")
            layout.prop(s, "ct_per_frame")
            frame = context.scene.frame_current - context.scene.frame_start
            layout.label(text=f"ct' this frame: {s.ct + frame * s.ct_per_frame:.4g}")
        else:
            layout.prop(s, "ct")
        draw_light_settings(layout, rs)
        col = layout.column()
        col.enabled = False
        col.prop(s, "gamma")
        layout.label(text=view_readout(context, cam), icon="INFO")


def clock_readout(scene) -> str:
    """'c = 10 m/s: ct 0.4167 per frame at 24 fps' (scene units, the scene clock)."""
    rs = scene.relray
    fps = scene.render.fps / scene.render.fps_base
    per_frame = rs.speed_of_light / fps if fps > 0 else float("nan")
    return f"lab time per frame ct = c / fps = {per_frame:.4g} (at {fps:.4g} fps)"


def draw_animation_source(layout, context) -> None:
    """The camera's Relativity panel when its motion is its animation."""
    scene = context.scene
    layout.prop(scene.relray, "speed_of_light")
    layout.label(text=clock_readout(scene), icon="TIME")
    layout.label(text="β at each frame: the animated location's velocity / c", icon="INFO")
    draw_light_settings(layout, scene.relray)


def draw_light_settings(layout, rs) -> None:
    """Doppler Shift, Searchlight and the Spectral Model (the scene's)."""
    col = layout.column(heading="Light")
    col.prop(rs, "doppler")
    col.prop(rs, "searchlight")
    layout.prop(rs, "spectral")


class RELRAY_PT_scene_relativity(RelrayPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    """Scene › Relativity: the speed of light and the scene clock."""

    bl_label = "Relativity"
    bl_context = "scene"

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        row = layout.row(align=True)
        for label, value in SPEED_OF_LIGHT_PRESETS:
            op = row.operator("relray.speed_of_light_preset", text=label)
            op.meters_per_second = value
        layout.use_property_split = True
        layout.prop(scene.relray, "speed_of_light")
        layout.label(text=clock_readout(scene), icon="TIME")
        cam = scene.camera
        if cam is not None and cam.type == "CAMERA" \
                and cam.data.relray.motion_source != "ANIMATION":
            layout.label(text="The camera's motion is typed (Velocity): the clock is used "
                              "when it follows its animation", icon="INFO")


#: (label, m/s) of the speed-of-light preset buttons.
SPEED_OF_LIGHT_PRESETS = (("Real", 299_792_458.0), ("100 m/s", 100.0), ("10 m/s", 10.0),
                          ("1 m/s", 1.0))


class RELRAY_PT_object_relativity(RelrayPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Relativity"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        obj = context.object
        return obj is not None and obj.type == "MESH" and super().poll(context)

    def draw(self, context):
        layout = self.layout
        s = context.object.relray
        layout.use_property_split = True
        layout.prop(s, "motion_source", expand=True)
        cam = context.scene.camera
        clock = cam is not None and cam.type == "CAMERA" \
            and cam.data.relray.motion_source == "ANIMATION"
        if s.motion_source == "ANIMATION":
            layout.label(text="Moves along its animated location (worldline)" if clock else
                         "Follows its animation only when the camera's motion does too",
                         icon="INFO")
            return
        layout.prop(s, "velocity")
        col = layout.column()
        col.enabled = False
        col.prop(s, "gamma")
        if any(s.velocity):
            layout.label(text="Its location is where it is at lab time 0", icon="INFO")


class RELRAY_PT_world_sky(RelrayPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    """World › Sky: what the Relativistic engine uses as the sky, and the bake of a
    procedural one (relblend/sky_bake.py)."""

    bl_label = "Sky"
    bl_context = "world"

    @classmethod
    def poll(cls, context):
        return context.world is not None and super().poll(context)

    def draw(self, context):
        from .nodes import background_source
        from .sky_bake import baked_path

        layout = self.layout
        world = context.world
        src = background_source(world)
        if src is None:
            layout.label(text="A constant colour (the Background node's)", icon="INFO")
        elif src.type == "TEX_ENVIRONMENT":
            name = src.image.name if src.image is not None else "no image"
            layout.label(text=f"Environment map: {name}", icon="IMAGE_DATA")
        else:
            baked = baked_path(world).is_file()
            layout.label(text=f"Procedural ({src.bl_label}): "
                              + ("baked" if baked else "not baked, rendered as a colour"),
                         icon="CHECKMARK" if baked else "ERROR")
            layout.operator("relray.bake_sky", icon="RENDER_STILL")


class RELRAY_PT_world_stars(RelrayPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    """World › Stars: the real star sky (``scene.stars`` of the job)."""

    bl_label = "Stars"
    bl_context = "world"

    @classmethod
    def poll(cls, context):
        return context.world is not None and super().poll(context)

    def draw_header(self, context):
        self.layout.prop(context.world.relray, "use_stars", text="")

    def draw(self, context):
        layout = self.layout
        s = context.world.relray
        layout.use_property_split = True
        layout.active = s.use_stars
        layout.prop(s, "star_magnitude_limit")
        layout.prop(s, "star_brightness")
        layout.label(text="Hipparcos-2: blackbody stars at infinity, aberrated and "
                          "Doppler-shifted", icon="INFO")


class RELRAY_PT_sampling(RelrayPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Sampling"
    bl_context = "render"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        rs = context.scene.relray
        heading = layout.column(heading="Noise Threshold", align=True)
        row = heading.row(align=True)
        row.prop(rs, "use_adaptive_sampling", text="")
        sub = row.row()
        sub.active = rs.use_adaptive_sampling
        sub.prop(rs, "adaptive_threshold", text="")
        layout.prop(rs, "samples", text="Max Samples" if rs.use_adaptive_sampling else
                    "Samples")
        layout.prop(rs, "preview_samples")
        layout.prop(rs, "max_depth")
        layout.prop(rs, "clamp")
        layout.prop(rs, "seed")
        layout.prop(rs, "threads")


class RELRAY_PT_relativity_summary(RelrayPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Relativity"
    bl_context = "render"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        rs = context.scene.relray
        layout.prop(rs, "spectral")
        col = layout.column(heading="Light")
        col.prop(rs, "doppler")
        col.prop(rs, "searchlight")
        obj = context.scene.camera
        box = layout.box()
        if obj is None or obj.type != "CAMERA":
            box.label(text="No active camera", icon="ERROR")
        else:
            s = obj.data.relray
            box.label(text=f"{obj.name}: {s.mode.lower()}, γ {s.gamma:.4f}, ct' {s.ct:.4g}",
                      icon="CAMERA_DATA")
            box.label(text=view_readout(context, obj.data))
        draw_farm(layout, context)


def draw_farm(layout, context) -> None:
    """Export for Farm, Render on Farm, and the farm run's status while it renders."""
    from .operators import active_farm_run
    from .properties import addon_preferences

    row = layout.row(align=True)
    row.operator("relray.export_farm", icon="EXPORT")
    row.operator("relray.render_farm", icon="NETWORK_DRIVE")
    run = active_farm_run()
    if run is not None:
        layout.label(text=run.progress.status_text(), icon="TIME")
    else:
        prefs = addon_preferences(context)
        where = prefs.scheduler.strip() if prefs is not None else ""
        layout.label(text=f"Farm: {where or 'this machine'} (add-on preferences)",
                     icon="PREFERENCES")


class RELRAY_PT_film(RelrayPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Film"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(context.scene.render, "film_transparent")
        layout.prop(context.scene.relray, "auto_exposure")


class RELRAY_PT_passes(RelrayPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Passes"
    bl_context = "view_layer"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        vl = context.view_layer
        col = layout.column(heading="Include")
        col.prop(vl, "use_pass_combined")
        col.prop(vl, "use_pass_z")
        col.prop(vl.relray, "use_pass_doppler")
        col.prop(vl.relray, "use_pass_lab_time")
        col.prop(vl.relray, "use_pass_denoising")


class RELRAY_PT_light(RelrayPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Light"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return context.light is not None and super().poll(context)

    def draw(self, context):
        layout = self.layout
        light = context.light
        layout.row().prop(light, "type", expand=True)
        layout.use_property_split = True
        layout.prop(light, "color")
        layout.prop(light, "energy", text="Power" if light.type != "SUN" else "Strength")
        if hasattr(light, "exposure"):
            layout.prop(light, "exposure")
        if light.type in ("POINT", "SPOT"):
            layout.prop(light, "shadow_soft_size", text="Radius")
        elif light.type == "AREA":
            layout.prop(light, "shape")
            sub = layout.column(align=True)
            if light.shape in ("SQUARE", "DISK"):
                sub.prop(light, "size")
            else:
                sub.prop(light, "size", text="Size X")
                sub.prop(light, "size_y", text="Y")


classes = (
    RELRAY_PT_scene_relativity,
    RELRAY_PT_camera_relativity,
    RELRAY_PT_object_relativity,
    RELRAY_PT_world_sky,
    RELRAY_PT_world_stars,
    RELRAY_PT_relativity_summary,
    RELRAY_PT_sampling,
    RELRAY_PT_film,
    RELRAY_PT_passes,
    RELRAY_PT_light,
)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    for panel in compat_panels():
        if ENGINE not in panel.COMPAT_ENGINES:
            panel.COMPAT_ENGINES.add(ENGINE)
            _added_to.append(panel)


def unregister() -> None:
    for panel in _added_to:
        panel.COMPAT_ENGINES.discard(ENGINE)
    _added_to.clear()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
