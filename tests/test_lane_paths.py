"""core/render/lane_paths.py: sixteen Lambert paths at a time in SIMD lanes, for static
scenes (flat or smooth-shaded, with or without image textures: base colour, roughness,
normal and emission; lit by emissive triangles, point, spot and sun lights, a constant
sky or a colour environment map) and for scenes with moving bodies, glowing or not.

Its estimator is whole_paths.py's (and the wavefront integrator's), with the same random
numbers, so the three must give the same radiance path by path (to float32 rounding: a
rounding difference may flip a roulette decision now and then, hence a small allowance
of differing paths), the same camera-ray hit distances and the same numbers of rays;
and the renderer must take it exactly where it applies.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_environment import write_spectral_map
from test_whole_paths import (
    _checker,
    _delta_lights,
    _moving_room,
    _sky,
    _textures,
    camera_paths,
    cornell,
    environment_scene,
    renderer,
    scene_data,
)

from relray.core.render import lane_paths, whole_paths
from relray.core.render.integrator import trace


def _glowing_blocks(data):
    """The blocks glow too (two more emission rows, 20 emissive triangles in the light
    CDF, two-sided): the lanes' binary search over the CDF has several steps."""
    data["materials"] += [
        {"name": "warm", "base_color": [0.6, 0.5, 0.4], "emission": [1.0, 0.6, 0.2],
         "emission_strength": 0.8},
        {"name": "cool", "base_color": [0.3, 0.4, 0.6], "emission": [0.2, 0.5, 1.0],
         "emission_strength": 0.5}]
    for o in data["objects"]:
        if o["name"] == "short_block":
            o["material"] = "warm"
        elif o["name"] == "tall_block":
            o["material"] = "cool"


def _two_sided_light(data):
    """The ceiling light emits from both faces (seen from above by rays that pass it)."""
    for m in data["materials"]:
        if m["name"] == "light":
            m["one_sided_emission"] = False


def _vertex_normals(data):
    """A smooth-shaded ball (interpolated vertex normals) on the floor."""
    data["objects"].append({"name": "ball", "shape": "sphere", "center": [0.0, 0.0, 0.3],
                            "radius": 0.2, "material": "white", "subdivisions": 2})


def _sky_on_a_transparent_film(data):
    """A constant sky that the camera rays do not see (render.transparent)."""
    _sky(data)
    data["render"]["transparent"] = True


def _everything(data):
    """Smooth shading, a sky, delta lights and glowing blocks together."""
    for change in (_vertex_normals, _sky, _delta_lights, _glowing_blocks):
        change(data)


def _smooth_textured(data, folder):
    """The textures (base colour, roughness, normal map, emission) and a smooth-shaded
    ball whose normal map bends its interpolated normals, under a sky."""
    _vertex_normals(data)
    _sky(data)
    _textures(data, folder)
    ball = next(o for o in data["objects"] if o["name"] == "ball")
    ball["material"] = "red"


def _map_scene(scene: str, spectral: str, folder, **render) -> dict:
    """The map-lit scene of test_whole_paths (ground, smooth ball, box under a 32 × 16
    map with a 1-texel sun); ``+transparent`` on a transparent film, ``+lights`` with
    point, spot and sun lights beside the map in the light CDF, ``+checker`` with
    base-colour and normal textures, ``+infrared`` with the ground glowing at 0.9–1.3 µm
    only: no light (no luminance at rest), seen by a camera fast enough to shift it into
    the visible."""
    data = environment_scene(folder, spectral=spectral, spp=8, **render)
    change = scene.partition("+")[2]
    if change == "transparent":
        data["render"]["transparent"] = True
    elif change == "lights":
        _delta_lights(data)
    elif change == "checker":
        _checker(data, folder)
    elif change == "infrared":
        data["materials"].append({"name": "glow", "base_color": [0.6, 0.6, 0.6],
                                  "emission_spectrum": {"nm": [900.0, 1000.0, 1200.0, 1300.0],
                                                        "values": [0.0, 1.0, 1.0, 0.0]},
                                  "emission_strength": 5.0})
        data["objects"][0]["material"] = "glow"
    return data


def _moving_smooth(data):
    """The room moves at 0.3 c (one body, the light at rest), a static smooth-shaded ball
    stands in it."""
    _moving_room(data)
    _vertex_normals(data)


def lane_scene(scene: str, spectral: str, beta: float, folder=None, **render) -> dict:
    if scene.startswith("cornell+"):  # test_whole_paths' scenes (moving bodies)
        data = scene_data(folder, scene, spectral, beta)
        data["render"].update(render)
        return data
    if scene == "moving_smooth":
        data = cornell(spectral=spectral, spp=8, **render)
        data["motion"]["beta"] = [0.0, beta, 0.0]
        _moving_smooth(data)
        return data
    if scene.startswith("environment"):
        data = _map_scene(scene, spectral, folder, **render)
        data["motion"]["beta"] = [0.0, beta, 0.0]
        return data
    data = cornell(spectral=spectral, spp=8, **render)
    data["motion"]["beta"] = [0.0, beta, 0.0]
    if scene in ("textures", "smooth_textured"):
        (_textures if scene == "textures" else _smooth_textured)(data, folder)
        return data
    {"cornell": lambda _: None, "glowing_blocks": _glowing_blocks,
     "two_sided_light": _two_sided_light, "vertex_normals": _vertex_normals, "sky": _sky,
     "sky_transparent": _sky_on_a_transparent_film, "delta_lights": _delta_lights,
     "everything": _everything}[scene](data)
    return data


@pytest.mark.parametrize("scene,spectral,beta,render", [
    ("cornell", "cie1931", 0.0, {}), ("cornell", "cie1931", 0.6, {}),
    ("cornell", "rgb", 0.0, {}), ("cornell", "cie1931", 0.0, {"max_depth": 1}),
    ("cornell", "cie1931", 0.0, {"max_depth": 2}),
    ("cornell", "cie1931", 0.3, {"width": 13, "height": 7}),
    ("glowing_blocks", "cie1931", 0.0, {}), ("glowing_blocks", "rgb", 0.4, {}),
    ("two_sided_light", "cie1931", 0.0, {}), ("vertex_normals", "cie1931", 0.0, {}),
    ("sky", "cie1931", 0.3, {}), ("sky_transparent", "cie1931", 0.0, {}),
    ("delta_lights", "cie1931", 0.0, {}), ("delta_lights", "rgb", 0.0, {}),
    ("everything", "cie1931", 0.5, {}), ("everything", "rgb", 0.0, {"max_depth": 3}),
    ("textures", "cie1931", 0.0, {}), ("textures", "cie1931", 0.6, {}),
    ("textures", "rgb", 0.0, {}), ("textures", "cie1931", 0.0, {"max_depth": 2}),
    ("smooth_textured", "cie1931", 0.3, {}),
    ("environment", "cie1931", 0.0, {}), ("environment", "cie1931", 0.6, {}),
    ("environment", "rgb", 0.0, {}), ("environment", "seed-gaussian", 0.3, {}),
    ("environment", "cie1931", 0.0, {"max_depth": 2}),
    ("environment+transparent", "cie1931", 0.0, {}), ("environment+lights", "cie1931", 0.4, {}),
    ("environment+lights", "rgb", 0.0, {}), ("environment+checker", "cie1931", 0.3, {}),
    ("environment+infrared", "cie1931", 0.6, {})])
def test_lanes_give_whole_paths_and_the_wavefronts_radiance_path_by_path(
        tmp_path, scene, spectral, beta, render):
    fr, ev = renderer(lane_scene(scene, spectral, beta, tmp_path, **render), tmp_path)
    assert fr.whole_paths and fr.lane_paths
    assert lane_paths.kind(fr.kernel)[2] == ("textur" in scene or "checker" in scene)
    assert lane_paths.kind(fr.kernel)[3] == scene.startswith("environment")
    # the map as the only light and nothing else glowing: the lanes make no other
    # light's sample and look up no emission (MAP_LIGHT)
    map_only = scene.startswith("environment") and scene.partition("+")[2] not in (
        "lights", "infrared")
    assert (lane_paths.kind(fr.kernel)[1] == lane_paths.MAP_LIGHT) == map_only
    keys, o, d, lamu, nlanes = camera_paths(fr, ev, 8)
    depth = fr.settings.max_depth
    seen = not fr.settings.transparent
    n = len(keys)
    # the ray cones' start (textures' level of detail): a spread per path
    spread = np.random.default_rng(3).uniform(1e-3, 2e-2, n).astype(np.float32)
    L1, t1 = np.full((n, 4), np.nan, np.float32), np.zeros(n, np.float32)
    rays1 = lane_paths.lane_trace(fr.kernel, fr.prep.tracer, keys, o, d, lamu, nlanes, depth,
                                  L1, t1, sky_seen=seen, spread=spread)
    L2, t2 = np.zeros((n, 4), np.float32), np.zeros(n, np.float32)
    rays2 = whole_paths.lambert_paths(fr.kernel, fr.prep.tracer, keys, o, d, lamu, spread,
                                      nlanes, depth, seen, L2, t2)
    L3, t3, _, _ = trace(fr.kernel, fr.prep.tracer, depth, keys, o.copy(), d.copy(), lamu,
                         nlanes, sky_seen=seen, spread=spread)
    assert np.all(np.isfinite(L1)) and L1[:, :nlanes].sum() > 0.0
    if nlanes == 3:
        assert np.all(L1[:, 3] == 0.0)
    assert whole_paths.paths_differing(L1[:, :nlanes], L2[:, :nlanes]) <= 0.005
    assert whole_paths.paths_differing(L1[:, :nlanes], L3[:, :nlanes]) <= 0.005
    # the camera rays' distances (Embree's packet kernel against its single-ray one:
    # equal but for rounding, on any CPU)
    assert distances_differing(t1, t2) <= 0.005 and distances_differing(t1, t3) <= 0.005
    # the same rays: every path's nearest-hit and shadow rays, 16 lanes to a packet
    n_rays, n_shadow, packets = rays1
    assert abs(n_rays - rays2[0]) <= 0.005 * n_rays
    assert abs(n_shadow - rays2[1]) <= 0.005 * n_shadow + 1
    assert n_rays / 16 <= packets < n_rays / 16 + 64
    if "sky" in scene or scene == "everything" or scene.startswith("environment"):
        # camera rays that escape
        assert np.any(t1 >= 1e30)
        assert np.all(L1[t1 >= 1e30] == 0.0) == (not seen)


@pytest.mark.parametrize("scene,spectral,beta,render", [
    ("cornell+moving_blocks", "cie1931", 0.6, {}), ("cornell+moving_blocks", "rgb", 0.0, {}),
    ("cornell+moving_blocks", "cie1931", 0.0, {"max_depth": 2}),
    ("cornell+moving_room", "cie1931", 0.3, {}),
    ("cornell+moving_room", "seed-gaussian", 0.0, {}),
    ("cornell+moving_room", "cie1931", 0.4, {"doppler": False}),
    ("cornell+moving_room", "cie1931", 0.4, {"searchlight": False}),
    ("moving_smooth", "cie1931", 0.5, {}), ("moving_smooth", "rgb", 0.0, {}),
    ("cornell+moving_light", "cie1931", 0.0, {}), ("cornell+moving_light", "cie1931", 0.5, {}),
    ("cornell+moving_blocks_and_light", "cie1931", 0.4, {}),
    ("cornell+moving_all", "cie1931", 0.0, {}), ("cornell+moving_all", "rgb", 0.3, {}),
    ("cornell+moving_all", "cie1931", 0.3, {"searchlight": False})])
def test_lanes_trace_moving_bodies_as_whole_paths_do_path_by_path(
        tmp_path, scene, spectral, beta, render):
    """Moving bodies: each lane's rays traced alone through the bodies' rest frames, the
    frame changes as lane arithmetic (the shift's logarithm as straight-line code): the
    radiance, the camera rays' distances and segments and the numbers of rays of whole
    paths and of the wavefront integrator, path by path. Under lights at rest: the
    blocks as two bodies (most bounces leave one body for the static room), the room as
    one (most land on the body they left: its rest-frame form is reused), without the
    Doppler shift or the searchlight factor, a static smooth ball in a moving room.
    Glowing: the light moving alone (sampled in its rest frame
    from the static vertices), with the blocks as other bodies (a moving vertex does not
    sample it), the room and its light as one body (sampled in their common frame, the
    MIS weights per rest-frame solid angle)."""
    fr, ev = renderer(lane_scene(scene, spectral, beta, tmp_path, **render), tmp_path)
    assert fr.whole_paths and fr.lane_paths
    glowing = "light" in scene or "all" in scene
    assert lane_paths.kind(fr.kernel, fr.prep.tracer)[4] == (
        lane_paths.GLOWING_BODIES if glowing else lane_paths.BODIES)
    assert fr.kernel.shift == render.get("doppler", spectral != "rgb")
    keys, o, d, lamu, nlanes = camera_paths(fr, ev, 8)
    depth, t0, n = fr.settings.max_depth, float(ev.t), len(keys)
    L1, t1 = np.full((n, 4), np.nan, np.float32), np.zeros(n, np.float32)
    s1 = np.full(n, 99, np.int32)
    rays1 = lane_paths.lane_trace(fr.kernel, fr.prep.tracer, keys, o, d, lamu, nlanes, depth,
                                  L1, t1, first_seg=s1, t0=t0)
    L2, t2, s2 = np.zeros((n, 4), np.float32), np.zeros(n, np.float32), np.zeros(n, np.int32)
    rays2 = whole_paths.lambert_paths(fr.kernel, fr.prep.tracer, keys, o, d, lamu,
                                      np.zeros(n, np.float32), nlanes, depth, True, L2, t2,
                                      s2, t0)
    L3, t3, s3, _ = trace(fr.kernel, fr.prep.tracer, depth, keys, o.copy(), d.copy(), lamu,
                          nlanes, t0=t0)
    assert np.all(np.isfinite(L1)) and L1[:, :nlanes].sum() > 0.0
    assert whole_paths.paths_differing(L1[:, :nlanes], L2[:, :nlanes]) <= 0.005
    assert whole_paths.paths_differing(L1[:, :nlanes], L3[:, :nlanes]) <= 0.005
    assert distances_differing(t1, t2) <= 0.005 and distances_differing(t1, t3) <= 0.005
    assert np.mean(s1 != s2) <= 0.005 and np.mean(s1 != s3) <= 0.005
    assert np.any(s1 >= 0) and np.all(s1[t1 >= 1e30] == -1)
    n_rays, n_shadow, packets = rays1
    assert abs(n_rays - rays2[0]) <= 0.005 * n_rays
    assert abs(n_shadow - rays2[1]) <= 0.005 * n_shadow + 1
    # (the escaped rays' paths end before the packet is shaded: fewer packets than rays/16)
    assert 0 < packets < n_rays / 16 + 64


def distances_differing(a: np.ndarray, b: np.ndarray) -> float:
    """The share of camera rays whose hit distances differ by more than 1e-5 relative."""
    return float(np.mean(np.abs(a - b) > 1e-5 * np.maximum(np.abs(a), np.abs(b))))


@pytest.mark.parametrize("scene", ["everything", "moving_smooth"])
@pytest.mark.parametrize("n", [1, 5, 15, 17])
def test_fewer_paths_than_lanes(tmp_path, n, scene):
    """A chunk of fewer paths than the 16 lanes (or one more): the lanes that never get a
    path run through the lane loops with defined state (uninitialised table columns
    crashed the stress suite's 1-pixel render) and the paths that exist are traced as
    whole paths trace them; with moving bodies too."""
    fr, ev = renderer(lane_scene(scene, "cie1931", 0.3), tmp_path)
    keys, o, d, lamu, nlanes = camera_paths(fr, ev, 8)
    pick = np.linspace(0, len(keys) - 1, n).astype(np.int64)
    keys, o, d, lamu = keys[pick], o[pick], d[pick], np.ascontiguousarray(lamu[pick])
    depth, t0 = fr.settings.max_depth, float(ev.t)
    L1, t1, s1 = np.full((n, 4), np.nan, np.float32), np.zeros(n, np.float32), np.zeros(n, np.int32)
    n_rays, _, packets = lane_paths.lane_trace(fr.kernel, fr.prep.tracer, keys, o, d, lamu,
                                               nlanes, depth, L1, t1, first_seg=s1, t0=t0)
    L2, t2, s2 = np.zeros((n, 4), np.float32), np.zeros(n, np.float32), np.zeros(n, np.int32)
    rays2 = whole_paths.lambert_paths(fr.kernel, fr.prep.tracer, keys, o, d, lamu,
                                      np.zeros(n, np.float32), nlanes, depth, True, L2, t2,
                                      s2, t0)
    assert np.all(np.isfinite(L1))
    assert whole_paths.paths_differing(L1, L2) == 0.0 and n_rays == rays2[0]
    assert distances_differing(t1, t2) == 0.0 and packets >= 1
    if scene.startswith("moving"):
        np.testing.assert_array_equal(s1, s2)


def test_packets_and_rays_one_at_a_time_trace_the_same_paths(tmp_path):
    """The lanes' rays as Embree's 16-ray packets (``lane_paths.PACKETS``: AVX-512) or one
    at a time (elsewhere): whatever this machine is, both kernels trace the same paths
    (Embree's packet and single-ray kernels agree but for rounding)."""
    fr, ev = renderer(lane_scene("everything", "cie1931", 0.3), tmp_path)
    keys, o, d, lamu, nlanes = camera_paths(fr, ev, 8)
    n, depth = len(keys), fr.settings.max_depth
    out = []
    for native16 in (True, False):
        L, t = np.full((n, 4), np.nan, np.float32), np.zeros(n, np.float32)
        rays = lane_paths.lane_trace(fr.kernel, fr.prep.tracer, keys, o, d, lamu, nlanes,
                                     depth, L, t, native16=native16)
        out.append((L, t, rays))
    (l16, t16, r16), (l1, t1, r1) = out
    assert np.all(np.isfinite(l16)) and np.all(np.isfinite(l1)) and l1.sum() > 0.0
    assert whole_paths.paths_differing(l16, l1) <= 0.005
    assert distances_differing(t16, t1) <= 0.005
    assert abs(r16[0] - r1[0]) <= 0.005 * r1[0] and abs(r16[1] - r1[1]) <= 0.005 * r1[1] + 1


def test_depth_one_sees_the_emitters_only(tmp_path):
    """max_depth 1: the camera rays' hits and no bounce, so no shadow ray, and radiance
    only where a camera ray meets the light."""
    fr, ev = renderer(lane_scene("cornell", "cie1931", 0.0, max_depth=1), tmp_path)
    keys, o, d, lamu, nlanes = camera_paths(fr, ev, 8)
    n = len(keys)
    L, t = np.zeros((n, 4), np.float32), np.zeros(n, np.float32)
    n_rays, n_shadow, _ = lane_paths.lane_trace(fr.kernel, fr.prep.tracer, keys, o, d, lamu,
                                                nlanes, 1, L, t)
    assert n_rays == n and n_shadow == 0
    lit = L[:, 0] > 0.0
    assert 0 < lit.sum() < n // 4


def test_the_packet_log_holds_every_ray(tmp_path):
    """lane_trace's log (benchmarks): each packet's rays and valid words, as many valid
    lanes as rays traced, the camera rays in the first packets."""
    fr, ev = renderer(lane_scene("cornell", "cie1931", 0.0), tmp_path)
    keys, o, d, lamu, nlanes = camera_paths(fr, ev, 8)
    n, depth = len(keys), fr.settings.max_depth
    log = lane_paths.packet_log(n, depth)
    L, t = np.zeros((n, 4), np.float32), np.zeros(n, np.float32)
    n_rays, n_shadow, packets = lane_paths.lane_trace(fr.kernel, fr.prep.tracer, keys, o, d,
                                                      lamu, nlanes, depth, L, t, log=log)
    rays, shadows, valid = log
    assert np.count_nonzero(valid[:packets, 0]) == n_rays
    assert np.count_nonzero(valid[:packets, 1]) == n_shadow
    np.testing.assert_array_equal(rays[0, :3].T, o[:16])
    np.testing.assert_array_equal(rays[0, 3:].T, d[:16])
    lengths = shadows[:packets, 6][valid[:packets, 1] != 0]
    assert np.all(lengths > 0.0) and np.all(np.isfinite(lengths))
    directions = shadows[:packets, 3:6].transpose(0, 2, 1)[valid[:packets, 1] != 0]
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-5)


def _no_light(data):
    data["objects"] = [o for o in data["objects"] if o["name"] != "ceiling_light"]


@pytest.mark.parametrize("change", [_no_light, "spectral map", "cornell+moving_textured",
                                    "environment+moving", "moving under a sky"])
def test_scenes_that_need_more_take_scalar_whole_paths(tmp_path, change):
    """No light to sample, a spectral map's bands; with moving bodies textures, a map, or
    a sky and delta lights (where the lanes did not pay): whole paths."""
    if change == "spectral map":  # its bands are interpolated at each λ: whole paths
        data = environment_scene(tmp_path)
        write_spectral_map(tmp_path / "bands.exr", [400.0, 550.0, 700.0],
                           np.full((4, 8, 3), 0.5))
        data["scene"]["environment"] = {"file": "bands.exr"}
    elif change == "moving under a sky":
        data = cornell()
        _moving_room(data)
        _sky(data)
        _delta_lights(data)
    elif isinstance(change, str):
        data = scene_data(tmp_path, change, "cie1931", 0.0)
    else:
        data = cornell()
        change(data)
    fr, _ = renderer(data, tmp_path)
    assert fr.whole_paths and not fr.lane_paths
    assert not lane_paths.applies(fr.kernel, fr.prep.tracer, False)


def test_denoising_features_leave_the_lanes(tmp_path):
    fr, _ = renderer(cornell(), tmp_path)
    assert lane_paths.applies(fr.kernel, fr.prep.tracer, False)
    assert not lane_paths.applies(fr.kernel, fr.prep.tracer, True)


@pytest.mark.parametrize("scene", ["cornell", "textures", "environment",
                                   "cornell+moving_blocks", "cornell+moving_all"])
def test_the_renderer_takes_the_lanes_and_its_image_is_that_of_whole_paths(tmp_path, scene):
    # (with textures: the renderer gives the lanes its camera rays' spread, as to whole
    # paths, so the levels of detail agree)
    fr, ev = renderer(lane_scene(scene, "cie1931", 0.0, tmp_path), tmp_path)
    assert fr.whole_paths and fr.lane_paths
    img = fr.render(ev, 1)[0].resolve(fr.to_rgb)
    fr.lane_paths = False
    ref = fr.render(ev, 1)[0].resolve(fr.to_rgb)
    np.testing.assert_allclose(img.rgba, ref.rgba, rtol=1e-3, atol=1e-4 * ref.rgba.max())
    assert distances_differing(img.aovs["depth"], ref.aovs["depth"]) <= 0.005


@pytest.mark.parametrize("n_cdf", [2, 3, 17, lane_paths.LINEAR_LIGHTS,
                                   lane_paths.LINEAR_LIGHTS + 1, 300])
def test_pick_lights_counts_the_cdf_entries_at_or_below_u(n_cdf):
    """pick_lights = searchsorted(cdf, u, "right") in every lane, by the count (short
    CDFs) and by the bisection (long ones): u at entries, between them, on empty steps
    (repeated entries: lights of no power), 0 and just below 1."""
    rng = np.random.default_rng(n_cdf)
    steps = rng.random(n_cdf - 1) * (rng.random(n_cdf - 1) > 0.3)
    steps[0] = max(steps[0], 0.1)
    cdf = np.concatenate([[0.0], np.cumsum(steps)])
    cdf /= cdf[-1]
    W = lane_paths.W
    for _ in range(20):
        ua = np.zeros((2, W))
        ua[0] = np.where(rng.random(W) < 0.5, rng.choice(cdf, W), rng.random(W))
        ua[0, :2] = 0.0, np.nextafter(1.0, 0.0)
        pos = np.full(W, 99, np.int64)  # (pick_lights starts the count itself)
        lane_paths.pick_lights(cdf, ua, pos)
        np.testing.assert_array_equal(pos, np.searchsorted(cdf, ua[0], side="right"))
