"""Embree's C API from the kernels (core/render/embree.py) against an independent
ray-triangle intersection written here (Möller–Trumbore in float64 numpy)."""

import os

import numpy as np
import pytest
from numba import njit

from relray.core.render import embree


def _moller_trumbore(tris: np.ndarray, o: np.ndarray, d: np.ndarray, tmax: float):
    """Nearest (t, triangle) of each ray over every triangle, float64, 0 < t < tmax."""
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    best_t = np.full(len(o), np.inf)
    best_i = np.full(len(o), -1)
    for k in range(len(tris)):
        p = np.cross(d, e2[k])
        det = p @ e1[k]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o - v0[k]
            u = np.einsum("ij,ij->i", s, p) * inv
            q = np.cross(s, e1[k])
            v = np.einsum("ij,ij->i", d, q) * inv
            t = (q @ e2[k]) * inv
        ok = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t < tmax)
        better = ok & (t < best_t)
        best_t[better], best_i[better] = t[better], k
    return best_t, best_i


def test_the_wheel_ships_the_library():
    path = embree.library_path()
    assert os.path.isfile(path) and "embree4" in os.path.basename(path).lower()


def test_nearest_hits_and_occlusion_match_an_independent_intersection():
    """2000 random rays through 200 random triangles: the hit triangle and t equal the
    float64 reference (t to float32 rounding of the scene's size), except for rays that
    pass within 1e-5 of a triangle edge (where float32 may take either side); occlusion
    of segments ending at half and at twice the reference distance."""
    rng = np.random.default_rng(7)
    tris = rng.uniform(-1.0, 1.0, (200, 3, 3)).astype(np.float32)
    scene = embree.TriangleScene(tris)
    n = 2000
    o = rng.uniform(-1.5, 1.5, (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    ref_t, ref_i = _moller_trumbore(tris.astype(np.float64), o.astype(np.float64),
                                    d.astype(np.float64), 1e30)
    t = np.empty(n, np.float32)
    prim = np.empty(n, np.int32)
    u, v = np.empty(n, np.float32), np.empty(n, np.float32)
    embree.intersect_rays(scene.handle, o, d, np.full(1, 1e30, np.float32), t, prim, u, v)
    hit = ref_i >= 0
    assert 0.3 < hit.mean() < 0.95
    same = prim == ref_i
    assert same.mean() > 0.995
    np.testing.assert_allclose(t[hit & same], ref_t[hit & same], rtol=1e-5, atol=1e-5)
    assert np.all(t[~hit & same] == np.float32(1e30))
    # the barycentrics reproduce the hit point
    k = np.flatnonzero(hit & same)
    tri = tris[prim[k]].astype(np.float64)
    p_bary = tri[:, 0] + u[k, None] * (tri[:, 1] - tri[:, 0]) + v[k, None] * (tri[:, 2]
                                                                                - tri[:, 0])
    p_ray = o[k] + t[k, None] * d[k]
    np.testing.assert_allclose(p_bary, p_ray, atol=1e-4)
    # occlusion: half way to the reference hit is free, twice as far is blocked
    k = np.flatnonzero(hit & same & (ref_t > 1e-3))
    out = np.empty(len(k), bool)
    embree.occluded_rays(scene.handle, o[k], d[k], (0.5 * ref_t[k]).astype(np.float32), out)
    free_before = ~out
    embree.occluded_rays(scene.handle, o[k], d[k], (2.0 * ref_t[k]).astype(np.float32), out)
    assert free_before.mean() > 0.995 and out.all()


def test_robust_scenes_and_bad_input():
    tris = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], np.float32)
    s = embree.TriangleScene(tris, robust=True)
    t, prim = np.empty(1, np.float32), np.empty(1, np.int32)
    u, v = np.empty(1, np.float32), np.empty(1, np.float32)
    embree.intersect_rays(s.handle, np.array([[0.25, 0.25, 1.0]], np.float32),
                          np.array([[0.0, 0.0, -1.0]], np.float32),
                          np.full(1, 1e30, np.float32), t, prim, u, v)
    assert prim[0] == 0 and t[0] == pytest.approx(1.0) and u[0] == pytest.approx(0.25)
    for bad in (np.zeros((0, 3, 3)), np.zeros((2, 3))):
        with pytest.raises(ValueError):
            embree.TriangleScene(bad)


def _packet_tracer(by_ray: bool):
    """A kernel that traces the rays 16 to a packet, lane l of each packet only where
    ``valid_lanes[l]``: by ``embree.intersect16``/``occluded16`` (Embree's packet
    queries), or by ``intersect_lanes``/``occluded_lanes`` (the same packets ray by ray:
    what the SIMD lanes call)."""
    nearest = embree.intersect_lanes if by_ray else embree.intersect16
    blocked_by = embree.occluded_lanes if by_ray else embree.occluded16

    @njit
    def trace(scene, o, d, lengths, valid_lanes, t, prim, blocked):
        W = embree.PACKET
        hit, f, valid = embree.packet_buffers()
        for start in range(0, o.shape[0], W):
            for occl in range(2):
                for lane in range(W):
                    i = min(start + lane, o.shape[0] - 1)
                    embree.set_packet_ray(f, hit, lane, o[i, 0], o[i, 1], o[i, 2], d[i, 0],
                                          d[i, 1], d[i, 2], lengths[i] if occl else 1e30)
                    valid[lane] = -1 if valid_lanes[lane] and start + lane < o.shape[0] else 0
                if occl:
                    blocked_by(scene, valid, hit)
                else:
                    nearest(scene, valid, hit)
                for lane in range(min(W, o.shape[0] - start)):
                    i = start + lane
                    if occl:
                        blocked[i] = f[embree.TFAR * W + lane] < 0.0
                    elif hit[embree.GEOM * W + lane] != 0xFFFFFFFF:
                        t[i], prim[i] = f[embree.TFAR * W + lane], hit[embree.PRIM * W + lane]

    return trace


@pytest.mark.parametrize("by_ray", [False, True], ids=["packets", "lane_by_lane"])
def test_packets_of_sixteen_give_the_single_rays_answers_in_their_valid_lanes(by_ray):
    """intersect16/occluded16 (Embree's packets) and intersect_lanes/occluded_lanes (the
    SIMD lanes' queries, core/render/lane_paths.py): the same nearest hits and occlusion
    as intersect1/occluded1, ray by ray, in the lanes marked valid; the lanes left out
    are not traced (their words unchanged: no hit, not blocked). Lane by lane it is
    rtcIntersect1 itself: bit for bit."""
    rng = np.random.default_rng(11)
    tris = rng.uniform(-1.0, 1.0, (200, 3, 3)).astype(np.float32)
    scene = embree.TriangleScene(tris)
    n = 1000  # not a multiple of 16: the last packet is partly empty
    o = rng.uniform(-1.5, 1.5, (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    far = np.full(1, 1e30, np.float32)
    t1, p1 = np.full(n, 1e30, np.float32), np.empty(n, np.int32)
    embree.intersect_rays(scene.handle, o, d, far, t1, p1, np.empty(n, np.float32),
                          np.empty(n, np.float32))
    lengths = np.where(p1 >= 0, 0.5 * t1, 1.0).astype(np.float32)
    lengths[::3] = np.where(p1[::3] >= 0, 2.0 * t1[::3], 1.0)
    b1 = np.empty(n, np.bool_)
    embree.occluded_rays(scene.handle, o, d, lengths, b1)
    valid_lanes = np.ones(16, np.bool_)
    valid_lanes[[3, 10]] = False
    t2, p2 = np.full(n, 1e30, np.float32), np.full(n, -1, np.int32)
    b2 = np.zeros(n, np.bool_)
    _packet_tracer(by_ray)(scene.handle, o, d, lengths, valid_lanes, t2, p2, b2)
    traced = valid_lanes[np.arange(n) % 16]
    assert 0.3 < (p1 >= 0).mean() < 0.95 and 0.1 < b1.mean() < 0.9
    assert np.all(p2[~traced] == -1) and not np.any(b2[~traced])
    if by_ray:
        np.testing.assert_array_equal(p2[traced], p1[traced])
        np.testing.assert_array_equal(t2[traced], t1[traced])
        np.testing.assert_array_equal(b2[traced], b1[traced])
        return
    # Embree's packet and single-ray kernels are different code: on another CPU a ray
    # within float32 rounding of an edge may take the other side (a tolerance, not bits)
    same = p2[traced] == p1[traced]
    assert same.mean() > 0.995 and (b2[traced] == b1[traced]).mean() > 0.995
    np.testing.assert_allclose(t2[traced][same], t1[traced][same], rtol=1e-5)
