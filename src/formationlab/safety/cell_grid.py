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
    side = radius
    cells = (math.floor((x1 - x0) / side) + 1) * (math.floor((y1 - y0) / side) + 1)
    if cells > 4 * n + 16:  # spread out: larger cells, a grid of about 4 n of them
        side = max(side, math.sqrt((x1 - x0 + side) * (y1 - y0 + side) / (4 * n + 16)) * 1.01)
    nx = int((x1 - x0) / side) + 1  # (>= 0: truncation is the floor)
    ny = int((y1 - y0) / side) + 1
    cell = np.empty(n, dtype=np.int64)
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    for i in range(n):
        cx = min(int((q[i, 0] - x0) / side), nx - 1)
        cy = min(int((q[i, 1] - y0) / side), ny - 1)
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
    cx = min(int((q[i, 0] - x0) / side), nx - 1)
    cy = min(int((q[i, 1] - y0) / side), ny - 1)
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
