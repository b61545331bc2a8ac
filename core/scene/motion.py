"""The camera through an animation: which camera, which frames, β and the shutter event
of every frame (physics.md, "Camera worldline and the shutter event").

Lab frame throughout: positions and β are lab coordinates; ``ct`` is the camera's
proper time at the shutter.
"""

from __future__ import annotations

import numpy as np

from ..errors import UserError
from ..physics import relativity
from .description import Job
from .geometry import Scene
from .gltf import find_camera


def frame_events(job: Job) -> list[tuple[int, relativity.ShutterEvent]]:
    """The shutter event of every frame of the job (physics.md, "Camera worldline")."""
    mo = job.motion
    frames = frame_list(job)
    if mo.mode == "events":
        by_frame = dict(mo.events)
        return [(f, by_frame[f]) for f in frames]
    position = np.asarray(camera_settings(job).position, np.float64)
    if mo.mode == "worldline":
        events = relativity.worldline_events(
            position, mo.frames, mo.ct, mo.ct_per_frame,
            keyframes=mo.keyframes, beta_const=None if mo.keyframes else mo.beta,
            proper_acceleration=mo.proper_acceleration)
        by_frame = dict(zip(range(mo.frames[0], mo.frames[1] + 1), events, strict=True))
        return [(f, by_frame[f]) for f in frames]
    out = []
    for f in frames:
        ct = mo.ct + (f - mo.frames[0]) * mo.ct_per_frame
        out.append((f, relativity.snapshot_event(position, beta_at_frame(job, f), ct)))
    return out


def camera_settings(job: Job):
    """The job's [camera], else the glTF file's first camera (read from its JSON only).

    Raises a UserError naming ``camera`` when there is neither.
    """
    cam = job.camera
    if cam is None and job.scene.file is not None:
        cam = find_camera(job.scene.file, job_file=job.path)
    if cam is None:
        raise UserError("no camera: add a [camera] table or a camera to the glTF file",
                        key="camera", file=job.path)
    return cam


def resolve_camera(job: Job, scene: Scene):
    """The job's [camera], else the built scene's (glTF) camera, else a clear error."""
    return job.camera or scene.camera or camera_settings(job)


def frame_list(job: Job) -> list[int]:
    """The frames to render, first to last inclusive (``--frames`` or motion.frames)."""
    first, last = job.motion.render_frames or job.motion.frames
    return list(range(first, last + 1))


def beta_at_frame(job: Job, frame: int) -> np.ndarray:
    """Camera beta at ``frame``: keyframes linear in frame (held outside), else motion.beta."""
    keys = job.motion.keyframes
    if not keys:
        return np.array(job.motion.beta, dtype=np.float64)
    at = np.array([f for f, _ in keys], dtype=np.float64)
    betas = np.stack([b for _, b in keys])
    return np.array([np.interp(frame, at, betas[:, k]) for k in range(3)])
