"""Helpers for end-to-end render tests: job dict -> FilmImage in memory, no files written.

``render(job_dict, tmp_path)`` runs the same pipeline as ``render_job`` (build_scene ->
prepare -> FrameRenderer.render -> Film.resolve), but returns the resolved image and
everything a test needs to interpret it (camera, shutter event, sensor matrix).

The pixel-direction and Doppler formulas here are written out from physics.md by hand,
independently of core/render/camera.py and core/physics/relativity.py, so tests can
compare the renderer against them.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from relray.core.physics import relativity
from relray.core.render.camera import PinholeCamera
from relray.core.render.film import FilmImage
from relray.core.render.frames import build_renderer
from relray.core.scene.description import Job
from relray.core.scene.geometry import Scene
from relray.core.scene.job import parse_job
from relray.core.scene.motion import frame_events


@dataclass
class Rendered:
    """A rendered frame and its context."""

    image: FilmImage
    job: Job
    camera: PinholeCamera
    event: relativity.ShutterEvent
    to_rgb: np.ndarray  # sensor -> linear Rec.709

    @property
    def rgb(self) -> np.ndarray:
        return self.image.rgba[..., :3].astype(np.float64)

    @property
    def alpha(self) -> np.ndarray:
        return self.image.rgba[..., 3].astype(np.float64)

    @property
    def sensor(self) -> np.ndarray:
        """(h, w, 3) sensor values (XYZ in cie1931), recovered from the linear RGB."""
        return self.rgb @ np.linalg.inv(self.to_rgb).T

    @property
    def luminance(self) -> np.ndarray:
        """(h, w) sensor luminance Y (the film's rel_error refers to this channel)."""
        return self.sensor[..., 1]

    @property
    def sigma_y(self) -> np.ndarray:
        """(h, w) standard error of the luminance mean, from the film's per-pixel variance."""
        return self.image.rel_error.astype(np.float64) * np.maximum(np.abs(self.luminance),
                                                                      1e-4)


def base_job(**sections: dict[str, Any]) -> dict[str, Any]:
    """A job dict with small-render defaults; ``sections`` are merged key by key."""
    job: dict[str, Any] = {
        "render": {"width": 16, "height": 16, "spp": 8, "max_depth": 1, "seed": 0,
                   "threads": 2},
        "output": {"formats": ["exr"], "aovs": ["depth", "doppler", "lab_time"]},
        "camera": {"position": [0.0, 0.0, 0.0], "look_at": [0.0, 1.0, 0.0],
                   "up": [0.0, 0.0, 1.0], "fov": 20.0},
        "motion": {"mode": "snapshot", "beta": [0.0, 0.0, 0.0], "ct": 0.0},
        "scene": {"background": [0.0, 0.0, 0.0]},
        "materials": [],
        "objects": [],
    }
    for name, value in sections.items():
        if isinstance(value, dict) and isinstance(job.get(name), dict):
            job[name] = {**job[name], **copy.deepcopy(value)}
        else:
            job[name] = copy.deepcopy(value)
    return job


def make_job(data: dict[str, Any], tmp_path: Path) -> Job:
    return parse_job(data, Path(tmp_path) / "job.toml")


def render(data: dict[str, Any], tmp_path: Path, frame: int | None = None,
           scene: Scene | None = None) -> Rendered:
    """Render one frame of the job dict (the first frame unless ``frame`` is given);
    ``scene``: render this scene instead of the job's (as the Blender add-on does)."""
    job = make_job(data, tmp_path)
    renderer = build_renderer(job, scene)
    camera = renderer.camera
    events = dict(frame_events(job))
    f = min(events) if frame is None else frame
    film, _ = renderer.render(events[f], f)
    assert film.nonfinite_samples == 0
    image = film.resolve(renderer.to_rgb)
    assert image.nonfinite_values == 0
    return Rendered(image, job, camera, events[f], renderer.to_rgb)


# --------------------------------------------------------------------------- hand-made optics


def camera_axes(position, look_at, up) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(right, true up, forward) from the job keys: right = forward × up (job-format.md)."""
    fwd = np.asarray(look_at, float) - np.asarray(position, float)
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.asarray(up, float))
    right /= np.linalg.norm(right)
    return right, np.cross(right, fwd), fwd


def ndc(col, row, width: int, height: int, fov_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Tangent-plane coordinates (x right, y up) of continuous pixel coordinates.

    Pinhole: x = (2 col/W - 1)·t·W/H, y = (1 - 2 row/H)·t, t = tan(fov/2); row 0 = top.
    """
    t = math.tan(math.radians(fov_deg) / 2.0)
    x = (2.0 * np.asarray(col, float) / width - 1.0) * t * width / height
    y = (1.0 - 2.0 * np.asarray(row, float) / height) * t
    return x, y


def pixel_to_pixelcoords(x, y, width: int, height: int, fov_deg: float):
    """Inverse of :func:`ndc`: tangent-plane (x, y) -> continuous (col, row)."""
    t = math.tan(math.radians(fov_deg) / 2.0)
    col = (np.asarray(x, float) / (t * width / height) + 1.0) * width / 2.0
    row = (1.0 - np.asarray(y, float) / t) * height / 2.0
    return col, row


def directions(x, y, axes) -> np.ndarray:
    """Unit camera-frame viewing directions through tangent-plane points (x, y)."""
    right, up, fwd = axes
    x = np.asarray(x, float)[..., None]
    y = np.asarray(y, float)[..., None]
    d = x * right + y * up + fwd
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def doppler(d_cam: np.ndarray, beta) -> np.ndarray:
    """D = 1/(γ(1 - β·d')) (physics.md), by hand."""
    beta = np.asarray(beta, float)
    g = 1.0 / math.sqrt(1.0 - float(beta @ beta))
    return 1.0 / (g * (1.0 - d_cam @ beta))


def aberrate(d_cam: np.ndarray, beta) -> np.ndarray:
    """Camera-frame viewing direction -> lab viewing direction (physics.md), by hand."""
    beta = np.asarray(beta, float)
    g = 1.0 / math.sqrt(1.0 - float(beta @ beta))
    bd = (d_cam @ beta)[..., None]
    return (d_cam / g + beta * (g * bd / (g + 1.0) - 1.0)) / (1.0 - bd)


def pixel_average(f, width: int, height: int, fov_deg: float, axes, n_sub: int = 16):
    """Per-pixel mean and standard deviation of f(d_cam) over the pixel's area.

    Midpoint rule on an n_sub × n_sub sub-grid (the jittered primary rays are uniform on
    the pixel). Returns (mean (h, w), std (h, w)).
    """
    u = (np.arange(n_sub) + 0.5) / n_sub
    cols = np.arange(width)[None, :, None, None] + u[None, None, None, :]
    rows = np.arange(height)[:, None, None, None] + u[None, None, :, None]
    cols, rows = np.broadcast_arrays(cols, rows)
    x, y = ndc(cols, rows, width, height, fov_deg)
    v = f(directions(x, y, axes))
    return v.mean(axis=(2, 3)), v.std(axis=(2, 3))


# --------------------------------------------------------------------------- analytic values


def zscore(value: np.ndarray, expected: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """(value - expected)/sigma; ±inf where sigma = 0 and they differ, 0 where equal."""
    diff = np.asarray(value, float) - expected
    with np.errstate(divide="ignore", invalid="ignore"):
        z = diff / sigma
    return np.where(diff == 0.0, 0.0, z)


def corner_factor(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Form factor from a point to a parallel rectangle with one corner straight above.

    Extents X·h, Y·h (signed: the factor is odd in X and in Y), h the height:
    F = [X/√(1+X²) atan(Y/√(1+X²)) + Y/√(1+Y²) atan(X/√(1+Y²))] / (2π).
    """
    sx, sy = np.sqrt(1.0 + X * X), np.sqrt(1.0 + Y * Y)
    return (X / sx * np.arctan(Y / sx) + Y / sy * np.arctan(X / sy)) / (2.0 * np.pi)


def rectangle_form_factor(x, y, h: float, x0: float, x1: float, y0: float,
                          y1: float) -> np.ndarray:
    """Form factor from points (x, y) of a plane to the rectangle [x0, x1] × [y0, y1] of a
    parallel plane at distance h facing it (corner decomposition with signs): a
    Lambertian surface of albedo ρ under a one-sided emitter of radiance L_e there has
    radiance ρ L_e F."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    return (corner_factor((x1 - x) / h, (y1 - y) / h) - corner_factor((x0 - x) / h, (y1 - y) / h)
            - corner_factor((x1 - x) / h, (y0 - y) / h)
            + corner_factor((x0 - x) / h, (y0 - y) / h))
