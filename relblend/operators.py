"""The add-on's actions: velocity keyframes, motion presets, export for farm, render on farm.

(No ``from __future__ import annotations`` here: Blender reads the operators'
property annotations as objects.)
"""

import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import bpy
from bpy.props import BoolProperty, FloatProperty, IntProperty, StringProperty

if TYPE_CHECKING:
    from .farm import FarmExport
    from .farm_run import FarmRun


def _export_errors() -> tuple[type[Exception], ...]:
    """The errors of an export that are the user's to fix (reported, not raised)."""
    from ..core.errors import UserError
    from .export import ExportError
    from .farm import FarmExportError
    from .motion import MotionError

    return (FarmExportError, ExportError, MotionError, UserError)


def _camera_data(context):
    """The camera whose Relativity settings an operator acts on."""
    cam = getattr(context, "camera", None)
    if cam is not None:
        return cam
    obj = context.scene.camera
    return obj.data if obj is not None and obj.type == "CAMERA" else None


class RELRAY_OT_add_velocity_keyframe(bpy.types.Operator):  # noqa: N801 - Blender naming
    """Keyframe the camera's velocity (β, or speed and direction) and ct' at this frame"""

    bl_idname = "relray.add_velocity_keyframe"
    bl_label = "Add Velocity Keyframe"
    bl_options = {"REGISTER", "UNDO"}

    linear: BoolProperty(name="Linear", default=True,
                         description="Linear interpolation, as the job format's keyframes")
    include_ct: BoolProperty(name="Include ct'", default=True,
                             description="Keyframe ct' too")

    @classmethod
    def poll(cls, context):
        return _camera_data(context) is not None

    def execute(self, context):
        from .presets import set_linear

        cam = _camera_data(context)
        s = cam.relray
        frame = context.scene.frame_current
        paths = ["relray.beta"] if s.velocity_input == "VECTOR" \
            else ["relray.speed", "relray.direction"]
        if self.include_ct:
            paths.append("relray.ct")
        for path in paths:
            cam.keyframe_insert(path, frame=frame)
            if self.linear:
                set_linear(cam, path)
        self.report({"INFO"}, f"keyed {', '.join(p[7:] for p in paths)} at frame {frame}")
        return {"FINISHED"}


class RELRAY_OT_speed_of_light_preset(bpy.types.Operator):  # noqa: N801 - Blender naming
    """Set the scene's speed of light (a value in m/s, turned into scene units per second
    by the scene's unit scale)"""

    bl_idname = "relray.speed_of_light_preset"
    bl_label = "Speed of Light Preset"
    bl_options = {"REGISTER", "UNDO"}

    meters_per_second: FloatProperty(name="m/s", min=1e-6, default=299_792_458.0)

    def execute(self, context):
        scene = context.scene
        scale = scene.unit_settings.scale_length or 1.0
        scene.relray.speed_of_light = self.meters_per_second / scale
        return {"FINISHED"}


class RELRAY_OT_load_motion_preset(bpy.types.Operator):  # noqa: N801 - Blender naming
    """Apply a motion profile (presets/motion/*.toml) to the camera: mode, β keyframes, ct'"""

    bl_idname = "relray.load_motion_preset"
    bl_label = "Load Motion Preset"
    bl_options = {"REGISTER", "UNDO"}

    filepath: StringProperty(name="File", subtype="FILE_PATH")

    @classmethod
    def poll(cls, context):
        return _camera_data(context) is not None

    def execute(self, context):
        from ..core.errors import UserError
        from .presets import load_preset

        try:
            motion = load_preset(context.scene, _camera_data(context), self.filepath)
        except UserError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self.report({"INFO"}, f"motion preset {Path(self.filepath).name}: {motion.mode}, "
                              f"frames {motion.frames[0]}-{motion.frames[1]}")
        return {"FINISHED"}


class RELRAY_MT_motion_presets(bpy.types.Menu):  # noqa: N801 - Blender naming
    """The motion profiles shipped in presets/motion."""

    bl_idname = "RELRAY_MT_motion_presets"
    bl_label = "Motion Presets"

    def draw(self, context):
        from .presets import motion_presets, preset_label

        layout = self.layout
        files = motion_presets()
        if not files:
            layout.label(text="No motion presets found")
        for path in files:
            op = layout.operator(RELRAY_OT_load_motion_preset.bl_idname,
                                 text=preset_label(path))
            op.filepath = str(path)


class RELRAY_OT_bake_sky(bpy.types.Operator):  # noqa: N801 - Blender naming
    """Render the world's procedural sky (Sky Texture, any nodes) into an environment map
    for the Relativistic engine (Cycles, once per setting)"""

    bl_idname = "relray.bake_sky"
    bl_label = "Bake Sky"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        from .sky_bake import is_procedural

        return context.scene.world is not None and is_procedural(context.scene.world)

    def execute(self, context):
        from .sky_bake import bake

        path = bake(context.scene.world)
        self.report({"INFO"}, f"Baked the sky into {path}")
        return {"FINISHED"}


class RELRAY_OT_export_farm(bpy.types.Operator):  # noqa: N801 - Blender naming
    """Write scene.glb and a job TOML with every frame's β and ct' for `relray render`"""

    bl_idname = "relray.export_farm"
    bl_label = "Export for Farm"
    bl_options = {"REGISTER"}

    directory: StringProperty(name="Directory", subtype="DIR_PATH")
    use_frame_range: BoolProperty(name="Scene Frame Range", default=True)
    frame_start: IntProperty(name="Start", default=1)
    frame_end: IntProperty(name="End", default=1)

    @classmethod
    def poll(cls, context):
        return context.scene.camera is not None

    def invoke(self, context, event):
        if not self.directory:
            base = Path(bpy.path.abspath("//")) if bpy.data.filepath else Path.home()
            self.directory = str(base / "relray_farm")
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        from .farm import export_farm

        if not self.directory:
            self.report({"ERROR"}, "no export directory given")
            return {"CANCELLED"}
        frames = None if self.use_frame_range else (self.frame_start, self.frame_end)
        try:
            result = export_farm(context, bpy.path.abspath(self.directory), frames)
        except _export_errors() as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        for message in result.warnings:
            self.report({"WARNING"}, message)
        self.report({"INFO"}, f"wrote {result.job_path} (frames {result.frames[0]}-"
                              f"{result.frames[1]}); render with: relray render "
                              f"{result.job_path}")
        return {"FINISHED"}


#: Seconds between two polls of a farm run (the modal timer).
FARM_TIMER_SECONDS = 0.25
#: The farm run in progress (at most one per Blender session).
_FARM_RUNS: list["FarmRun"] = []


def active_farm_run() -> "FarmRun | None":
    """The farm run still in progress, or None."""
    run = _FARM_RUNS[0] if _FARM_RUNS else None
    return run if run is not None and not run.progress.finished else None


def farm_directory(prefs) -> Path:
    """The preferences' farm folder; by default relray_farm beside the .blend file (the
    temp folder's for an unsaved file)."""
    raw = (prefs.farm_directory.strip() if prefs is not None else "") or "//relray_farm"
    if raw.startswith("//") and not bpy.data.filepath:
        return Path(tempfile.gettempdir()) / (raw[2:].strip("/\\") or "relray_farm")
    return Path(bpy.path.abspath(raw)).expanduser()


def start_farm_render(context, directory: str | Path, scheduler: str = "",
                      overwrite: bool = False, connect_timeout: float | None = None,
                      env: dict[str, str] | None = None) -> tuple["FarmRun", "FarmExport"]:
    """Export the scene's job into ``directory`` and launch ``relray render`` on it.

    Returns (the :class:`.farm_run.FarmRun`, the :class:`.farm.FarmExport`). Resume is
    the core's (``relray render`` compares each frame's recorded digest): frames the
    changed scene would draw differently render again, the others (a cancelled run's,
    an unchanged export's, those of an extended frame range) are kept.
    """
    from .farm import export_farm
    from .farm_run import start_render

    result = export_farm(context, directory)
    run = start_render(result.job_path, scheduler, overwrite, connect_timeout, env)
    _FARM_RUNS[:] = [run]
    return run, result


def show_farm_status(context, text: str | None) -> None:
    """The run's status line in the status bar and the editor's header (None: clear)."""
    workspace = getattr(context, "workspace", None)
    if workspace is not None:
        workspace.status_text_set(text)
    area = getattr(context, "area", None)
    if area is not None:
        area.header_text_set(text)
    screen = getattr(context, "screen", None)
    for other in screen.areas if screen is not None else ():
        if other.type == "PROPERTIES":  # the Render tab's status line
            other.tag_redraw()


class RELRAY_OT_render_farm(bpy.types.Operator):  # noqa: N801 - Blender naming
    """Export the farm job and render it with `relray render` in a separate process"""

    bl_idname = "relray.render_farm"
    bl_label = "Render on Farm"
    bl_description = ("Export the farm job and render it with `relray render` in a separate "
                      "process: on this machine, or on the Dask scheduler set in the add-on's "
                      "preferences. Esc cancels")
    bl_options = {"REGISTER"}

    overwrite: BoolProperty(
        name="Overwrite", default=False,
        description="Render every frame again (otherwise only frames whose scene, settings "
                    "or renderer changed, and missing ones, are rendered)")

    @classmethod
    def poll(cls, context):
        return context.scene.camera is not None and active_farm_run() is None

    def _start(self, context):
        """Export and launch; None (and an error report) when that fails."""
        from .farm_run import FarmRunError
        from .properties import addon_preferences

        prefs = addon_preferences(context)
        scheduler = prefs.scheduler.strip() if prefs is not None else ""
        timeout = prefs.connect_timeout if prefs is not None else None
        try:
            run, result = start_farm_render(context, farm_directory(prefs), scheduler,
                                            self.overwrite, timeout)
        except (*_export_errors(), FarmRunError, OSError) as e:
            self.report({"ERROR"}, str(e))
            return None
        for message in result.warnings:
            self.report({"WARNING"}, message)
        self.report({"INFO"}, f"relray farm: rendering {result.job_path} (frames "
                              f"{result.frames[0]}-{result.frames[1]}) on "
                              f"{scheduler or 'this machine'}")
        return run

    def _finish(self, run):
        """Report how the run ended: frames done, failed frames, the user error, cancelled."""
        level, message = run.progress.outcome()
        self.report({level}, message)
        return {"FINISHED"} if run.progress.state == "done" else {"CANCELLED"}

    def execute(self, context):
        """Scripts and background mode (no event loop): render and wait for the end."""
        run = self._start(context)
        if run is None:
            return {"CANCELLED"}
        run.wait()
        return self._finish(run)

    def invoke(self, context, event):
        """Start the run and a modal timer that polls it (Blender's UI never waits)."""
        if context.window is None:
            return self.execute(context)
        run = self._start(context)
        if run is None:
            return {"CANCELLED"}
        self._run = run
        wm = context.window_manager
        self._timer = wm.event_timer_add(FARM_TIMER_SECONDS, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0.0, 1.0)
        show_farm_status(context, run.progress.status_text())
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        """TIMER: poll the run, show its progress; Esc: cancel it; other events pass."""
        run = self._run
        escape = event.type == "ESC" and event.value == "PRESS"
        if escape:
            run.cancel()
        elif event.type != "TIMER":
            return {"PASS_THROUGH"}
        progress = run.poll()
        context.window_manager.progress_update(progress.fraction)
        show_farm_status(context, progress.status_text())
        if progress.finished:
            self._end(context)
            return self._finish(run)
        return {"RUNNING_MODAL"} if escape else {"PASS_THROUGH"}

    def cancel(self, context):
        """Blender ends the operator (a file is loaded, Blender quits): stop the child."""
        self._run.cancel()
        self._end(context)

    def _end(self, context):
        """Remove the timer, the progress and the status text."""
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        show_farm_status(context, None)


classes = (
    RELRAY_OT_bake_sky,
    RELRAY_OT_add_velocity_keyframe,
    RELRAY_OT_speed_of_light_preset,
    RELRAY_OT_load_motion_preset,
    RELRAY_MT_motion_presets,
    RELRAY_OT_export_farm,
    RELRAY_OT_render_farm,
)


def _export_menu(self, context):
    self.layout.operator(RELRAY_OT_export_farm.bl_idname, text="relray Farm Job (.glb + .toml)")


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_export.append(_export_menu)


def unregister() -> None:
    bpy.types.TOPBAR_MT_file_export.remove(_export_menu)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
