"""Obstacles as plain arrays, and their geometry for compiled loops (numba).

:func:`obstacle_terms` turns circles and polygons (:mod:`.obstacles`) into an
:class:`ObstacleTerms` of arrays, and the functions below compute, for one robot at
a time, what :mod:`.obstacles` and :mod:`.contact` compute vectorised in numpy, with
the same arithmetic (so a compiled loop follows the numpy closed loop to rounding):

* :func:`signed_distance`: ``delta`` and its gradient (``Circle.signed_distance``,
  ``Polygon.signed_distance``: nearest edge point, crossing-number sign);
* :func:`repel`: ``u_i -= k sum_o gamma'(s_io) grad s_io``, Khatib's repulsion on the
  clearances ``s = delta - rho_i / 2`` (``System._repelled``);
* :func:`barrier_row`: the row ``-2 (q_i - p*) . u_i <= b(h)`` of one barrier
  piece (``obstacle_barrier_rows``);
* :func:`swept_clearance`: the least clearance along a straight step
  (``swept_clearances``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..controllers.kinds.khatib import khatib_prime
from .condition import barrier_bound
from .obstacles import Circle, Obstacle

__all__ = [
    "ObstacleTerms",
    "barrier_row",
    "hull_distance",
    "obstacle_terms",
    "piece_count",
    "repel",
    "signed_distance",
    "swept_clearance",
]


class ObstacleTerms(NamedTuple):
    """``O`` obstacles as arrays; obstacle ``o`` is a circle when ``radius[o] > 0``.

    A circle's centre is ``vertices[start[o]]``; a polygon's vertices are
    ``vertices[start[o]:start[o + 1]]``.
    """

    radius: NDArray[np.float64]  #: (O,) circle radius, 0 for a polygon
    start: NDArray[np.int64]  #: (O + 1,)
    vertices: NDArray[np.float64]  #: (V, 2)
    hull: NDArray[np.float64]  #: (O, 3) a disc holding the obstacle: centre, radius
    d_obstacle: float  #: D_o of the filter's rows
    gamma: float  #: the filter's gain
    step: float  #: the Euler step its rows guard (0: the continuous rows)
    gain: float  #: the law's repulsion gain k (0: no repulsion)
    eta: float
    influence: float  #: s0


def obstacle_terms(
    obstacles: Sequence[Obstacle],
    *,
    d_obstacle: float = 0.0,
    gamma: float = 0.0,
    step: float = 0.0,
    gain: float = 0.0,
    eta: float = 1.0,
    influence: float = 1.0,
) -> ObstacleTerms:
    """The :class:`ObstacleTerms` of ``obstacles`` (in their order)."""
    radius, verts, start, hull = [], [np.zeros((0, 2))], [0], [np.zeros((0, 3))]
    for ob in obstacles:
        if isinstance(ob, Circle):
            radius.append(ob.radius)
            verts.append(np.asarray(ob.center, dtype=float)[None])
            hull.append(np.array([[*ob.center, ob.radius]]))
        else:
            radius.append(0.0)
            verts.append(np.asarray(ob.vertices, dtype=float))
            mid = 0.5 * (verts[-1].min(axis=0) + verts[-1].max(axis=0))
            reach = np.sqrt(np.sum((verts[-1] - mid) ** 2, axis=-1)).max()
            hull.append(np.array([[*mid, reach * (1 + 1e-12) + 1e-12]]))  # (rounding margin)
        start.append(start[-1] + len(verts[-1]))
    return ObstacleTerms(
        radius=np.array(radius, dtype=float), start=np.array(start, dtype=np.int64),
        vertices=np.ascontiguousarray(np.concatenate(verts)),
        hull=np.ascontiguousarray(np.concatenate(hull)), d_obstacle=float(d_obstacle),
        gamma=float(gamma), step=float(step), gain=float(gain), eta=float(eta),
        influence=float(influence),
    )  # fmt: skip


@njit(cache=True, nogil=True, inline="always")
def hull_distance(obs: ObstacleTerms, o: int, x: float, y: float):
    """``(low, high)``: bounds on the distance of ``(x, y)`` to any point of obstacle ``o``.

    From its enclosing disc: ``low <= delta`` where ``delta >= 0`` (``low`` may be negative),
    and ``high`` at least the distance to its farthest point.
    """
    dx = x - obs.hull[o, 0]
    dy = y - obs.hull[o, 1]
    d = math.sqrt(dx * dx + dy * dy)
    return d - obs.hull[o, 2], d + obs.hull[o, 2]


@njit(cache=True, nogil=True, inline="always")
def piece_count(obs: ObstacleTerms) -> int:
    """Barrier pieces: one per circle, one per polygon edge."""
    total = 0
    for o in range(obs.radius.shape[0]):
        total += 1 if obs.radius[o] > 0 else obs.start[o + 1] - obs.start[o]
    return total


@njit(cache=True, nogil=True, inline="always")
def _edge_point(x: float, y: float, ax: float, ay: float, bx: float, by: float):
    """Nearest point of the segment ``[a, b]`` to ``(x, y)`` (``nearest_on_edges``)."""
    ex = bx - ax
    ey = by - ay
    t = ((x - ax) * ex + (y - ay) * ey) / (ex * ex + ey * ey)
    t = min(max(t, 0.0), 1.0)
    return ax + t * ex, ay + t * ey


@njit(cache=True, nogil=True, inline="always")
def signed_distance(obs: ObstacleTerms, o: int, x: float, y: float):
    """``(delta, gx, gy)``: signed distance of ``(x, y)`` to obstacle ``o`` and its gradient."""
    v = obs.vertices
    s0 = obs.start[o]
    if obs.radius[o] > 0:
        wx = x - v[s0, 0]
        wy = y - v[s0, 1]
        dist = math.sqrt(wx * wx + wy * wy)
        den = dist if dist > 0 else 1.0
        return dist - obs.radius[o], wx / den, wy / den
    s1 = obs.start[o + 1]
    best = np.inf
    nx = 0.0
    ny = 0.0
    crossings = 0
    for k in range(s0, s1):
        kb = k + 1 if k + 1 < s1 else s0
        px, py = _edge_point(x, y, v[k, 0], v[k, 1], v[kb, 0], v[kb, 1])
        d2 = (x - px) ** 2 + (y - py) ** 2
        if d2 < best:  # the first nearest edge, as argmin
            best = d2
            nx = px
            ny = py
        if (v[k, 1] > y) != (v[kb, 1] > y):  # crossing-number test (Polygon.contains)
            xc = v[k, 0] + (y - v[k, 1]) * (v[kb, 0] - v[k, 0]) / (v[kb, 1] - v[k, 1])
            if x < xc:
                crossings += 1
    wx = x - nx
    wy = y - ny
    dist = math.sqrt(wx * wx + wy * wy)
    sign = -1.0 if crossings % 2 == 1 else 1.0
    den = dist if dist > 0 else 1.0
    return sign * dist, sign * wx / den, sign * wy / den


@njit(cache=True, nogil=True, inline="always")
def repel(obs: ObstacleTerms, radius: NDArray, p: NDArray, u: NDArray) -> None:
    """``u_i -= k sum_o gamma'(s_io) grad s_io`` for every robot (``p``, ``u``: (n, 2))."""
    s0 = obs.influence
    for i in range(p.shape[0]):
        gx = 0.0
        gy = 0.0
        for o in range(obs.radius.shape[0]):
            if hull_distance(obs, o, p[i, 0], p[i, 1])[0] - radius[i] >= s0:
                continue  # gamma'(s) = 0 here: the term adds exactly 0
            delta, dx, dy = signed_distance(obs, o, p[i, 0], p[i, 1])
            s = delta - radius[i]
            slope = khatib_prime(s, obs.eta, s0) if s < s0 else 0.0  # Khatib's gamma'(s)
            gx += slope * dx
            gy += slope * dy
        u[i, 0] = u[i, 0] - obs.gain * gx
        u[i, 1] = u[i, 1] - obs.gain * gy


@njit(cache=True, nogil=True, inline="always")
def barrier_row(obs: ObstacleTerms, o: int, k: int, x: float, y: float):
    """``(a0, a1, b, h)`` of piece ``k`` of obstacle ``o`` (the circle, or its ``k``-th edge).

    ``h = |q - p*|^2 - rho^2``, row ``-2 (q - p*) . u <= b(h)`` (``obstacle_barrier_rows``;
    ``b`` is :func:`~formationlab.safety.condition.barrier_bound`).
    """
    v = obs.vertices
    s0 = obs.start[o]
    if obs.radius[o] > 0:
        px = v[s0, 0]
        py = v[s0, 1]
        rho = obs.radius[o] + obs.d_obstacle
    else:
        s1 = obs.start[o + 1]
        ka = s0 + k
        kb = ka + 1 if ka + 1 < s1 else s0
        px, py = _edge_point(x, y, v[ka, 0], v[ka, 1], v[kb, 0], v[kb, 1])
        rho = obs.d_obstacle
    wx = x - px
    wy = y - py
    h = wx * wx + wy * wy - rho * rho
    return -2.0 * wx, -2.0 * wy, barrier_bound(h, obs.gamma, obs.step), h


@njit(cache=True, nogil=True, inline="always")
def _point_segment(px: float, py: float, ax: float, ay: float, bx: float, by: float) -> float:
    ex = bx - ax
    ey = by - ay
    ee = ex * ex + ey * ey
    s = ((px - ax) * ex + (py - ay) * ey) / (ee if ee > 0 else 1.0)
    s = min(max(s, 0.0), 1.0)
    wx = px - (ax + s * ex)
    wy = py - (ay + s * ey)
    return math.sqrt(wx * wx + wy * wy)


@njit(cache=True, nogil=True)
def swept_clearance(obs: ObstacleTerms, o: int, x0, y0, x1, y1, r: float) -> float:
    """Least clearance to obstacle ``o`` of a robot of radius ``r`` moving ``x0 -> x1``.

    As :func:`formationlab.safety.swept_clearances`: a circle's centre to the segment;
    for a polygon the signed distance of an end inside, else the least distance of the
    segment to an edge (0 when they cross).
    """
    v = obs.vertices
    s0 = obs.start[o]
    if obs.radius[o] > 0:
        return _point_segment(v[s0, 0], v[s0, 1], x0, y0, x1, y1) - obs.radius[o] - r
    sd0 = signed_distance(obs, o, x0, y0)[0]
    sd1 = signed_distance(obs, o, x1, y1)[0]
    if sd0 < 0 or sd1 < 0:
        return min(sd0, sd1) - r
    s1 = obs.start[o + 1]
    best = np.inf
    for k in range(s0, s1):
        kb = k + 1 if k + 1 < s1 else s0
        ax, ay, bx, by = v[k, 0], v[k, 1], v[kb, 0], v[kb, 1]
        d = min(
            min(_point_segment(x0, y0, ax, ay, bx, by), _point_segment(x1, y1, ax, ay, bx, by)),
            min(_point_segment(ax, ay, x0, y0, x1, y1), _point_segment(bx, by, x0, y0, x1, y1)),
        )
        o1 = (x1 - x0) * (ay - y0) - (y1 - y0) * (ax - x0)
        o2 = (x1 - x0) * (by - y0) - (y1 - y0) * (bx - x0)
        o3 = (bx - ax) * (y0 - ay) - (by - ay) * (x0 - ax)
        o4 = (bx - ax) * (y1 - ay) - (by - ay) * (x1 - ax)
        if o1 * o2 < 0 and o3 * o4 < 0:
            d = 0.0
        best = min(best, d)
    return best - r
