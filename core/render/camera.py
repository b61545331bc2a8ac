"""The relativistic pinhole camera.

A pixel sample becomes a viewing direction ``d_cam`` in the camera's rest frame S'
(from the job's camera axes, which are the same numeric vectors in S' and the lab
because the boost is pure), then the aberrated lab direction ``d_lab`` along which the
integrator traces backwards from the shutter event, and the Doppler factor

    D = ν_cam / ν_lab = 1 / (γ (1 - β·d_cam)) = γ (1 + β·d_lab)

with which the integrator shifts wavelengths (λ_lab = D λ_cam) and weights radiance
(L_cam(λ) = D⁵ L_lab(Dλ)).  See physics.md, "Aberration" and "Doppler factor".

Image convention (job-format.md): row 0 is the top of the picture, right = forward × up,
``fov`` is the full vertical angle; ``shift`` moves the image window in units of the
larger image side, as Blender's lens shift does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..jit import INLINE, njit
from ..physics import relativity
from ..physics.relativity import aberrate_doppler_ray
from ..scene.description import CameraSettings
from .sampling import DIM_PIXEL, sobol2
from .stack import stack_array


@dataclass(frozen=True)
class PinholeCamera:
    """Camera axes (lab = camera-frame numbers) and the image window.

    ``rotation`` columns are right, up, backward (the camera looks along -column 2).
    """

    rotation: np.ndarray
    tan_half_fov: float
    width: int
    height: int
    shift: tuple[float, float] = (0.0, 0.0)

    @classmethod
    def from_settings(cls, cam: CameraSettings, width: int, height: int) -> PinholeCamera:
        tan_half = math.tan(math.radians(cam.fov) / 2.0)
        return cls(np.asarray(cam.rotation, np.float64), tan_half, width, height,
                   tuple(cam.shift))

    def window(self) -> tuple[float, float, float, float, float]:
        """(tan(fov/2), aspect, scale, shift_x, shift_y) for :func:`view_direction`."""
        aspect = self.width / self.height
        scale = max(self.width, self.height) / self.height
        return self.tan_half_fov, aspect, scale, float(self.shift[0]), float(self.shift[1])

    def directions_cam(self, col: np.ndarray, row: np.ndarray) -> np.ndarray:
        """Unit camera-frame viewing directions d_cam through image points.

        ``col`` and ``row`` are continuous pixel coordinates (pixel centre = index + 0.5),
        row 0 at the top.  x_ndc = (2 col/W - 1)·tan(fov/2)·W/H, y_ndc = (1 - 2 row/H)·tan(fov/2).
        """
        out = np.empty((len(col), 3))
        _directions(self.rotation, *self.window(), self.width, self.height,
                    np.asarray(col, np.float64), np.asarray(row, np.float64), out)
        return out

    def project(self, d_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The inverse of :meth:`directions_cam`: continuous pixel coordinates (col, row)
        of camera-frame viewing directions (N, 3), and where each lies in front of the
        camera (forward component > 0; elsewhere col, row are meaningless).

        With camera coordinates (x_c, y_c, z_f) = (right, up, forward)·d and the image
        plane at unit distance, x = x_c/z_f, y = y_c/z_f:
        col = (W/2)(x/tan(fov/2) − 2 shift_x scale)/aspect + W/2,
        row = (H/2)(1 + 2 shift_y scale − y/tan(fov/2)).
        """
        tan_half, aspect, scale, sx, sy = self.window()
        cam = np.asarray(d_cam, np.float64) @ self.rotation  # (right, up, backward)
        front = cam[:, 2] < 0.0
        z = np.where(front, -cam[:, 2], 1.0)
        x, y = cam[:, 0] / z, cam[:, 1] / z
        col = 0.5 * self.width * ((x / tan_half - 2.0 * sx * scale) / aspect + 1.0)
        row = 0.5 * self.height * (1.0 + 2.0 * sy * scale - y / tan_half)
        return col, row, front

    def pixel_solid_angle(self, col: np.ndarray, row: np.ndarray) -> np.ndarray:
        """dΩ/d(pixel area) at continuous pixel positions: the solid angle of one pixel
        there, (2 tan(fov/2)/H)² cos³θ with θ the angle from the optical axis (the image
        plane at unit distance: dΩ = cos³θ dA). A point source of flux F seen at (col,
        row) is the pixel mean radiance F / this, as the film's box filter averages it."""
        tan_half, aspect, scale, sx, sy = self.window()
        x = ((2.0 * np.asarray(col) / self.width - 1.0) * aspect + 2.0 * sx * scale) * tan_half
        y = ((1.0 - 2.0 * np.asarray(row) / self.height) + 2.0 * sy * scale) * tan_half
        cos3 = (1.0 + x * x + y * y) ** -1.5
        return (2.0 * tan_half / self.height) ** 2 * cos3

    def primary_rays(self, beta: np.ndarray, keys: np.ndarray, pixels: np.ndarray,
                     origin_local: np.ndarray, radius: float,
                     out: tuple[np.ndarray, ...] | None = None):
        """The camera stage of a wavefront, fused in one kernel.

        Jitters each path's pixel (the Sobol pair ``sampling.DIM_PIXEL``), builds d_cam,
        aberrates it into the lab and computes D; the ray starts at the shutter event
        (``origin_local``, in accelerator coordinates, float64) advanced to the scene's
        bounding sphere of
        ``radius``.  Returns (o float32 (N,3), d_lab float32 (N,3), D float64 (N,),
        skipped distance float64 (N,)). ``out``: those four arrays to fill (at least N
        rows; the first N are written and returned), so that a caller can reuse them
        across wavefronts (fresh multi-MB arrays cost a page fault per 4 KiB).
        """
        n = len(keys)
        if out is None:
            out = (np.empty((n, 3), np.float32), np.empty((n, 3), np.float32),
                   np.empty(n), np.empty(n))
        o, d, D, skipped = (a[:n] for a in out)
        _primary_rays(self.rotation, *self.window(), self.width, self.height,
                      *relativity.beta_kernel_args(beta), keys, pixels,
                      np.asarray(origin_local, np.float64), float(radius), o, d, D, skipped)
        return o, d, D, skipped


@njit(cache=True, nogil=True, error_model="numpy")
def view_direction(rot, tan_half, aspect, scale, sx, sy, width, height, col, row):
    """Unit d_cam through the continuous pixel position (col, row), row 0 at the top."""
    x = ((2.0 * col / width - 1.0) * aspect + 2.0 * sx * scale) * tan_half
    y = ((1.0 - 2.0 * row / height) + 2.0 * sy * scale) * tan_half
    dx = x * rot[0, 0] + y * rot[0, 1] - rot[0, 2]
    dy = x * rot[1, 0] + y * rot[1, 1] - rot[1, 2]
    dz = x * rot[2, 0] + y * rot[2, 1] - rot[2, 2]
    inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    return dx * inv, dy * inv, dz * inv


@njit(cache=True, nogil=True, error_model="numpy")
def _directions(rot, tan_half, aspect, scale, sx, sy, width, height, col, row, out):
    for i in range(len(col)):
        out[i, 0], out[i, 1], out[i, 2] = view_direction(
            rot, tan_half, aspect, scale, sx, sy, width, height, col[i], row[i])


@njit(**INLINE)
def pixel_column_row(pixel, width):
    """(column, row) of pixel index ``pixel`` = row · ``width`` + column, as float64, by
    floating-point arithmetic: row = ⌊(p + ½) · (1/w)⌋, column = p − row · w, exact for
    p < 2³¹ and w ≤ 2¹⁵ (the job's limits: :data:`..scene.schema.MAX_PIXELS`,
    ``MAX_IMAGE_SIDE``): (p + ½) / w is at least ½ / w ≥ 2⁻¹⁶ from an integer, and the
    product, rounded twice (< 2³¹), within 2⁻²¹ of it. The integer ``divmod`` is a 64-bit
    division per ray, which no SIMD unit has (2026-11-28, AVX2: with :func:`_primary_rays`'
    uniform tests hoisted as well, the camera stage 63 → 26 ns per ray)."""
    p = np.float64(pixel)
    row = math.floor((p + 0.5) * (1.0 / width))
    return p - row * width, row


@njit(**INLINE)
def camera_ray(rot, tan_half, aspect, scale, sx, sy, width, height, hx, hy, hz, b, inv_g,
               key, pixel, x0, c, r2):
    """One path's camera ray (:meth:`PinholeCamera.primary_rays`): (unit d_lab, D, the
    distance t_in from the shutter event x0 to the bounding sphere |x| = r (0 inside it:
    c = |x0|² - r² ≤ 0)): :func:`camera_ray_as` with the camera's two tests, β > 0 and
    c > 0."""
    return camera_ray_as(rot, tan_half, aspect, scale, sx, sy, width, height, hx, hy, hz,
                         b, inv_g, key, pixel, x0, c, r2, b > 0.0, c > 0.0)


@njit(**INLINE)
def camera_ray_as(rot, tan_half, aspect, scale, sx, sy, width, height, hx, hy, hz, b, inv_g,
                  key, pixel, x0, c, r2, moving, outside):
    """:func:`camera_ray` of a camera that moves (``moving``: aberration and D) or not,
    outside the scene's bounding sphere (``outside``: the ray starts where it enters it)
    or not; both the same for every ray, so :func:`_primary_rays` passes them as
    constants and its loop is straight-line vector code. The sphere's discriminant comes
    from the perpendicular offset p = x0 - (x0·d) d, not from (x0·d)² - |x0|² + r²,
    which cancels catastrophically for a far camera."""
    jx, jy = sobol2(key, DIM_PIXEL)
    col, row = pixel_column_row(pixel, width)
    dx, dy, dz = view_direction(rot, tan_half, aspect, scale, sx, sy, width, height,
                                col + jx, row + jy)
    f = 1.0
    if moving:
        dx, dy, dz, f = aberrate_doppler_ray(dx, dy, dz, hx, hy, hz, b, inv_g)
    t_in = 0.0
    if outside:
        bb = dx * x0[0] + dy * x0[1] + dz * x0[2]
        px, py, pz = x0[0] - bb * dx, x0[1] - bb * dy, x0[2] - bb * dz
        disc = r2 - (px * px + py * py + pz * pz)
        t_in = max(0.0, -bb - math.sqrt(disc)) if disc > 0.0 else 0.0
    return dx, dy, dz, f, t_in


#: paths per block of :func:`_primary_rays` (its stack arrays' width: a literal there)
RAY_BLOCK = 16
assert RAY_BLOCK == 16  # _primary_rays' stack_array(5, 16, …) holds one block


@njit(**INLINE)
def _ray_block(rot, tan_half, aspect, scale, sx, sy, width, height, hx, hy, hz, b, inv_g,
               keys, pixels, x0, c, r2, ray, i0, m, moving, outside):  # pragma: no cover
    """:func:`camera_ray_as` of paths i0 … i0 + m - 1 into the columns of ``ray`` (stack
    memory: d_lab, D, t_in rows)."""
    for j in range(m):
        ray[0, j], ray[1, j], ray[2, j], ray[3, j], ray[4, j] = camera_ray_as(
            rot, tan_half, aspect, scale, sx, sy, width, height, hx, hy, hz, b, inv_g,
            keys[i0 + j], pixels[i0 + j], x0, c, r2, moving, outside)


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def _primary_rays(rot, tan_half, aspect, scale, sx, sy, width, height, hx, hy, hz, b, inv_g,
                  keys, pixels, x0, radius, o, d, D, skipped):
    """:func:`camera_ray` for every path, in blocks of ``RAY_BLOCK``: each block's rays
    into the kernel's stack memory first (:func:`.stack.stack_array`, which LLVM knows
    aliases none of the input arrays, so that loop is vector code: the Sobol hashing,
    the aberration and the square roots of 8 paths per AVX-512 instruction), then
    copied out. Written straight into the output arrays, the loop stayed scalar (about
    2× the time; bit-identical results)."""
    r2 = radius * radius
    c = x0[0] * x0[0] + x0[1] * x0[1] + x0[2] * x0[2] - r2
    moving, outside = b > 0.0, c > 0.0
    ray = stack_array(5, 16, np.float64)
    for i0 in range(0, keys.shape[0], RAY_BLOCK):
        m = min(RAY_BLOCK, keys.shape[0] - i0)
        # the camera's two tests as constants of the block's loop (a test inside it kept
        # the loop from LLVM's vector code: 48 against 26 ns per ray, AVX2 2026-11-28)
        if moving and outside:
            _ray_block(rot, tan_half, aspect, scale, sx, sy, width, height, hx, hy, hz, b,
                       inv_g, keys, pixels, x0, c, r2, ray, i0, m, True, True)
        elif moving:
            _ray_block(rot, tan_half, aspect, scale, sx, sy, width, height, hx, hy, hz, b,
                       inv_g, keys, pixels, x0, c, r2, ray, i0, m, True, False)
        elif outside:
            _ray_block(rot, tan_half, aspect, scale, sx, sy, width, height, hx, hy, hz, b,
                       inv_g, keys, pixels, x0, c, r2, ray, i0, m, False, True)
        else:
            _ray_block(rot, tan_half, aspect, scale, sx, sy, width, height, hx, hy, hz, b,
                       inv_g, keys, pixels, x0, c, r2, ray, i0, m, False, False)
        for j in range(m):
            i = i0 + j
            t_in = ray[4, j]
            for k in range(3):
                o[i, k] = x0[k] + t_in * ray[k, j]
                d[i, k] = ray[k, j]
            D[i] = ray[3, j]
            skipped[i] = t_in


def lab_rays(d_cam: np.ndarray, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Aberrate camera-frame viewing directions into the lab and give their Doppler factors.

    Returns (d_lab (N,3) float64 unit, D (N,) float64).  At β = 0 this is exactly
    (d_cam, 1).
    """
    beta = np.asarray(beta, np.float64)
    if not np.any(beta):
        return d_cam, np.ones(len(d_cam))
    return relativity.aberrate(d_cam, beta), relativity.doppler_factor(d_cam, beta)
