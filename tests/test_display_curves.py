"""Blender's view Curves and Gamma on the PNG (core/output/display_curves.py): the tables
against analytic functions, the order around the view transform, bad input."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from relray.core import cli
from relray.core.output.display_curves import apply_curves, apply_gamma
from relray.core.output.imageio import display_codes
from relray.core.scene.description import DisplayCurves, ViewTransform


def curves(tables, black=(0.0,) * 3, white=(1.0,) * 3, u_range=(0.0, 1.0),
           slopes=((0.0, 0.0),) * 3) -> DisplayCurves:
    return DisplayCurves(black, white, (u_range,) * 3, tuple(tuple(t) for t in tables),
                         slopes)


def blender_config() -> Path:
    origin = Path(importlib.util.find_spec("bpy").origin).parent
    return sorted(origin.glob("*/datafiles/colormanagement/config.ocio"))[0]


def test_an_identity_table_clamps_with_horizontal_ends_and_passes_with_slope_one():
    x = np.array([[-0.5, 0.0, 0.3], [0.7, 1.0, 2.5]])[None]  # (1, 2, 3)
    grid = np.linspace(0.0, 1.0, 5)
    flat = apply_curves(x, curves([grid] * 3))
    np.testing.assert_allclose(flat, np.clip(x, 0.0, 1.0), atol=1e-15)
    through = apply_curves(x, curves([grid] * 3, slopes=((1.0, 1.0),) * 3))
    np.testing.assert_allclose(through, x, atol=1e-15)


def test_black_and_white_levels_map_onto_the_tables_range():
    """u = (x - black) / (white - black) per channel, then the table."""
    grid = np.linspace(0.0, 1.0, 3)
    c = curves([grid] * 3, black=(0.1, 0.2, -0.5), white=(0.9, 0.4, 1.5),
               slopes=((1.0, 1.0),) * 3)
    x = np.array([0.5, 0.3, 0.5])
    np.testing.assert_allclose(apply_curves(x, c), [0.5, 0.5, 0.5], atol=1e-15)


def test_a_sampled_parabola_is_within_the_linear_interpolation_bound():
    """T(u) = u² sampled at n points: |error| ≤ h²/8 · max|T''| = h²/4 (h = 1/(n-1))."""
    n = 257
    grid = np.linspace(0.0, 1.0, n)
    c = curves([grid**2, grid**2, grid**2])
    u = np.linspace(0.0, 1.0, 10001)
    x = np.stack([u, u, u], axis=-1)
    err = np.abs(apply_curves(x, c)[..., 0] - u**2).max()
    h = 1.0 / (n - 1)
    assert 0.0 < err <= h * h / 4 * (1 + 1e-9)


def test_outside_the_range_the_table_continues_with_its_slopes():
    grid = np.linspace(0.0, 1.0, 3)
    c = curves([0.2 + 0.5 * grid] * 3, slopes=((2.0, 0.25), (0.0, 0.0), (1.0, 1.0)))
    x = np.array([[-1.0, -1.0, -1.0], [3.0, 3.0, 3.0]])
    out = apply_curves(x, c)
    np.testing.assert_allclose(out[0], [0.2 - 2.0, 0.2, 0.2 - 1.0], atol=1e-15)
    np.testing.assert_allclose(out[1], [0.7 + 0.5, 0.7, 0.7 + 2.0], atol=1e-15)


def test_gamma_is_a_power_on_display_values():
    v = np.array([-0.1, 0.0, 0.04, 0.5, 1.0])
    np.testing.assert_allclose(apply_gamma(v, 1.6), [0.0, 0.0, 0.04**0.625, 0.5**0.625, 1.0])
    np.testing.assert_array_equal(apply_gamma(v, 1.0), np.maximum(v, 0.0))


def ocio(rgba: np.ndarray, config: Path, view: str) -> np.ndarray:
    buf = oiio.ImageBuf(oiio.ImageSpec(rgba.shape[1], rgba.shape[0], 4, oiio.FLOAT))
    buf.set_pixels(oiio.ROI(), rgba.astype(np.float32))
    return oiio.ImageBufAlgo.ociodisplay(buf, "sRGB", view, fromspace="scene_linear",
                                         unpremult=True, colorconfig=str(config)
                                         ).get_pixels(oiio.FLOAT)


@pytest.mark.parametrize("view", ["Standard", "AgX"])
def test_the_png_takes_curves_then_exposure_then_the_view_then_gamma(view):
    """Blender's order (module docstring): the codes equal OCIO's display transform of
    2^exposure · T(x), raised to 1/gamma, rounded."""
    config = blender_config()
    rng = np.random.default_rng(3)
    rgba = np.ones((4, 6, 4), np.float32)
    rgba[..., :3] = np.exp2(rng.uniform(-6.0, 2.0, (4, 6, 3)))
    grid = np.linspace(0.0, 1.0, 65)
    s_curve = 0.5 - 0.5 * np.cos(math.pi * grid)  # an S-curve from 0 to 1
    c = curves([s_curve, grid, grid**2], black=(0.0, 0.05, 0.0), white=(2.0, 1.0, 1.5),
               slopes=((0.0, 0.0), (0.0, 1.0), (0.0, 0.0)))
    vt = ViewTransform(config, "sRGB", view, gamma=1.6, curves=c)
    codes = display_codes(rgba, 0.5, vt)
    curved = rgba.copy()
    curved[..., :3] = apply_curves(rgba[..., :3], c) * 2.0**0.5
    ref = np.clip(ocio(curved, config, view)[..., :3], 0.0, None) ** (1 / 1.6)
    expect = np.floor(np.clip(ref, 0.0, 1.0) * 255 + 0.5)
    assert np.abs(codes[..., :3].astype(int) - expect).max() <= 1  # float32 vs float64
    plain = display_codes(rgba, 0.5, ViewTransform(config, "sRGB", view))
    assert np.abs(codes[..., :3].astype(int) - plain[..., :3]).mean() > 10  # it does act


JOB = """
[render]
width = 4
height = 3
spp = 1
[output]
dir = "out"
[output.view_transform]
config = "{config}"
view = "AgX"
{extra}
[[materials]]
name = "m"
[[objects]]
shape = "sphere"
center = [0.0, 0.0, 1.0]
radius = 0.5
material = "m"
"""


@pytest.mark.parametrize("extra, key", [
    ("gamma = 0.0", "output.view_transform.gamma"),
    ("gamma = nan", "output.view_transform.gamma"),
    ("[output.view_transform.curves]\nred = [0.0, 1.0]\ngreen = [0.0, 1.0]\n"
     "blue = [0.0, 0.5, 1.0]", "output.view_transform.curves.blue"),
    ("[output.view_transform.curves]\nred = [0.0, 1.0]\ngreen = [0.0, 1.0]\n"
     "blue = [0.0, 1.0]\nwhite = [1.0, 0.0, 1.0]\nblack = [0.0, 0.0, 0.0]",
     "output.view_transform.curves.white"),
    ("[output.view_transform.curves]\nred = [0.0, 1.0]\ngreen = [0.0, 1.0]\n"
     "blue = [0.0, 1.0]\nranges = [[0.0, 1.0], [1.0, 0.0], [0.0, 1.0]]",
     "output.view_transform.curves.ranges"),
    ("[output.view_transform.curves]\nred = [0.0, 1.0]\ngreen = [0.0, 1.0]",
     "output.view_transform.curves"),
])
def test_bad_gamma_or_curves_exit_2_naming_key_and_file(tmp_path, capsys, extra, key):
    path = tmp_path / "job.toml"
    path.write_text(JOB.format(config=blender_config(), extra=extra))
    assert cli.main(["render", str(path), "--quiet"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and str(path) in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_a_good_gamma_and_curves_render_and_are_named_in_the_png(tmp_path):
    path = tmp_path / "job.toml"
    path.write_text(JOB.format(config=blender_config(), extra=(
        "gamma = 1.6\n[output.view_transform.curves]\nred = [0.0, 1.0]\n"
        "green = [0.0, 1.0]\nblue = [0.0, 1.0]")))
    assert cli.main(["render", str(path), "--quiet"]) == 0
    png = tmp_path / "out" / "frame_0001.png"
    assert oiio.ImageBuf(str(png)).spec().get_string_attribute(
        "relray:view_transform") == "OCIO sRGB / AgX, gamma 1.6, curves"
