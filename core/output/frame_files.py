"""A frame's files: their names, the metadata they record, whether a frame is already
done (resume), and writing a finished film.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..physics import relativity
from ..render.film import Film
from ..scene.description import Job
from ..scene.motion import frame_events
from .imageio import frame_complete, metadata_for, remove_stale_temps, write_frame


def frame_metadata(job: Job, frame: int, event: relativity.ShutterEvent) -> dict[str, str]:
    """What a finished frame records (and what resume compares)."""
    return metadata_for(frame, event.beta, float(event.tau), job.render.spp,
                        extra={"relray:spectral": job.render.spectral,
                               "relray:t_lab": repr(float(event.t)),
                               "relray:seed": str(job.render.seed)})


def frame_is_done(job: Job, frame: int, event: relativity.ShutterEvent) -> bool:
    """A frame is done when every requested file exists and its EXR says it is complete."""
    out = job.output
    stem = out.name.format(frame=frame)
    wanted = {"exr": f"{stem}.exr", "png": f"{stem}.png", "spectral-exr": f"{stem}.spectral.exr"}
    if not all((out.dir / wanted[f]).exists() for f in out.formats):
        return False
    if "exr" in out.formats:
        meta = frame_metadata(job, frame, event)
        keys = ("relray:spp", "relray:beta", "relray:ct", "relray:spectral", "relray:seed")
        return frame_complete(out.dir / wanted["exr"], {k: meta[k] for k in keys})
    return True


@dataclass
class FramePlan:
    """Which frames of a job's range still need rendering (resume), from :func:`plan_frames`."""

    frames: list[int]
    todo: list[tuple[int, relativity.ShutterEvent]]
    stale_temps_removed: int = 0

    @property
    def done(self) -> int:
        """Frames of the range already complete (skipped)."""
        return len(self.frames) - len(self.todo)


def plan_frames(job: Job, overwrite: bool = False) -> FramePlan:
    """The frames to render: all with ``overwrite``, else those not :func:`frame_is_done`.

    Also removes stale temporary files of interrupted writes from the output folder.
    """
    events = frame_events(job)
    todo = [(f, ev) for f, ev in events if overwrite or not frame_is_done(job, f, ev)]
    removed = remove_stale_temps(job.output.dir) if job.output.dir.exists() else 0
    return FramePlan([f for f, _ in events], todo, removed)


def write_film(job: Job, frame: int, event: relativity.ShutterEvent, film: Film,
               to_rgb: np.ndarray, seconds: float, d_range: tuple[float, float]) -> list:
    """Resolve ``film`` and write the frame's files atomically (EXR last); return the paths."""
    if film.nonfinite_samples:
        logging.getLogger("relray").warning("frame %d: %d non-finite samples dropped", frame,
                                            film.nonfinite_samples)
    image = film.resolve(to_rgb)
    meta = frame_metadata(job, frame, event)
    meta["relray:seconds"] = f"{seconds:.3f}"
    meta["relray:doppler_range"] = f"{d_range[0]:.6g},{d_range[1]:.6g}"
    return write_frame(job.output.dir, job.output.name.format(frame=frame), job.output.formats,
                       image, meta, job.output.exposure)
