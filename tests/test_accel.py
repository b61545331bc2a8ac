"""The Embree scenes: nearest hits, occlusion, far-from-origin precision, and the C-API
queries against embreex's own (an independent binding of the same library)."""

import numpy as np
from embreex import mesh_construction, rtcore_scene

from relray.core.render.accel import MISS_DISTANCE, Accel

QUAD = np.array([[[-1, -1, 0], [1, -1, 0], [1, 1, 0]], [[-1, -1, 0], [1, 1, 0], [-1, 1, 0]]],
                np.float32)


def test_hits_and_misses():
    a = Accel(QUAD)
    o = a.local(np.array([[0.2, 0.3, 5.0], [3.0, 0.0, 5.0]]))
    d = np.array([[0, 0, -1], [0, 0, -1]], np.float32)
    h = a.intersect(o, d)
    assert h.prim[0] >= 0 and abs(h.t[0] - 5.0) < 1e-5
    assert h.prim[1] == -1 and h.t[1] == MISS_DISTANCE


def test_occlusion_respects_segment_length():
    a = Accel(QUAD)
    o = a.local(np.array([[0.0, 0.0, 5.0]] * 2))
    d = np.array([[0, 0, -1]] * 2, np.float32)
    blocked = a.occluded(o, d, np.array([4.9, 5.1], np.float32))
    assert blocked.tolist() == [False, True]


def test_geometry_far_from_origin_keeps_precision():
    """Triangles at 1e6 are stored relative to their centre, so a hit is exact to ~1e-6."""
    far = QUAD.astype(np.float64) * 1e-3 + 1e6
    a = Accel(far)
    o = a.local(np.array([[1e6 + 0.0004, 1e6 + 0.0003, 1e6 + 1.0]]))
    h = a.intersect(o, np.array([[0, 0, -1]], np.float32))
    assert h.prim[0] >= 0 and abs(h.t[0] - 1.0) < 1e-5


def test_empty_batches():
    a = Accel(QUAD)
    e = np.empty((0, 3), np.float32)
    assert len(a.intersect(e, e).t) == 0
    assert len(a.occluded(e, e, np.empty(0, np.float32))) == 0


def test_intersect_t_is_tfar_on_hits_and_miss_distance_on_misses():
    """t comes straight from Embree's tfar (float32), started at MISS_DISTANCE."""
    a = Accel(QUAD)
    rng = np.random.default_rng(0)
    o = a.local(np.column_stack([rng.uniform(-2, 2, (500, 2)), np.full(500, 3.0)]))
    d = rng.normal(size=(500, 3))
    d[:, 2] = -np.abs(d[:, 2]) - 0.5
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    h = a.intersect(o, d)
    hit = h.prim >= 0
    assert h.t.dtype == np.float32 and 0 < hit.sum() < 500
    assert np.all(h.t[~hit] == MISS_DISTANCE) and np.all(h.t[hit] < 1e3)
    ref = _Embreex(a, QUAD).run(o, d, output=1)  # embreex's default tfar (1e37)
    # (embreex hands Embree the same triangles in its own layout: t agrees to an ulp)
    np.testing.assert_allclose(h.t[hit], ref["tfar"][hit], rtol=1e-6)
    np.testing.assert_array_equal(h.prim, ref["primID"])


class _Embreex:
    """embreex's scene over the same float32 local triangles as an Accel."""

    def __init__(self, a: Accel, triangles: np.ndarray):
        self.scene = rtcore_scene.EmbreeScene()
        local = a.local(triangles.reshape(-1, 3)).reshape(-1, 3, 3)
        self.mesh = mesh_construction.TriangleMesh(self.scene, local)

    def run(self, *args, **kwargs):
        return self.scene.run(*args, **kwargs)


def test_queries_agree_with_embreex_on_a_random_soup():
    """Nearest hits (triangle, t, u, v) and occlusion of 4000 random rays through 300
    random triangles, bounded and unbounded, equal embreex's answers (the same Embree
    library under another binding)."""
    rng = np.random.default_rng(3)
    tris = rng.uniform(-1.0, 1.0, (300, 3, 3)).astype(np.float32)
    a = Accel(tris)
    ref = _Embreex(a, tris)
    o = a.local(rng.uniform(-1.5, 1.5, (4000, 3)))
    d = rng.normal(size=(4000, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    tmax = rng.uniform(0.0, 2.0, 4000).astype(np.float32)
    for lengths in (None, tmax):
        h = a.intersect(o, d, lengths)
        # (embreex writes its answers' tfar into ``dists``: it gets a copy)
        r = ref.run(o, d, output=1, **({} if lengths is None else {"dists": lengths.copy()}))
        np.testing.assert_array_equal(h.prim, r["primID"])
        hit = h.prim >= 0
        assert 0.2 < hit.mean() < 1.0
        # a few ulps of the scene's size: embreex hands Embree its own triangle layout
        np.testing.assert_allclose(h.t[hit], r["tfar"][hit], rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(h.u[hit], r["u"][hit], atol=1e-5)
        np.testing.assert_allclose(h.v[hit], r["v"][hit], atol=1e-5)
    blocked = a.occluded(o, d, tmax)
    assert 0.1 < blocked.mean() < 0.9
    np.testing.assert_array_equal(blocked, ref.run(o, d, dists=tmax.copy(), query="OCCLUDED") == 0)


def test_a_scene_is_released_with_its_accel():
    """The Embree scene lives as long as its Accel (a finalizer releases it)."""
    a = Accel(QUAD)
    release = a._scene._release
    assert release.alive
    del a
    assert not release.alive
