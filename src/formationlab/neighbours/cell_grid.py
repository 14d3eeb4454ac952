"""Points binned into a grid of cells, compiled (numba): the one cell grid.

Points are binned into cells of side at least a radius ``R`` (counting sort: squares in the
plane, cubes in space), so the points within ``R`` of point ``i`` lie in its cell and the
ones around it (8 in the plane, 26 in space): ``O(n)`` work for a swarm of bounded density
instead of the ``O(n^2)`` of all pairs. A spread-out swarm gets larger cells, so that the
grid has at most as many cells as its scratch holds (``start.size - 1``). Two users: the
close-pair (Verlet) list of the compiled loop (:mod:`.close_list`, Khatib's repulsion and
contact, in the plane and in space, into scratch it keeps from step to step) and each
robot's neighbours within the safety filter's sensing radius in the plane
(:func:`build_grid`, :func:`neighbours_of`, in ascending order, the order of
:func:`formationlab.safety.neighbour_lists`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["bin_points", "build_grid", "cell", "cell_index", "neighbours_of"]


@njit(cache=True, nogil=True, inline="always")
def cell(v, v0, side, count):
    """The cell ``0 <= c < count`` of coordinate ``v`` in cells of ``side`` from ``v0``.

    Clamped before the conversion to an integer, which is undefined for a quotient that
    is NaN or beyond the integers (a coordinate around 1e154 or not finite): such a
    point goes to an edge cell, where the grid stays valid for the finite ones.
    """
    t = (v - v0) / side
    if not t >= 0.0:  # NaN as well
        return 0
    if t >= count - 1:
        return count - 1
    return int(t)


@njit(cache=True, nogil=True, inline="always")
def _cells(wide, high, deep, side):
    """How many cells of ``side`` cover an extent ``wide x high x deep`` (``deep`` 0: the
    plane), counted in floats: the cell counts of a huge extent are beyond the integers."""
    return (
        (math.floor(wide / side) + 1.0)
        * (math.floor(high / side) + 1.0)
        * (math.floor(deep / side) + 1.0)
    )


@njit(cache=True, nogil=True, inline="always")
def cell_index(q, i, x0, y0, z0, side, nx, ny, nz):
    """The cell ``c = (cx ny + cy) nz + cz`` of point ``i`` of ``q`` (``cz = 0`` when
    ``nz`` is 1: the plane, or a flat layout in space)."""
    c = cell(q[i, 0], x0, side, nx) * ny + cell(q[i, 1], y0, side, ny)
    if nz > 1:
        c = c * nz + cell(q[i, 2], z0, side, nz)
    return c


@njit(cache=True, nogil=True)
def bin_points(q, side, cell_of, items, start):
    """Counting sort of the points ``q`` ``(n, d)`` into cells of side ``>= side``: squares
    in the plane (``d = 2``), cubes in space (``d = 3``).

    At most ``start.size - 1`` cells: a spread-out layout gets larger cells (to about that
    many from its area or volume, then doubled until they fit; wider cells still hold every
    pair within ``side``); points whose extent is not finite (NaN, infinite, or too far apart
    for their difference to be a float) all go into one cell. ``cell_of`` and ``items``
    ``(n,)`` and ``start`` are scratch. Returns ``nx, ny, nz, side, x0, y0, z0`` (``nz = 1``
    and ``z0 = 0`` in the plane); the points of cell ``c = (cx ny + cy) nz + cz``
    (:func:`cell_index`) are ``items[start[c]:start[c + 1]]``, in ascending order.
    """
    n = q.shape[0]
    space = q.shape[1] == 3
    limit = start.size - 1
    x0, y0, x1, y1 = np.inf, np.inf, -np.inf, -np.inf
    z0, z1 = 0.0, 0.0
    for i in range(n):
        x0, x1 = min(x0, q[i, 0]), max(x1, q[i, 0])
        y0, y1 = min(y0, q[i, 1]), max(y1, q[i, 1])
    if space and n > 0:
        z0, z1 = np.inf, -np.inf
        for i in range(n):
            z0, z1 = min(z0, q[i, 2]), max(z1, q[i, 2])
    wide, high, deep = x1 - x0, y1 - y0, z1 - z0
    nx, ny, nz = 1, 1, 1
    if (
        math.isfinite(wide)
        and math.isfinite(high)
        and math.isfinite(deep)
        and math.isfinite(side)
        and side > 0.0
    ):
        if _cells(wide, high, deep, side) > limit:
            if space:  # (from the volume)
                volume = (wide + side) * (high + side) * (deep + side)
                side = max(side, (volume / limit) ** (1.0 / 3.0) * 1.01)
            else:
                side = max(side, math.sqrt((wide + side) * (high + side) / limit) * 1.01)
        while _cells(wide, high, deep, side) > limit:
            side *= 2.0  # a thin layout, or one whose area or volume above overflowed
        nx = int(wide / side) + 1  # (>= 1: truncation is the floor)
        ny = int(high / side) + 1
        nz = int(deep / side) + 1
    else:
        x0, y0, z0, side = 0.0, 0.0, 0.0, np.inf
    cells = nx * ny * nz
    start[: cells + 1] = 0
    for i in range(n):
        c = cell_index(q, i, x0, y0, z0, side, nx, ny, nz)
        cell_of[i] = c
        start[c + 1] += 1
    for c in range(cells):
        start[c + 1] += start[c]
    for i in range(n - 1, -1, -1):  # backwards, so that each cell lists its points in order
        c = cell_of[i]
        start[c + 1] -= 1
        items[start[c + 1]] = i
    for c in range(cells):  # start[c + 1] now points at cell c's first point; shift back
        start[c] = start[c + 1]
    start[cells] = n
    return nx, ny, nz, side, x0, y0, z0


@njit(cache=True, nogil=True)
def build_grid(q: NDArray, radius: float):
    """The points ``q`` ``(n, 2)`` in squares of side ``>= radius``, at most ``4 n + 16`` of them.

    Returns ``(origin_x, origin_y, side, nx, ny, start, order)``: point ``order[k]`` for
    ``start[c] <= k < start[c + 1]`` lies in cell ``c = cx ny + cy`` (:func:`bin_points`).
    """
    n = q.shape[0]
    cell_of = np.empty(n, dtype=np.int64)
    order = np.empty(n, dtype=np.int64)
    start = np.zeros(4 * n + 16 + 1, dtype=np.int64)
    nx, ny, _, side, x0, y0, _ = bin_points(q, radius, cell_of, order, start)
    return x0, y0, side, nx, ny, start[: nx * ny + 1], order


@njit(cache=True, nogil=True, inline="always")
def neighbours_of(i, q, r2, x0, y0, side, nx, ny, start, order, out) -> int:
    """Points ``j != i`` with ``|q_i - q_j|^2 <= r2`` into ``out``, ascending; their count."""
    cx = cell(q[i, 0], x0, side, nx)
    cy = cell(q[i, 1], y0, side, ny)
    deg = 0
    for gx in range(max(cx - 1, 0), min(cx + 2, nx)):
        for gy in range(max(cy - 1, 0), min(cy + 2, ny)):
            c = gx * ny + gy
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
