"""Image output: EXR/PNG/spectral EXR contents, orientation, atomic writes, resume checks."""

from __future__ import annotations

import os
import time
from pathlib import Path

import colour
import numpy as np
import OpenImageIO as oiio
import pytest

from relray import __version__
from relray.core.errors import UserError
from relray.core.output import imageio
from relray.core.render.film import Film, FilmImage

H, W = 5, 7


def _rgba(seed: int = 0) -> np.ndarray:
    rgba = np.random.default_rng(seed).normal(0.5, 2.0, (H, W, 4)).astype(np.float32)
    rgba[0, 0] = [123.25, -7.5, 1e-7, 0.75]  # top-left marker
    return rgba


def _aovs() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(1)
    return {
        "depth": np.where(rng.random((H, W)) < 0.5, 1e10, rng.random((H, W)) * 5).astype(
            np.float32
        ),
        "doppler": (1.0 + rng.random((H, W)) / 3).astype(np.float32),
        "lab_time": (5.0 - rng.random((H, W)) * 3).astype(np.float32),
    }


def _image(bands: bool = True) -> FilmImage:
    centers = np.arange(380.0, 781.0, 10.0)
    spectral = None
    if bands:
        spectral = np.random.default_rng(2).random((H, W, len(centers))).astype(np.float32)
    return FilmImage(
        rgba=_rgba(),
        aovs=_aovs(),
        spectral=spectral,
        band_centers_nm=centers if bands else None,
        spp=np.full((H, W), 4, np.int32),
        rel_error=np.zeros((H, W), np.float32),
    )


def _meta(**extra) -> dict[str, str]:
    return imageio.metadata_for(7, (0.1, 1 / 3, 0.0), 5.0, 64, extra=extra or None)


def _read_uint8(path: Path) -> np.ndarray:
    """The stored 8-bit codes (asking OpenImageIO not to premultiply PNG alpha on read)."""
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    assert inp is not None, oiio.geterror()
    try:
        return inp.read_image(oiio.UINT8)
    finally:
        inp.close()


# ---------------------------------------------------------------------- EXR
def test_exr_round_trip(tmp_path):
    path = tmp_path / "f.exr"
    rgba, aovs, meta = _rgba(), _aovs(), _meta()
    imageio.write_exr(path, rgba, aovs, meta)
    channels, md = imageio.read_exr(path)
    assert set(channels) == {"R", "G", "B", "A", "Depth.Z", "Doppler.D", "LabTime.T"}
    for i, c in enumerate("RGBA"):
        np.testing.assert_array_equal(channels[c], rgba[..., i])
    np.testing.assert_array_equal(channels["Depth.Z"], aovs["depth"])
    np.testing.assert_array_equal(channels["Doppler.D"], aovs["doppler"])
    np.testing.assert_array_equal(channels["LabTime.T"], aovs["lab_time"])
    # Row 0 = top: the marker stays in the top-left pixel, in the file's first scanline.
    assert channels["R"][0, 0] == np.float32(123.25) and channels["G"][0, 0] == -7.5
    inp = oiio.ImageInput.open(str(path))
    first_line = inp.read_scanline(0, 0, oiio.FLOAT)
    inp.close()
    assert first_line[0, 0] == np.float32(123.25)
    for key, value in meta.items():
        assert md[key] == value
    assert md["relray:beta"] == "0.1,0.3333333333333333,0.0"
    assert [float(x) for x in md["relray:beta"].split(",")] == [0.1, 1 / 3, 0.0]
    assert md["relray:version"] == __version__ and md["Software"] == f"relray {__version__}"
    assert md["compression"] == "zip"


def test_exr_denoising_layers_round_trip(tmp_path):
    """albedo and normal become Albedo.R/G/B and Normal.X/Y/Z (Blender reads them as an
    "Albedo" colour pass and a "Normal" vector pass); read back with OpenImageIO."""
    rng = np.random.default_rng(3)
    aovs = {"depth": _aovs()["depth"],
            "albedo": rng.random((H, W, 3)).astype(np.float32),
            "normal": rng.uniform(-1, 1, (H, W, 3)).astype(np.float32)}
    path = tmp_path / "d.exr"
    imageio.write_exr(path, _rgba(), aovs, _meta())
    inp = oiio.ImageInput.open(str(path))
    names = list(inp.spec().channelnames)
    inp.close()
    assert set(names) == {"R", "G", "B", "A", "Depth.Z", "Albedo.R", "Albedo.G", "Albedo.B",
                          "Normal.X", "Normal.Y", "Normal.Z"}
    channels, _ = imageio.read_exr(path)
    for i, c in enumerate("RGB"):
        np.testing.assert_array_equal(channels[f"Albedo.{c}"], aovs["albedo"][..., i])
    for i, c in enumerate("XYZ"):
        np.testing.assert_array_equal(channels[f"Normal.{c}"], aovs["normal"][..., i])
    np.testing.assert_array_equal(channels["Depth.Z"], aovs["depth"])
    assert imageio.aov_channel_names("normal") == ("Normal.X", "Normal.Y", "Normal.Z")
    assert imageio.aov_channel_names("depth") == ("Depth.Z",)
    with pytest.raises(ValueError, match="albedo"):  # a plane where RGB is due
        imageio.write_exr(tmp_path / "e.exr", _rgba(), {"albedo": aovs["depth"]}, _meta())


def test_metadata_for():
    m = imageio.metadata_for(3, np.array([0.5, 0, 0]), 2, 16, extra={"seed": 4, "x:y": 1.5})
    assert m["relray:frame"] == "3" and m["relray:spp"] == "16" and m["relray:ct"] == "2.0"
    assert m["relray:beta"] == "0.5,0.0,0.0" and m["relray:complete"] == "1"
    assert m["relray:seed"] == "4" and m["x:y"] == "1.5"
    assert all(isinstance(v, str) for v in m.values())


# ---------------------------------------------------------------------- PNG
def test_png_srgb_codes(tmp_path):
    lin = np.array([0.0, 0.0031308, 0.18, 1.0, 4.0, -1.0, np.nan], np.float32)
    rgba = np.ones((2, len(lin), 4), np.float32)
    rgba[0, :, :3] = lin[:, None]
    rgba[1, :, :3] = lin[:, None] / 2.0  # exposure +1 brings it back
    path = tmp_path / "a.png"
    imageio.write_png(path, rgba, exposure=1.0)
    codes = _read_uint8(path)
    assert codes.shape == (2, len(lin), 3)
    expect = [0, 10, 118, 255, 255, 0, 0]
    np.testing.assert_array_equal(codes[1, :, 0], expect)
    np.testing.assert_array_equal(codes[1, :, 1], expect)
    np.testing.assert_array_equal(codes[0, :, 2], [0, 18, 162, 255, 255, 0, 0])  # 2x brighter
    # The same curve as colour-science's sRGB encoding.
    # (within rounding to the nearest code: colour-science's float64 curve may differ from
    # ours in the last bits, which would flip a code only at an exact half)
    ref = colour.cctf_encoding(np.clip(np.nan_to_num(lin), 0, 1), function="sRGB")
    assert np.all(np.abs(codes[1, :, 0] - ref * 255) <= 0.5 + 1e-9)


def test_png_alpha_is_straight(tmp_path):
    rgba = np.zeros((1, 3, 4), np.float32)
    rgba[0, 0] = [0.09, 0.09, 0.09, 0.5]  # associated: straight 0.18 -> 118
    rgba[0, 1] = [0.0, 0.0, 0.0, 0.0]
    rgba[0, 2] = [1.0, 0.18, 0.0, 1.0]
    path = tmp_path / "a.png"
    imageio.write_png(path, rgba, alpha=True)
    codes = _read_uint8(path)
    np.testing.assert_array_equal(
        codes[0], [[118, 118, 118, 128], [0, 0, 0, 0], [255, 118, 0, 255]]
    )


# ---------------------------------------------------------------------- spectral EXR
def test_spectral_channel_name():
    assert imageio.spectral_channel_name(550) == "S0.550,000000nm"
    assert imageio.spectral_channel_name(387.5) == "S0.387,500000nm"


def test_spectral_exr_read_by_colour(tmp_path):
    centers = np.array([380.0, 387.5, 550.0, 780.0])
    spectral = np.random.default_rng(3).random((H, W, 4)).astype(np.float32)
    spectral[0, 0] = [1.0, 2.0, 3.0, 4.0]
    path = tmp_path / "s.spectral.exr"
    imageio.write_spectral_exr(path, spectral, centers, _meta(), rgba=_rgba())
    components, spec = colour.io.read_spectral_image_Fichet2021(path, additional_data=True)
    assert set(components) == {"S0"} and spec.is_emissive and not spec.is_polarised
    wl, values = components["S0"]
    order = np.argsort(wl)
    np.testing.assert_array_equal(wl[order], centers)
    np.testing.assert_array_equal(values[..., order], spectral)
    attrs = {a.name: a.value for a in spec.attributes}
    assert attrs["spectralLayoutVersion"] == "1.0"
    assert attrs["emissiveUnits"] == "W.m^-2.sr^-1"
    assert attrs["relray:spp"] == "64"
    channels, _ = imageio.read_exr(path)
    assert "S0.550,000000nm" in channels and "S0.387,500000nm" in channels
    np.testing.assert_array_equal(channels["R"], _rgba()[..., 0])


def test_film_bands_to_spectral_exr(tmp_path):
    # End to end: a 550 nm line sample lands in the 550 nm channel with the band mean.
    f = Film(2, 1, bands=(380, 780, 10))
    lam = np.array([[550.0, 551.0, 700.0, 300.0]])
    f.add_samples(np.array([1]), np.ones((1, 3)), np.ones(1), None, lam, np.ones((1, 4)))
    img = f.resolve(np.eye(3))
    (path,) = imageio.write_frame(tmp_path, "f", ["spectral-exr"], img, _meta())
    assert path.name == "f.spectral.exr"
    wl, values = colour.io.read_spectral_image_Fichet2021(path)["S0"]
    spectrum = dict(zip(wl.tolist(), values[0, 1].tolist(), strict=True))
    assert spectrum[550.0] == pytest.approx(0.2) and spectrum[700.0] == pytest.approx(0.1)
    assert sum(spectrum.values()) == pytest.approx(0.3)
    assert not values[0, 0].any()


# ---------------------------------------------------------------------- write_frame
def test_write_frame_all_formats(tmp_path):
    out = tmp_path / "new" / "dir"
    paths = imageio.write_frame(
        out, "frame_0007", ["png", "exr", "spectral-exr"], _image(), _meta()
    )
    assert [p.name for p in paths] == [
        "frame_0007.png",
        "frame_0007.exr",
        "frame_0007.spectral.exr",
    ]
    assert sorted(os.listdir(out)) == sorted(p.name for p in paths)  # no temp files left
    assert imageio.frame_complete(paths[1], {"spp": 64})


def test_write_frame_rejects_bad_requests_before_writing(tmp_path):
    with pytest.raises(UserError) as e:
        imageio.write_frame(tmp_path / "o", "f", ["exr", "tiff"], _image(), _meta())
    assert e.value.key == "output.formats"
    with pytest.raises(UserError) as e:
        imageio.write_frame(tmp_path / "o", "f", ["exr", "spectral-exr"], _image(False), _meta())
    assert e.value.key == "output.spectral_bands"
    assert not (tmp_path / "o").exists()


def test_unwritable_dir_is_user_error(tmp_path):
    blocker = tmp_path / "file.txt"
    blocker.write_text("not a folder")
    with pytest.raises(UserError) as e:
        imageio.write_frame(blocker / "out", "f", ["exr"], _image(False), _meta())
    assert e.value.key == "output.dir" and str(blocker / "out") in str(e.value)
    with pytest.raises(UserError) as e:
        imageio.write_exr(tmp_path / "missing" / "f.exr", _rgba(), {}, _meta())
    assert e.value.key == "output.dir" and "f.exr" in str(e.value)
    assert not (tmp_path / "missing").exists()


# ---------------------------------------------------------------------- atomicity
@pytest.mark.parametrize("exc", [RuntimeError("disk on fire"), KeyboardInterrupt()])
@pytest.mark.parametrize("existing", [False, True])
def test_failed_write_leaves_no_trace(tmp_path, monkeypatch, exc, existing):
    target = tmp_path / "f.exr"
    if existing:
        imageio.write_exr(target, _rgba(), _aovs(), _meta())
        before = target.read_bytes()

    def broken(self, *args, **kwargs):
        raise exc

    monkeypatch.setattr(oiio.ImageOutput, "write_image", broken)
    with pytest.raises(type(exc)):
        imageio.write_exr(target, _rgba(5), _aovs(), _meta())
    with pytest.raises(type(exc)):
        imageio.write_png(tmp_path / "f.png", _rgba(5))
    monkeypatch.undo()
    assert os.listdir(tmp_path) == (["f.exr"] if existing else [])
    if existing:
        assert target.read_bytes() == before
        assert imageio.frame_complete(target)


def test_failed_rename_leaves_no_temp(tmp_path, monkeypatch):
    def broken_replace(src, dst):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(UserError) as e:
        imageio.write_png(tmp_path / "f.png", _rgba())
    assert e.value.key == "output.dir"
    assert os.listdir(tmp_path) == []


# ---------------------------------------------------------------------- resume
def test_frame_complete(tmp_path):
    path = tmp_path / "f.exr"
    imageio.write_exr(path, _rgba(), _aovs(), _meta())
    assert imageio.frame_complete(path)
    assert imageio.frame_complete(path, _meta())
    assert imageio.frame_complete(path, {"spp": 64, "beta": (0.1, 1 / 3, 0), "ct": 5})
    assert imageio.frame_complete(path, {"relray:frame": "7"})
    assert not imageio.frame_complete(path, {"spp": 128})
    assert not imageio.frame_complete(path, {"beta": (0.1, 0.3333, 0.0)})
    assert not imageio.frame_complete(path, {"missing_key": "1"})
    assert not imageio.frame_complete(tmp_path / "nope.exr")
    assert not imageio.frame_complete(tmp_path)


def test_frame_complete_rejects_broken_files(tmp_path):
    good = tmp_path / "good.exr"
    imageio.write_exr(good, _rgba(), _aovs(), _meta())
    data = good.read_bytes()
    for i, cut in enumerate([0, 50, len(data) // 2, len(data) - 8]):
        bad = tmp_path / f"cut{i}.exr"
        bad.write_bytes(data[:cut])
        assert not imageio.frame_complete(bad), cut
    junk = tmp_path / "junk.exr"
    junk.write_bytes(b"\x76\x2f\x31\x01" + os.urandom(500))  # EXR magic, then noise
    assert not imageio.frame_complete(junk)

    not_done = tmp_path / "partial.exr"
    imageio.write_exr(not_done, _rgba(), {}, {**_meta(), "relray:complete": "0"})
    assert not imageio.frame_complete(not_done)
    no_meta = tmp_path / "foreign.exr"
    imageio.write_exr(no_meta, _rgba(), {}, {})
    assert not imageio.frame_complete(no_meta)
    # An EXR without alpha is not one of ours.
    rgb_only = tmp_path / "rgb.exr"
    spec = oiio.ImageSpec(W, H, 3, oiio.FLOAT)
    for k, v in _meta().items():
        spec.attribute(k, v)
    out = oiio.ImageOutput.create(str(rgb_only))
    out.open(str(rgb_only), spec)
    out.write_image(np.zeros((H, W, 3), np.float32))
    out.close()
    assert not imageio.frame_complete(rgb_only)


# ---------------------------------------------------------------------- stale temps
def test_remove_stale_temps(tmp_path):
    host, me = imageio._host_tag(), os.getpid()
    dead_pid = 999_999_999  # above any pid_max
    names = {
        "dead": f".frame_0001.tmp-{host}-{dead_pid}-0123abcd.exr",
        "dead_spectral": f".frame_0001.spectral.tmp-{host}-{dead_pid}-89abcdef.exr",
        "live": f".frame_0002.tmp-{host}-{me}-0123abcd.png",
        "foreign_fresh": f".frame_0003.tmp-otherbox-{dead_pid}-0123abcd.exr",
        "foreign_old": f".frame_0004.tmp-otherbox-{dead_pid}-0123abcd.exr",
        "finished": "frame_0001.exr",
        "hidden": ".frame_0001.exr",
        "lookalike": "frame.tmp-host-1-0123abcd.exr",
    }
    for name in names.values():
        (tmp_path / name).write_bytes(b"x")
    old = time.time() - 2 * imageio.STALE_TEMP_AGE_S
    os.utime(tmp_path / names["foreign_old"], (old, old))
    assert imageio.remove_stale_temps(tmp_path) == 3
    left = set(os.listdir(tmp_path))
    assert left == {names[k] for k in ("live", "foreign_fresh", "finished", "hidden", "lookalike")}
    assert imageio.remove_stale_temps(tmp_path / "absent") == 0


def test_temp_names_are_recognised(tmp_path):
    for name in ("frame_0001.exr", "frame_0001.spectral.exr", "a.png"):
        tmp = imageio.temp_path_for(tmp_path / name)
        assert tmp.parent == tmp_path and tmp.suffix == Path(name).suffix
        assert tmp.name.startswith(".") and imageio._TEMP_RE.match(tmp.name)


def test_add_exr_channels_keeps_the_file_and_appends(tmp_path):
    """Channels are appended to an EXR (pixels, channels and metadata kept); channels it
    already has are left alone."""
    from relray.core.output.imageio import add_exr_channels, write_exr

    rng = np.random.default_rng(1)
    rgba = rng.random((5, 7, 4)).astype(np.float32)
    path = tmp_path / "a.exr"
    write_exr(path, rgba, {}, {"relray:frame": 3})
    extra = rng.random((5, 7)).astype(np.float32)
    assert add_exr_channels(path, {"Layer.Doppler.D": extra, "R": extra}) == ["Layer.Doppler.D"]
    buf = oiio.ImageBuf(str(path))
    spec = buf.spec()
    assert list(spec.channelnames) == ["R", "G", "B", "A", "Layer.Doppler.D"]
    px = buf.get_pixels(oiio.FLOAT)
    np.testing.assert_array_equal(px[..., :4], rgba)
    np.testing.assert_array_equal(px[..., 4], extra)
    assert spec.get_string_attribute("relray:frame") == "3"
    assert add_exr_channels(path, {"Layer.Doppler.D": extra}) == []


def _blender_config():
    import importlib.util
    from pathlib import Path

    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        return None
    found = sorted(Path(spec.origin).parent.glob("*/datafiles/colormanagement/config.ocio"))
    return found[0] if found else None


def test_a_png_through_blenders_agx_view_as_blender_writes_it(tmp_path):
    """``output.view_transform``: pixels through Blender's config, display sRGB, view
    AgX, get the codes of OCIO's own AgX display transform (from Linear Rec.709, which
    the config's scene_linear role names); a bright saturated colour that the plain sRGB
    curve clips keeps detail; the file names the transform."""
    from relray.core.output.imageio import write_png
    from relray.core.scene.description import ViewTransform

    config = _blender_config()
    assert config is not None, "bpy (a dev dependency) ships Blender's OCIO config"
    rgba = np.zeros((1, 2, 4), np.float32)
    rgba[0, 0] = (0.18, 0.18, 0.18, 1.0)
    rgba[0, 1] = (4.0, 0.5, 0.05, 1.0)  # bright and saturated: AgX desaturates it
    plain, agx = tmp_path / "plain.png", tmp_path / "agx.png"
    write_png(plain, rgba)
    write_png(agx, rgba, view=ViewTransform(config, "sRGB", "AgX"))
    p = oiio.ImageBuf(str(plain)).get_pixels(oiio.UINT8)
    a = oiio.ImageBuf(str(agx)).get_pixels(oiio.UINT8)
    cc = oiio.ImageBuf(oiio.ImageSpec(2, 1, 4, oiio.FLOAT))
    cc.set_pixels(oiio.ROI(), rgba)
    ref = oiio.ImageBufAlgo.ociodisplay(cc, "sRGB", "AgX", fromspace="Linear Rec.709",
                                        colorconfig=str(config)).get_pixels(oiio.FLOAT)
    np.testing.assert_array_equal(a[0, :, :3], np.floor(ref[0, :, :3] * 255 + 0.5))
    assert p[0, 1, 0] == 255 and a[0, 1, 0] < 255  # the plain curve clips, AgX does not
    assert oiio.ImageBuf(str(agx)).spec().get_string_attribute(
        "relray:view_transform") == "OCIO sRGB / AgX"
