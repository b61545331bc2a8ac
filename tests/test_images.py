"""core.scene.images: reading texture and environment images (OpenImageIO)."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import OpenImageIO as oiio
import pytest

from relray.core.errors import UserError
from relray.core.scene import images


def write(path, pixels, fmt=oiio.UINT8):
    pixels = np.asarray(pixels)
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(w, h, c, fmt)
    spec.attribute("oiio:UnassociatedAlpha", 1)  # store the colour as given
    assert out.open(str(path), spec)
    assert out.write_image(pixels)
    out.close()
    return path


def png_header(path, width, height):
    """A PNG whose header claims width × height (8-bit RGB) and whose data is one row."""
    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
                     + chunk(b"IDAT", zlib.compress(b"\0" * 4)) + chunk(b"IEND", b""))
    return path


def test_srgb_decoding_matches_the_standard():
    c = np.array([0.0, 0.04045, 0.5, 1.0], np.float32)
    expected = [0.0, 0.04045 / 12.92, ((0.5 + 0.055) / 1.055) ** 2.4, 1.0]
    assert np.allclose(images.srgb_to_linear(c), expected, rtol=1e-6, atol=1e-9)


def test_png_is_srgb_decoded_and_bottom_row_first(tmp_path):
    px = np.zeros((2, 3, 4), np.uint8)
    px[0, :, :3] = 255          # top row white
    px[1, :, 0] = 128           # bottom row half red
    px[..., 3] = 128            # alpha stays linear
    img = images.read_image(write(tmp_path / "a.png", px), key="k", file=None)
    assert img.pixels.shape == (2, 3, 4) and img.pixels.dtype == np.float32
    assert np.allclose(img.pixels[1, :, :3], 1.0)                     # top row last
    red = images.srgb_to_linear(np.float32(128 / 255))
    assert np.allclose(img.pixels[0, :, 0], red, rtol=1e-5)
    assert np.allclose(img.pixels[..., 3], 128 / 255, rtol=1e-5)
    linear = images.read_image(tmp_path / "a.png", key="k", file=None, encoding="linear")
    assert np.allclose(linear.pixels[0, :, 0], 128 / 255, rtol=1e-5)


def test_exr_is_linear_and_memoised(tmp_path):
    px = np.full((4, 5, 3), 2.5, np.float32)
    path = write(tmp_path / "a.exr", px, oiio.FLOAT)
    a = images.read_image(path, key="k", file=None)
    assert np.allclose(a.pixels, 2.5) and (a.width, a.height, a.channels()) == (5, 4, 3)
    assert images.read_image(str(path), key="k", file=None) is a
    assert images.read_image("a.exr", key="k", file=None, base=tmp_path) is a


@pytest.mark.parametrize("case", ["missing", "not an image", "nan", "huge", "folder"])
def test_bad_images_are_one_line_user_errors(tmp_path, case):
    job = tmp_path / "job.toml"
    path = tmp_path / "img.png"
    if case == "not an image":
        path.write_bytes(b"hello")
    elif case == "nan":
        path = write(tmp_path / "img.exr", np.full((2, 2, 3), np.nan, np.float32), oiio.FLOAT)
    elif case == "huge":
        png_header(path, 65536, 32768)  # 2**31 texels
    elif case == "folder":
        path.mkdir()
    with pytest.raises(UserError) as e:
        images.read_image(path, key="materials.base_color_texture", file=job)
    text = str(e.value)
    assert "\n" not in text and "materials.base_color_texture" in text and str(job) in text
    if case == "huge":
        assert "2147483648 texels" in text


def test_an_empty_image_is_refused_in_one_line(tmp_path, capfd):
    """A 0×0 PNG is refused from its header, before libpng could print its own line."""
    path = png_header(tmp_path / "empty.png", 0, 0)
    with pytest.raises(UserError, match="empty"):
        images.read_image(path, key="k", file=tmp_path / "job.toml")
    assert capfd.readouterr().err == ""


def test_fichet_channel_names_give_wavelengths():
    """Fichet et al. 2021 emissive channels: decimal comma, length or frequency units."""
    from relray.core.scene.images import fichet_wavelength_nm
    assert fichet_wavelength_nm("S0.550,000000nm") == 550.0
    assert fichet_wavelength_nm("S0.1,5um") == 1500.0
    assert fichet_wavelength_nm("S0.600THz") == pytest.approx(499.654097, rel=1e-9)
    assert fichet_wavelength_nm("S0.0Hz") is None
    assert fichet_wavelength_nm("S1.550nm") is None
    assert fichet_wavelength_nm("S0.550nmx") is None
    assert fichet_wavelength_nm("R") is None
