"""Make the demo's textures (deterministic; no downloads): a checkerboard, bricks and a
planet map, 8-bit sRGB PNGs written with OpenImageIO beside this script.

    .venv/bin/python presets/textures/make_textures.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio

HERE = Path(__file__).resolve().parent


def write_png(name: str, srgb: np.ndarray) -> Path:
    """Write sRGB values in [0, 1] (h, w, 3), row 0 = the top, as an 8-bit PNG."""
    path = HERE / name
    h, w, c = srgb.shape
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, c, oiio.UINT8))
    out.write_image(np.round(np.clip(srgb, 0.0, 1.0) * 255.0).astype(np.uint8))
    out.close()
    return path


def checker(size: int = 256, squares: int = 8) -> np.ndarray:
    """Warm white and slate squares."""
    i = (np.arange(size) * squares // size)
    odd = (i[:, None] + i[None, :]) % 2 == 1
    return np.where(odd[..., None], [0.16, 0.18, 0.22], [0.92, 0.88, 0.78])


def bricks(size: int = 256, rows: int = 8, per_row: int = 4, mortar: float = 0.06,
           seed: int = 3) -> np.ndarray:
    """Running-bond bricks of slightly varied red-brown in light grey mortar."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    row = np.floor(y * rows).astype(int)
    xs = x * per_row + 0.5 * (row % 2)
    col = np.floor(xs).astype(int) % per_row
    fy, fx = y * rows - row, xs - np.floor(xs)
    joint = (fy < mortar) | (fx < mortar * rows / per_row / 2)
    tint = rng.uniform(0.8, 1.1, (rows, per_row))[row, col]
    brick = np.stack([0.62 * tint, 0.27 * tint, 0.18 * tint], axis=-1)
    return np.where(joint[..., None], [0.72, 0.70, 0.66], brick)


def planet(width: int = 512, height: int = 256, seed: int = 11) -> np.ndarray:
    """An equirectangular planet: oceans, continents from smoothed noise, ice caps."""
    rng = np.random.default_rng(seed)
    lat = (0.5 - (np.arange(height) + 0.5) / height) * np.pi
    lon = (np.arange(width) + 0.5) / width * 2 * np.pi
    lon, lat = np.meshgrid(lon, lat)
    p = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], -1)
    def noise(octaves: int) -> np.ndarray:
        """A sum of random plane waves on the sphere: smooth and seamless."""
        f = np.zeros(lat.shape)
        for k in range(1, octaves + 1):
            for _ in range(6):
                n = rng.normal(size=3)
                f += np.sin(k * 2.0 * p @ (n / np.linalg.norm(n)) + rng.uniform(0, 6.3)) / k
        return f

    field, moist = noise(7), noise(4)
    land = field > 0.35
    ocean = np.array([0.05, 0.18, 0.42]) * (0.8 + 0.2 * np.tanh(field))[..., None]
    green = np.array([0.20, 0.42, 0.16])
    desert = np.array([0.70, 0.58, 0.36])
    dry = np.clip(0.5 + 0.8 * moist - 1.2 * np.abs(lat), 0.0, 1.0)[..., None]
    ground = green * (1 - dry) + desert * dry
    img = np.where(land[..., None], ground, ocean)
    ice = np.abs(lat) > 1.2 + 0.12 * np.tanh(noise(3))
    return np.where(ice[..., None], [0.93, 0.95, 0.97], img)


if __name__ == "__main__":
    for name, img in (("checker.png", checker()), ("bricks.png", bricks()),
                      ("planet.png", planet())):
        print(write_png(name, img))
