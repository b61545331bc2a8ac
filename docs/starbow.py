"""Why there is no "starbow": docs/gallery/starbow.png.

    .venv/bin/python docs/starbow.py

For β = 0.5, 0.9 and 0.99, two strips across the camera-frame angle θ' from the
direction of motion (0° on the left, 180° on the right):

* "line": a sky of stars that each emit one line at 550 nm (the assumption behind the
  "starbow", a rainbow ring around the direction of motion): the line is seen at
  λ = 550 nm / D, so its colour runs through the spectrum where 0.79 < D < 1.45 and it
  vanishes into the UV and IR elsewhere;
* "5800 K": blackbody stars, as relray draws them: F_cam(λ) = (Ω/D²) B(λ, D·T), whose
  colour only moves along the Planckian locus (orange, white, pale blue) and whose
  brightness grows smoothly ahead (McKinley & Doherty, Am. J. Phys. 47, 309, 1979).

Each column shows the colour of the sky's surface brightness there: the flux of one star
times the density of stars, which aberration raises by D² (dΩ_cam = dΩ_lab / D²);
D = 1/(γ (1 − β cos θ')). Brightness is scaled to the strip's brightest column, then
sRGB-encoded, so a dim colour stays visible as dark.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from relray.core.output.contact import write_contact_sheet
from relray.core.physics import spectrum

ROOT = Path(__file__).resolve().parents[1]
WIDTH, HEIGHT = 720, 56


def srgb(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def strip(rgb: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Columns of hue ``rgb`` (W, 3), max channel 1, at relative luminance ``y`` (W,)."""
    hue = np.clip(rgb, 0.0, None)
    hue = hue / np.maximum(hue.max(axis=1, keepdims=True), 1e-30)
    col = srgb(hue * (y / max(float(y.max()), 1e-300))[:, None])
    return np.repeat(col[None, :, :], HEIGHT, axis=0)


def strips(b: float) -> tuple[np.ndarray, np.ndarray]:
    theta = np.radians(np.linspace(0.0, 180.0, WIDTH))
    gamma = 1.0 / math.sqrt((1 - b) * (1 + b))
    D = 1.0 / (gamma * (1.0 - b * np.cos(theta)))
    lam = spectrum.sensor_nm()
    w = np.ones(len(lam))
    w[0] = w[-1] = 0.5
    cmf = spectrum.sensor_response("cie1931").astype(np.float64) * w
    m = spectrum.sensor_to_rgb("cie1931")
    # a 550 nm line: F_cam = D² δ(λ − 550/D); density × D²
    seen = 550.0 / D
    xyz_line = np.stack([np.interp(seen, lam, c, left=0.0, right=0.0) for c in cmf], 1)
    line = strip(xyz_line @ m.T, xyz_line[:, 1] * D**4)
    # 5800 K blackbody: F_cam = (Ω/D²) B(λ, D T); density × D²
    xyz_bb = np.stack([cmf @ spectrum.planck(lam, 5800.0 * d) for d in D])
    bb = strip(xyz_bb @ m.T, xyz_bb[:, 1])
    return line, bb


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        pngs, captions = [], []
        for b in (0.5, 0.9, 0.99):
            for name, img in zip(("550 nm line (the 'starbow')", "5800 K blackbody"),
                                 strips(b), strict=True):
                p = Path(tmp) / f"{len(pngs)}.png"
                out = oiio.ImageOutput.create(str(p))
                out.open(str(p), oiio.ImageSpec(WIDTH, HEIGHT, 3, oiio.UINT8))
                out.write_image(np.round(img * 255).astype(np.uint8))
                out.close()
                pngs.append(p)
                captions.append(f"b = {b}: {name}, angle from the motion 0..180 deg")
        print(write_contact_sheet(pngs, ROOT / "docs" / "gallery" / "starbow.png", columns=1,
                                  captions=captions))


if __name__ == "__main__":
    main()
