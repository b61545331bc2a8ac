"""The add-on's actions: velocity keyframes, motion presets, export for farm.

(No ``from __future__ import annotations`` here: Blender reads the operators'
property annotations as objects.)
"""

from pathlib import Path

import bpy
from bpy.props import BoolProperty, IntProperty, StringProperty


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
        from ..core.errors import UserError
        from .export import ExportError
        from .farm import FarmExportError, export_farm
        from .motion import MotionError

        if not self.directory:
            self.report({"ERROR"}, "no export directory given")
            return {"CANCELLED"}
        frames = None if self.use_frame_range else (self.frame_start, self.frame_end)
        try:
            result = export_farm(context, bpy.path.abspath(self.directory), frames)
        except (FarmExportError, ExportError, MotionError, UserError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        for message in result.warnings:
            self.report({"WARNING"}, message)
        self.report({"INFO"}, f"wrote {result.job_path} (frames {result.frames[0]}-"
                              f"{result.frames[1]}); render with: relray render "
                              f"{result.job_path}")
        return {"FINISHED"}


classes = (
    RELRAY_OT_add_velocity_keyframe,
    RELRAY_OT_load_motion_preset,
    RELRAY_MT_motion_presets,
    RELRAY_OT_export_farm,
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
