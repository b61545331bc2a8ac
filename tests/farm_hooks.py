"""Fault injection for the farm tests: a Dask worker preload, not part of relray.

Load it into every worker of a cluster with the Dask setting
``distributed.worker.preload`` (:data:`PRELOAD_ENV`: the environment form, which worker
processes started by a LocalCluster, a ``relray render --workers N`` child or a nanny
restart all read). It wraps :func:`relray.core.farm.worker_renderer` so that, read from
the worker's environment at each render:

- ``RELRAY_TEST_CRASH_FRAME=N``: rendering frame N raises ``RuntimeError`` half-way,
  every time;
- ``RELRAY_TEST_PAUSE_FRAME=N:FLAG``: the first process to reach the middle of frame N
  writes its process id to the file FLAG (only if FLAG does not exist yet) and sleeps up
  to :data:`PAUSE_SECONDS`, so a test can kill it mid-frame.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

CRASH_ENV = "RELRAY_TEST_CRASH_FRAME"
PAUSE_ENV = "RELRAY_TEST_PAUSE_FRAME"
PAUSE_SECONDS = 60.0
PRELOAD_ENV = {"DASK_DISTRIBUTED__WORKER__PRELOAD": json.dumps([str(Path(__file__))])}


def _hook(frame: int, total: int, progress):
    """The progress callback that injects the fault of the environment, or ``progress``."""
    crash = os.environ.get(CRASH_ENV, "").strip()
    pause_frame, _, flag = os.environ.get(PAUSE_ENV, "").strip().partition(":")
    crash_frame = int(crash) if crash else None
    if crash_frame != frame and (not pause_frame or int(pause_frame) != frame):
        return progress
    seen, fired = [0], [False]

    def hook(n: int) -> None:
        if progress is not None:
            progress(n)
        seen[0] += n
        if fired[0] or 2 * seen[0] < total:
            return
        fired[0] = True
        if crash_frame == frame:
            raise RuntimeError(f"{CRASH_ENV}: frame {frame} crashes (test hook)")
        flag_path = Path(flag)
        if flag and not flag_path.exists():
            tmp = flag_path.with_name(flag_path.name + f".{os.getpid()}")
            tmp.write_text(str(os.getpid()))
            os.replace(tmp, flag_path)
            time.sleep(PAUSE_SECONDS)

    return hook


class _Faulty:
    """A FrameRenderer whose render() takes the hook of the environment."""

    def __init__(self, renderer, job) -> None:
        self._renderer, self._job = renderer, job

    def __getattr__(self, name):
        return getattr(self._renderer, name)

    def render(self, event, frame, progress=None, samples=None, **kwargs):
        s = self._job.render
        n = (samples[1] - samples[0]) if samples is not None else s.spp
        return self._renderer.render(event, frame,
                                     progress=_hook(frame, s.width * s.height * n, progress),
                                     samples=samples, **kwargs)


def install() -> None:
    from relray.core import farm

    if getattr(farm.worker_renderer, "_faulty", False):
        return
    real = farm.worker_renderer

    def worker_renderer(job, run_id, threads):
        return _Faulty(real(job, run_id, threads), job)

    worker_renderer._faulty = True
    farm.worker_renderer = worker_renderer


def dask_setup(worker) -> None:  # the preload entry point
    install()
