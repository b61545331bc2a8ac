"""Worldlines and velocity groups of moving objects (core/scene/worldlines.py)."""

import math

import numpy as np
import pytest

from relray.core.physics import relativity
from relray.core.scene import worldlines
from relray.core.scene.description import ObjectSpec, Worldline, frozen


def obj(velocity=(0.0, 0.0, 0.0), pivot=(0.0, 0.0, 0.0), worldline=None) -> ObjectSpec:
    return ObjectSpec(name="o", shape="sphere", material="m", params={},
                      velocity=frozen(velocity), pivot=frozen(pivot), worldline=worldline)


def test_is_moving():
    assert not worldlines.is_moving(obj())
    assert worldlines.is_moving(obj(velocity=(0.0, 1e-12, 0.0)))
    w = Worldline(frozen([0.0, 1.0]), frozen([[0, 0, 0], [0.5, 0, 0]]))
    assert worldlines.is_moving(obj(worldline=w))


def test_a_constant_velocity_is_one_open_segment_through_its_pivot():
    (s,) = worldlines.object_segments(obj(velocity=(0.6, 0.0, 0.0), pivot=(1.0, 2.0, 3.0)))
    assert s.u.tolist() == [0.6, 0.0, 0.0] and s.t_ref == 0.0
    assert s.p_ref.tolist() == [1.0, 2.0, 3.0]
    assert s.t_lo == -math.inf and s.t_hi == math.inf
    assert s.gamma == pytest.approx(1.25, rel=1e-15)


def test_a_worldline_is_a_segment_per_piece_with_emission_windows():
    w = Worldline(frozen([0.0, 4.0, 8.0]), frozen([[0, 0, 1], [2, 0, 1], [2, 3, 1]]))
    segs = worldlines.object_segments(obj(worldline=w))
    assert [s.u.tolist() for s in segs] == [[0.5, 0.0, 0.0], [0.0, 0.75, 0.0]]
    assert [(s.t_lo, s.t_hi) for s in segs] == [(-math.inf, 4.0), (4.0, math.inf)]
    assert [s.t_ref for s in segs] == [0.0, 4.0]
    assert segs[1].p_ref.tolist() == [2.0, 0.0, 1.0]


@pytest.mark.parametrize("b", [0.0, 0.3, 0.9, 1 - 1e-9])
def test_spatial_boost_is_the_boost_of_a_separation_at_equal_lab_time(b):
    """B x = spatial part of Λ(u)·(0, x): γ x along u, x across it."""
    u = b * np.array([0.6, 0.8, 0.0])
    x = np.array([[1.0, -2.0, 0.5], [0.0, 0.0, 3.0]])
    lam = relativity.lorentz_boost(u)
    expect = (lam @ np.c_[np.zeros(2), x].T).T[:, 1:]
    np.testing.assert_allclose(worldlines.spatial_boost(u, x), expect, rtol=1e-9, atol=1e-9)


def test_objects_sharing_a_velocity_share_a_group_and_keep_their_rest_separation():
    """Two boxes at lab separation Δ along u at t = 0 are γΔ apart in their rest frame."""
    u = (0.8, 0.0, 0.0)
    objs = [obj(), obj(velocity=u, pivot=(0, 5, 0)), obj(velocity=u, pivot=(3, 5, 0)),
            obj(velocity=(0.0, 0.8, 0.0), pivot=(0, 5, 0))]
    index, groups, offsets = worldlines.rest_frame_offsets(objs)
    assert index == [0, 1, 1, 2] and len(groups) == 2
    assert groups[0].segments[0].p_ref.tolist() == [0.0, 5.0, 0.0]
    np.testing.assert_array_equal(offsets[0], 0.0)
    np.testing.assert_allclose(offsets[1], [0.0, -5.0, 0.0])
    # the second box's pivot sits at B(p2 - p1) = (3γ, 0, 0) in the group's frame
    np.testing.assert_allclose(offsets[2] + np.array([3.0, 5.0, 0.0]), [3.0 / 0.6, 0, 0],
                               rtol=1e-12)


def test_objects_on_one_worldline_are_placed_by_their_own_pivot():
    w = Worldline(frozen([0.0, 1.0]), frozen([[0, 0, 0], [0.5, 0, 0]]))
    index, groups, offsets = worldlines.rest_frame_offsets(
        [obj(worldline=w, pivot=(1, 1, 1)), obj(worldline=w, pivot=(2, 0, 0))])
    assert index == [1, 1] and len(groups) == 1
    np.testing.assert_array_equal(offsets[0], [-1.0, -1.0, -1.0])
    np.testing.assert_array_equal(offsets[1], [-2.0, 0.0, 0.0])
