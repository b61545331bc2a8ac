"""Blender's view Curves and view Gamma on a PNG (``output.view_transform``).

Blender's colour management (Render Properties › Color Management) draws an image as

    x  --curves-->  x'  --× 2^exposure, look, view, display (OCIO)-->  v  --gamma-->  v^(1/g)

per pixel, on the scene-linear, alpha-premultiplied values: the RGB curves act on the
scene-linear values *before* the exposure and the view transform; the gamma is a power on
the display values *after* them. This order was measured against Blender (bpy 5.0's
``Image.save_render``, which F12's "Save as Render" uses): a ramp through Standard or AgX
with gamma 1.6 matches ``v^(1/1.6)`` within 0.16 of an 8-bit code, and curves applied
to the scene-linear values first match to 0.02 code (tests/blender/test_parity.py checks
a whole render).

The curves (:class:`..scene.description.DisplayCurves`, baked from Blender's
``CurveMapping`` by the add-on's farm export): per channel c,

    u_c     = (x_c - black_c) / (white_c - black_c)          (black and white levels)
    x'_c    = T_c(u_c)

where T_c is the channel's curve followed by the combined "C" curve, C(curve_c(u)),
tabulated at evenly spaced u over ``u_ranges[c]`` and linearly interpolated between the
samples, as Blender's own 257-entry table (its ``premultiplied`` table) is; outside
that range it continues along a straight line from the end value with ``slopes_c``
(0: the end value holds, Blender's Extend Horizontal; Extend Extrapolated multiplies
the channel curve's end slope by the combined curve's, as Blender does).
"""

from __future__ import annotations

import numpy as np

from ..scene.description import DisplayCurves

__all__ = ["apply_curves", "apply_gamma"]


def _table(u: np.ndarray, values: np.ndarray, u_range: tuple[float, float],
           slopes: tuple[float, float]) -> np.ndarray:
    """T(u): linear interpolation of ``values`` (evenly over ``u_range``), continued by
    straight lines of ``slopes`` (below, above) outside it."""
    u0, u1 = u_range
    grid = np.linspace(u0, u1, values.size)
    out = np.interp(u, grid, values)
    out = np.where(u < u0, values[0] + (u - u0) * slopes[0], out)
    return np.where(u > u1, values[-1] + (u - u1) * slopes[1], out)


def apply_curves(rgb: np.ndarray, curves: DisplayCurves) -> np.ndarray:
    """x' = T_c((x - black_c) / (white_c - black_c)) for each channel of scene-linear
    ``rgb`` (..., 3), in float64 (module docstring)."""
    rgb = np.asarray(rgb, np.float64)
    out = np.empty_like(rgb)
    for c in range(3):
        u = (rgb[..., c] - curves.black[c]) / (curves.white[c] - curves.black[c])
        out[..., c] = _table(u, np.asarray(curves.tables[c], np.float64), curves.u_ranges[c],
                             curves.slopes[c])
    return out


def apply_gamma(display: np.ndarray, gamma: float) -> np.ndarray:
    """v^(1/gamma) of display values (negative values become 0), Blender's view Gamma."""
    v = np.maximum(np.asarray(display, np.float64), 0.0)
    return v if gamma == 1.0 else v ** (1.0 / float(gamma))
