"""core/render/whole_paths.py: whole paths in one kernel call for static Lambert scenes
(flat or smooth-shaded, textured or not, lit by emissive triangles, point, spot and sun
lights, a constant sky or an environment map).

Its estimator is the wavefront integrator's, with the same random numbers, so the two
must give the same radiance path by path (to float32 rounding: a rounding difference may
flip a roulette decision now and then, hence a small allowance of differing paths), and
the same camera-ray hit distances; and the renderer must take it exactly where it
applies.
"""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from relray.core.render import whole_paths
from relray.core.render.frames import build_renderer
from relray.core.render.integrator import trace
from relray.core.scene.job import parse_job
from relray.core.scene.motion import frame_events

CORNELL = Path(__file__).resolve().parents[1] / "presets" / "cornell.toml"


def cornell(**render) -> dict:
    data = tomllib.loads(CORNELL.read_text())
    data["render"].update({"width": 16, "height": 16, "spp": 4, "threads": 1, **render})
    data["output"]["aovs"] = ["depth"]
    return data


def renderer(data: dict, tmp_path: Path):
    job = parse_job(copy.deepcopy(data), tmp_path / "job.toml")
    return build_renderer(job), frame_events(job)[0][1]


def camera_paths(fr, ev, spp: int):
    """The camera stage of every path of frame 1 (:meth:`FrameRenderer.camera_paths`):
    (keys, origins, directions, lanes' table coordinates, lanes)."""
    n_pix = fr.camera.width * fr.camera.height
    pix = np.repeat(np.arange(n_pix, dtype=np.int64), spp)
    samp = np.tile(np.arange(spp, dtype=np.int64), n_pix)
    cp = fr.camera_paths(ev, 1, pix, samp)
    return cp.keys, cp.o, cp.d, np.ascontiguousarray(cp.lamu), cp.nlanes


def write_sky_map(path: Path) -> Path:
    """A 32 × 16 map: a blue upper half, a brown lower half, a bright 1-texel sun."""
    px = np.zeros((16, 32, 3), np.float32)  # row 0 = top (file order)
    px[:8] = (0.3, 0.4, 0.6)
    px[8:] = (0.1, 0.08, 0.05)
    px[4, 12] = 400.0
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(32, 16, 3, oiio.FLOAT))
    assert out.write_image(px)
    out.close()
    return path


def environment_scene(tmp_path: Path, **render) -> dict:
    """A grey ground, a smooth-shaded sphere (vertex normals) and a box under the map."""
    write_sky_map(tmp_path / "sky.exr")
    grey = {"name": "grey", "base_color": [0.6, 0.6, 0.6]}
    return {
        "render": {"width": 16, "height": 12, "spp": 8, "max_depth": 5, "seed": 3,
                   "threads": 1, **render},
        "camera": {"position": [0.0, -6.0, 2.5], "look_at": [0.0, 0.0, 0.6], "fov": 50.0},
        "motion": {"beta": [0.0, 0.0, 0.0]},
        "output": {"aovs": ["depth"]},
        "scene": {"environment": {"file": "sky.exr"}},
        "materials": [grey],
        "objects": [
            {"shape": "quad", "corners": [[-8, -8, 0], [8, -8, 0], [8, 8, 0], [-8, 8, 0]],
             "material": "grey"},
            {"shape": "sphere", "center": [-0.9, 0.3, 0.8], "radius": 0.8, "material": "grey",
             "subdivisions": 2},
            {"shape": "box", "center": [1.0, 0.5, 0.6], "size": [1.2, 1.2, 1.2],
             "material": "grey"},
        ],
    }


def _sky(data):
    data["scene"]["background"] = [0.2, 0.3, 0.4]


def _delta_lights(data):
    data["lights"] = [
        {"type": "point", "position": [0.3, 0.0, 1.5], "power": 10.0},
        {"type": "spot", "position": [-0.3, 0.2, 1.8], "direction": [0.0, 0.0, -1.0],
         "power": 20.0, "spot_size": 60.0},
        {"type": "sun", "direction": [0.3, 0.5, -1.0], "power": 2.0}]


def _transparent(data):
    data["render"]["transparent"] = True


def write_texture(path: Path, pixels) -> str:
    """An EXR of ``pixels`` (H, W, C), top row first; returns its file name."""
    px = np.ascontiguousarray(np.asarray(pixels, np.float32))
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(px.shape[1], px.shape[0], px.shape[2],
                                              oiio.FLOAT))
    assert out.write_image(px)
    out.close()
    return path.name


def _textures(data, folder: Path):
    """A base-colour checker on the white surfaces, a roughness map and a tilted normal
    map on the red and green walls, a glowing texture on the blocks (emission)."""
    ij = np.indices((8, 8)).sum(axis=0) % 2
    checker = np.where(ij[..., None] == 1, [0.8, 0.7, 0.2], [0.1, 0.3, 0.6])
    tilt = np.tile([0.75, 0.5, 0.93], (4, 4, 1))
    glow = np.tile(np.linspace(0.0, 2.0, 8)[:, None, None] * [1.0, 0.5, 0.2], (1, 8, 1))
    mats = {m["name"]: m for m in data["materials"]}
    mats["white"]["base_color_texture"] = write_texture(folder / "checker.exr", checker)
    for wall in ("red", "green"):
        mats[wall]["roughness_texture"] = write_texture(folder / "rough.exr",
                                                        np.full((4, 4, 1), 0.4))
        mats[wall]["normal_texture"] = write_texture(folder / "tilt.exr", tilt)
    data["materials"].append({"name": "glow", "base_color": [0.5, 0.5, 0.5],
                              "emission_texture": write_texture(folder / "glow.exr", glow),
                              "emission_strength": 0.5})
    for o in data["objects"]:
        if o["name"] in ("short_block", "tall_block"):
            o["material"] = "glow"


def _checker(data, folder: Path):
    """A base-colour checker and a tilted normal map on every material (the map-lit scene:
    the kernel compiled for a map and textures together)."""
    ij = np.indices((8, 8)).sum(axis=0) % 2
    checker = write_texture(folder / "checker.exr",
                            np.where(ij[..., None] == 1, [0.8, 0.7, 0.2], [0.1, 0.3, 0.6]))
    tilt = write_texture(folder / "tilt.exr", np.tile([0.75, 0.5, 0.93], (4, 4, 1)))
    for m in data["materials"]:
        m.update(base_color_texture=checker, normal_texture=tilt)


def _moving_blocks(data):
    """The two blocks move (two bodies, 0.4 c and 0.5 c), the room and the light rest."""
    for o in data["objects"]:
        if o["name"] == "short_block":
            o["velocity"] = [0.4, 0.0, 0.0]
        elif o["name"] == "tall_block":
            o["velocity"] = [0.0, -0.3, 0.4]


def _moving_room(data):
    """Everything but the light is one body at 0.3 c: most bounces leave a body and land
    on the same one again (its rest-frame form is reused)."""
    for o in data["objects"]:
        if o["name"] != "ceiling_light":
            o["velocity"] = [0.3, 0.0, 0.0]


def _moving_bodies(data):
    """The sphere and the box under the map move (0.5 c and 0.3 c), the ground rests."""
    data["objects"][1]["velocity"] = [0.5, 0.0, 0.0]
    data["objects"][2]["velocity"] = [0.0, 0.2, 0.2]


def _moving_light(data):
    """The light moves (0.15 c along the ceiling, sampled in its rest frame from the static
    vertices)."""
    for o in data["objects"]:
        if o["name"] == "ceiling_light":
            o["velocity"] = [0.15, 0.0, 0.0]


def _moving_blocks_and_light(data):
    """The blocks and the light move, each its own body: a moving vertex does not sample
    another body's light (BSDF sampling finds it)."""
    _moving_blocks(data)
    _moving_light(data)


def _moving_all(data):
    """The room and its light are one body: the light is sampled in their common rest
    frame."""
    for o in data["objects"]:
        o["velocity"] = [0.3, 0.0, 0.0]


def scene_data(tmp_path: Path, scene: str, spectral: str, beta: float) -> dict:
    """A scene that takes whole paths: the Cornell box (plain, under a constant sky, with
    delta lights added, or with moving bodies) or :func:`environment_scene` (plain or on
    a transparent film), moving towards the scene at ``beta`` (shifted lanes,
    aberration)."""
    name, _, change = scene.partition("+")
    data = environment_scene(tmp_path) if name == "environment" else cornell()
    data["render"].update(spectral=spectral, spp=8)
    data["motion"]["beta"] = [0.0, beta, 0.0]
    if change in ("textures", "checker", "moving_textured"):
        if change == "moving_textured":
            _moving_blocks(data)
        (_textures if change == "textures" else _checker)(data, tmp_path)
    elif change:
        {"sky": _sky, "delta_lights": _delta_lights, "transparent": _transparent,
         "moving_blocks": _moving_blocks, "moving_room": _moving_room,
         "moving_light": _moving_light, "moving_blocks_and_light": _moving_blocks_and_light,
         "moving_all": _moving_all, "moving": _moving_bodies}[change](data)
    return data


@pytest.mark.parametrize("scene,spectral,beta", [
    ("cornell", "cie1931", 0.0), ("cornell", "cie1931", 0.6), ("cornell", "rgb", 0.0),
    ("cornell+sky", "cie1931", 0.3), ("cornell+delta_lights", "cie1931", 0.0),
    ("cornell+delta_lights", "rgb", 0.0), ("environment", "cie1931", 0.0),
    ("environment", "cie1931", 0.6), ("environment", "rgb", 0.0),
    ("environment+transparent", "cie1931", 0.0), ("cornell+textures", "cie1931", 0.0),
    ("cornell+textures", "cie1931", 0.6), ("cornell+textures", "rgb", 0.0),
    ("environment+checker", "cie1931", 0.6), ("cornell+moving_blocks", "cie1931", 0.0),
    ("cornell+moving_blocks", "cie1931", 0.6), ("cornell+moving_blocks", "rgb", 0.0),
    ("cornell+moving_room", "cie1931", 0.3), ("cornell+moving_light", "cie1931", 0.0),
    ("cornell+moving_blocks_and_light", "cie1931", 0.4), ("cornell+moving_all", "cie1931", 0.0),
    ("cornell+moving_textured", "cie1931", 0.5), ("environment+moving", "cie1931", 0.0),
    ("environment+moving", "cie1931", 0.5), ("environment+moving", "rgb", 0.0)])
def test_whole_paths_give_the_wavefront_integrators_radiance_path_by_path(
        tmp_path, scene, spectral, beta):
    fr, ev = renderer(scene_data(tmp_path, scene, spectral, beta), tmp_path)
    assert fr.whole_paths
    keys, o, d, lamu, nlanes = camera_paths(fr, ev, 8)
    depth = fr.settings.max_depth
    sky_seen = not fr.settings.transparent
    spread = 0.01  # the ray cones' start (textures' level of detail)
    t0 = float(ev.t)
    L1, t1, seg1 = whole_paths.trace(fr.kernel, fr.prep.tracer, depth, keys, o.copy(),
                                     d.copy(), lamu, nlanes, sky_seen=sky_seen, t0=t0,
                                     spread=spread)
    L1, t1, seg1 = L1.copy(), t1.copy(), seg1.copy()
    L2, t2, seg2, _ = trace(fr.kernel, fr.prep.tracer, depth, keys, o.copy(), d.copy(), lamu,
                            nlanes, sky_seen=sky_seen, t0=t0, spread=spread)
    assert np.all(np.isfinite(L1)) and L1[:, :nlanes].sum() > 0.0
    if nlanes == 3:
        assert np.all(L1[:, 3] == 0.0)
    assert whole_paths.paths_differing(L1[:, :nlanes], L2[:, :nlanes]) <= 0.005
    np.testing.assert_array_equal(t1, t2)
    np.testing.assert_array_equal(seg1, seg2)
    if "moving" in scene:  # the camera sees the moving bodies
        assert np.any(seg1 >= 0)
    else:
        assert np.all(seg1 == -1)
    if not sky_seen:  # a camera ray that escapes sees nothing
        assert np.all(L1[t1 >= 1e30] == 0.0) and np.any(t1 >= 1e30)


def test_the_renderer_takes_whole_paths_where_they_apply_and_its_image_is_unchanged(
        tmp_path):
    fr, ev = renderer(cornell(spp=8), tmp_path)
    assert fr.whole_paths
    film, _ = fr.render(ev, 1)
    img = film.resolve(fr.to_rgb)
    fr.whole_paths = False
    film2, _ = fr.render(ev, 1)
    ref = film2.resolve(fr.to_rgb)
    np.testing.assert_allclose(img.rgba, ref.rgba, rtol=1e-3, atol=1e-4 * ref.rgba.max())
    np.testing.assert_array_equal(img.aovs["depth"], ref.aovs["depth"])


def _metal_walls(data):
    data["materials"][0]["metallic"] = 1.0
    data["materials"][0]["roughness"] = 0.3


def _glass_walls(data):
    data["materials"][0]["transmission"] = 1.0


def _area_light(data):
    data["lights"] = [{"type": "area", "position": [0.0, 0.0, 1.5],
                       "direction": [0.0, 0.0, -1.0], "size": [0.3, 0.3], "power": 10.0}]


def _metallic_map(data, folder: Path):
    data["materials"][0]["metallic_texture"] = write_texture(folder / "metal.exr",
                                                             np.full((4, 4, 1), 0.7))


def _alpha_mask(data, folder: Path):
    rgba = np.tile([0.5, 0.5, 0.5, 1.0], (4, 4, 1))
    rgba[:2, :, 3] = 0.0
    data["materials"][0]["base_color_texture"] = write_texture(folder / "mask.exr", rgba)
    data["materials"][0]["alpha_mode"] = "mask"


@pytest.mark.parametrize("change", [_metal_walls, _glass_walls, _area_light, _metallic_map,
                                    _alpha_mask])
def test_scenes_that_need_more_take_the_wavefront_integrator(tmp_path, change):
    data = cornell()
    if change in (_metallic_map, _alpha_mask):
        change(data, tmp_path)
    else:
        change(data)
    fr, _ = renderer(data, tmp_path)
    assert not fr.whole_paths


def test_denoising_features_take_the_wavefront_integrator(tmp_path):
    data = cornell()
    fr, _ = renderer(data, tmp_path)
    assert whole_paths.applies(fr.kernel, fr.prep.tracer, False)
    assert not whole_paths.applies(fr.kernel, fr.prep.tracer, True)
    data["output"]["aovs"] = ["albedo", "normal"]
    fr, _ = renderer(data, tmp_path)
    assert not fr.whole_paths


def test_the_ray_log_of_moving_bodies_traces_again_to_the_kernels_own_hits(tmp_path):
    """lambert_paths' log (whole_paths.ray_log, the benchmarks' replay of a path's rays,
    bench/path_floor.py): with moving bodies each nearest-hit ray's lab time, the segment
    it leaves and its rest-frame form there are recorded, so MovingScene.intersect finds
    again the hit the kernel found: the body the path's next ray leaves (its recorded
    segment), the next origin one offset from the hit point, and the camera rays' hit
    distances; each shadow ray's origin time is its vertex's (before the camera's)."""
    fr, ev = renderer(scene_data(tmp_path, "cornell+moving_room", "cie1931", 0.3), tmp_path)
    keys, o, d, lamu, nlanes = camera_paths(fr, ev, 4)
    n, depth = len(keys), fr.settings.max_depth
    L = np.empty((n, 4), np.float32)
    first_t, first_seg = np.empty(n, np.float32), np.empty(n, np.int32)
    log = whole_paths.ray_log(n, depth)
    n_rays, n_sh = whole_paths.lambert_paths(fr.kernel, fr.prep.tracer, keys, o, d, lamu,
                                             np.zeros(n, np.float32), nlanes, depth, True, L,
                                             first_t, first_seg, float(ev.t), log=log)
    rec_o, rec_d, sh_o, sh_d, sh_t, bounces, rec_t, rec_seg, rec_rest, sh_t0 = log
    # a path traces its camera ray and at most one ray per continuation (roulette may end it)
    assert n < n_rays <= n + int(bounces.sum())
    hits = fr.prep.tracer.intersect(rec_o[:n_rays], rec_d[:n_rays], rec_t[:n_rays], {},
                                    rec_seg[:n_rays], rec_rest[:n_rays])
    # a ray that leaves a body: the ray before it (the same path's) hit that body
    k = np.flatnonzero(rec_seg[1:n_rays] >= 0)
    assert len(k) > 100
    np.testing.assert_array_equal(hits.seg[k], rec_seg[k + 1])
    point = rec_o[k] + hits.t[k, None] * rec_d[k]
    assert np.max(np.linalg.norm(rec_o[k + 1] - point, axis=1)) < 1e-3
    # the camera rays: the first of each path, at the recorded distances
    starts, j = [], 0
    for i in range(n):  # the log holds each path's rays in order, the camera ray first
        while not (np.array_equal(rec_o[j], o[i]) and np.array_equal(rec_d[j], d[i])):
            j += 1
        starts.append(j)
        j += 1
    np.testing.assert_allclose(hits.t[starts], first_t, rtol=1e-6)
    np.testing.assert_array_equal(hits.seg[starts], first_seg)
    assert np.all(rec_seg[starts] == -1) and np.all(rec_t[starts] == float(ev.t))
    # every shadow ray leaves a vertex, an event before the camera's (not the camera's time)
    assert np.all(sh_t0[:n_sh] < float(ev.t))
    blocked = fr.prep.tracer.occluded(sh_o[:n_sh], sh_d[:n_sh], sh_t[:n_sh], sh_t0[:n_sh], {})
    assert 0.0 < blocked.mean() < 1.0


def test_paths_differing_counts_the_rows_beyond_the_relative_tolerance():
    a = np.ones((4, 3), np.float32)
    b = a.copy()
    b[1, 2] = 1.0 + 5e-5  # within 1e-4 of the larger value (plus the floor)
    b[3, 0] = 1.01        # beyond it
    assert whole_paths.paths_differing(a, b) == 0.25
    assert whole_paths.paths_differing(a, a) == 0.0


def test_one_kernel_per_kind_of_scene_even_when_threads_ask_at_once():
    """whole_paths.kernel: one compiled variant per (map, textures, moving bodies,
    record), the same object for every caller, also for threads that ask at the same
    time."""
    from concurrent.futures import ThreadPoolExecutor
    from itertools import product

    kinds = list(product((False, True), repeat=4))
    with ThreadPoolExecutor(8) as pool:
        got = list(pool.map(lambda k: whole_paths.kernel(*k), kinds * 4))
    by_kind = {}
    for k, fn in zip(kinds * 4, got, strict=True):
        assert by_kind.setdefault(k, fn) is fn
    assert len({id(f) for f in by_kind.values()}) == len(kinds)
