"""The Embree wrapper: nearest hits, occlusion, far-from-origin precision."""

import numpy as np

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
    ref = a._scene.run(o, d, output=1)  # embreex's default tfar (1e37)
    np.testing.assert_array_equal(h.t[hit], ref["tfar"][hit])
    np.testing.assert_array_equal(h.prim, ref["primID"])
