"""Rendering: from a scene and a shutter event to a film of per-pixel sums.

Owns the relativistic pinhole camera (:mod:`.camera`), the Embree accelerator
(:mod:`.accel`), samplers and warps (:mod:`.sampling`), BSDF lobes (:mod:`.bsdf`), the
light table and light sampling (:mod:`.lights`), the kernels' spectral tables
(:mod:`.materials`), the wavefront path tracer (:mod:`.integrator`), the film
(:mod:`.film`) and one frame's work split over threads (:mod:`.frames`).

May import: :mod:`relray.core.physics`, :mod:`relray.core.scene`,
:mod:`relray.core.errors`, :mod:`relray.core.jit`.
"""
