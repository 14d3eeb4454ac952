"""Neighbours within a sensing radius by a grid of cells, compiled (numba).

Robots are binned into square cells of side at least the radius ``R`` (counting sort),
so the robots within ``R`` of robot ``i`` lie in its cell and the eight around it:
``O(n)`` work for a swarm of bounded density instead of the ``O(n^2)`` of all pairs.
A spread-out swarm gets larger cells, so that the grid has at most about ``4 n`` of
them. :func:`neighbours_of` lists a robot's neighbours in ascending order, the order of
:func:`formationlab.safety.neighbour_lists`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["build_grid", "neighbours_of"]


@njit(cache=True, nogil=True, inline="always")
def _cell(v, v0, side, count):
    """The cell ``0 <= c < count`` of coordinate ``v``, clamped before the conversion to an
    integer (undefined for a NaN quotient or one beyond the integers)."""
    t = (v - v0) / side
    if not t >= 0.0:
        return 0
    if t >= count - 1:
        return count - 1
    return int(t)


@njit(cache=True, nogil=True)
def build_grid(q: NDArray, radius: float):
    """Bin the points ``q`` ``(n, 2)`` into cells of side ``>= radius``.

    Returns ``(origin_x, origin_y, side, nx, ny, start, order)``: robot ``order[k]`` for
    ``start[c] <= k < start[c + 1]`` lies in cell ``c = cx + nx cy``.
    """
    n = q.shape[0]
    x0 = np.inf
    y0 = np.inf
    x1 = -np.inf
    y1 = -np.inf
    for i in range(n):
        x0 = min(x0, q[i, 0])
        y0 = min(y0, q[i, 1])
        x1 = max(x1, q[i, 0])
        y1 = max(y1, q[i, 1])
    wide, high = x1 - x0, y1 - y0
    side = radius
    nx, ny = 1, 1
    if math.isfinite(wide) and math.isfinite(high) and math.isfinite(side) and side > 0.0:
        # counted in floats: the cell counts of a huge extent are beyond the integers
        cells = (math.floor(wide / side) + 1.0) * (math.floor(high / side) + 1.0)
        if cells > 4 * n + 16:  # spread out: larger cells, a grid of about 4 n of them
            side = max(side, math.sqrt((wide + side) * (high + side) / (4 * n + 16)) * 1.01)
            while (math.floor(wide / side) + 1.0) * (math.floor(high / side) + 1.0) > 4 * n + 16:
                side *= 2.0  # a thin layout, or one whose area above overflowed
        nx = int(wide / side) + 1  # (>= 0: truncation is the floor)
        ny = int(high / side) + 1
    else:  # not finite, or too far apart for their difference to be a float: one cell
        x0, y0, side = 0.0, 0.0, np.inf
    cell = np.empty(n, dtype=np.int64)
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    for i in range(n):
        cx = _cell(q[i, 0], x0, side, nx)
        cy = _cell(q[i, 1], y0, side, ny)
        cell[i] = cx + nx * cy
        start[cell[i] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        order[fill[cell[i]]] = i
        fill[cell[i]] += 1
    return x0, y0, side, nx, ny, start, order


@njit(cache=True, nogil=True, inline="always")
def neighbours_of(i, q, r2, x0, y0, side, nx, ny, start, order, out) -> int:
    """Robots ``j != i`` with ``|q_i - q_j|^2 <= r2`` into ``out``, ascending; their count."""
    cx = _cell(q[i, 0], x0, side, nx)
    cy = _cell(q[i, 1], y0, side, ny)
    deg = 0
    for gy in range(max(cy - 1, 0), min(cy + 2, ny)):
        for gx in range(max(cx - 1, 0), min(cx + 2, nx)):
            c = gx + nx * gy
            for k in range(start[c], start[c + 1]):
                j = order[k]
                if j == i:
                    continue
                dx = q[i, 0] - q[j, 0]
                dy = q[i, 1] - q[j, 1]
                if dx * dx + dy * dy <= r2:
                    t = deg  # insertion into the sorted list
                    while t > 0 and out[t - 1] > j:
                        out[t] = out[t - 1]
                        t -= 1
                    out[t] = j
                    deg += 1
    return deg
