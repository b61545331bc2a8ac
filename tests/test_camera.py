"""The relativistic pinhole: pixel → d_cam → aberrated lab ray, D, bounding-sphere start."""

import math

import numpy as np
import pytest

from relray.core.physics import relativity
from relray.core.render.camera import PinholeCamera, camera_ray, pixel_column_row
from relray.core.render.sampling import path_keys, sobol2_dims
from relray.core.scene.job import look_at_rotation
from relray.core.scene.schema import MAX_IMAGE_SIDE, MAX_PIXELS


def camera(width=40, height=30, fov=50.0):
    rot = look_at_rotation(np.zeros(3), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    return PinholeCamera(rot, math.tan(math.radians(fov) / 2), width, height)


def test_image_corners_follow_the_pinhole_convention():
    """Row 0 is the top, column 0 the left; fov is the full vertical angle."""
    cam = camera()
    d = cam.directions_cam(np.array([20.0, 0.0, 20.0]), np.array([15.0, 15.0, 0.0]))
    np.testing.assert_allclose(d[0], [0, 1, 0], atol=1e-15)            # centre: forward
    assert d[1, 0] < 0 and abs(d[1, 2]) < 1e-15                        # left edge: -x
    assert math.isclose(math.degrees(math.atan2(d[2, 2], d[2, 1])), 25.0, rel_tol=1e-12)


def test_primary_rays_at_rest_are_the_jittered_pinhole():
    cam = camera()
    pix = np.arange(cam.width * cam.height, dtype=np.int64)
    keys = path_keys(0, 1, pix, np.zeros_like(pix))
    o, d, D, skipped = cam.primary_rays(np.zeros(3), keys, pix, np.zeros(3), 100.0)
    jitter = sobol2_dims(keys, 0)
    col = pix % cam.width + jitter[:, 0]
    row = pix // cam.width + jitter[:, 1]
    np.testing.assert_allclose(d, cam.directions_cam(col, row), atol=1e-7)   # float32 out
    assert np.all(D == 1.0) and np.all(skipped == 0.0) and np.all(o == 0.0)


def test_primary_rays_are_aberrated_and_doppler_shifted():
    cam = camera()
    beta = np.array([0.9, 0.0, 0.0])
    pix = np.arange(cam.width * cam.height, dtype=np.int64)
    keys = path_keys(0, 1, pix, np.zeros_like(pix))
    _, d, D, _ = cam.primary_rays(beta, keys, pix, np.zeros(3), 100.0)
    jitter = sobol2_dims(keys, 0)
    d_cam = cam.directions_cam(pix % cam.width + jitter[:, 0], pix // cam.width + jitter[:, 1])
    np.testing.assert_allclose(d, relativity.aberrate(d_cam, beta), atol=1e-7)
    np.testing.assert_allclose(D, relativity.doppler_factor(d_cam, beta), rtol=1e-14)


def test_far_camera_starts_on_the_bounding_sphere():
    """From 1e6 away the ray is advanced in float64 to the sphere; the line is unchanged."""
    cam = camera(fov=1e-5)   # so that every pixel of the image sees the sphere from 1e6
    x0 = np.array([0.0, -1e6, 0.0])
    pix = np.array([cam.width * cam.height // 2 + cam.width // 2], np.int64)
    keys = path_keys(0, 0, pix, np.zeros(1, np.int64))
    o, d, _, skipped = cam.primary_rays(np.zeros(3), keys, pix, x0, 2.0)
    assert abs(np.linalg.norm(o[0].astype(np.float64)) - 2.0) < 1e-6
    back = o[0].astype(np.float64) - skipped[0] * d[0].astype(np.float64)
    assert np.linalg.norm(back - x0) < 0.1   # float32 direction over 1e6: ~0.06 at most
    assert math.isclose(skipped[0], 1e6 - math.sqrt(4.0 - np.sum(o[0, [0, 2]] ** 2)),
                        rel_tol=1e-9)


def test_project_inverts_directions_cam_with_shift_and_aspect():
    cam = PinholeCamera(camera().rotation, math.tan(math.radians(70) / 2), 64, 36,
                        (0.1, -0.05))
    rng = np.random.default_rng(3)
    col, row = rng.uniform(-5, 69, 200), rng.uniform(-5, 41, 200)
    c, r, front = cam.project(cam.directions_cam(col, row))
    assert front.all()
    np.testing.assert_allclose(c, col, atol=1e-10)
    np.testing.assert_allclose(r, row, atol=1e-10)
    assert not cam.project(-cam.directions_cam(col[:3], row[:3]))[2].any()  # behind


def test_pixel_solid_angle_is_the_pixels_solid_angle():
    """Summed over every pixel (the midpoint rule of ∫ dΩ over the image) it converges to
    the image's solid angle, 4 asin(sin a sin b) for a rectangle of half-angles a, b seen
    from its centre, with the midpoint rule's error: O(1/N²), a quarter at twice the
    pixels (so no bias is left)."""
    def error(w, h):
        cam = camera(width=w, height=h, fov=50.0)
        cols, rows = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
        total = cam.pixel_solid_angle(cols, rows).sum()
        a, b = math.atan(cam.tan_half_fov * w / h), math.atan(cam.tan_half_fov)
        return total / (4 * math.asin(math.sin(a) * math.sin(b))) - 1

    coarse, fine = error(40, 30), error(80, 60)
    assert abs(coarse) < 2e-4
    assert 3.8 < coarse / fine < 4.2


def test_pixel_solid_angle_at_the_centre():
    cam = camera(width=100, height=80, fov=30.0)
    assert cam.pixel_solid_angle(np.array([50.0]), np.array([40.0]))[0] == \
        pytest.approx((2 * cam.tan_half_fov / 80) ** 2, rel=1e-14)


@pytest.mark.parametrize("n", [1, 15, 16, 17, 53])
def test_primary_rays_in_blocks_are_each_paths_own_ray(n):
    """The kernel computes its rays in blocks of RAY_BLOCK paths in stack memory and
    copies them out: every path, the last partial block's too, gets exactly the ray that
    camera_ray gives it alone (moving camera outside the bounding sphere: aberration,
    D and the skipped distance all in play), and an ``out`` buffer longer than the
    wavefront keeps its rows beyond N."""
    cam = camera()
    beta, x0, radius = np.array([0.2, 0.5, 0.3]), np.array([3.0, -40.0, 7.0]), 30.0
    pix = (620 + np.arange(n, dtype=np.int64) * 97) % (cam.width * cam.height)  # centre first
    keys = path_keys(4, 1, pix, np.arange(n, dtype=np.int64) // 3)
    out = (np.full((n + 5, 3), 7.0, np.float32), np.full((n + 5, 3), 7.0, np.float32),
           np.full(n + 5, 7.0), np.full(n + 5, 7.0))
    o, d, D, skipped = cam.primary_rays(beta, keys, pix, x0, radius, out)
    hx, hy, hz, b, inv_g = relativity.beta_kernel_args(beta)
    c = x0 @ x0 - radius * radius
    for i in range(n):
        dx, dy, dz, f, t_in = camera_ray(cam.rotation, *cam.window(), cam.width, cam.height,
                                         hx, hy, hz, b, inv_g, keys[i], pix[i], x0, c,
                                         radius * radius)
        assert f != 1.0
        assert np.array_equal(d[i], np.float32([dx, dy, dz]))
        assert np.array_equal(o[i], np.float32(x0 + t_in * np.array([dx, dy, dz])))
        assert D[i] == f and skipped[i] == t_in
    assert np.any(skipped > 0.0) and (n < 15 or np.any(skipped == 0.0))  # hits and misses
    assert all(np.all(a[n:] == 7.0) for a in out) and o.base is out[0]


def test_pixel_column_row_is_the_integer_divmod_up_to_the_jobs_limits():
    """The camera's pixel (column, row) by a float64 division (no 64-bit integer division
    per ray): equal to divmod at every row boundary (k·w - 1, k·w, k·w + 1) for widths
    from 1 to MAX_IMAGE_SIDE and rows up to MAX_PIXELS / w, and at random pixels."""
    rng = np.random.default_rng(3)
    for w in (1, 2, 3, 7, 640, 1920, 4099, MAX_IMAGE_SIDE - 1, MAX_IMAGE_SIDE):
        k = np.unique(np.concatenate([np.arange(1, 200), rng.integers(1, MAX_PIXELS // w, 500),
                                      [MAX_PIXELS // w - 1, MAX_PIXELS // w]]))
        p = np.concatenate([k * w - 1, k * w, k * w + 1, rng.integers(0, MAX_PIXELS, 500)])
        p = p[(p >= 0) & (p < MAX_PIXELS)]
        got = np.array([pixel_column_row(int(q), w) for q in p])
        row, col = np.divmod(p, w)
        np.testing.assert_array_equal(got[:, 0], col)
        np.testing.assert_array_equal(got[:, 1], row)
