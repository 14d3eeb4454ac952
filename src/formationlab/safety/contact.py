"""Contact with obstacles along a straight step: the exact swept clearance.

The contact rule of the closed loop (:meth:`formationlab.dynamics.System.step_verdict`)
rejects a step that ends in contact and a step whose straight path passes through
contact while both ends are clear. Between robots that is the closest approach of two
points moving on straight lines; for obstacles it is, for each robot centre moving from
``q0`` to ``q1``:

* a **circle** or a **sphere** (centre ``c``, radius ``R``): the distance from ``c`` to the segment
  ``[q0, q1]`` (the nearest point at ``s* = clip(-(q0 - c).(q1 - q0) / |q1 - q0|^2, 0, 1)``),
  minus ``R``;
* a **polygon**: the distance from the segment to the polygon as a closed set, which is
  zero when the segment meets the boundary and otherwise the least distance between the
  segment and an edge (the least of the four endpoint-to-segment distances, since two
  disjoint segments in the plane are nearest at an endpoint of one of them); negative
  when an end lies inside (its signed distance).

minus the robot's radius ``rho_i / 2``: the least clearance ``s`` over the step. Both are
exact, not sampled, so a step cannot carry a robot through a thin obstacle unseen.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .obstacles import Obstacle, Polygon
from .solids import Ball, Box, segment_box_distance

__all__ = ["segment_distances", "swept_clearances"]


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _point_segment(
    p: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Distance from points ``p`` to segments ``[a, b]`` (broadcast over ``(..., d)``)."""
    e = b - a
    ee = np.sum(e * e, axis=-1)
    s = np.clip(np.sum((p - a) * e, axis=-1) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
    w = p - (a + s[..., None] * e)
    return np.sqrt(np.sum(w * w, axis=-1))


def segment_distances(
    p0: ArrayLike, p1: ArrayLike, a: ArrayLike, b: ArrayLike
) -> NDArray[np.float64]:
    """Least distance between segments ``[p0, p1]`` and ``[a, b]``; ``(..., 2) -> (...)``.

    Zero when they meet (proper crossing by orientation tests, touching and collinear
    overlap through the endpoint distances); otherwise the least of the four
    endpoint-to-segment distances.
    """
    p0, p1, a, b = (np.asarray(x, dtype=float) for x in (p0, p1, a, b))
    d = np.minimum(
        np.minimum(_point_segment(p0, a, b), _point_segment(p1, a, b)),
        np.minimum(_point_segment(a, p0, p1), _point_segment(b, p0, p1)),
    )
    o1, o2 = _cross(p1 - p0, a - p0), _cross(p1 - p0, b - p0)
    o3, o4 = _cross(b - a, p0 - a), _cross(b - a, p1 - a)
    crossing = (o1 * o2 < 0) & (o3 * o4 < 0)
    return np.where(crossing, 0.0, d)


def swept_clearances(
    q0: ArrayLike, q1: ArrayLike, radii: ArrayLike, obstacles: Sequence[Obstacle]
) -> NDArray[np.float64]:
    """Least clearance ``s`` of every robot to every obstacle along the straight step.

    Parameters
    ----------
    q0, q1 : array_like, shape (..., n, d)
        Robot centres at the start and the end of the step.
    radii : array_like, shape (n,)
        Robot radii ``rho_i / 2``.
    obstacles : sequence of Circle, Polygon, Sphere or Box
        ``O`` obstacles.

    Returns
    -------
    ndarray, shape (..., n, O)
        ``min over the step of (delta - rho_i / 2)`` (module docstring); ``<= 0`` means
        the step touches or enters the obstacle.
    """
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    radii = np.asarray(radii, dtype=float)
    out = np.empty((*q0.shape[:-1], len(obstacles)))
    for o, ob in enumerate(obstacles):
        if isinstance(ob, Ball):  # a circle or a sphere
            out[..., o] = _point_segment(ob.center, q0, q1) - ob.radius
            continue
        sd0, sd1 = ob.signed_distance(q0)[0], ob.signed_distance(q1)[0]
        if isinstance(ob, Box):
            dist = segment_box_distance(q0, q1, *ob.corners)
            out[..., o] = np.where((sd0 < 0) | (sd1 < 0), np.minimum(sd0, sd1), dist)
            continue
        assert isinstance(ob, Polygon)
        a, b = ob.edges
        dist = segment_distances(q0[..., None, :], q1[..., None, :], a, b).min(axis=-1)
        out[..., o] = np.where((sd0 < 0) | (sd1 < 0), np.minimum(sd0, sd1), dist)
    return out - radii[:, None]
