"""Rendering a job in this process: scene, renderer, then frame after frame to files.

The local default of ``relray render`` (the Dask variant is :mod:`.farm`): every core
on the frame in flight through the renderer's threads.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from .output.frame_files import exposure_chain, plan_frames, write_film
from .progress import default_reporter
from .render.frames import build_renderer
from .scene.description import Job
from .scene.geometry import build_scene
from .scene.motion import resolve_camera
from .scene.spectral_model import resolved_job


def render_job(job: Job, overwrite: bool = False, show_progress: bool = True,
               reporter=None, cancel: Callable[[], bool] | None = None) -> list:
    """Render every frame of ``job`` that is not already done; return the written paths.

    This is the local default: one process, frames one after another, every core on the
    frame in flight through the renderer's threads. ``reporter`` (a
    :class:`.farm.Reporter`) hears the plan ("N done, M to render"), the progress in
    paths, each finished frame and the end; by default a tqdm bar (nothing without
    ``show_progress``). ``cancel`` is polled between wavefronts; when it says True the
    frame in flight stops with :class:`RenderCancelled` (finished frames stay).

    Frames are written in frame order, so ``output.exposure = "auto"`` smooths its
    exposure over them (:func:`.output.frame_files.exposure_chain`; the frames done in an
    earlier run give their recorded meter readings, so resuming changes nothing).
    """
    reporter = reporter if reporter is not None else default_reporter(show_progress)
    t0 = time.perf_counter()
    plan = plan_frames(job, overwrite)  # digests of the input files before they are loaded
    scene = build_scene(job)
    resolve_camera(job, scene)
    job = resolved_job(job)  # render.spectral = "auto" (after the plan's digests)
    s = job.render
    reporter.start(job, plan, mode="local", units=len(plan.todo) * s.width * s.height * s.spp,
                   unit="path")
    written: list = []
    if plan.todo:
        renderer = build_renderer(job, scene)
        chain = exposure_chain(job, plan.frames)
        for frame, ev in plan.todo:
            film, stats = renderer.render(ev, frame, progress=reporter.advance, cancel=cancel)
            paths, exposure = write_film(job, frame, ev, film, renderer.to_rgb, stats.seconds,
                                         (stats.d_min, stats.d_max), plan.digests[frame], chain)
            written += paths
            reporter.frame_done(frame, paths, stats.seconds, (stats.d_min, stats.d_max),
                                exposure)
    reporter.finish("ok", time.perf_counter() - t0)
    return written
