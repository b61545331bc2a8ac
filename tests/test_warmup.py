"""The warm-up (core/warmup.py) compiles what a render uses: its scenes pass the compiled
kernels the same argument types as the presets' (a read-only array, another dtype or
layout would be a new signature, compiled at the first render instead of read from the
kernel cache)."""

from pathlib import Path

import numba
import pytest

from relray.core import warmup
from relray.core.render.frames import prepare
from relray.core.render.lane_paths import ANY_LIGHTS as ANY
from relray.core.render.lane_paths import BODIES
from relray.core.render.lane_paths import MAP_LIGHT as MAP
from relray.core.render.lane_paths import TRIANGLE_LIGHTS as TRI
from relray.core.render.rest_frames import MovingScene
from relray.core.scene.geometry import build_scene
from relray.core.scene.job import load_job, parse_job

PRESETS = Path(__file__).resolve().parent.parent / "presets"


def kernel_types(job) -> numba.types.Type:
    """The numba type of the kernel scene of ``job`` (what ``shade`` is typed by)."""
    prep = prepare(build_scene(job), job.render.spectral)
    return numba.typeof(prep.kernel)


@pytest.mark.parametrize("preset", ["cornell.toml", "moving/terrell.toml"])
def test_a_preset_passes_the_kernels_the_types_the_warm_up_compiled(preset, tmp_path):
    warm = {kernel_types(parse_job(d, tmp_path / "warmup.toml"))
            for d in warmup.warmup_jobs(tmp_path)}
    assert kernel_types(load_job(PRESETS / preset)) in warm


def whole_path_kernel(job):
    """The whole-path kernel a job's scene runs, as (map, textures, moving bodies,
    argument types); ("lanes", argument types) where it takes the SIMD lanes
    (render/lane_paths.py); None where it takes the wavefront (render/whole_paths.py)."""
    from relray.core.render import lane_paths, whole_paths

    prep = prepare(build_scene(job), job.render.spectral)
    if not whole_paths.applies(prep.kernel, prep.tracer, False):
        return None
    args = tuple(numba.typeof(a) for a in whole_paths.scene_args(prep.kernel, prep.tracer))
    if lane_paths.applies(prep.kernel, prep.tracer, False):
        return ("lanes", *lane_paths.kind(prep.kernel, prep.tracer), args)
    return (prep.kernel.env_on, prep.kernel.tex.enabled, isinstance(prep.tracer, MovingScene),
            args)


def test_the_warm_up_compiles_every_kind_of_whole_path_kernel(tmp_path):
    """The SIMD lanes compiled apart for flat or smooth shading, for emissive triangles,
    other lights too or the map alone, for textures, for a colour map and for moving
    bodies under lights at rest (``lane_paths.kernel``), and the whole-path kernel
    compiled apart for a scene without a light and for moving bodies under a sky
    (``whole_paths.kernel``; a spectral map's, or a map's with moving bodies, is compiled
    at its first render): the warm-up renders each kind, with the argument types the
    Cornell box (the lanes), a seed figure (a sky and smooth shading: the lanes' general
    kind), the stars (no light: the plain whole-path kernel), the default fly-by
    (textured, smooth, under a sky: the lanes) and the train and Terrell presets (moving
    bodies under a sky and a sun: whole paths) pass; moving bodies lit by a triangle take
    the lanes."""
    warm = {whole_path_kernel(parse_job(d, tmp_path / "warmup.toml"))
            for d in warmup.warmup_jobs(tmp_path)} - {None}
    assert {kind[:-1] for kind in warm} == {
        ("lanes", False, TRI, False, False, False), ("lanes", False, ANY, False, False, False),
        ("lanes", True, TRI, False, False, False), ("lanes", True, ANY, False, False, False),
        ("lanes", True, ANY, True, False, False), ("lanes", False, ANY, False, True, False),
        ("lanes", True, ANY, True, True, False), ("lanes", True, MAP, False, True, False),
        ("lanes", True, MAP, True, True, False), ("lanes", False, TRI, False, False, BODIES),
        (False, False, False), (False, False, True)}
    for preset in ("cornell.toml", "seed_figures/fig1-1.toml", "stars/ahead.toml",
                   "flyby.toml", "moving/train.toml", "moving/terrell.toml"):
        assert whole_path_kernel(load_job(PRESETS / preset)) in warm, preset
    assert whole_path_kernel(load_job(PRESETS / "cornell.toml"))[:6] == (
        "lanes", False, TRI, False, False, False)
    assert whole_path_kernel(load_job(PRESETS / "seed_figures/fig1-1.toml"))[:6] == (
        "lanes", True, ANY, False, False, False)
    assert whole_path_kernel(load_job(PRESETS / "flyby.toml"))[:6] == (
        "lanes", True, ANY, True, False, False)
    assert whole_path_kernel(load_job(PRESETS / "moving/train.toml"))[:3] == (
        False, False, True)
