"""The warm-up (core/warmup.py) compiles what a render uses: its scenes pass the compiled
kernels the same argument types as the presets' (a read-only array, another dtype or
layout would be a new signature, compiled at the first render instead of read from the
kernel cache)."""

from pathlib import Path

import numba
import pytest

from relray.core import warmup
from relray.core.render.frames import prepare
from relray.core.scene.geometry import build_scene
from relray.core.scene.job import load_job, parse_job

PRESETS = Path(__file__).resolve().parent.parent / "presets"


def kernel_types(job) -> numba.types.Type:
    """The numba type of the kernel scene of ``job`` (what ``shade`` is typed by)."""
    prep = prepare(build_scene(job), job.render.spectral)
    return numba.typeof(prep.kernel)


@pytest.mark.parametrize("preset", ["cornell.toml", "moving/terrell.toml"])
def test_a_preset_passes_the_kernels_the_types_the_warm_up_compiled(preset):
    warm = {kernel_types(parse_job(d, Path("warmup.toml"))) for d in warmup.warmup_jobs()}
    assert kernel_types(load_job(PRESETS / preset)) in warm


def test_the_warm_up_renders_a_scene_that_takes_whole_paths():
    """The Cornell box's integrator (render/whole_paths.py) is compiled by the warm-up too,
    with the argument types the preset passes it."""
    from relray.core.render import whole_paths

    def whole(job):
        prep = prepare(build_scene(job), job.render.spectral)
        if not whole_paths.applies(prep.kernel, prep.tracer, False):
            return None
        return tuple(numba.typeof(a) for a in whole_paths.scene_args(prep.kernel, prep.tracer))

    warm = {whole(parse_job(d, Path("warmup.toml"))) for d in warmup.warmup_jobs()} - {None}
    assert warm and whole(load_job(PRESETS / "cornell.toml")) in warm
