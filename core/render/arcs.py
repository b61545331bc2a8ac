"""Inverse trigonometric functions as straight-line polynomial code, for the SIMD lanes.

libm's ``acos`` and ``atan2`` are calls: a loop over the lanes (:mod:`.lane_paths`) that
makes one is not vectorised at all. These are selects and a polynomial each, so LLVM
compiles a loop of them to vector code, and one path at a time they cost less than the
calls (the environment map's direction → (u, v), :func:`.environment.direction_to_uv`).
Angles in radians, within 1e-15 (atan2) and 1.6e-15 (acos, whose reduction doubles
asin's error) of libm's; ``tests/test_arcs.py`` derives the bounds.

**arctan2(y, x)**: t = min(|x|, |y|) / max(|x|, |y|) ∈ [0, 1]; above tan(π/8),
atan t = π/4 + atan((t − 1)/(t + 1)), so the argument s has |s| ≤ tan(π/8) and

    atan s = s + s³ P(s²)     (P of degree 9, relative error ≤ 5e-16 on that interval);

then π/2 − a where |y| > |x|, π − a where x is negative (its sign bit: x = −0 too),
and y's sign (libm's conventions at the zeros: atan2(±0, −0) = ±π, atan2(±0, +0) = ±0).

**arccos(x)** (|x| ≤ 1): asin s = s + s³ Q(s²) for |s| ≤ ½ (Q of degree 10, relative
error ≤ 7e-16); acos x = π/2 − asin x for |x| ≤ ½, 2 asin √((1 − x)/2) above ½ and
π − 2 asin √((1 + x)/2) below −½ (1 ∓ x is exact there).

P and Q are least-squares fits of (atan s − s)/s³ and (asin s − s)/s³ in s² on 6000
Chebyshev nodes, weighted by s³/f(s) (the final relative error), made with numpy's
``polyfit`` for this module.
"""

from __future__ import annotations

import math

from ..jit import INLINE_FAST, njit

_ATAN = (-0.33333333333329085, 0.19999999998871204, -0.14285714181660486,
         0.1111110621800967, -0.09090774107201532, 0.07689968578188999,
         -0.06640360039477758, 0.056889588811723645, -0.043496458512633555,
         0.02115289894317583)
_ASIN = (0.16666666666682714, 0.07499999996309503, 0.04464286007581368,
         0.030381828568083222, 0.022374808389826587, 0.017314893882214195,
         0.01431648279962871, 0.009409344048751381, 0.01816880664664346,
         -0.011560543841850963, 0.03141689999050577)
_TAN_PI_8 = math.tan(math.pi / 8.0)
_QUARTER_PI = 0.25 * math.pi
_HALF_PI = 0.5 * math.pi


@njit(**INLINE_FAST)
def _odd_series(s, c):
    """s + s³ Σ_k c[k] s²ᵏ, by Horner's rule in s² (a loop of constant length: LLVM
    unrolls it, so a loop over lanes that calls this stays vector code)."""
    z = s * s
    p = 0.0
    for k in range(len(c) - 1, -1, -1):
        p = p * z + c[k]
    return s + s * z * p


@njit(**INLINE_FAST)
def arctan2(y, x):
    """The angle of (x, y) from +x, in [−π, π], as libm's ``atan2`` (module docstring)."""
    ax, ay = abs(x), abs(y)
    hi, lo = max(ax, ay), min(ax, ay)
    t = lo / hi if hi > 0.0 else 0.0
    big = t > _TAN_PI_8
    s = (t - 1.0) / (t + 1.0) if big else t
    a = _odd_series(s, _ATAN)  # atan s, |s| ≤ tan(π/8)
    a = a + _QUARTER_PI if big else a
    a = _HALF_PI - a if ay > ax else a
    a = math.pi - a if math.copysign(1.0, x) < 0.0 else a
    return math.copysign(a, y)


@njit(**INLINE_FAST)
def arccos(x):
    """acos x ∈ [0, π] for |x| ≤ 1 (module docstring)."""
    ax = abs(x)
    big = ax > 0.5
    s = math.sqrt(0.5 * (1.0 - ax)) if big else x
    a = _odd_series(s, _ASIN)  # asin s, |s| ≤ ½
    r = _HALF_PI - a
    r = 2.0 * a if big else r
    return math.pi - r if big and x < 0.0 else r
