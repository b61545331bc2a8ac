"""How the core's kernels are compiled: numba's ``njit`` with one rule for inlining.

A helper that a kernel must have inlined (the SIMD lanes' loops, the shading's device
functions, the physics' per-ray formulas) is declared ``njit(..., forceinline=True)``:
it is typed and lowered once per signature as a function of its own, marked
``alwaysinline``, and LLVM inlines it into every caller while it optimises the module, so
the caller's constants (a kind of scene, a lane count) still fold into it (its loops are
another matter: "Loops" below). Such a helper
compiles without reference counting (``_nrt=False``): it borrows its caller's arrays and
makes none on the heap, so an inlined call costs no atomic increment. Its floating-point
flags are its own, compiled once (it cannot take each caller's flags as an IR copy did):
exact IEEE arithmetic unless it says otherwise. The render kernels' own modules
(``integrator``, ``whole_paths``, ``lane_paths``, ``bsdf``, ``lights``, ``textures``,
``environment``, ``arcs``) give theirs :data:`FAST_MATH` (``@njit(**INLINE_FAST)``);
the physics, the camera and the samplers stay exact (``@njit(**INLINE)``), so a formula
gives the same bits inlined into a vector loop as called alone (``tests/test_camera.py``,
``tests/test_textures.py``).

numba's own ``inline="always"`` copies the callee's IR into each call site before typing
instead. numba 0.68 deep-copies the callee's whole variable scope once for each of its
blocks there (numba issues #8989 and #9204; numba-cuda #688 measures the same), so a
kernel of nested inlined helpers spent three quarters of its compile time copying IR: a
kind of SIMD-lane kernel took 44 s to compile, 13 s with ``forceinline`` (issue 12).

Loops. A helper inlined by LLVM was optimised as a function of its own first, where its
arrays are arguments that may alias and its loops are all it has: the loop vectoriser has
already decided on them (and marked them ``llvm.loop.isvectorized``, so the caller's
optimiser leaves them alone), and its branches and inner loops are already shaped, so a
loop over the SIMD lanes around such a call may stay scalar. So the lanes' own loops
(``lane_paths._LANES``) and the helpers they call per lane that have loops and branches of
their own (the environment map's lookups and sampling, the lights' selection and
sampling: ``@njit(**INLINE_IR)``) keep numba's ``inline="always"``: their IR is copied
into the lane kernel before typing, with the kernel's flags, and LLVM optimises each lane
loop as one piece. Their calls to ``forceinline`` helpers stay calls in numba's IR, so
the copies stay small. Measured (issue 12, ``bench.ab``, environment-lit scene, 128², 64
spp, 1 thread, 10 alternated pairs): everything ``forceinline`` 1.21× the CPU per path of
everything ``inline="always"``; with these IR-inlined 0.89× the all-``forceinline``
code (0.85× for everything IR-inlined), the kernel's LLVM IR 15640 → 12481 lines (its
42 scalar square roots vector ones), its compile about 17 s longer. The cost: every
kernel that calls these helpers copies their IR, the whole-path and wavefront kernels
too, so the warm-up from an empty cache took 571 s instead of about 270 s (both with the
other core busy).

Every other function says ``forceinline=False``: numba lets a callee inherit
``forceinline``, ``_nrt`` and ``fastmath`` from whichever function's compilation reaches
it first, so without it a helper would be inlined or called depending on which kernel
happened to compile first (and an inlined helper's flags would).
"""

from __future__ import annotations

from typing import Any

import numba

#: The render kernels' fast-math flags (the shading, whole paths, the SIMD lanes): without
#: ``nnan``/``ninf``, so NaN and infinity checks keep their meaning.
FAST_MATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

#: The options of an inlined helper with exact arithmetic (the physics, the camera, the
#: samplers): ``@njit(**INLINE)``. Cached, without the GIL, numpy's error model (a
#: division by zero gives inf or NaN, as in the kernels), ``alwaysinline``.
INLINE: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy",
                          "forceinline": True}

#: The options of an inlined helper of the render kernels' own modules (module
#: docstring): :data:`INLINE` with :data:`FAST_MATH`, ``@njit(**INLINE_FAST)``.
INLINE_FAST: dict[str, Any] = {**INLINE, "fastmath": FAST_MATH}

#: The options of a helper that the SIMD lanes call inside their loops over the lanes
#: (module docstring, "Loops"): numba's IR inlining, with the kernels' :data:`FAST_MATH`
#: where it is called on its own, ``@njit(**INLINE_IR)``.
INLINE_IR: dict[str, Any] = {**INLINE_FAST, "forceinline": False, "inline": "always"}


def njit(*args: Any, **options: Any) -> Any:
    """``numba.njit`` with ``forceinline=False`` unless given; a ``forceinline=True``
    helper with ``_nrt=False`` and ``fastmath=False`` unless given (module docstring)."""
    options.setdefault("forceinline", False)
    if options["forceinline"]:
        options.setdefault("_nrt", False)
        options.setdefault("fastmath", False)
    return numba.njit(*args, **options)
