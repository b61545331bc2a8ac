"""Textures (core/render/textures.py): pyramids, texel-exact lookups, wrap modes, the level
of detail, the memory bound; end-to-end renders of textured surfaces."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from render_helpers import base_job, render

from relray.core.errors import UserError
from relray.core.render import textures as tx
from relray.core.scene.description import MaterialSpec, TextureSpec


def write_image(path: Path, pixels: np.ndarray, fmt: str = "float") -> Path:
    """Write ``pixels`` (H, W, C), row 0 = the BOTTOM row, as an image file (OIIO stores
    the top row first)."""
    pixels = np.asarray(pixels)
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    assert out is not None, oiio.geterror()
    spec = oiio.ImageSpec(w, h, c, fmt)
    assert out.open(str(path), spec)
    data = pixels[::-1]
    if fmt == "uint8":
        data = np.clip(np.round(data * 255), 0, 255).astype(np.uint8)
    else:
        data = data.astype(np.float32)
    assert out.write_image(np.ascontiguousarray(data))
    out.close()
    return path


def table_of(tmp_path: Path, pixels: np.ndarray, wrap=("repeat", "repeat")) -> tx.TextureTable:
    f = write_image(tmp_path / "t.exr", pixels)
    m = MaterialSpec(name="m", base_color_texture=TextureSpec(file=f, wrap=wrap,
                                                              key="materials[0].bct"))
    return tx.build_textures([m], None, 1, "rgb")


def look(t: tx.TextureTable, u: float, v: float, lod: float = 0.0) -> np.ndarray:
    return np.array(tx.texture_trilinear(t.atlas, t.desc, t.level_rows, 0, lod, u, v))


# ---------------------------------------------------------------- pyramids and memory


@pytest.mark.parametrize("shape", [(8, 8), (5, 7), (1, 9), (6, 3)])
def test_every_level_keeps_the_mean_down_to_one_texel(shape):
    rng = np.random.default_rng(1)
    img = rng.random((*shape, 3)).astype(np.float32)
    levels = tx.mip_pyramid(img)
    assert levels[-1].shape == (1, 1, 4)
    for lv in levels:
        np.testing.assert_allclose(lv[..., :3].mean(axis=(0, 1)), img.mean(axis=(0, 1)),
                                   rtol=1e-5)
        np.testing.assert_allclose(lv[..., 3], 1.0)
    h, w = shape
    assert sum(lv.shape[0] * lv.shape[1] for lv in levels) == tx.pyramid_texels(w, h)
    assert tx.pyramid_texels(w, h) <= 4 / 3 * w * h + len(levels)


def test_box_filter_of_an_even_image_is_the_2x2_mean():
    img = np.arange(16, dtype=np.float32).reshape(4, 4, 1)
    lv1 = tx.mip_pyramid(img)[1][..., 0]
    np.testing.assert_allclose(lv1, [[2.5, 4.5], [10.5, 12.5]])


def test_channels_expand_to_rgba():
    grey_alpha = np.dstack([np.full((2, 2), 0.3), np.full((2, 2), 0.6)]).astype(np.float32)
    np.testing.assert_allclose(tx.mip_pyramid(grey_alpha)[0][0, 0], [0.3, 0.3, 0.3, 0.6])


def test_atlas_beyond_the_bound_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(tx, "MAX_ATLAS_BYTES", 1000)
    f = write_image(tmp_path / "big.exr", np.zeros((8, 8, 3)))  # 85 texels × 16 B
    m = MaterialSpec(name="m", base_color_texture=TextureSpec(
        file=f, key="materials[0].base_color_texture", job_file=tmp_path / "job.toml"))
    with pytest.raises(UserError, match="GiB bound") as e:
        tx.build_textures([m], None, 1, "rgb")
    assert e.value.key == "materials[0].base_color_texture"


def test_seed_gaussian_refuses_textures(tmp_path):
    f = write_image(tmp_path / "t.exr", np.zeros((2, 2, 3)))
    m = MaterialSpec(name="m", base_color_texture=TextureSpec(file=f, key="materials[0].x"))
    with pytest.raises(UserError, match="seed-gaussian"):
        tx.build_textures([m], None, 1, "seed-gaussian")


# ----------------------------------------------------------------------- lookups


def test_texel_centres_are_exact_and_row_0_is_the_bottom(tmp_path):
    rng = np.random.default_rng(2)
    img = rng.random((4, 8, 3)).astype(np.float32)
    t = table_of(tmp_path, img)
    for j in range(4):
        for i in range(8):
            got = look(t, (i + 0.5) / 8, (j + 0.5) / 4)
            np.testing.assert_allclose(got[:3], img[j, i], rtol=1e-6)
    # half-way between two texel centres: their mean
    np.testing.assert_allclose(look(t, 2 / 8, 0.5 / 4)[:3], 0.5 * (img[0, 1] + img[0, 2]),
                               rtol=1e-6)


@pytest.mark.parametrize("wrap,expect_col", [("repeat", 0), ("clamp", 3), ("mirror", 3)])
def test_wrap_modes_beyond_the_right_edge(tmp_path, wrap, expect_col):
    """u = 1 + ½ texel: repeat reads column 0, clamp the last, mirror the last (the
    reflection of column w is column w - 1)."""
    img = np.zeros((1, 4, 3), np.float32)
    img[0, :, 0] = [1.0, 2.0, 3.0, 4.0]
    t = table_of(tmp_path, img, (wrap, "repeat"))
    assert look(t, 1.0 + 0.5 / 4, 0.5)[0] == pytest.approx(img[0, expect_col, 0])
    # 1.5 texels beyond: repeat column 1, clamp 3, mirror 2
    want = {"repeat": 2.0, "clamp": 4.0, "mirror": 3.0}[wrap]
    assert look(t, 1.0 + 1.5 / 4, 0.5)[0] == pytest.approx(want)
    # negative u: repeat wraps to the last column, clamp and mirror read column 0
    want = {"repeat": 4.0, "clamp": 1.0, "mirror": 1.0}[wrap]
    assert look(t, -0.5 / 4, 0.5)[0] == pytest.approx(want)



@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 8, 12, 256])
def test_wrap_index_of_every_mode_and_size(n):
    """repeat is i mod n (power-of-two sizes by a mask, others by division), clamp
    [0, n-1], mirror the period-2n reflection, for indices several periods either side."""
    from numba import njit

    wrap = njit(lambda i, size, mode: tx.wrap_index(i, size, mode))
    for i in range(-3 * n - 2, 3 * n + 3):
        k = i % (2 * n)
        assert wrap(i, n, 0) == i % n, (i, n)
        assert wrap(i, n, 1) == min(max(i, 0), n - 1), (i, n)
        assert wrap(i, n, 2) == min(k, 2 * n - 1 - k), (i, n)

def test_mip_level_selection_and_blend(tmp_path):
    """lod 0 is the image, lod = levels - 1 (and beyond) the mean, a fractional lod the
    linear mix of the two levels around it."""
    rng = np.random.default_rng(3)
    img = rng.random((8, 8, 3)).astype(np.float32)
    t = table_of(tmp_path, img)
    levels = tx.mip_pyramid(img)
    mean = img.mean(axis=(0, 1))
    np.testing.assert_allclose(look(t, 0.3, 0.7, 3.0)[:3], mean, rtol=1e-5)
    np.testing.assert_allclose(look(t, 0.3, 0.7, 9.0)[:3], mean, rtol=1e-5)
    c1 = levels[1][1, 1, :3]  # level 1's texel (1, 1) centre at (1.5/4, 1.5/4)
    c2 = levels[2][0, 0, :3]  # level 2's texel (0, 0) centre at (0.5/2, 0.5/2)
    uv = (1.5 / 4, 1.5 / 4)
    at2 = look(t, *uv, 2.0)[:3]
    np.testing.assert_allclose(look(t, *uv, 1.0)[:3], c1, rtol=1e-5)
    np.testing.assert_allclose(look(t, *uv, 1.25)[:3], 0.75 * c1 + 0.25 * at2, rtol=1e-5)
    assert not np.allclose(at2, c1)
    # level 2 at its own texel centre (0.5/2, 0.5/2) is that texel
    np.testing.assert_allclose(look(t, 0.25, 0.25, 2.0)[:3], c2, rtol=1e-5)


def test_texel_reflectance_is_the_tables_blend_of_sigmoids_bit_for_bit():
    """texel_reflectance's four lanes at once (one vector loop of 32 sigmoids) give, lane
    by lane, rgb_table.cell_reflectance at the lane's wavelength exactly: colours,
    greys, black, white, wavelengths inside and outside the sigmoid band; the material's
    reflectance_uv/_ir below/above the band; the rgb mode's channels."""
    from relray.core.physics import rgb_table

    scale, data = tx.coefficient_table()
    rng = np.random.default_rng(7)
    rgb = rng.random((400, 3))
    rgb[:40] = rgb[:40, :1]  # greys
    rgb[40], rgb[41] = 0.0, 1.0
    lamu = (rng.random((400, 4)) * 120.0 - 10.0).astype(np.float32)  # columns, some beyond
    rho = np.zeros(4)
    for i in range(len(rgb)):
        cell = rgb_table.table_cell(scale, data, *rgb[i])
        lam = [rgb_table.lambda_of_column(float(u)) for u in lamu[i]]
        want = [rgb_table.cell_reflectance(data, cell, x) for x in lam]
        tx.texel_reflectance(rgb[i], False, scale, data, lamu, i, math.nan, math.nan, 4, rho)
        assert list(rho) == want, i
        tx.texel_reflectance(rgb[i], False, scale, data, lamu, i, 0.25, 0.75, 4, rho)
        lo, hi = rgb_table.SIGMOID_BAND_NM
        assert list(rho) == [0.25 if x < lo else 0.75 if x > hi else w
                             for x, w in zip(lam, want, strict=True)], i
    tx.texel_reflectance(rgb[0], True, scale, data, lamu, 0, math.nan, math.nan, 3, rho)
    assert list(rho[:3]) == list(rgb[0])


def test_pixel_spread_and_lab_spread():
    assert tx.pixel_spread(math.tan(math.radians(30)), 100) == pytest.approx(
        math.atan(2 * math.tan(math.radians(30)) / 100))
    np.testing.assert_allclose(tx.lab_spread(0.01, np.array([0.5, 1.0, 2.0])),
                               [0.005, 0.01, 0.02], rtol=1e-6)


# ------------------------------------------------------------------ end-to-end renders
# Small renders in the rgb mode (texels are the lanes' values, so expectations are exact)
# unless a test is about the spectral path. The camera looks along +y from the origin.

FOV = 30.0
W = H = 48


def marker_texture(path: Path, w: int, h: int, i: int, j: int) -> tuple[Path, tuple]:
    """A black w × h image with one white texel (column i, row j from the bottom); returns
    the file and the UV of that texel's centre."""
    img = np.zeros((h, w, 3), np.float32)
    img[j, i] = 1.0
    return write_image(path, img), ((i + 0.5) / w, (j + 0.5) / h)


def project(P: np.ndarray, cam=(0.0, 0.0, 0.0), fov: float = FOV, size: int = W):
    """(col, row) of the lab point P seen by the default camera (looking along +y, z up)."""
    d = np.asarray(P, float) - cam
    t = math.tan(math.radians(fov) / 2)
    x, z = d[0] / d[1] / t, d[2] / d[1] / t
    return (x + 1) * size / 2, (1 - z) * size / 2


def peak(r) -> tuple[float, float]:
    """The (col, row) of the brightest pixel's luminance-weighted neighbourhood centre."""
    y = r.rgb.sum(axis=2)
    row, col = np.unravel_index(np.argmax(y), y.shape)
    sl = (slice(max(row - 2, 0), row + 3), slice(max(col - 2, 0), col + 3))
    rr, cc = np.mgrid[sl]
    wgt = y[sl]
    return float((cc * wgt).sum() / wgt.sum()) + 0.5, float((rr * wgt).sum() / wgt.sum()) + 0.5


def emitter_job(texture: str, obj: dict, **render_keys) -> dict:
    return base_job(render={"width": W, "height": H, "spp": 4, "max_depth": 1,
                            "spectral": "rgb", **render_keys},
                    camera={"fov": FOV},
                    materials=[{"name": "e", "base_color": [0, 0, 0],
                                "emission_texture": texture, "emission_strength": 1.0}],
                    objects=[{**obj, "material": "e"}])


@pytest.mark.parametrize("shape", ["quad", "box", "sphere"])
def test_built_in_shapes_uv_convention_marker_lands_at_its_pixel(tmp_path, shape):
    """A marker texel seen on each built-in shape (an emission texture, seen directly)
    shows at the pixel its UV predicts (job-format.md "Textures"), within 1 pixel."""
    if shape == "quad":  # corners in order -> (0,0), (1,0), (1,1), (0,1)
        c = np.array([[-1, 6, -1], [1, 6, -1], [1, 6, 1], [-1, 6, 1]], float)
        f, (u, v) = marker_texture(tmp_path / "m.exr", 8, 8, 6, 1)
        obj = {"shape": "quad", "corners": c.tolist()}
        P = c[0] + u * (c[1] - c[0]) + v * (c[3] - c[0])
    elif shape == "box":  # the -y face: u along +x, v along +z (seen from outside)
        f, (u, v) = marker_texture(tmp_path / "m.exr", 8, 8, 2, 6)
        obj = {"shape": "box", "center": [0, 6, 0], "size": [2, 2, 2]}
        P = np.array([-1 + 2 * u, 5, -1 + 2 * v])
    else:  # u = azimuth/2π from +x towards +y, v = 1 - polar/π; the camera sees azimuth 270°
        f, (u, v) = marker_texture(tmp_path / "m.exr", 32, 16, 23, 10)
        obj = {"shape": "sphere", "center": [0, 6, 0], "radius": 1.2, "subdivisions": 6}
        phi, theta = 2 * math.pi * u, math.pi * (1 - v)
        P = np.array([0, 6, 0]) + 1.2 * np.array([math.sin(theta) * math.cos(phi),
                                                  math.sin(theta) * math.sin(phi),
                                                  math.cos(theta)])
    r = render(emitter_job(f.name, obj), tmp_path)
    want = project(P)
    got = peak(r)
    assert math.dist(got, want) < 1.0, (got, want)


def textured_quad_glb(path: Path, pos: np.ndarray, uv: np.ndarray, image: str,
                      material) -> None:
    """A glb of one quad (glTF positions ``pos``, TEXCOORD_0 ``uv``) with ``material``,
    whose texture 0 is the image file ``image`` beside it."""
    import pygltflib as g
    from test_gltf import QUAD_IDX, GlbBuilder

    b = GlbBuilder()
    pa = b.add(pos, g.FLOAT, g.VEC3)
    ta = b.add(uv, g.FLOAT, g.VEC2)
    ia = b.add(QUAD_IDX, g.UNSIGNED_SHORT, g.SCALAR)
    gl = g.GLTF2(scene=0, scenes=[g.Scene(nodes=[0])], nodes=[g.Node(mesh=0)],
                 meshes=[g.Mesh(primitives=[g.Primitive(
                     attributes=g.Attributes(POSITION=pa, TEXCOORD_0=ta), indices=ia,
                     material=0)])],
                 materials=[material], textures=[g.Texture(source=0)],
                 images=[g.Image(uri=image)])
    b.finish(gl, path)


def test_gltf_uv_convention_marker_lands_at_its_pixel(tmp_path):
    """A glTF quad with TEXCOORD_0 (top-left origin) and an emissive texture: the marker
    is where glTF's UVs put it (v flipped on import, so the picture is upright)."""
    import pygltflib as g

    # glTF positions are Y-up: (x, y, z)_gltf -> (x, -z, y); a quad at relray y = 6
    pos = np.array([[-1, -1, -6], [1, -1, -6], [1, 1, -6], [-1, 1, -6]], np.float32)
    uv_gl = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)  # image upright
    img = np.zeros((8, 8, 3), np.float32)
    img[6, 1] = 1.0  # column 1, row 6 from the bottom: near the top-left
    write_image(tmp_path / "m.png", img, "uint8")
    textured_quad_glb(tmp_path / "q.glb", pos, uv_gl, "m.png", g.Material(
        emissiveFactor=[1.0, 1.0, 1.0], emissiveTexture=g.TextureInfo(index=0),
        pbrMetallicRoughness=g.PbrMetallicRoughness(baseColorFactor=[0, 0, 0, 1])))
    job = base_job(render={"width": W, "height": H, "spp": 4, "max_depth": 1,
                           "spectral": "rgb"}, camera={"fov": FOV},
                   scene={"file": "q.glb", "background": [0, 0, 0]})
    r = render(job, tmp_path)
    u, v = 1.5 / 8, 6.5 / 8
    want = project(np.array([-1 + 2 * u, 6, -1 + 2 * v]))
    assert math.dist(peak(r), want) < 1.0, (peak(r), want)


def lit_quad_job(tmp_path: Path, mat: dict, spectral: str = "rgb", spp: int = 16,
                 size: int = 24) -> dict:
    """A quad z = 0 exactly filling the view of a camera straight above it (a plane
    parallel to the image maps affinely to it: the pixel mean is the area mean), lit by a
    sun of E = 2 W/m² straight down; max_depth 2 (direct light only)."""
    h = 10.0 * math.tan(math.radians(FOV) / 2)
    return base_job(render={"width": size, "height": size, "spp": spp, "max_depth": 2,
                            "spectral": spectral, "doppler": False, "searchlight": False},
                    camera={"position": [0, 0, 10], "look_at": [0, 0, 0], "up": [0, 1, 0],
                            "fov": FOV},
                    materials=[{"name": "t", "roughness": 1.0, **mat}],
                    objects=[{"shape": "quad", "material": "t",
                              "corners": [[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]]}],
                    lights=[{"type": "sun", "direction": [0, 0, -1], "power": 2.0}])


def image_mean_and_sigma(r) -> tuple[np.ndarray, np.ndarray]:
    """Per channel: the image mean and its standard error from the per-pixel errors."""
    rgb = r.rgb
    sig = r.image.rel_error[..., None].astype(float) * np.maximum(np.abs(rgb), 1e-4)
    return rgb.mean(axis=(0, 1)), np.sqrt((sig**2).sum(axis=(0, 1))) / sig[..., 0].size


@pytest.mark.parametrize("spectral", ["rgb", "cie1931"])
def test_textured_quad_matches_direct_lighting_of_its_mean_albedo(tmp_path, spectral):
    """L = ρ̄ E/π per channel (Lambert, sun along the normal), ρ̄ the texture's mean
    (the quad is one period of it, filling the view: the pixel mean is the area mean):
    within 5σ of the Monte Carlo error. In cie1931 each texel is the sigmoid spectrum of
    its colour, whose colour under the sun's D65 is the texel's up to the RGB→spectrum
    table's interpolation (ΔE00 < 0.5, rgb_table's bound): 1 % of the mean is added."""
    rng = np.random.default_rng(4)
    img = rng.uniform(0.1, 0.9, (8, 8, 3)).astype(np.float32)
    write_image(tmp_path / "a.exr", img)
    r = render(lit_quad_job(tmp_path, {"base_color_texture": "a.exr"}, spectral,
                            spp=16 if spectral == "rgb" else 64), tmp_path)
    mean, sigma = image_mean_and_sigma(r)
    want = img.mean(axis=(0, 1)) * 2.0 / math.pi
    table = 0.0 if spectral == "rgb" else 0.01 * want
    assert np.all(np.abs(mean - want) <= 5 * sigma + table), (mean, want, sigma)
    assert np.std(r.rgb[..., 0]) > 0.05  # the texture is visible, not averaged away


def test_flat_normal_map_changes_nothing_and_a_tilted_one_tilts(tmp_path):
    """A flat normal map (0.5, 0.5, 1) gives the untextured render (within MC error);
    a map tilting the normal by α gives L × cos α (sun and camera along the normal)."""
    flat = np.tile(np.array([0.5, 0.5, 1.0], np.float32), (4, 4, 1))
    write_image(tmp_path / "flat.exr", flat)
    a = math.radians(40)
    tilt = np.tile(np.array([0.5 + 0.5 * math.sin(a), 0.5, 0.5 + 0.5 * math.cos(a)],
                            np.float32), (4, 4, 1))
    write_image(tmp_path / "tilt.exr", tilt)
    base = {"base_color": [0.6, 0.6, 0.6]}
    r0 = render(lit_quad_job(tmp_path, base), tmp_path)
    r1 = render(lit_quad_job(tmp_path, {**base, "normal_texture": "flat.exr"}), tmp_path)
    r2 = render(lit_quad_job(tmp_path, {**base, "normal_texture": "tilt.exr"}), tmp_path)
    m0, s0 = image_mean_and_sigma(r0)
    m1, s1 = image_mean_and_sigma(r1)
    m2, s2 = image_mean_and_sigma(r2)
    want = 0.6 * 2.0 / math.pi
    assert np.all(np.abs(m0 - want) <= 5 * s0 + 1e-3)
    assert np.all(np.abs(m1 - m0) <= 5 * np.hypot(s0, s1) + 1e-3)
    assert np.all(np.abs(m2 - want * math.cos(a)) <= 5 * s2 + 2e-3), (m2, want * math.cos(a))


def test_roughness_and_metallic_maps_replace_the_constants(tmp_path):
    """A metallic map of 1 makes a rough-1 grey a GGX conductor, a metallic map of 0 and
    a roughness map leave the Lambertian result: the sun straight down and the camera
    straight up see ρ E/π from Lambert, something else from the conductor."""
    write_image(tmp_path / "one.exr", np.ones((2, 2, 1), np.float32))
    write_image(tmp_path / "zero.exr", np.zeros((2, 2, 1), np.float32))
    base = {"base_color": [0.6, 0.6, 0.6], "metallic": 1.0, "roughness": 0.1}
    lam = render(lit_quad_job(tmp_path, {**base, "metallic_texture": "zero.exr",
                                         "roughness_texture": "one.exr"}), tmp_path)
    m, s = image_mean_and_sigma(lam)
    assert np.all(np.abs(m - 0.6 * 2 / math.pi) <= 5 * s + 1e-3), m
    metal = render(lit_quad_job(tmp_path, {"base_color": [0.6, 0.6, 0.6],
                                           "metallic_texture": "one.exr"}), tmp_path)
    assert abs(metal.rgb.mean() - 0.6 * 2 / math.pi) > 0.02


def grazing_job(tmp_path: Path, x: float) -> dict:
    """A checkerboard floor of 0.25 m squares (a 2 × 2 texel image repeated by uv_scale
    over 200 m × 200 m: albedos 0.1 and 0.9) seen at a grazing angle from x, 0.5 m above
    it, lit by a sun straight down; rgb mode, 16 spp."""
    img = (np.indices((2, 2)).sum(axis=0) % 2).astype(np.float32)[..., None]
    write_image(tmp_path / "c.exr", np.repeat(img, 3, axis=2) * 0.8 + 0.1)
    return base_job(render={"width": 32, "height": 16, "spp": 16, "max_depth": 2,
                            "spectral": "rgb"},
                    camera={"position": [x, 0.0, 0.5], "look_at": [x, 10.0, 0.5],
                            "fov": 30.0},
                    materials=[{"name": "c", "roughness": 1.0, "base_color_texture": "c.exr",
                                "uv_scale": [400.0, 400.0]}],
                    objects=[{"shape": "quad", "material": "c", "corners":
                              [[-100, -100, 0], [100, -100, 0], [100, 100, 0],
                               [-100, 100, 0]]}],
                    lights=[{"type": "sun", "direction": [0, 0, -1], "power": 2.0}])


def test_grazing_checkerboard_averages_to_its_mean_without_aliasing(tmp_path, monkeypatch):
    """A checkerboard seen at a grazing angle by a camera moving sideways (5 frames, a
    fraction of a square apart, 16 spp): in the far rows (tens of squares per pixel)
    every pixel has the mean albedo 0.5 (L = 0.5 E/π) in every frame with ray cones, and
    their frame-to-frame standard deviation (per pixel, averaged) is far below that of
    the same renders with the cones off (level 0 only, as without mip maps: aliasing)."""
    def far_rows() -> np.ndarray:
        return np.array([render(grazing_job(tmp_path, 0.07 * k), tmp_path).rgb[9:13, :, 0]
                         for k in range(5)])
    want = 0.5 * 2 / math.pi
    cones = far_rows()
    monkeypatch.setattr("relray.core.render.frames.pixel_spread", lambda *a: 0.0)
    level0 = far_rows()
    flicker_cones = cones.std(axis=0).mean()
    flicker_level0 = level0.std(axis=0).mean()
    print(f"far rows: mean {cones.mean():.4f} (want {want:.4f}), frame-to-frame σ per "
          f"pixel: cones {flicker_cones:.4f}, level 0 {flicker_level0:.4f}")
    assert np.all(np.abs(cones.mean(axis=(1, 2)) - want) < 0.01 * want), cones.mean()
    assert np.abs(cones - want).max() < 0.05 * want
    assert flicker_cones < 0.2 * flicker_level0, (flicker_cones, flicker_level0)


def test_textured_body_moving_keeps_its_texture_in_its_rest_frame(tmp_path):
    """A quad moving at β = 0.6 along x, far from the camera (all its points are seen at
    one lab time t_e = -distance, to 1e-3 of a pixel): the marker texel shows where the
    rest-frame UV puts it, contracted by 1/γ about the pivot's lab position at t_e."""
    f, (u, v) = marker_texture(tmp_path / "m.exr", 8, 8, 6, 2)
    d = 60.0
    beta, gamma = 0.6, 1.25
    x0 = beta * d  # the pivot's x at lab time 0: at t_e = -d it is at x = 0
    job = emitter_job(f.name, {"shape": "quad", "velocity": [beta, 0, 0],
                               "pivot": [x0, d, 0], "corners":
                               [[x0 - 2, d, -2], [x0 + 2, d, -2], [x0 + 2, d, 2],
                                [x0 - 2, d, 2]]},
                      doppler=False, searchlight=False)
    job["camera"]["fov"] = 8.0
    r = render(job, tmp_path)
    t_e = -d  # emission time of light reaching the camera at t = 0 (centre; to O(w²/d))
    P = np.array([x0 + beta * t_e + (-2 + 4 * u) / gamma, d, -2 + 4 * v])
    want = project(P, fov=8.0)
    assert math.dist(peak(r), want) < 1.0, (peak(r), want)


# ------------------------------------------------------------------- bad input (CLI)

CLI_JOB = """
[render]
width = 8
height = 8
spp = 1
[output]
dir = "out"
[[materials]]
name = "t"
base_color_texture = "{image}"
[[objects]]
shape = "{shape}"
{geometry}
material = "t"
"""
QUAD = 'corners = [[-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1]]'


@pytest.mark.parametrize("case, key", [
    ("missing", "materials[0].base_color_texture"),
    ("not an image", "materials[0].base_color_texture"),
    ("0x0", "materials[0].base_color_texture"),
    ("2^31 texels", "materials[0].base_color_texture"),
    ("NaN UVs", "objects[0].file"),
])
def test_bad_texture_input_is_one_line_exit_2_nothing_written(tmp_path, case, key):
    """Through the command line: one line naming the key and the job file, exit 2, no
    output folder. The 2³¹-texel image is a PNG header claiming 65536 × 32768 texels (one
    row of data): refused from its header, before any pixel is read."""
    from test_images import png_header

    image, shape, geometry = "t.png", "quad", QUAD
    if case == "not an image":
        (tmp_path / "t.png").write_bytes(b"hello")
    elif case == "0x0":
        png_header(tmp_path / "t.png", 0, 0)
    elif case == "2^31 texels":
        png_header(tmp_path / "t.png", 65536, 32768)
    elif case == "NaN UVs":
        write_image(tmp_path / "t.png", np.full((2, 2, 3), 0.5), "uint8")
        (tmp_path / "m.obj").write_text("v 0 2 0\nv 1 2 0\nv 0 2 1\nvt nan 0.5\n"
                                        "vt 0.75 0.5\nvt 0.25 1.0\nf 1/1 2/2 3/3\n")
        shape, geometry = "mesh", 'file = "m.obj"'
    job = tmp_path / "job.toml"
    job.write_text(CLI_JOB.format(image=image, shape=shape, geometry=geometry))
    r = subprocess.run([sys.executable, "-m", "relray.core.cli", "render", str(job)],
                       capture_output=True, text=True, timeout=600)
    lines = r.stderr.strip().splitlines()
    if case == "0x0":  # libpng itself prints its diagnostic to stderr before OIIO fails
        # (not relray's line: reported; the relray error is still one line)
        lines = [x for x in lines if not x.startswith("libpng error:")]
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and key in lines[0] and str(job) in lines[0], r.stderr
    assert lines[0].startswith("relray: error:")
    assert not (tmp_path / "out").exists()


def test_gltf_base_color_texture_times_its_factor(tmp_path):
    """A glTF quad whose baseColorTexture (a constant 8-bit sRGB PNG, decoded to the
    linear ρ) is multiplied by baseColorFactor 0.5 (glTF: the factor multiplies the
    texture), lit by the sun along its normal: L = 0.5 ρ E/π (rgb mode: exact)."""
    import pygltflib as g

    h = 10.0 * math.tan(math.radians(FOV) / 2)
    # relray z = 0 is glTF's y = 0 (Y-up: (x, y, z)_glTF -> (x, -z, y))
    pos = np.array([[-h, 0, h], [h, 0, h], [h, 0, -h], [-h, 0, -h]], np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    srgb = 0.7
    write_image(tmp_path / "c.png", np.full((4, 4, 3), srgb, np.float32), "uint8")
    rho = ((round(srgb * 255) / 255 + 0.055) / 1.055) ** 2.4  # sRGB decoding
    textured_quad_glb(tmp_path / "q.glb", pos, uv, "c.png", g.Material(
        pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=[0.5, 0.5, 0.5, 1.0], metallicFactor=0.0, roughnessFactor=1.0,
            baseColorTexture=g.TextureInfo(index=0))))
    job = lit_quad_job(tmp_path, {"base_color": [0, 0, 0]})
    job["objects"] = []
    job["materials"] = []
    job["scene"] = {"file": "q.glb", "background": [0, 0, 0]}
    r = render(job, tmp_path)
    mean, sigma = image_mean_and_sigma(r)
    want = 0.5 * rho * 2.0 / math.pi
    assert np.all(np.abs(mean - want) <= 5 * sigma + 1e-6), (mean, want)


def test_emission_texture_is_an_rgb_emitter(tmp_path):
    """A quad with a constant emission texel (0.6, 0.3, 0.1) filling the view, seen
    directly (cie1931, at rest): its colour is the texel's (an RGB emitter is scale · s(λ)
    · D65_ext(λ), whose colour is rgb), within 5σ plus the table's 1 % (ΔE00 < 0.5), and
    equal to a constant ``emission`` of the same colour within their errors."""
    rgb = np.array([0.6, 0.3, 0.1])
    write_image(tmp_path / "e.exr", np.tile(rgb.astype(np.float32), (4, 4, 1)))
    h = 10.0 * math.tan(math.radians(FOV) / 2)
    corners = [[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]]

    def job(mat):
        return base_job(render={"width": 16, "height": 16, "spp": 16, "max_depth": 1},
                        camera={"position": [0, 0, 10], "look_at": [0, 0, 0],
                                "up": [0, 1, 0], "fov": FOV},
                        materials=[{"name": "e", "base_color": [0, 0, 0],
                                    "emission_strength": 2.0, **mat}],
                        objects=[{"shape": "quad", "material": "e", "corners": corners}])
    tex = render(job({"emission_texture": "e.exr"}), tmp_path)
    const = render(job({"emission": rgb.tolist()}), tmp_path)
    m_t, s_t = image_mean_and_sigma(tex)
    m_c, s_c = image_mean_and_sigma(const)
    assert np.all(np.abs(m_t - 2 * rgb) <= 5 * s_t + 0.01 * 2 * rgb), (m_t, 2 * rgb)
    assert np.all(np.abs(m_t - m_c) <= 5 * np.hypot(s_t, s_c) + 0.01 * 2 * rgb), (m_t, m_c)


# ------------------------------------------------------------------ alpha cut-outs


def mask_job(tmp_path: Path, alpha: list[float], max_depth: int) -> dict:
    """A black masked quad (base_color_texture: one row of texels of alpha ``alpha``,
    alpha_mode = "mask", cutoff 0.5) 1 m above a grey floor (ρ = 0.6), the sun straight
    down, the camera above both looking down: it sees the quad, and the floor through
    the quad's holes."""
    img = np.zeros((1, len(alpha), 4), np.float32)
    img[0, :, 3] = alpha
    write_image(tmp_path / "mask.exr", img)
    h = 10.0 * math.tan(math.radians(FOV) / 2)
    return base_job(render={"width": 16, "height": 16, "spp": 16, "max_depth": max_depth,
                            "spectral": "rgb"},
                    camera={"position": [0, 0, 10], "look_at": [0, 0, 0], "up": [0, 1, 0],
                            "fov": FOV},
                    materials=[{"name": "mask", "base_color_texture": "mask.exr",
                                "alpha_mode": "mask", "alpha_cutoff": 0.5,
                                "roughness": 1.0},
                               {"name": "floor", "base_color": [0.6, 0.6, 0.6],
                                "roughness": 1.0}],
                    objects=[{"shape": "quad", "material": "mask", "corners":
                              [[-3 * h, -3 * h, 1], [3 * h, -3 * h, 1], [3 * h, 3 * h, 1],
                               [-3 * h, 3 * h, 1]]},
                             {"shape": "quad", "material": "floor", "corners":
                              [[-40, -40, 0], [40, -40, 0], [40, 40, 0], [-40, 40, 0]]}],
                    lights=[{"type": "sun", "direction": [0, 0, -1], "power": 2.0}])


@pytest.mark.parametrize("moving", [False, True])
def test_rays_and_shadows_pass_the_holes_of_a_mask_without_a_bounce(tmp_path, moving):
    """All holes: the floor is seen and lit as if the quad were not there, L = ρ E/π,
    with max_depth 2 (camera -> floor -> sun): passing the hole is not a bounce (else the
    light sample would be a 3rd segment) and the sun's shadow ray passes it too; also
    when the masked quad moves (at 0.3 c, in its plane)."""
    job = mask_job(tmp_path, [0.0, 0.0], 2)
    if moving:
        job["objects"][0]["velocity"] = [0.3, 0.0, 0.0]
    r = render(job, tmp_path)
    np.testing.assert_allclose(r.rgb, 0.6 * 2 / math.pi, rtol=1e-5)
    assert np.all(r.image.rgba[..., 3] == 1.0)


def test_a_half_mask_shows_the_floor_through_its_holes_only(tmp_path):
    """Alpha 0 on the quad's left half (u < 1/2 along +x), 1 on its right: the left of the
    image is the lit floor (ρ E/π), the right the quad's black opaque half (0); the
    pixels at the edge are mixed."""
    r = render(mask_job(tmp_path, [0.0, 1.0], 2), tmp_path)
    y = r.rgb[..., 0]
    # the view spans a third of the quad around its centre: u = 1/2 at the image centre
    np.testing.assert_allclose(y[:, :7], 0.6 * 2 / math.pi, rtol=1e-5)
    np.testing.assert_allclose(y[:, 9:], 0.0, atol=1e-7)


def test_alpha_mode_mask_needs_a_base_color_texture(tmp_path):
    job = base_job(materials=[{"name": "m", "alpha_mode": "mask"}],
                   objects=[{"shape": "sphere", "center": [0, 5, 0], "radius": 1,
                             "material": "m"}])
    with pytest.raises(UserError, match="base_color_texture") as e:
        render(job, tmp_path)
    assert e.value.key == "materials[0].alpha_mode"
