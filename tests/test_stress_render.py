"""Render stress (issue 5, parts 2, 3 and 5): β -> 1, extreme ct, far cameras, tiny and huge
scenes, the N^-½ convergence of the estimator, and the memory bound.

Every render goes through the real pipeline (job dict -> parse_job -> build_scene ->
prepare -> FrameRenderer -> Film.resolve, as tests/render_helpers.py) and is checked for:

1. **Finite output**: no NaN or Inf in any channel, AOV or the error estimate, no sample
   dropped as non-finite, no value zeroed by a float32 overflow.
2. **The Doppler AOV against the analytic D range**: a pixel's AOV is the mean of D over
   its jittered samples, so it lies between the minimum and the maximum of the analytic D
   over the pixel's area (computed here by hand, exactly: see :func:`pixel_d_range`). So the
   image's AOV range lies inside the analytic range over the image and reaches its ends to
   within one pixel's variation.
3. **Brightness against the D range (the D⁵ law, exactly)**: the same job is rendered
   twice with the same seed, ``searchlight`` on and off. Every random number, path and
   hero wavelength is the same (Russian roulette ignores the D⁵ film weight, see
   core/render/integrator.py), so per pixel and per sensor channel (XYZ)
   ``S_on = Σ_i D_i⁵ s_i`` and ``S_off = Σ_i s_i`` with s_i >= 0: the ratio S_on / S_off
   is a weighted mean of D_i⁵ and lies in [min D⁵, max D⁵] over the pixel. For a
   uniform sky with ``doppler = false`` this is the D⁵ law itself, at every β up to
   1 - 1e-9; with ``doppler = true`` it checks the searchlight weight while wavelengths
   leave every table. (The statistical per-pixel D⁵ test of the sky, the white furnace at
   rest and in motion and the two-seed test already live in test_render_physics.py:
   test_uniform_sky_d5, test_white_furnace, test_seeds_agree_within_error_bars.)

Where float32 cannot resolve a configuration the renderer must warn once and stay
finite; the limits found are in README.md, "Numerical limits".

Default grids keep this file fast (``make test``); ``make stress`` (RELRAY_STRESS=1)
runs the full grids, the 1920×1080 memory bound and the larger convergence fit.
"""

from __future__ import annotations

import logging
import math
import re
import resource
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from render_helpers import base_job, make_job, ndc
from stress_config import only_in_stress, pick

from relray.core.render.frames import build_renderer, prepare
from relray.core.scene import geometry as scene_mod
from relray.core.scene.motion import frame_events

pytestmark = pytest.mark.stress

ROOT = Path(__file__).resolve().parents[1]
CORNELL = ROOT / "presets" / "cornell.toml"
EPS32 = 2.0**-24
EPS64 = float(np.finfo(np.float64).eps)


# =========================================================================== rendering


class Result:
    """A rendered frame with what the checks need: image, film counters, camera, β."""

    def __init__(self, image, film, job, camera, event, to_rgb):
        self.image, self.film, self.job = image, film, job
        self.camera, self.event, self.to_rgb = camera, event, to_rgb

    @property
    def sensor(self) -> np.ndarray:
        """(h, w, 3) sensor values (XYZ), recovered from the float32 linear RGB."""
        return self.image.rgba[..., :3].astype(np.float64) @ np.linalg.inv(self.to_rgb).T

    @property
    def sensor_err(self) -> np.ndarray:
        """Bound on |sensor error| from storing RGB in float32: Σ_k |M⁻¹_ck| |rgb_k| 2^-24,
        doubled for the float64 -> float32 mean and the product."""
        rgb = np.abs(self.image.rgba[..., :3].astype(np.float64))
        return rgb @ np.abs(np.linalg.inv(self.to_rgb)).T * 2 * EPS32


def render_case(data: dict, tmp_path: Path, frame: int | None = None) -> Result:
    """Like render_helpers.render, but returns the film's counters instead of asserting."""
    job = make_job(data, tmp_path)
    renderer = build_renderer(job)
    events = dict(frame_events(job))
    f = min(events) if frame is None else frame
    film, _ = renderer.render(events[f], f)
    return Result(film.resolve(renderer.to_rgb), film, job, renderer.camera, events[f],
                  renderer.to_rgb)


def with_render(data: dict, **render) -> dict:
    out = {**data, "render": {**data["render"], **render}}
    return out


# =========================================================================== analytic D


def stable_d(d_cam: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """D = 1/(γ(1 - β·d')) by hand, without cancellation near b = 1:
    1 - b cos θ' = (1 - b) + b·2 sin²(θ'/2), 2 sin(θ'/2) = |d' - β̂|; 1/γ = sqrt((1-b)(1+b))."""
    b = float(math.hypot(*beta))
    if b == 0.0:
        return np.ones(d_cam.shape[:-1])
    bh = beta / b
    chord2 = np.sum((d_cam - bh) ** 2, axis=-1)
    return math.sqrt((1.0 - b) * (1.0 + b)) / ((1.0 - b) + b * 0.5 * chord2)


def _candidates(lo: float, hi: float, p: float) -> np.ndarray:
    return np.array([lo, hi, min(max(p, lo), hi)])


def pixel_d_range(res: Result) -> tuple[np.ndarray, np.ndarray]:
    """Exact (min, max) of the analytic D over every pixel's area, (h, w) each.

    D depends only on the angle between d' and β̂ (monotone in it). For β̂ along the
    view (±forward) the angle is monotone in the tangent-plane distance from the image
    point of ±β̂; for β̂ along the image's right or up axis it is monotone in that
    coordinate and in the distance from the other axis. In both cases the extremes over
    a pixel rectangle lie among its corners and the points of its edges closest to the
    image point p of ±β̂ ((0, 0) for β̂ in the image plane): the 3 x 3 candidates
    {x0, x1, clamp(p_x)} x {y0, y1, clamp(p_y)}.
    """
    cam, beta = res.camera, np.asarray(res.event.beta, float)
    W, H = cam.width, cam.height
    rot = cam.rotation
    right, up, fwd = rot[:, 0], rot[:, 1], -rot[:, 2]
    b = float(math.hypot(*beta))
    if b == 0.0:
        return np.ones((H, W)), np.ones((H, W))
    bh = beta / b
    comps = np.array([bh @ right, bh @ up, bh @ fwd])
    assert np.sum(np.abs(comps) > 1e-12) == 1, "β must lie along a camera axis"
    p = (0.0, 0.0)
    fov = 2.0 * math.degrees(math.atan(cam.tan_half_fov))
    lo, hi = np.empty((H, W)), np.empty((H, W))
    for row in range(H):
        for col in range(W):
            xs, ys = ndc(np.array([col, col + 1.0]), np.array([row + 1.0, row]), W, H, fov)
            X, Y = np.meshgrid(_candidates(xs[0], xs[1], p[0]), _candidates(ys[0], ys[1], p[1]))
            d = X[..., None] * right + Y[..., None] * up + fwd
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            D = stable_d(d, beta)
            lo[row, col], hi[row, col] = D.min(), D.max()
    return lo, hi


def d_tolerance(beta) -> float:
    """Relative slack between the renderer's D and the hand formula: both float64 from
    directions with a few ulps of error, which move ln D by <= γ(1+b) per radian
    (64 ulps of that), plus float32 storage of the AOV (2^-24, twice for the mean)."""
    b = float(np.linalg.norm(beta))
    g = 1.0 / math.sqrt((1.0 - b) * (1.0 + b))
    return 64 * EPS64 * g * (1.0 + b) + 2 * EPS32


# =========================================================================== the checks


def assert_finite(res: Result) -> None:
    im = res.image
    assert res.film.nonfinite_samples == 0, res.film.nonfinite_samples
    assert im.nonfinite_values == 0, im.nonfinite_values
    assert np.all(np.isfinite(im.rgba)), "rgba"
    assert np.all(np.isfinite(im.rel_error)), "rel_error"
    for name, a in im.aovs.items():
        assert np.all(np.isfinite(a)), name
    assert np.all((im.rgba[..., 3] >= 0.0) & (im.rgba[..., 3] <= 1.0))
    assert np.all(im.spp == res.job.render.spp)


def assert_doppler_aov(res: Result) -> tuple[np.ndarray, np.ndarray]:
    """Every pixel's D AOV within its analytic range; the image range reaches the ends."""
    lo, hi = pixel_d_range(res)
    tol = d_tolerance(res.event.beta)
    aov = res.image.aovs["doppler"].astype(np.float64)
    assert np.all(aov >= lo * (1 - tol)), np.min(aov / lo)
    assert np.all(aov <= hi * (1 + tol)), np.max(aov / hi)
    # The AOV's extremes come within one pixel's variation of the analytic extremes.
    imax, imin = np.unravel_index(hi.argmax(), hi.shape), np.unravel_index(lo.argmin(), lo.shape)
    assert aov.max() >= lo[imax] * (1 - tol)
    assert aov.min() <= hi[imin] * (1 + tol)
    return lo, hi


def assert_searchlight_ratio(on: Result, off: Result, lo: np.ndarray, hi: np.ndarray) -> int:
    """S_on within [lo⁵ S_off, hi⁵ S_off] per pixel and XYZ channel (module docstring, 3).

    Slack: the float32 RGB storage of both images (sensor_err) and the D range's own
    tolerance (×5 for the fifth power). Returns the number of non-black pixel channels.
    """
    tol = 5 * d_tolerance(on.event.beta)
    s_on, s_off = on.sensor, off.sensor
    e_on, e_off = on.sensor_err, off.sensor_err
    lo5, hi5 = (lo**5)[..., None], (hi**5)[..., None]
    assert np.all(s_on >= lo5 * (1 - tol) * s_off - e_on - lo5 * e_off), "below min D⁵"
    assert np.all(s_on <= hi5 * (1 + tol) * s_off + e_on + hi5 * e_off), "above max D⁵"
    np.testing.assert_array_equal(on.image.rgba[..., 3], off.image.rgba[..., 3])
    return int(np.count_nonzero(s_off > 10 * e_off))


def assert_lab_time(res: Result) -> None:
    """lab_time = t_shutter - depth (float32 storage of both, and of their float64 sum)."""
    t = float(res.event.t)
    depth = res.image.aovs["depth"].astype(np.float64)
    lab = res.image.aovs["lab_time"].astype(np.float64)
    assert np.all(depth > 0.0)
    np.testing.assert_array_less(np.abs(lab + depth - t), 4 * EPS32 * (abs(t) + 2 * depth) + 1e-30)


def check_pair(data: dict, tmp_path: Path) -> tuple[Result, Result, int]:
    """Render with searchlight on and off; run every check; return both and the count of
    lit pixel channels (so a test can make sure it saw something)."""
    on = render_case(with_render(data, searchlight=True), tmp_path)
    off = render_case(with_render(data, searchlight=False), tmp_path)
    for r in (on, off):
        assert_finite(r)
        assert_lab_time(r)
    lo, hi = assert_doppler_aov(on)
    np.testing.assert_array_equal(on.image.aovs["doppler"], off.image.aovs["doppler"])
    lit = assert_searchlight_ratio(on, off, lo, hi)
    return on, off, lit


# =========================================================================== scenes


def cornell(size: int = 9, spp: int = 4, scale: float = 1.0, shift=(0.0, 0.0, 0.0),
            **sections) -> dict:
    """presets/cornell.toml as a dict: size x size pixels (odd: the axis is a pixel centre),
    every length multiplied by ``scale`` and moved by ``shift`` (camera included)."""
    data = tomllib.loads(CORNELL.read_text())
    data["output"] = {"formats": ["exr"], "aovs": ["depth", "doppler", "lab_time"]}
    data["render"].update({"width": size, "height": size, "spp": spp, "max_depth": 3,
                           "threads": 2})
    s, t = float(scale), np.asarray(shift, float)
    for obj in data["objects"]:
        if "corners" in obj:
            obj["corners"] = (np.asarray(obj["corners"]) * s + t).tolist()
        if "center" in obj:
            obj["center"] = (np.asarray(obj["center"]) * s + t).tolist()
        if "size" in obj:
            obj["size"] = (np.asarray(obj["size"]) * s).tolist()
    for key in ("position", "look_at"):
        data["camera"][key] = (np.asarray(data["camera"][key]) * s + t).tolist()
    for name, value in sections.items():
        data.setdefault(name, {}).update(value)
    return data


def open_scene(size: int = 9, spp: int = 4, **sections) -> dict:
    """A grey sphere on a ground under a pale blue sky (an RGB emitter × D65): the sky
    fills the upper half of the view. Camera at (0, -4, 1) looking along +y."""
    data = base_job(
        render={"width": size, "height": size, "spp": spp, "max_depth": 3, "threads": 2},
        camera={"position": [0.0, -4.0, 1.0], "look_at": [0.0, 0.0, 1.0], "fov": 50.0},
        scene={"background": [0.6, 0.7, 1.0]},
        materials=[{"name": "grey", "base_color": [0.5, 0.5, 0.5], "roughness": 1.0},
                   {"name": "red", "base_color": [0.7, 0.1, 0.1], "roughness": 0.3,
                    "metallic": 0.5}],
        objects=[{"shape": "sphere", "center": [0.0, 0.0, 1.0], "radius": 1.0,
                  "subdivisions": 3, "material": "red"},
                 {"shape": "quad", "material": "grey",
                  "corners": [[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]]}],
    )
    for name, value in sections.items():
        data[name] = {**data.get(name, {}), **value}
    return data


SCENES = {"cornell": cornell, "open": open_scene}
BETAS = [1e-12, 0.5, 0.9, 0.99, 0.9999, 1.0 - 1e-9]
AXES = {"along": np.array([0.0, 1.0, 0.0]),     # the view direction (both scenes: +y)
        "across": np.array([1.0, 0.0, 0.0]),    # the image's right
        "against": np.array([0.0, -1.0, 0.0])}  # away from the view (redshift)
CTS = [0.0, 1e3, 1e6]

GRID = [(s, b, a, ct, dop) for s in SCENES for b in BETAS for a in AXES for ct in CTS
        for dop in (True, False)]
DEFAULT_GRID = [(s, b, a, 0.0, dop) for s in SCENES for b in (1e-12, 0.9, 1.0 - 1e-9)
                for a in ("along", "across") for dop in (True, False)]
DEFAULT_GRID += [("open", 0.99, "along", 1e6, True), ("cornell", 0.5, "across", 1e3, True),
                 ("open", 0.9999, "against", 1e3, False), ("cornell", 0.99, "against", 0.0, True)]


def _id(v) -> str:
    if isinstance(v, bool):
        return "doppler" if v else "no-doppler"
    return f"{v:g}" if isinstance(v, float) else str(v)


@pytest.mark.parametrize("scene, b, axis, ct, doppler", pick(DEFAULT_GRID, GRID), ids=_id)
def test_render_stress_grid(tmp_path, scene, b, axis, ct, doppler):
    """One cell of the grid: scene × β × direction × ct × doppler on/off.

    Checks 1–3 of the module docstring. With ct = 1e6 the snapshot camera has travelled
    γβ·1e6 (up to 2e10) before the shutter: a camera far from the origin. With doppler
    on, a strongly redshifted view is black (D65 is 0 below 300 nm), so the brightness
    check needs doppler off to have something to compare: there every visible pixel is lit.
    """
    beta = (b * AXES[axis]).tolist()
    data = SCENES[scene](motion={"beta": beta, "ct": ct})
    data = with_render(data, doppler=doppler)
    on, _, lit = check_pair(data, tmp_path)
    if not doppler and (scene == "open" or on.image.rgba[..., 3].max() > 0):
        assert lit > 0  # something is visible: the checks had something to check


def test_uniform_sky_follows_d5_at_every_speed(tmp_path):
    """A uniform white sky with doppler off: per pixel, Y_on / Y_off is a mean of D⁵ over
    the pixel's samples (checks 2 and 3), at every β of the issue, including 1 - 1e-9
    where D⁵ spans 1e-23 .. 1e23 over the view."""
    for b in BETAS:
        data = base_job(render={"width": 9, "height": 9, "spp": 4, "doppler": False},
                        camera={"fov": 30.0}, motion={"beta": [0.0, b, 0.0]},
                        scene={"background": [1.0, 1.0, 1.0]},
                        materials=[{"name": "g"}],
                        objects=[{"shape": "sphere", "center": [0.0, -1000.0, 0.0],
                                  "radius": 0.01, "subdivisions": 0, "material": "g"}])
        _, off, lit = check_pair(data, tmp_path)
        assert lit == 9 * 9 * 3
        # With searchlight off the sky is the rest-frame white (Y = 1) at any speed: the
        # mean of 4 spectral samples per pixel, noisy but within a factor 2 here.
        assert 0.5 < float(np.mean(off.sensor[..., 1])) < 2.0


# =========================================================================== far and odd scales


def test_scene_far_from_the_origin_renders_as_at_the_origin(tmp_path):
    """The Cornell box and its camera moved by (1e6, -1e6, 1e6): the same image.

    Found by this suite: Scene.triangles were rounded to float32 in absolute lab
    coordinates, a 1/16-unit grid at 1e6 (the light at z = 1.99 merged with the ceiling;
    the mean luminance fell from 0.21 to 0.12). Now the vertices stay float64 and only
    the accelerator's coordinates relative to the scene centre are float32.
    Same seed, so every sample is the same unless a float rounding flips a hit: the
    per-pixel difference must stay within 6σ of the combined error bars (which would hold
    even for independent renders), and almost every pixel must be bit-identical (a float
    rounding flips a sample only at a silhouette).
    """
    ref = render_case(cornell(size=16, spp=8), tmp_path)
    far = render_case(cornell(size=16, spp=8, shift=(1e6, -1e6, 1e6)), tmp_path)
    assert_finite(far)
    y0, y1 = ref.sensor[..., 1], far.sensor[..., 1]
    sig = np.hypot(ref.image.rel_error * np.maximum(np.abs(y0), 1e-4),
                   far.image.rel_error * np.maximum(np.abs(y1), 1e-4))
    assert np.all(np.abs(y1 - y0) <= 6 * sig + 1e-6 * np.abs(y0))
    assert np.mean(y0 == y1) > 0.9
    d0, d1 = ref.image.aovs["depth"], far.image.aovs["depth"]
    assert np.median(np.abs(d1 / d0 - 1)) <= 1e-5


def test_small_triangles_far_from_the_origin_are_kept(tmp_path):
    """A 1 mm triangle at (1e6, 1e6, 1e6): float32 *lab* coordinates (a 1/16-unit grid
    there) collapse it to a point, so it used to be dropped as degenerate. Judged, as the
    accelerator stores it, relative to the scene's centre, it is a fine triangle."""
    (tmp_path / "t.obj").write_text("v 1e6 1e6 1e6\nv 1000000.001 1e6 1e6\n"
                                    "v 1e6 1000000.001 1e6\nf 1 2 3\n")
    data = base_job(materials=[{"name": "g"}],
                    objects=[{"shape": "mesh", "file": "t.obj", "material": "g"}])
    sc = scene_mod.build_scene(make_job(data, tmp_path))
    assert sc.dropped_degenerate == 0 and len(sc.triangles) == 1
    assert sc.triangles.dtype == np.float64
    np.testing.assert_array_equal(sc.triangles[0, 1] - sc.triangles[0, 0],
                                  [1000000.001 - 1e6, 0.0, 0.0])


@pytest.mark.parametrize("scale", pick([1e-4, 1e5], [1e-4, 1e-3, 1e3, 1e5]))
def test_scaled_cornell_box_is_scale_invariant(tmp_path, scale):
    """All lengths × 1e-4 or × 1e5: radiance is scale invariant (emitters are surfaces of
    fixed radiance, seen under the same solid angles), depth scales by the factor.

    The ray offset is 1e-5 of the extent (floor 1e-9 units), so both scales keep it
    relative. Same seed: per-pixel difference within 6σ, most pixels bit-identical, depth
    AOV/scale equal to float32 precision (median).
    """
    ref = render_case(cornell(size=16, spp=8), tmp_path)
    res = render_case(cornell(size=16, spp=8, scale=scale), tmp_path)
    assert_finite(res)
    y0, y1 = ref.sensor[..., 1], res.sensor[..., 1]
    sig = np.hypot(ref.image.rel_error * np.maximum(np.abs(y0), 1e-4),
                   res.image.rel_error * np.maximum(np.abs(y1), 1e-4))
    assert np.all(np.abs(y1 - y0) <= 6 * sig + 1e-5 * np.abs(y0))
    assert np.mean(np.abs(y1 - y0) <= 1e-5 * np.abs(y0)) > 0.8
    d0, d1 = ref.image.aovs["depth"].astype(float), res.image.aovs["depth"].astype(float)
    assert np.median(np.abs(d1 / (scale * d0) - 1)) <= 1e-5


def far_sphere_job(size: float, dist: float) -> dict:
    """A sphere of radius size/2 at the origin seen from ``dist`` along a generic direction
    (so the camera's coordinates are not exactly representable in float32), fov chosen so
    the sphere fills the same part of the image whatever size and dist."""
    fov = math.degrees(2.0 * math.atan(0.8 * size / dist))
    pos = dist * np.array([0.48, -0.6, 0.64])
    return base_job(render={"width": 16, "height": 16, "spp": 8, "spectral": "rgb"},
                    camera={"position": pos.tolist(), "look_at": [0.0, 0.0, 0.0], "fov": fov},
                    materials=[{"name": "g", "base_color": [0.5, 0.5, 0.5]}],
                    objects=[{"shape": "sphere", "center": [0.0, 0.0, 0.0],
                              "radius": 0.5 * size, "material": "g"}])


def coverage_agrees(far: Result, near: Result) -> bool:
    """Σ alpha of the two images within 5σ (Bernoulli α(1-α)/spp per pixel, both)."""
    a, b = far.image.rgba[..., 3].astype(float), near.image.rgba[..., 3].astype(float)
    spp = far.job.render.spp
    var = (a * (1 - a) + b * (1 - b)) / spp
    return abs(a.sum() - b.sum()) <= 5 * math.sqrt(var.sum()) + 1e-9


def test_camera_1e6_from_a_unit_scene(tmp_path):
    """A unit sphere seen from 1e6 units: the primary rays are advanced to the scene's
    bounding sphere in float64 before they become float32 (render.py), so the image is that
    of the same view from 3 units (same angular size)."""
    far = render_case(far_sphere_job(1.0, 1e6), tmp_path)
    near = render_case(far_sphere_job(1.0, 3.0), tmp_path)
    assert_finite(far)
    assert coverage_agrees(far, near)
    depth = far.image.aovs["depth"][far.image.rgba[..., 3] == 1.0]
    assert np.all(np.abs(depth / 1e6 - 1.0) <= 1e-6)


@pytest.mark.parametrize("size", [1e-2, 1e-4])
def test_camera_1e6_from_a_small_scene(tmp_path, size):
    """A sphere of 1e-2 (or 1e-4) units seen from 1e6 units, narrow fov: the same image as
    from 3·size units.

    Regression: the entry distance to the bounding sphere was computed from
    disc = b² - c (b = d·o, c = |o|² - r²). At |o| = 1e6, b² and |o|² are ~1e12 with an
    ulp of 1.2e-4, more than r² = 2.5e-5 (or 2.5e-9): disc was rounding noise, most rays
    that cross the sphere kept t_in = 0, started 1e6 units away in float32 (a 0.06-unit
    grid) and missed (coverage 0.05 instead of 0.31). camera._primary_rays now takes
    disc = r² - |o - b d|² (the perpendicular offset, errors ~ulp(|o|) = 1e-10 << r).
    Rays that miss the bounding sphere still start at the far camera in float32; there
    Embree cannot resolve the small triangles at all, so they cannot hit spuriously.
    """
    far = render_case(far_sphere_job(size, 1e6), tmp_path)
    near = render_case(far_sphere_job(size, 3.0 * size), tmp_path)
    assert_finite(far)
    assert coverage_agrees(far, near)


# ================================================================ limits: warn, stay finite


def test_the_integrator_offsets_rays_by_the_scenes_ray_offset(tmp_path):
    """The kernels' offset is geometry.ray_offset of the accelerator's extent (the offset's
    one home, which the resolution warning also uses), at every scale."""
    for data in (cornell(), cornell(scale=1e-6), cornell(scale=1e5)):
        job = make_job(data, tmp_path)
        sc = scene_mod.build_scene(job)
        prep = prepare(sc, job.render.spectral)
        assert prep.kernel.eps == scene_mod.ray_offset(prep.accel.extent)


def test_details_below_the_ray_offset_warn_once_and_stay_finite(tmp_path, caplog):
    """A 1e5-unit ground with a 1e-2 sphere on it: the ray offset is 1 unit (1e-5 of the
    extent), so float32 rays cannot resolve the sphere. build_scene warns once, with the
    count, and the render stays finite."""
    data = open_scene(motion={"beta": [0.0, 0.5, 0.0]})
    data["objects"] = [{"shape": "sphere", "center": [0.0, 0.0, 0.01], "radius": 0.01,
                        "subdivisions": 1, "material": "red"},
                       {"shape": "quad", "material": "grey", "corners":
                        [[-5e4, -5e4, 0], [5e4, -5e4, 0], [5e4, 5e4, 0], [-5e4, 5e4, 0]]}]
    with caplog.at_level(logging.WARNING, logger="relray"):
        res = render_case(data, tmp_path)
    warnings = [r for r in caplog.records if "ray offset" in r.getMessage()]
    assert len(warnings) == 1 and "80 triangles" in warnings[0].getMessage()
    assert_finite(res)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="relray"):
        render_case(cornell(), tmp_path)  # a normal scene: no warning
    assert not [r for r in caplog.records if "ray offset" in r.getMessage()]


def test_d5_beyond_float32_is_zeroed_with_one_warning(tmp_path, caplog):
    """β = 1 - 2^-53 (the last float below 1, a valid job): straight ahead D = 1.34e8 and
    D⁵ = 4.4e40 > 3.4e38, float32's largest value. The film sums are float64 (finite);
    the resolved RGB overflows float32: those values are set to 0, counted, and one
    warning is logged. Every output stays finite."""
    b = 1.0 - 2.0**-53
    data = base_job(render={"width": 1, "height": 1, "spp": 4, "doppler": False},
                    camera={"fov": 1e-9}, motion={"beta": [0.0, b, 0.0]},
                    scene={"background": [1.0, 1.0, 1.0]}, materials=[{"name": "g"}],
                    objects=[{"shape": "sphere", "center": [0.0, -1000.0, 0.0],
                              "radius": 0.01, "subdivisions": 0, "material": "g"}])
    with caplog.at_level(logging.WARNING, logger="relray"):
        res = render_case(data, tmp_path)
    assert res.film.nonfinite_samples == 0
    assert float(res.film.sum_sensor[0, 1]) / 4 > 3.4e38  # the float64 sum is right
    assert res.image.nonfinite_values > 0
    assert np.all(np.isfinite(res.image.rgba))
    assert len([r for r in caplog.records if "float32" in r.getMessage()]) == 1
    assert res.image.aovs["doppler"][0, 0] == pytest.approx(math.sqrt((1 + b) / (1 - b)),
                                                            rel=1e-6)


# =========================================================================== convergence


def test_error_falls_like_one_over_sqrt_n(tmp_path):
    """The estimator's error falls at least like N^-½, with no bias floor.

    Set-up: the white furnace of test_render_physics.test_white_furnace (albedo-1 sphere
    on an albedo-1 floor under a uniform white sky) seen by a camera moving at β = 0.5
    with doppler and searchlight off, so the exact value of every pixel is Y = 1 (the
    spectral, NEE + MIS estimator at work, the truth known exactly). The camera looks
    down: every pixel sees a surface. Error per pixel r_p = Y_p - 1, e(N)² = mean_p r_p²,
    for N = 4, 16, 64, 256 samples per pixel, each level with its own seed.

    Why the test is meaningful and not flaky: e² is a mean over P independent pixels, so
    SE(ln e) = sd(r²) / (2 √P mean(r²)) (delta method, computed from the data; for
    Gaussian pixel errors it is 1/sqrt(2P)). A weighted fit over x = ln N (spacing ln 4)
    has SE(slope) = 1/sqrt(Σ w (x - x̄)²), w = 1/SE(ln e)². With P = 48 x 32 = 1536 and
    Gaussian errors SE(slope) = sqrt(1/(2P)) / sqrt(Σ (x - x̄)²) = 0.018/3.1 = 0.006
    (measured: 0.009). We require SE(slope) <= 0.02.

    Expected: steeper than -0.5. The pixel position, light and BSDF samples are
    Owen-scrambled Sobol points and the hero wavelengths van der Corput, all stratified
    over a pixel's samples, so their share of the error falls faster than N^-½ (up to
    N^-1.5 for smooth integrands); the i.i.d. parts (roulette, lobe choice) fall like
    N^-½ and take over at large N, so the local slope flattens towards -0.5 (measured:
    fit -0.74; segments -0.89, -0.71, -0.54). A bias b flattens it further, towards 0
    (e² = b² + σ²/N), and perfectly correlated samples would not converge at all. So
    the fitted slope must lie in [-1.5, -0.5 + 5 SE] and the last segment (the largest
    N, where a bias shows first) must not be flatter than -0.5 + 5 SE(segment), with
    SE(segment) = sqrt(SE(ln e_a)² + SE(ln e_b)²) / ln 4.
    """
    W, H = pick((48, 32), (96, 64))
    levels = pick([4, 16, 64, 256], [4, 16, 64, 256, 1024])
    x, y, se = [], [], []
    for k, n in enumerate(levels):
        data = base_job(
            render={"width": W, "height": H, "spp": n, "max_depth": 64, "doppler": False,
                    "searchlight": False, "seed": 10 + k},
            camera={"position": [0.0, -4.0, 3.0], "look_at": [0.0, 0.0, 0.5], "fov": 40.0},
            motion={"beta": [0.5, 0.0, 0.0]}, scene={"background": [1.0, 1.0, 1.0]},
            materials=[{"name": "white", "base_color": [1.0, 1.0, 1.0], "roughness": 1.0}],
            objects=[{"shape": "sphere", "center": [0.0, 0.0, 1.0], "radius": 1.0,
                      "material": "white"},
                     {"shape": "quad", "material": "white",
                      "corners": [[-30, -30, 0], [30, -30, 0], [30, 30, 0], [-30, 30, 0]]}])
        res = render_case(data, tmp_path)
        assert_finite(res)
        assert np.all(res.image.rgba[..., 3] == 1.0)
        r2 = (res.sensor[..., 1] - 1.0).ravel() ** 2
        x.append(math.log(n))
        y.append(0.5 * math.log(r2.mean()))
        se.append(r2.std(ddof=1) / math.sqrt(r2.size) / (2.0 * r2.mean()))
    x, y, w = np.array(x), np.array(y), 1.0 / np.array(se) ** 2
    xm, ym = np.sum(w * x) / w.sum(), np.sum(w * y) / w.sum()
    sxx = float(np.sum(w * (x - xm) ** 2))
    slope = float(np.sum(w * (x - xm) * (y - ym)) / sxx)
    slope_se = 1.0 / math.sqrt(sxx)
    assert slope_se <= 0.02, slope_se
    assert -1.5 <= slope <= -0.5 + 5.0 * slope_se, (slope, slope_se, y)
    seg = (y[-1] - y[-2]) / (x[-1] - x[-2])
    seg_se = math.hypot(se[-1], se[-2]) / (x[-1] - x[-2])
    assert seg <= -0.5 + 5.0 * seg_se, (seg, seg_se, y)


# =========================================================================== resources


MEMORY_LIMIT = 2 * 2**30


@only_in_stress
def test_1080p_16spp_stays_under_2_gb(tmp_path):
    """``relray render`` of the Cornell box at 1920 x 1080, 16 spp: peak resident memory
    below 2 GB (the film is 260 bytes per pixel at peak, the paths go in wavefronts of
    64k). Measured with GNU time (``/usr/bin/time -v``, "Maximum resident set size") when
    installed, else with getrusage of the child (the same kernel counter)."""
    text = CORNELL.read_text()
    text = re.sub(r"(?m)^width = .*$", "width = 1920", text)
    text = re.sub(r"(?m)^height = .*$", "height = 1080", text)
    text = re.sub(r"(?m)^spp = .*$", "spp = 16", text)
    text = re.sub(r"(?m)^dir = .*$", 'dir = "out"', text)
    job = tmp_path / "job.toml"
    job.write_text(text)
    cmd = [sys.executable, "-m", "relray.core.cli", "render", str(job), "--quiet"]
    gnu_time = shutil.which("time", path="/usr/bin")
    if gnu_time:
        r = subprocess.run([gnu_time, "-v", *cmd], capture_output=True, text=True, timeout=1800)
        kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr).group(1))
    else:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
        kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out" / "cornell_0001.exr").exists()
    print(f"1920x1080 16 spp: max RSS {kb / 1024:.0f} MiB")
    assert kb * 1024 < MEMORY_LIMIT, kb

