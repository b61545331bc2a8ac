"""4D intersection in rest frames (core/render/rest_frames.py) against a brute-force march
through the lab: a box moving at u occupies, at lab time t, the points x with
B(x - p - u t) inside its rest shape (B the boost's spatial part)."""

import math

import numpy as np
import pytest

from relray.core.physics.relativity import aberrate_doppler_ray
from relray.core.render import rest_frames as rf
from relray.core.render.accel import MISS_DISTANCE, Accel
from relray.core.render.rest_frames import (
    GroupAccel,
    MovingScene,
    meets_box,
    reaches_box,
    rest_ray,
)
from relray.core.scene import shapes
from relray.core.scene.worldlines import Segment, spatial_boost

HALF = np.array([0.5, 1.0, 0.75])  # the box's rest half-sizes


def inside(x: np.ndarray, t: np.ndarray, seg: Segment) -> np.ndarray:
    """Whether lab events (t, x) lie in the box of ``seg`` (rest frame about its pivot)."""
    rel = x - seg.p_ref - seg.u * (t - seg.t_ref)[:, None]
    return np.all(np.abs(spatial_boost(seg.u, rel)) <= HALF, axis=1)


def march(x0, d, t0, segs, s_max=60.0, n=60000):
    """First lab parameter s at which the backward ray (t0 - s, x0 + s d) enters the box
    of a segment whose window holds the emission time t0 - s; inf if none."""
    s = np.linspace(0.0, s_max, n)
    x = x0 + s[:, None] * d
    t = t0 - s
    hit = np.zeros(n, bool)
    for seg in segs:
        in_window = (t >= seg.t_lo) & (t < seg.t_hi)
        hit |= in_window & inside(x, t, seg)
    k = np.flatnonzero(hit)
    if len(k) == 0:
        return math.inf
    lo, hi = s[max(k[0] - 1, 0)], s[k[0]]
    for _ in range(50):  # bisection on the entry
        mid = 0.5 * (lo + hi)
        xm, tm = x0 + mid * d, np.array([t0 - mid])
        ok = any(((tm >= g.t_lo) & (tm < g.t_hi) & inside(xm[None], tm, g))[0] for g in segs)
        lo, hi = (lo, mid) if ok else (mid, hi)
    return hi


def retarded(u: np.ndarray, p: np.ndarray, t0: float) -> np.ndarray:
    """Where the pivot p + u t was when it emitted the light reaching the origin at t0:
    |p + u t| = t0 - t, the earlier root."""
    a, b, c = u @ u - 1.0, 2.0 * (p @ u + t0), p @ p - t0 * t0
    t = (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a) if a else -c / b
    t = min(t, (-b - math.sqrt(b * b - 4 * a * c)) / (2 * a)) if a else t
    return p + u * t


def scene_of(segs: tuple[Segment, ...]) -> MovingScene:
    tris = shapes.box(np.zeros(3), 2 * HALF, 0.0)
    group = GroupAccel(Accel(tris), 0, segs, 0)
    return MovingScene(None, [group], lab_origin=np.array([0.3, -0.2, 0.1]))


def rays(rng, n, t0, aim, spread=2.5):
    """Rays from near the origin towards points around ``aim``."""
    x0 = rng.normal(0.0, 0.2, (n, 3))
    target = aim + rng.uniform(-spread, spread, (n, 3))
    d = target - x0
    return x0, d / np.linalg.norm(d, axis=1, keepdims=True), np.full(n, t0)


@pytest.mark.parametrize("u", [(0.0, 0.0, 0.0), (0.6, 0.0, 0.0), (0.3, -0.5, 0.2),
                               (0.0, -0.9, 0.0), (0.0, 0.95, 0.0)])
def test_constant_velocity_hits_match_the_lab_march(u):
    rng = np.random.default_rng(7)
    seg = Segment(np.array(u, np.float64), 0.0, np.array([0.0, 8.0, 0.0]))
    ms = scene_of((seg,))
    # the box as seen at t0 = 0: look where its light comes from (its retarded position)
    aim = retarded(np.array(u), np.array([0.0, 8.0, 0.0]), 0.0)
    x0, d, t = rays(rng, 150, 0.0, aim, 1.5)
    h = ms.intersect((x0 - ms.lab_origin).astype(np.float32), d.astype(np.float32), t)
    reach = 1.5 * float(np.linalg.norm(aim)) + 10.0
    expect = np.array([march(x0[i], d[i], 0.0, (seg,), reach, int(2000 * reach))
                       for i in range(len(x0))])
    hit = np.isfinite(expect)
    assert 15 < hit.sum() < len(hit) - 15  # both hits and misses are tested
    # a ray grazing an edge may go either way within the march's step (1e-3)
    graze = np.abs(h.t - np.where(hit, expect, MISS_DISTANCE)) > 1e-3
    assert graze.sum() <= 3, (h.t[graze], expect[graze])
    ok = hit & ~graze
    np.testing.assert_allclose(h.t[ok], expect[ok], atol=2e-4)  # float32 rays of length ~8
    assert np.all(h.seg[hit & ~graze] == 0) and np.all(h.prim[~hit & ~graze] == -1)


def test_a_worldline_is_seen_where_its_light_left_each_segment():
    """At rest until lab time 0, then at 0.9 c along x: a camera at t = 5 sees the resting
    box (emitted at t ≈ -3); at t = 30 the ray to the old place misses, and the box is
    found where the light that reaches it left the moving segment."""
    p = np.array([0.0, 8.0, 0.0])
    segs = (Segment(np.zeros(3), 0.0, p, -math.inf, 0.0),
            Segment(np.array([0.9, 0.0, 0.0]), 0.0, p, 0.0, math.inf))
    ms = scene_of(segs)
    d = np.array([[0.0, 1.0, 0.0]], np.float32)
    o = (np.zeros((1, 3)) - ms.lab_origin).astype(np.float32)
    early = ms.intersect(o, d, np.array([5.0]))
    assert early.seg[0] == 0 and early.t[0] == pytest.approx(7.0, abs=1e-5)
    assert ms.intersect(o, d, np.array([30.0])).prim[0] == -1
    rng = np.random.default_rng(3)
    x0, dd, t = rays(rng, 200, 30.0, retarded(segs[1].u, p, 30.0), 1.5)
    h = ms.intersect((x0 - ms.lab_origin).astype(np.float32), dd.astype(np.float32), t)
    expect = np.array([march(x0[i], dd[i], 30.0, segs) for i in range(len(x0))])
    hit = np.isfinite(expect)
    assert hit.sum() > 20
    graze = np.abs(h.t - np.where(hit, expect, MISS_DISTANCE)) > 1e-3
    assert graze.sum() <= 3
    np.testing.assert_allclose(h.t[hit & ~graze], expect[hit & ~graze], atol=3e-4)
    assert np.all(h.seg[hit & ~graze] == 1)


def test_a_moving_occluder_blocks_only_while_it_is_in_the_way():
    """A shadow segment along y through the box's path at x = 0: blocked when the box
    crosses x = 0 at the time the segment's light passes, free before and after."""
    seg = Segment(np.array([0.8, 0.0, 0.0]), 0.0, np.array([0.0, 8.0, 0.0]))
    ms = scene_of((seg,))
    o = np.repeat((np.zeros((1, 3)) - ms.lab_origin).astype(np.float32), 3, axis=0)
    d = np.repeat(np.array([[0.0, 1.0, 0.0]], np.float32), 3, axis=0)
    # the light passing y = 8 left it at t0 - 8: the box is at x = 0.8 (t0 - 8)
    t0 = np.array([8.0, 8.0 + 5.0, 8.0 - 5.0])
    blocked = ms.occluded(o, d, np.full(3, 20.0, np.float32), t0)
    assert blocked.tolist() == [True, False, False]
    # a segment that ends before the box: never blocked
    assert not ms.occluded(o[:1], d[:1], np.array([6.0], np.float32), t0[:1])[0]


def test_the_nearest_of_static_and_moving_wins():
    static = Accel(shapes.quad(np.array([[-5, 20, -5], [5, 20, -5], [5, 20, 5], [-5, 20, 5]],
                                        np.float64)))
    seg = Segment(np.array([0.5, 0.0, 0.0]), 0.0, np.array([0.0, 8.0, 0.0]))
    group = GroupAccel(Accel(shapes.box(np.zeros(3), 2 * HALF, 0.0)), 2, (seg,), 0)
    ms = MovingScene(static, [group], static.origin)
    o = (np.zeros((2, 3)) - static.origin).astype(np.float32)
    d = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]], np.float32)
    # at t = 7.5 the light from y = 7.5 left at t = 0 (box at x = 0); at t = 40 the box
    # is far along x, and the wall behind it is hit
    h = ms.intersect(o, d, np.array([7.5, 40.0]))
    assert h.seg.tolist() == [0, -1] and h.prim[0] >= 2
    assert h.t[0] == pytest.approx(7.0, abs=1e-5) and h.t[1] == pytest.approx(20.0, abs=1e-5)


def test_the_static_box_test_changes_no_hit():
    """The static BVH traced only for the rays that meet its bounding box: the same hits
    and the same occlusion as the BVH alone, for rays that start inside and outside the
    box, graze its faces and end short of it."""
    rng = np.random.default_rng(11)
    # a small flat light-like quad and a tilted triangle: a thin, off-centre box
    tris = np.concatenate([
        shapes.quad(np.array([[-0.5, -0.5, 2.0], [0.5, -0.5, 2.0], [0.5, 0.5, 2.0],
                              [-0.5, 0.5, 2.0]], np.float64)),
        np.array([[[1.0, 0.0, 1.0], [1.5, 0.2, 1.4], [1.2, 0.7, 1.1]]])])
    static = Accel(tris)
    ms = MovingScene(static, [], static.origin)
    n = 4000
    x0 = rng.uniform(-2.0, 2.0, (n, 3)) + [0.0, 0.0, 1.0]
    aim = rng.uniform(-1.0, 1.0, (n, 3)) * [1.0, 1.0, 0.0] + [0.0, 0.0, 2.0]
    d = np.where(rng.uniform(size=(n, 1)) < 0.5, aim - x0, rng.normal(size=(n, 3)))
    d[: n // 8, 2] = 0.0  # along the quad's plane (rays at z = 2 among them)
    x0[: n // 16, 2] = 2.0
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = (x0 - static.origin).astype(np.float32)
    d = d.astype(np.float32)
    want = static.intersect(o, d)
    got = ms.intersect(o, d, np.zeros(n), {})
    assert (want.prim >= 0).sum() > n // 16 and (want.prim < 0).sum() > n // 16
    np.testing.assert_array_equal(got.prim, want.prim)
    np.testing.assert_array_equal(got.t, want.t)
    np.testing.assert_array_equal(got.u[want.prim >= 0], want.u[want.prim >= 0])
    assert np.all(got.seg == -1)
    # shadow segments ending just short of, at and beyond the hits
    length = np.where(want.prim >= 0, want.t * rng.choice([0.999, 1.001], n), 5.0)
    length = length.astype(np.float32)
    blocked = static.occluded(o, d, length)
    assert 0 < blocked.sum() < n
    np.testing.assert_array_equal(ms.occluded(o, d, length, np.zeros(n), {}), blocked)
    meets = [meets_box(*map(float, o[i]), *map(float, d[i]), 1e30, static.box_lo,
                       static.box_hi) for i in range(n)]
    assert n // 8 < n - sum(meets) < n - n // 8  # the box test did leave rays out


@pytest.mark.parametrize("u", [(0.6, 0.0, 0.0), (0.3, -0.5, 0.2), (0.0, 0.0, -0.99)])
def test_a_ray_leaving_a_body_in_its_rest_frame_form_finds_the_same_hit(u):
    """A continuation ray made on a moving body carries its rest-frame form (origin in the
    group's BVH coordinates, direction, k = γ (1 + u·d)); the tracer uses it for that
    segment instead of transforming the lab ray: the same hits as the lab form. Rays
    from inside the (hollow) moving box, at lab time 2, each hit its inside."""
    rng = np.random.default_rng(11)
    u = np.array(u, np.float64)
    seg = Segment(u, 0.0, np.array([0.0, 8.0, 0.0]))
    ms = scene_of((seg,))
    n, t0 = 300, 2.0
    rest_pt = rng.uniform(-0.9, 0.9, (n, 3)) * HALF
    g = 1.0 / math.sqrt(1.0 - u @ u)
    h = u / np.linalg.norm(u)
    lab_rel = rest_pt - (1.0 - 1.0 / g) * (rest_pt @ h)[:, None] * h  # contracted along u
    x0 = seg.p_ref + u * (t0 - seg.t_ref) + lab_rel
    assert np.all(inside(x0, np.full(n, t0), seg))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d32 = d.astype(np.float32)
    d64 = d32.astype(np.float64)  # the direction both forms trace
    rest = np.zeros((n, 7), np.float32)
    for i in range(n):
        du = aberrate_doppler_ray(*d64[i], *(-h), float(np.linalg.norm(u)), 1.0 / g)[:3]
        rest[i, :3] = spatial_boost(u, lab_rel[i]) - ms.groups[0].accel.origin
        rest[i, 3:6] = du
        rest[i, 6] = g * (1.0 + u @ d64[i])
    o = (x0 - ms.lab_origin).astype(np.float32)
    t = np.full(n, t0)
    lab = ms.intersect(o, d32, t)
    lab = lab._replace(**{k: v.copy() for k, v in lab._asdict().items()})
    carried = ms.intersect(o, d32, t, None, np.zeros(n, np.int32), rest)
    assert np.all(lab.prim >= 0) and np.all(carried.prim >= 0)
    assert np.all(carried.seg == 0)
    # the two forms differ by rounding (float32 origins of a box of size ~2)
    np.testing.assert_allclose(carried.t, lab.t, rtol=1e-5, atol=2e-5)
    same = carried.prim == lab.prim
    assert same.mean() > 0.98  # a ray through an edge may pick either triangle


@pytest.mark.parametrize("u", [(0.0, 0.0, 0.0), (0.3, -0.5, 0.2), (0.0, 0.0, -0.99)])
def test_the_groups_bounding_sphere_and_box_change_no_hit(u):
    """A group is traced only where its rest-frame ray reaches its bounding sphere and box
    (rest_frames.rest_ray, reaches_box): the same hits and the same occlusion as with both
    bounds taken away, for rays from inside and outside a thin, off-centre group (a
    tilted plate: its box and sphere differ), aimed at it, grazing it and ending short of
    it; the bounds do leave rays out."""
    rng = np.random.default_rng(5)
    plate = shapes.quad(np.array([[-1.0, -0.2, 0.0], [1.0, -0.2, 0.3], [1.0, 0.2, 0.3],
                                  [-1.0, 0.2, 0.0]], np.float64))
    tris = np.concatenate([plate, plate[:1] + [0.0, 0.0, 0.5]])
    seg = Segment(np.array(u, np.float64), 0.0, np.array([0.0, 3.0, 0.0]))
    group = Accel(tris)
    ms = MovingScene(None, [GroupAccel(group, 0, (seg,), 0)], np.zeros(3))
    open_ms = MovingScene(None, [GroupAccel(group, 0, (seg,), 0)], np.zeros(3))
    f = open_ms.segments.f
    f[:, rf.RAD], f[:, rf.LO:rf.LO + 3], f[:, rf.HI:rf.HI + 3] = np.inf, -np.inf, np.inf
    n, t0 = 6000, 4.0
    aim = retarded(np.array(u), seg.p_ref, t0) + group.origin
    x0 = rng.normal(0.0, 1.5, (n, 3)) + np.where(rng.uniform(size=(n, 1)) < 0.3, aim, 0.0)
    d = np.where(rng.uniform(size=(n, 1)) < 0.6, aim + rng.normal(0.0, 0.6, (n, 3)) - x0,
                 rng.normal(size=(n, 3)))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o, d, t = x0.astype(np.float32), d.astype(np.float32), np.full(n, t0)
    want = open_ms.intersect(o, d, t, {})
    got = ms.intersect(o, d, t, {})
    hit = want.prim >= 0
    assert n // 20 < hit.sum() < n - n // 20
    np.testing.assert_array_equal(got.prim, want.prim)
    np.testing.assert_array_equal(got.t, want.t)
    np.testing.assert_array_equal(got.u[hit], want.u[hit])
    length = np.where(hit, want.t * rng.choice([0.999, 1.001], n), 20.0).astype(np.float32)
    blocked = open_ms.occluded(o, d, length, t, {})
    assert 0 < blocked.sum() < n
    np.testing.assert_array_equal(ms.occluded(o, d, length, t, {}), blocked)
    # how many rays each bound leaves out (the sphere's nearest approach, the box's slabs)
    kept = [rest_ray(*map(float, o[i]), *map(float, d[i]), t0, MISS_DISTANCE,
                     ms.segments.f, 0) for i in range(n)]
    in_sphere = np.array([k[0] for k in kept])
    in_box = np.array([k[0] and reaches_box(ms.segments.f, 0, *k[1:7], k[8]) for k in kept])
    assert np.all(in_sphere[hit]) and np.all(in_box[hit])
    assert n // 10 < n - in_sphere.sum() and n // 50 < in_sphere.sum() - in_box.sum()
