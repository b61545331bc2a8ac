"""Which spectral model a job renders with: ``render.spectral = "auto"`` resolved.

The opt-in ``"auto"`` renders with the ``rgb`` model when nothing in the job shifts a
wavelength, and with ``cie1931`` otherwise. A lane's lab wavelength is λ_lab = D·λ_cam,
D the product of the Doppler factors along its path (the camera's,
D = 1/(γ(1 − β·d')) in the camera frame, and D_u, D_out at every moving body), so

    D ≡ 1 on every path  ⇔  doppler = false,
                            or β = 0 in every frame rendered and no body moves.

Then a spectral render adds only colour fidelity, which the rgb model gives up for speed
(bench/RESULTS.md §5, "rgb when Doppler is off"). What changes (physics.md, "Spectral
model"): the rgb model multiplies reflectances channel by channel, so light that
bounced more than once takes a different colour (about 1–3 ΔE00 in the indirect light
of the Cornell box, bench/RESULTS.md §2); direct light of an RGB emitter on an RGB
material keeps its colour, and spectral emitters (blackbody, lines, tabulated spectra,
spectral environment maps) become their rest-frame Rec.709 colour. ``spectral-exr``
output needs a spectral model, so it keeps ``cie1931``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from . import gltf
from .description import Job
from .motion import frame_events
from .worldlines import is_moving

AUTO = "auto"


def has_moving_bodies(job: Job) -> bool:
    """Whether a body of the job moves: an object with a ``velocity`` or a ``worldline``,
    or a glTF mesh node with one in its ``extras.relray`` (exactly when the scene has
    velocity groups, :func:`.worldlines.rest_frame_offsets`). Read from the job and the
    glTF's JSON part only: no mesh or BVH is built."""
    if any(is_moving(obj) for obj in job.scene.objects):
        return True
    return job.scene.file is not None and gltf.has_moving_nodes(job.scene.file,
                                                                job_file=job.path)


def resolve(job: Job) -> tuple[str, str]:
    """(model, reason) for ``job`` (``render.spectral`` as given unless it is "auto")."""
    given = job.render.spectral
    if given != AUTO:
        return given, "as given"
    if "spectral-exr" in job.output.formats:
        return "cie1931", "spectral-exr output needs spectra"
    if not job.render.doppler:
        return "rgb", "doppler = false: no wavelength shifts"
    if has_moving_bodies(job):
        return "cie1931", "moving bodies shift wavelengths"
    if any(np.any(np.asarray(ev.beta) != 0.0) for _, ev in frame_events(job)):
        return "cie1931", "the camera moves: Doppler shifts wavelengths"
    return "rgb", "nothing moves: no wavelength shifts"


def resolved_job(job: Job) -> Job:
    """``job`` with ``render.spectral`` resolved (:func:`resolve`); the same job when it
    was not "auto". The one place "auto" is decided: the drivers call it once on the job
    they render, and :func:`..render.frames.build_renderer` on a job given as is."""
    model, _ = resolve(job)
    if model == job.render.spectral:
        return job
    return replace(job, render=replace(job.render, spectral=model))
