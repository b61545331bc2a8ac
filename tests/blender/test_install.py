"""The extension installs from its zip into a fresh user directory and registers cleanly."""

from __future__ import annotations

import tomllib

import bpy
import pytest
import rendering
from conftest import EXT_MODULE, ext_module


def test_zip_installs_and_enables(installed):
    manifest = tomllib.loads((installed.path / "blender_manifest.toml").read_text())
    assert manifest["id"] == "relray"
    assert manifest["schema_version"] == "1.0.0"
    assert manifest["blender_version_min"] == "4.2.0"
    assert installed.path.is_relative_to(installed.user_dir)
    assert EXT_MODULE in bpy.context.preferences.addons.keys()
    assert (installed.path / "core" / "render" / "frames.py").is_file()
    assert (installed.path / "presets" / "motion").is_dir()
    print(f"install + enable: {installed.seconds * 1000:.0f} ms")


def test_engine_registered(ext):
    engines = rendering.engine_classes()
    assert "RELRAY" in engines and rendering.engine_available("RELRAY")
    cls = engines["RELRAY"]
    assert cls.bl_label == "Relativistic"
    assert cls.__module__ == f"{EXT_MODULE}.relblend.engine"  # relative imports throughout
    scene = bpy.context.scene
    scene.render.engine = "RELRAY"
    assert scene.render.engine == "RELRAY"


def test_properties_are_keyframeable(ext):
    bpy.ops.wm.read_homefile(use_empty=True)
    cam = bpy.data.cameras.new("c")
    for path in ("relray.beta", "relray.speed", "relray.direction", "relray.ct",
                 "relray.ct_per_frame"):
        assert cam.keyframe_insert(path, frame=1), path
    scene = bpy.context.scene
    for path in ("relray.doppler", "relray.searchlight", "relray.samples"):
        assert scene.keyframe_insert(path, frame=1), path
    cam.relray.beta = (0.3, 0.4, 0.0)
    assert cam.relray.gamma == pytest.approx(1 / 0.75**0.5)
    cam.relray.velocity_input = "SPEED"
    cam.relray.speed = 0.6
    assert cam.relray.gamma == pytest.approx(1.25)
    prop = cam.relray.bl_rna.properties["gamma"]
    assert prop.is_readonly
    beta = cam.relray.bl_rna.properties["beta"]
    assert beta.hard_max < 1.0 and beta.soft_max < beta.hard_max


def test_compat_panels(ext):
    for name in ("DATA_PT_lens", "DATA_PT_camera", "RENDER_PT_format", "RENDER_PT_frame_range",
                 "RENDER_PT_output", "RENDER_PT_color_management", "DATA_PT_context_light",
                 "EEVEE_MATERIAL_PT_surface", "EEVEE_WORLD_PT_surface"):
        assert "RELRAY" in getattr(bpy.types, name).COMPAT_ENGINES, name
    for name in ("DATA_PT_camera_dof", "VIEWLAYER_PT_layer_passes", "DATA_PT_light"):
        assert "RELRAY" not in getattr(bpy.types, name).COMPAT_ENGINES, name
    bpy.context.scene.render.engine = "RELRAY"
    assert bpy.types.RELRAY_PT_sampling.poll(bpy.context)
    bpy.context.scene.render.engine = "CYCLES"
    assert not bpy.types.RELRAY_PT_sampling.poll(bpy.context)


def test_disable_and_reenable_leave_no_trace(ext, cornell, engine):
    assert bpy.ops.preferences.addon_disable(module=EXT_MODULE) == {"FINISHED"}
    assert not hasattr(bpy.types.Camera, "relray")
    assert not hasattr(bpy.types, "RELRAY_PT_camera_relativity")
    assert "RELRAY" not in bpy.types.DATA_PT_lens.COMPAT_ENGINES
    assert not rendering.engine_available("RELRAY")
    handlers = [h.__module__ for h in bpy.app.handlers.render_init]
    assert not any(m.startswith(EXT_MODULE) for m in handlers)
    assert bpy.ops.preferences.addon_enable(module=EXT_MODULE) == {"FINISHED"}
    assert hasattr(bpy.types.Camera, "relray")
    assert "RELRAY" in bpy.types.DATA_PT_lens.COMPAT_ENGINES
    # The scene's settings survive (stored as ID properties), and it still renders.
    bpy.context.scene.render.engine = "RELRAY"
    bpy.ops.render.render()
    assert 1 in ext_module("relblend.engine").RESULTS


def test_extension_cli_validates_the_zip(installed):
    """Blender's own validator accepts the built zip (shallow, but Blender's tag list)."""
    import os
    import sys

    sys.path.append(os.path.join(bpy.utils.system_resource("SCRIPTS"), "addons_core"))
    from bl_pkg import bl_extension_cli

    assert bl_extension_cli.cli_extension_handler(
        ["validate", os.environ["RELRAY_TEST_ZIP"]]) == 0
