"""Close-pair (Verlet) lists on a cell grid, compiled: who can touch or repel whom.

Khatib's repulsion acts only between robots closer than ``a_ij + s0`` and contact
only at ``r_ij <= a_ij``, so a run of many robots needs, at each step, only the
pairs whose clearance ``r_ij - a_ij`` is below some ``c``. :func:`build_close_list`
finds exactly the pairs with clearance below ``reach`` (robots binned into cells at least
``max a_ij + reach`` wide by :mod:`.cell_grid`, squares in the plane and cubes in space,
each robot looking at the 3 x 3 or 3 x 3 x 3 cells around its own), leaving out excluded
partners (a formation's neighbours, whose edge potential has its own barrier). A list
built with ``reach = c + skin`` still holds every pair of clearance below ``c`` while no
robot has moved more than ``skin / 2`` since the build (a pair's clearance changes by at
most the sum of its robots' moves), so it is rebuilt only then (:func:`list_holds`).

The pairs come out sorted, ``i < j``, and each robot's row of the list (the
pairs it belongs to, as signed pair numbers: ``p`` where it is ``i``, ``~p``
where it is ``j``) is sorted by partner: the same list, and the same order of
every sum over it, whenever and from whatever state it was built.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from .cell_grid import bin_points, cell

__all__ = ["CloseList", "build_close_list", "close_list", "grown", "list_holds", "pair_rows"]

#: relative slack of the list's guarantee against rounding of the clearances
_SLACK = 1e-9


@njit(cache=True)
def build_close_list(q, radius, reach, ex_ptr, ex_nbr, pairs, cell_of, items, start, stamp, cand):
    """Pairs ``i < j``, not excluded, with ``r_ij - radius_i - radius_j < reach``.

    Parameters
    ----------
    q : (n, d) positions (finite), d = 2 or 3 (squares or cubes of the cell grid);
        radius : (n,) half diameters; reach : clearance bound.
    ex_ptr, ex_nbr : CSR rows of the excluded partners of each robot (int32).
    pairs : (cap, 2) int32 buffer, filled with the first ``min(count, cap)`` pairs.
    cell_of, items, stamp, cand : (n,) int32 scratch; start : (cells + 1,) int32 scratch.

    Returns
    -------
    count : int, the number of pairs, sorted lexicographically in ``pairs``. Nothing is
    allocated here: when ``count > cap`` the list is incomplete, and the caller builds it
    again into a buffer of at least ``count`` rows (:func:`grown`).
    """
    n = q.shape[0]
    top = 0.0
    for i in range(n):
        top = max(top, radius[i])
    side = (2.0 * top + reach) * (1.0 + _SLACK) + 1e-300
    nx, ny, nz, side, x0, y0, z0 = bin_points(q, side, cell_of, items, start)
    space = q.shape[1] == 3
    stamp[:] = -1
    count = 0
    for i in range(n):
        for p in range(ex_ptr[i], ex_ptr[i + 1]):
            stamp[ex_nbr[p]] = i
        cx = cell(q[i, 0], x0, side, nx)
        cy = cell(q[i, 1], y0, side, ny)
        cz = cell(q[i, 2], z0, side, nz) if nz > 1 else 0
        m = 0
        for gx in range(max(cx - 1, 0), min(cx + 2, nx)):
            for gy in range(max(cy - 1, 0), min(cy + 2, ny)):
                for gz in range(max(cz - 1, 0), min(cz + 2, nz)):  # (nz = 1: the plane)
                    c = (gx * ny + gy) * nz + gz
                    for pos in range(start[c], start[c + 1]):
                        j = items[pos]
                        if j <= i or stamp[j] == i:
                            continue
                        dx = q[j, 0] - q[i, 0]
                        dy = q[j, 1] - q[i, 1]
                        r2 = dx * dx + dy * dy
                        if space:
                            dz = q[j, 2] - q[i, 2]
                            r2 += dz * dz
                        if math.sqrt(r2) - (radius[i] + radius[j]) < reach:
                            cand[m] = j
                            m += 1
        for a in range(1, m):  # insertion sort: rows are short
            v = cand[a]
            b = a - 1
            while b >= 0 and cand[b] > v:
                cand[b + 1] = cand[b]
                b -= 1
            cand[b + 1] = v
        for a in range(m):
            if count < pairs.shape[0]:
                pairs[count, 0] = i
                pairs[count, 1] = cand[a]
            count += 1
    return count


def grown(a: NDArray, rows: int) -> NDArray:
    """``a`` with room for at least ``rows`` rows (doubling), its rows kept."""
    if a.shape[0] >= rows:
        return a
    b = np.zeros((max(rows, 2 * a.shape[0], 16), *a.shape[1:]), a.dtype)
    b[: a.shape[0]] = a
    return b


@njit(cache=True)
def pair_rows(pairs, count, n, ptr, rows):
    """Each robot's row of the list: signed pair numbers sorted by partner.

    ``ptr`` ``(n + 1,)`` int32 and ``rows``, a buffer of at least ``2 count`` int32, are
    filled. Pair
    ``p = (i, j)`` is ``p`` in row ``i`` and ``~p`` in row ``j``. The pairs being
    sorted, robot ``i`` meets its partners ``j < i`` (as the second robot) in
    increasing order before its partners ``j > i`` (as the first).
    """
    ptr[:] = 0
    for p in range(count):
        ptr[pairs[p, 0] + 1] += 1
        ptr[pairs[p, 1] + 1] += 1
    for i in range(n):
        ptr[i + 1] += ptr[i]
    fill = ptr[:n].copy()
    for p in range(count):
        j = pairs[p, 1]
        rows[fill[j]] = ~p
        fill[j] += 1
    for p in range(count):
        i = pairs[p, 0]
        rows[fill[i]] = p
        fill[i] += 1


@njit(cache=True)
def list_holds(drift, reach, need):
    """Whether a list built with ``reach`` still holds every pair of clearance below ``need``
    (the closest is at most ``need``) when no robot has moved more than ``drift`` since."""
    return 2.0 * drift + _SLACK * (1.0 + reach) < reach - need


class CloseList:
    """A close-pair list of ``n`` robots with its scratch space (allocated once)."""

    def __init__(self, n: int, capacity: int = 16) -> None:
        self.pairs = np.empty((max(capacity, 16), 2), np.int32)
        self.count = 0
        self.ptr = np.zeros(n + 1, np.int32)
        self.rows = np.empty(2 * max(capacity, 16), np.int32)
        self.cell_of = np.empty(n, np.int32)
        self.items = np.empty(n, np.int32)
        self.start = np.empty(4 * n + 17, np.int32)  # at most 4 n + 16 cells
        self.stamp = np.empty(n, np.int32)
        self.cand = np.empty(n, np.int32)

    def build(
        self,
        q: NDArray[np.float64],
        radius: NDArray[np.float64],
        reach: float,
        ex_ptr: NDArray[np.int32],
        ex_nbr: NDArray[np.int32],
    ) -> None:
        """Fill the list from positions ``q`` ``(n, d)`` (:func:`build_close_list`)."""
        n = q.shape[0]
        while True:
            self.count = build_close_list(
                q, radius, reach, ex_ptr, ex_nbr, self.pairs, self.cell_of, self.items,
                self.start, self.stamp, self.cand,
            )  # fmt: skip
            if self.count <= self.pairs.shape[0]:
                break
            self.pairs = grown(self.pairs, self.count)
        self.rows = grown(self.rows, 2 * self.count)
        pair_rows(self.pairs, self.count, n, self.ptr, self.rows)


def close_list(
    q: NDArray[np.float64],
    radius: NDArray[np.float64] | float,
    reach: float,
    exclude: NDArray[np.int64] | None = None,
) -> tuple[NDArray[np.int64], NDArray[np.int32], NDArray[np.int32]]:
    """The pairs ``i < j`` of ``q`` ``(n, d)`` (``d`` 2 or 3) with clearance
    ``r_ij - rho_i/2 - rho_j/2 < reach``, not in ``exclude`` ``(m, 2)``: ``(p, 2)`` sorted,
    and each robot's row (``ptr`` ``(n + 1,)``, ``rows``: signed pair numbers sorted by
    partner)."""
    q = np.ascontiguousarray(q, dtype=float)
    n = q.shape[0]
    rad = np.broadcast_to(np.asarray(radius, dtype=float), (n,)).copy()
    e = np.zeros((0, 2), np.int64) if exclude is None else np.asarray(exclude, np.int64)
    e = e.reshape(-1, 2)
    ends = np.concatenate([e[:, 0], e[:, 1]])
    order = np.argsort(ends, kind="stable")
    ex_ptr = np.concatenate([[0], np.cumsum(np.bincount(ends, minlength=n))]).astype(np.int32)
    ex_nbr = np.concatenate([e[:, 1], e[:, 0]])[order].astype(np.int32)
    cl = CloseList(n)
    cl.build(q, rad, float(reach), ex_ptr, ex_nbr)
    return cl.pairs[: cl.count].astype(np.int64), cl.ptr, cl.rows[: 2 * cl.count]
