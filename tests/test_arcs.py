"""The polynomial inverse trigonometric functions against numpy's (libm's)."""

import math
import re

import numpy as np
from numba import njit

from relray.core.render import arcs

# 1e-15 rad is about 2 ulp of π (4.4e-16 each): atan's polynomial error (≤ 5e-16
# relative) plus the reductions' rounding
TOL = 1e-15
_ULP_HALF, _ULP_PI = float(np.spacing(0.5)), float(np.spacing(math.pi))
# acos below −½ is π − 2 asin s with s = √((1 + x)/2) ≤ ½: the fit's relative error
# (≤ 7e-16) on asin s ≤ π/6, doubled; asin's last addition (½ ulp of ½) and the square
# root's rounding (½ ulp of s, times d asin/ds ≤ 2/√3), doubled; π − 2a rounded (½ ulp
# of π) with π itself rounded (math.pi is 1.2e-16 below π); and the reference's own
# rounding (½ ulp of π). Whether LLVM fuses the polynomial's steps (FMA) depends on the
# machine's vector width, so the rounding is not the same on every CPU.
TOL_ACOS = (2.0 * 7e-16 * math.pi / 6.0 + 2.0 * (0.5 + 0.5 * 2.0 / math.sqrt(3.0)) * _ULP_HALF
            + 0.5 * _ULP_PI + 1.23e-16 + 0.5 * _ULP_PI)


@njit(error_model="numpy")  # as the lane loops: a division never raises
def _atan2_all(y, x, out):
    for i in range(y.shape[0]):
        out[i] = arcs.arctan2(y[i], x[i])


@njit(error_model="numpy")  # as the lane loops: a division never raises
def _acos_all(x, out):
    for i in range(x.shape[0]):
        out[i] = arcs.arccos(x[i])


def _atan2(y, x):
    y, x = np.broadcast_arrays(np.asarray(y, np.float64), np.asarray(x, np.float64))
    out = np.empty(y.size)
    _atan2_all(np.ascontiguousarray(y.ravel()), np.ascontiguousarray(x.ravel()), out)
    return out


def _acos(x):
    x = np.ascontiguousarray(np.asarray(x, np.float64).ravel())
    out = np.empty(x.size)
    _acos_all(x, out)
    return out


def test_arctan2_on_the_circle_and_off_it():
    phi = np.linspace(-math.pi, math.pi, 200_001)
    r = np.random.default_rng(1).uniform(1e-3, 1e3, phi.size)
    y, x = r * np.sin(phi), r * np.cos(phi)
    assert np.max(np.abs(_atan2(y, x) - np.arctan2(y, x))) < TOL


def test_arctan2_near_the_reduction_edges_and_the_axes():
    t = math.tan(math.pi / 8)
    s = np.concatenate([t + np.linspace(-1e-9, 1e-9, 2001), 1.0 + np.linspace(-1e-9, 1e-9, 2001),
                        np.geomspace(1e-300, 1e-1, 2001)])
    for y, x in ((s, np.ones_like(s)), (np.ones_like(s), s), (-s, -np.ones_like(s)),
                 (s, -np.ones_like(s)), (-np.ones_like(s), s)):
        assert np.max(np.abs(_atan2(y, x) - np.arctan2(y, x))) < TOL


def test_arctan2_keeps_libms_signs_at_the_zeros():
    y = np.array([0.0, -0.0, 0.0, -0.0, 1.0, -1.0, 0.0, -0.0, 1.0])
    x = np.array([0.0, 0.0, -0.0, -0.0, 0.0, -0.0, -2.0, -2.0, -0.0])
    got, want = _atan2(y, x), np.arctan2(y, x)
    assert np.array_equal(got, want)
    assert np.array_equal(np.signbit(got), np.signbit(want))


def test_arccos_over_its_domain():
    x = np.concatenate([np.linspace(-1.0, 1.0, 400_001), [0.5, -0.5, np.nextafter(0.5, 1.0),
                                                         np.nextafter(-0.5, -1.0)],
                        1.0 - np.geomspace(1e-16, 1e-2, 2001),
                        -1.0 + np.geomspace(1e-16, 1e-2, 2001)])
    assert np.max(np.abs(_acos(x) - np.arccos(x))) < TOL_ACOS
    assert _acos([1.0])[0] == 0.0 and _acos([-1.0])[0] == math.pi


def test_a_loop_of_them_compiles_to_vector_code_without_libm_calls():
    """What they are for: LLVM vectorises a loop over the lanes that calls them (a call
    to libm's atan2 or acos would leave the loop scalar)."""
    for kernel, libm in ((_atan2_all, "@atan2("), (_acos_all, "@acos(")):
        ir = "\n".join(kernel.inspect_llvm().values())
        assert libm not in ir
        assert re.search(r"<(2|4|8) x double>", ir)  # packed double arithmetic
