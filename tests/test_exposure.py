"""Automatic exposure (core/output/exposure.py): metering against known answers, the
scaling law, smoothing of a step, and end to end: the searchlight effect at β = 0.5
head-on and β = 0.9 looking back, resume, the metadata, the progress events (on a Dask
farm: tests/test_farm.py)."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from relray.core import cli
from relray.core.errors import UserError
from relray.core.output import exposure, imageio
from relray.core.progress import JsonReporter
from relray.core.runner import render_job
from relray.core.scene import job as jobmod

Y709 = np.array([0.2126, 0.7152, 0.0722])


def grey(L: float, shape: tuple[int, int] = (6, 8), alpha: float = 1.0) -> np.ndarray:
    img = np.full(shape + (4,), L, np.float32)
    img[..., 3] = alpha
    return img


def stops_for(L: float) -> float:
    """log2(0.18 / L) for the float32 value L becomes in an image."""
    return math.log2(0.18 / float(np.float32(L)))


def random_image(seed: int = 1, shape: tuple[int, int] = (40, 50)) -> np.ndarray:
    """Log-normal colours over 16 stops, alpha 1."""
    rng = np.random.default_rng(seed)
    rgb = np.exp2(rng.normal(-3.0, 4.0, shape + (3,))) * rng.uniform(0.2, 1.0, shape + (3,))
    return np.concatenate([rgb, np.ones(shape + (1,))], axis=2).astype(np.float32)


# ------------------------------------------------------------------------ metering


@pytest.mark.parametrize("L", [0.18, 1.0, 0.01, 37.5, 2.0**-20])
def test_a_uniform_grey_meters_log2_of_key_over_its_luminance(L):
    assert exposure.meter(grey(L)) == pytest.approx(stops_for(L), abs=1e-12)


def test_luminance_weights_are_rec709():
    """A pure red, green or blue image meters by its own Rec.709 weight."""
    for c, w in enumerate(Y709):
        img = np.zeros((4, 4, 4), np.float32)
        img[..., c] = 1.0
        assert exposure.meter(img) == pytest.approx(math.log2(0.18 / w), abs=1e-6)


def test_meter_is_the_geometric_mean_written_out():
    """Without trimming: log2(0.18) minus the log2 of exp(mean ln Y), computed here."""
    img = random_image(2)
    Y = img[..., :3].astype(np.float64) @ Y709
    geometric_mean = math.exp(float(np.mean(np.log(Y))))
    assert exposure.meter(img, trim=0.0) == pytest.approx(math.log2(0.18 / geometric_mean),
                                                          abs=1e-9)
    assert exposure.log_average_luminance(img, trim=0.0) == pytest.approx(geometric_mean,
                                                                           rel=1e-9)


@pytest.mark.parametrize("k", [-30, -7, -1, 1, 3, 20])
def test_scaling_the_image_by_2_to_the_k_shifts_the_exposure_by_minus_k(k):
    img = random_image(3)
    img[0, 0, 0], img[0, 1, 1], img[0, 2, :3] = np.nan, np.inf, 0.0  # pixels the meter skips
    img[0, 3, :3] = -2.0
    scaled = img.copy()
    scaled[..., :3] *= np.float32(2.0**k)
    base = exposure.meter(img)
    assert base is not None and abs(base) > 0.1  # not a trivially grey image
    assert exposure.meter(scaled) == pytest.approx(base - k, abs=1e-9)


def test_nan_inf_zero_and_negative_pixels_are_left_out():
    img = random_image(4)
    dirty = img.copy()
    dirty[0, 0, 0], dirty[0, 1, 1], dirty[0, 2, 2] = np.nan, np.inf, -np.inf
    dirty[0, 3, :3] = 0.0
    dirty[0, 4, :3] = -0.5
    clean = np.delete(img.reshape(-1, 4), [0, 1, 2, 3, 4], axis=0)[None]
    assert exposure.meter(dirty, trim=0.0) == pytest.approx(exposure.meter(clean, trim=0.0),
                                                            abs=1e-12)


def test_the_trim_drops_fireflies():
    """0.5 % of pixels a million times too bright: left out at the default 1 % trim."""
    img = grey(0.18, (20, 20))
    img[0, :2, :3] = 1e6
    assert exposure.meter(img) == pytest.approx(stops_for(0.18), abs=1e-12)
    untrimmed = stops_for(0.18) - 2 / 400 * math.log2(1e6 / float(np.float32(0.18)))
    assert exposure.meter(img, trim=0.0) == pytest.approx(untrimmed, abs=1e-9)


def test_pixels_outside_the_objects_count_when_they_show_the_sky():
    """alpha is not a weight: a sky pixel (alpha 0) with radiance is metered, a black
    one is not."""
    img = grey(0.18, (4, 4))  # rows 2-3: an object
    img[:2, :, 3] = 0.0  # rows 0-1: the sky, two stops brighter
    img[:2, :, :3] = 4.0 * np.float32(0.18)
    assert exposure.meter(img) == pytest.approx(stops_for(0.18) - 1.0, abs=1e-12)
    img[:2, :, :3] = 0.0  # a black sky is left out
    assert exposure.meter(img) == pytest.approx(stops_for(0.18), abs=1e-12)


def test_a_black_frame_has_no_reading_and_keeps_the_previous_exposure():
    assert exposure.meter(grey(0.0)) is None
    assert exposure.meter(np.full((3, 3, 4), np.nan, np.float32)) is None
    assert exposure.smooth(None, None) == 0.0
    assert exposure.smooth(2.5, None) == 2.5
    first = exposure.frame_exposure(grey(0.0), None)
    assert (first.stops, first.metered, first.auto) == (0.0, None, True)


def test_readings_are_clamped_to_the_job_range():
    assert exposure.meter(grey(1e-30)) == exposure.MAX_EXPOSURE_STOPS == 64.0
    assert exposure.meter(grey(1e30)) == -64.0
    assert exposure.meter(grey(1e-15)) == pytest.approx(stops_for(1e-15), abs=1e-9)


def test_bad_arguments():
    with pytest.raises(ValueError):
        exposure.meter(np.zeros((4, 4)))
    with pytest.raises(ValueError):
        exposure.meter(grey(1.0), trim=0.5)
    with pytest.raises(ValueError):
        exposure.meter(grey(1.0), key=0.0)
    with pytest.raises(ValueError):
        exposure.smoothing_weight(-1.0)


# ----------------------------------------------------------------------- smoothing


@pytest.mark.parametrize("tau", [0.5, 2.0, 5.0])
def test_a_step_is_followed_exponentially_with_the_time_constant(tau):
    readings = [1.0] * 4 + [11.0] * 12
    out = exposure.smooth_series(readings, tau)
    assert out[:4] == [1.0] * 4
    for j, e in enumerate(out[4:], start=1):  # j frames after the step
        assert e == pytest.approx(1.0 + 10.0 * (1.0 - math.exp(-j / tau)), abs=1e-12)
    assert all(a < b <= 11.0 for a, b in zip(out[3:], out[4:], strict=False))


def test_the_default_time_constant_is_two_frames():
    out = exposure.smooth_series([0.0, 10.0, 10.0])
    assert out[1] == pytest.approx(10.0 * (1.0 - math.exp(-0.5)))
    assert exposure.smooth_series([3.0, 7.0], 0.0) == [3.0, 7.0]  # τ = 0: no smoothing


def test_black_frames_hold_the_exposure_and_the_first_reading_starts_it():
    a = 1.0 - math.exp(-0.5)  # α at τ = 2 frames
    out = exposure.smooth_series([None, None, 4.0, None, 8.0])
    assert out == pytest.approx([0.0, 0.0, 4.0 * a, 4.0 * a, 4.0 * a + a * (8.0 - 4.0 * a)],
                                abs=1e-12)
    assert exposure.smooth_series([None, 4.0]) == pytest.approx([0.0, 4.0 * a])
    assert exposure.smooth_series([4.0, None]) == [4.0, 4.0]


def test_the_chain_gives_the_series_whichever_readings_come_from_files():
    readings = {1: 2.0, 2: None, 3: -4.0, 4: 6.5, 5: 6.5}
    want = exposure.smooth_series(readings.values())
    asked: list[int] = []

    def lookup(frame: int) -> float | None:
        asked.append(frame)
        return readings[frame]

    chain = exposure.ExposureChain(list(readings), lookup)
    img = grey(0.18 * 2.0**-6.5)
    got = chain.record(4, img)  # frames 1-3 are read back, 4 is metered
    assert got.metered == pytest.approx(6.5) and got.stops == pytest.approx(want[3])
    assert asked == [1, 2, 3]
    assert chain.stops(5) == pytest.approx(want[4]) and asked == [1, 2, 3, 5]
    assert chain.stops(2) == pytest.approx(want[1])  # asked again: same answer
    with pytest.raises(ValueError):
        chain.stops(9)


def test_metadata_round_trip():
    e = exposure.FrameExposure(-1.25, 0.1 + 0.2, auto=True)
    meta = e.metadata()
    assert meta == {"relray:exposure": "-1.25", "relray:exposure_metered": repr(0.1 + 0.2)}
    assert exposure.parse_metered(meta["relray:exposure_metered"]) == 0.1 + 0.2
    assert exposure.FrameExposure(0.0, None, auto=True).metadata()[
        "relray:exposure_metered"] == "none"
    for text in ("none", None, "nan", "inf", "x"):
        assert exposure.parse_metered(text) is None
    assert exposure.FrameExposure(2.0).metadata() == {"relray:exposure": "2.0"}


# ------------------------------------------------------------------------ end to end

# The camera sits inside a hot sphere (a 6000 K blackbody, near the Sun's colour) and
# looks at a grey ball the sphere lights. β along the view: head-on, the searchlight
# effect and the blueshift brighten the view (about 2.6 stops at β = 0.5); looking back
# at β = 0.9 (D ≈ 0.23) the visible band sees the sphere's infrared: about 20 stops darker.
SEARCHLIGHT = """
[render]
width = 24
height = 16
spp = 4
max_depth = 2
threads = 2
[output]
dir = "out"
name = "f_{{frame:03d}}"
exposure = {exposure}
[camera]
position = [0.0, 0.0, 0.0]
look_at = [0.0, 1.0, 0.0]
up = [0.0, 0.0, 1.0]
fov = 40.0
[motion]
{motion}
[[materials]]
name = "hot"
base_color = [0.0, 0.0, 0.0]
emission_blackbody = 6000.0
emission_strength = 0.3
[[materials]]
name = "grey"
base_color = [0.5, 0.5, 0.5]
roughness = 1.0
[[objects]]
shape = "sphere"
center = [0.0, 0.0, 0.0]
radius = 6.0
material = "hot"
[[objects]]
shape = "sphere"
center = [0.0, 3.0, 0.0]
radius = 0.6
material = "grey"
"""
WHITE, BLACK = 0.9, 0.01
"""Mean PNG luminance above which a frame is white, below which it is black."""
GREY_FACTOR = 2.0
"""Auto exposure puts the PNG's mean luminance within this factor of middle grey (0.18):
the meter maps the geometric mean onto 0.18, the arithmetic mean of a frame whose
pixels differ is higher, and sRGB's 8 bits round."""


def png_luminance(path: Path) -> np.ndarray:
    """(h, w) linear Rec.709 luminance of an sRGB PNG, decoded here."""
    v = oiio.ImageBuf(str(path)).get_pixels(oiio.UINT8)[..., :3] / 255.0
    linear = np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)
    return linear @ Y709


def read_rgba(path: Path) -> tuple[np.ndarray, dict[str, str]]:
    channels, meta = imageio.read_exr(path)
    return np.stack([channels[c] for c in "RGBA"], axis=2), meta


def render(tmp_path: Path, name: str, exposure_text: str, motion: str) -> Path:
    folder = tmp_path / name
    folder.mkdir()
    path = folder / "job.toml"
    path.write_text(SEARCHLIGHT.format(exposure=exposure_text, motion=motion))
    assert cli.main(["render", str(path), "--quiet"]) == 0
    return folder / "out"


@pytest.mark.parametrize("beta, exposed_at_0", [(0.5, "white"), (-0.9, "black")],
                         ids=["head-on 0.5", "looking back 0.9"])
def test_searchlight_auto_exposure_brings_white_and_black_to_grey(tmp_path, beta,
                                                                  exposed_at_0):
    motion = f"beta = [0.0, {beta}, 0.0]"
    fixed = render(tmp_path, "fixed", "0.0", motion)
    auto = render(tmp_path, "auto", '"auto"', motion)
    Y0 = png_luminance(fixed / "f_001.png").mean()
    assert (Y0 > WHITE) if exposed_at_0 == "white" else (Y0 < BLACK), Y0
    Y = png_luminance(auto / "f_001.png").mean()
    assert 0.18 / GREY_FACTOR < Y < 0.18 * GREY_FACTOR, Y
    # the EXR stays linear and unexposed: the same pixels as at exposure 0
    rgba, meta = read_rgba(auto / "f_001.exr")
    fixed_rgba, fixed_meta = read_rgba(fixed / "f_001.exr")
    np.testing.assert_array_equal(rgba, fixed_rgba)
    # what the files record is the meter of those pixels, applied to the PNG
    metered = exposure.meter(rgba)
    assert metered is not None and float(meta["relray:exposure_metered"]) == metered
    assert float(meta["relray:exposure"]) == metered  # one frame: nothing to smooth
    assert (metered < -1.5) if exposed_at_0 == "white" else (metered > 10.0)
    assert imageio.read_metadata(auto / "f_001.png")["relray:exposure"] == meta[
        "relray:exposure"]
    assert fixed_meta["relray:exposure"] == "0.0" and "relray:exposure_metered" not in \
        fixed_meta
    codes = imageio.png_codes(rgba, metered)
    np.testing.assert_array_equal(oiio.ImageBuf(str(auto / "f_001.png")).get_pixels(
        oiio.UINT8), codes)


# An acceleration away from the view, then a coast: the meter changes frame to frame.
ANIMATION = """frames = [1, 5]
keyframes = [{frame = 1, beta = [0.0, 0.0, 0.0]}, {frame = 3, beta = [0.0, -0.6, 0.0]},
             {frame = 5, beta = [0.0, -0.6, 0.0]}]"""


def recorded(out: Path, frames=range(1, 6)) -> list[dict[str, str]]:
    return [imageio.read_metadata(out / f"f_{f:03d}.exr") for f in frames]


def test_an_animation_smooths_and_a_resume_applies_the_same_exposure(tmp_path):
    whole = render(tmp_path, "whole", '"auto"', ANIMATION)
    metas = recorded(whole)
    readings = [float(m["relray:exposure_metered"]) for m in metas]
    applied = [float(m["relray:exposure"]) for m in metas]
    assert readings[2] - readings[0] > 3.0  # darker by stops: the exposure rises
    assert applied == pytest.approx(exposure.smooth_series(readings), abs=1e-12)
    assert all(abs(a - r) > 0.1 for a, r in zip(applied[1:], readings[1:], strict=False))

    # the same job, stopped after frame 2, then resumed: frames 3-5 continue the average
    folder = tmp_path / "resumed"
    folder.mkdir()
    path = folder / "job.toml"
    path.write_text((tmp_path / "whole" / "job.toml").read_text())
    out = folder / "out"
    with pytest.raises(Exception) as stopped:
        render_job(jobmod.load_job(path), show_progress=False,
                   cancel=lambda: (out / "f_002.exr").exists())
    assert "Cancel" in type(stopped.value).__name__
    assert not (out / "f_003.exr").exists()
    json_lines = io.StringIO()
    render_job(jobmod.load_job(path), reporter=JsonReporter(json_lines))
    for m, r in zip(metas, recorded(out), strict=True):
        assert r["relray:exposure"] == m["relray:exposure"]
        assert r["relray:exposure_metered"] == m["relray:exposure_metered"]
        assert r["relray:digest"] == m["relray:digest"]
    for f in range(1, 6):
        a = oiio.ImageBuf(str(whole / f"f_{f:03d}.png")).get_pixels(oiio.UINT8)
        b = oiio.ImageBuf(str(out / f"f_{f:03d}.png")).get_pixels(oiio.UINT8)
        np.testing.assert_array_equal(a, b)
    events = [json.loads(line) for line in json_lines.getvalue().splitlines()]
    done = [e for e in events if e["event"] == "frame_done"]
    assert [e["frame"] for e in done] == [3, 4, 5]
    assert [e["exposure"] for e in done] == pytest.approx(applied[2:], abs=1e-12)
    assert [e["exposure_metered"] for e in done] == pytest.approx(readings[2:], abs=1e-12)


def test_a_frame_range_is_its_own_animation(tmp_path):
    """--frames 3-5 starts the average at frame 3: deterministic for the job and range."""
    whole = render(tmp_path, "whole", '"auto"', ANIMATION)
    readings = [float(m["relray:exposure_metered"]) for m in recorded(whole)]
    path = tmp_path / "whole" / "job.toml"
    sub = tmp_path / "sub"
    assert cli.main(["render", str(path), "--quiet", "--frames", "3-5", "--out",
                     str(sub)]) == 0
    metas = recorded(sub, range(3, 6))
    assert [float(m["relray:exposure_metered"]) for m in metas] == readings[2:]
    assert [float(m["relray:exposure"]) for m in metas] == pytest.approx(
        exposure.smooth_series(readings[2:]), abs=1e-12)


def test_a_number_is_applied_as_before_and_recorded(tmp_path):
    out = render(tmp_path, "fixed", "-1.5", "beta = [0.0, 0.0, 0.0]")
    rgba, meta = read_rgba(out / "f_001.exr")
    assert meta["relray:exposure"] == "-1.5" and "relray:exposure_metered" not in meta
    np.testing.assert_array_equal(oiio.ImageBuf(str(out / "f_001.png")).get_pixels(
        oiio.UINT8), imageio.png_codes(rgba, -1.5))


@pytest.mark.parametrize("value, word", [('"autox"', "did you mean 'auto'"),
                                         ("nan", "finite")])
def test_a_bad_exposure_exits_2_naming_key_and_file(tmp_path, capsys, value, word):
    path = tmp_path / "job.toml"
    path.write_text(SEARCHLIGHT.format(exposure=value, motion=""))
    with pytest.raises(UserError) as err:
        jobmod.load_job(path)
    assert err.value.key == "output.exposure" and word in str(err.value)
    assert cli.main(["render", str(path), "--quiet"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "output.exposure" in lines[0] and str(path) in lines[0]
    assert not (tmp_path / "out").exists()
