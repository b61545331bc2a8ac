"""Physics: special relativity and colour, with no knowledge of scenes or images.

Owns γ, boosts, aberration, the Doppler factor, shutter events and worldlines
(:mod:`.relativity`); the lab-wavelength grid, colour-matching functions, hero-wavelength
sampling, emitter spectra and RGB → spectrum fits (:mod:`.spectrum`, :mod:`.sigmoid`,
:mod:`.cie_tables`).

May import: numpy, numba, :mod:`relray.core.errors`, :mod:`relray.core.jit` (how kernels
compile) and the core's cache folder. Nothing
else of the core imports into it (layering enforced by ``tests/test_layout.py``).
"""
