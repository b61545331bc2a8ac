"""Worldlines of moving objects and their velocity groups (physics.md, "Moving objects").

An object with its own lab velocity u (|u| < 1) is static in its rest frame S_u. The job
gives its shape in S_u around its **pivot** p: a lab event (t, x) has the S_u coordinates

    (t_u, x_u) = Λ(u) · (t - t_ref, x - p_ref)

where (t_ref, p_ref) is the lab event at which the pivot is at the frame's origin; a
constant velocity has (t_ref, p_ref) = (0, p). The object occupies its job coordinates
minus p in S_u at every t_u.

A **piecewise-linear worldline** (samples (t_k, p_k), k = 0..n-1) is a sequence of
inertial pieces: segment k moves at u_k = (p_{k+1} - p_k)/(t_{k+1} - t_k), has the frame
origin event (t_k, p_k) and is seen only by light emitted in its window of lab times
[t_k, t_{k+1}) (the first window reaches back to -∞, the last one on to +∞; outside the
samples the object keeps the first or last segment's velocity). Every segment has its own
contraction, so the shape jumps at a kink (Born rigidity is not modelled).

**Velocity groups.** Objects that share a velocity (or the same worldline) share one
rest frame and so one BVH: a :class:`VelocityGroup` holds the rest-frame triangles of
all its objects (an object with pivot p_i joins the group whose frame origin is at p_0
with the offset B(p_i - p_0), the boost's spatial part B x = x + γ²/(γ+1) (u·x) u, i.e.
its lab separation at equal lab time, uncontracted) and one :class:`Segment` per inertial
piece. Static objects are group 0, traced in the lab as always.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..physics import relativity
from .description import ObjectSpec

#: The emission-time window of a worldline's open ends.
OPEN = math.inf


@dataclass(frozen=True, eq=False)
class Segment:
    """One inertial piece of a group's motion (lab frame).

    ``u`` (3,) its velocity; ``t_ref``, ``p_ref`` (3,) the lab event of its rest frame's
    origin; light emitted at lab times in [``t_lo``, ``t_hi``) sees it.
    """

    u: np.ndarray
    t_ref: float
    p_ref: np.ndarray
    t_lo: float = -OPEN
    t_hi: float = OPEN

    @property
    def gamma(self) -> float:
        """γ_u = 1/sqrt((1 - b)(1 + b)), b = |u| (:func:`relativity.gamma`)."""
        return float(relativity.gamma(self.u))


@dataclass(frozen=True, eq=False)
class VelocityGroup:
    """Objects at rest in one frame: their :class:`Segment` s (one for a constant
    velocity) and, in :class:`..geometry.Scene`, the triangles whose ``tri_group`` is
    this group's index (1-based; 0 is the static lab group)."""

    segments: tuple[Segment, ...]


def is_moving(obj: ObjectSpec) -> bool:
    """Whether an object has its own motion (a non-zero velocity or a worldline)."""
    return obj.worldline is not None or bool(np.any(np.asarray(obj.velocity) != 0.0))


def spatial_boost(u: np.ndarray, x: np.ndarray) -> np.ndarray:
    """B x = x + γ²/(γ+1) (u·x) u: the S_u coordinates of a lab separation x at equal lab
    time, as a vector or rows (..., 3) (the rest length along u is γ times the lab one)."""
    u = np.asarray(u, np.float64)
    g = float(relativity.gamma(u))
    x = np.asarray(x, np.float64)
    return x + (g * g / (g + 1.0)) * (x @ u)[..., None] * u


def object_segments(obj: ObjectSpec) -> tuple[Segment, ...]:
    """The inertial pieces of a moving object's pivot (module docstring)."""
    w = obj.worldline
    if w is None:
        return (Segment(np.array(obj.velocity, np.float64), 0.0,
                        np.array(obj.pivot, np.float64)),)
    t = np.asarray(w.t, np.float64)
    p = np.asarray(w.pivot, np.float64)
    n = len(t)
    segs = []
    for k in range(n - 1):
        u = (p[k + 1] - p[k]) / (t[k + 1] - t[k])
        lo = -OPEN if k == 0 else float(t[k])
        hi = OPEN if k == n - 2 else float(t[k + 1])
        segs.append(Segment(u, float(t[k]), p[k].copy(), lo, hi))
    return tuple(segs)


def _motion_key(obj: ObjectSpec) -> tuple:
    """Objects with equal keys share a rest frame (and a group)."""
    if obj.worldline is None:
        return ("velocity", tuple(float(x) for x in obj.velocity))
    w = obj.worldline
    return ("worldline", tuple(float(x) for x in w.t),
            tuple(float(x) for x in np.asarray(w.pivot, np.float64).ravel()))


def rest_frame_offsets(objects: list[ObjectSpec]) -> tuple[list[int], list[VelocityGroup],
                                                           list[np.ndarray]]:
    """Assign each object its group: (group index per object, 0 for a static one; the
    groups; the translation that takes each object's job coordinates into its group's
    rest-frame coordinates).

    With a constant velocity the translation is -p_i + B(p_i - p_0), p_0 the pivot of the
    group's first object (its frame's origin). On a worldline the frame's origin is the
    worldline itself and each object's own pivot p_i follows it: -p_i."""
    keys: dict[tuple, int] = {}
    groups: list[VelocityGroup] = []
    first_pivot: list[np.ndarray] = []
    index, offsets = [], []
    for obj in objects:
        if not is_moving(obj):
            index.append(0)
            offsets.append(np.zeros(3))
            continue
        key = _motion_key(obj)
        if key not in keys:
            keys[key] = len(groups) + 1
            groups.append(VelocityGroup(object_segments(obj)))
            first_pivot.append(np.array(obj.pivot, np.float64))
        g = keys[key]
        p_i = np.array(obj.pivot, np.float64)
        index.append(g)
        if obj.worldline is None:
            u = groups[g - 1].segments[0].u
            offsets.append(-p_i + spatial_boost(u, p_i - first_pivot[g - 1]))
        else:
            offsets.append(-p_i)
    return index, groups, offsets
