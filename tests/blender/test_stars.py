"""World › Stars: the real star sky in F12, the export and the farm job."""

from __future__ import annotations

import math
import tomllib

import bpy
import numpy as np
import pytest
import rendering
from conftest import ext_module
from test_farm import core_render


def look_at_the_sky(scene) -> None:
    """The Cornell camera turned round: out of the open box, at the sky (RA 18h)."""
    cam = scene.camera
    cam.rotation_euler = (math.radians(90.0), 0.0, math.radians(180.0))
    cam.data.angle = math.radians(60.0)
    scene.render.resolution_x, scene.render.resolution_y = 64, 48
    scene.relray.samples = 4


def test_stars_render_in_f12_the_viewport_export_and_the_farm(cornell, engine, tmp_path):
    scene = cornell
    look_at_the_sky(scene)
    w = scene.world.relray
    assert w.use_stars is False  # off by default: a scene renders as before
    rendering.render_still(scene)
    dark = engine.RESULTS[1]["rgba"].copy()
    w.use_stars = True
    w.star_magnitude_limit = 6.0
    w.star_brightness = 10.0
    rendering.render_still(scene)
    lit = engine.RESULTS[1]["rgba"]

    # the same seed: the paths are the same, the stars only add light to sky pixels
    added = (lit - dark)[..., :3]
    assert added.min() >= -1e-6
    starry = added.max(axis=2) > 1e-4
    assert starry.sum() >= 20, starry.sum()
    assert np.array_equal(lit[..., 3], dark[..., 3])  # stars do not change alpha

    export = ext_module("relblend.export")
    stars_mod = ext_module("core.scene.stars")
    description = ext_module("core.scene.description")
    ex = export.export_scene(bpy.context.evaluated_depsgraph_get())
    assert ex.stars == description.StarsSettings("hipparcos", 6.0, 10.0)
    assert len(ex.scene.stars) == stars_mod.star_count(ex.stars) > 1000

    out = tmp_path / "farm"
    assert bpy.ops.relray.export_farm(directory=str(out)) == {"FINISHED"}
    doc = tomllib.loads((out / "job.toml").read_text())
    assert doc["scene"]["stars"] == {"catalog": "hipparcos", "magnitude_limit": 6.0,
                                     "brightness": pytest.approx(10.0)}
    rgba, _ = core_render(out / "job.toml", 1)
    # the farm's stars are where Blender's are, as bright (same catalogue, same camera)
    farm_starry = rgba[..., :3].max(axis=2) > 1e-4
    assert (farm_starry & starry).sum() >= 0.9 * starry.sum()
    np.testing.assert_allclose(rgba[starry, :3].sum(), lit[starry, :3].sum(), rtol=0.05)

    w.use_stars = False
    assert export.export_scene(bpy.context.evaluated_depsgraph_get()).scene.stars is None
