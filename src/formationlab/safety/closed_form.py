"""The centralized barrier QP in closed form when one or two rows are active.

The QP of :mod:`.barrier` is ``min 1/2 |x - x_hat|^2`` s.t. ``g_k . x <= b_k``, a
projection onto a polyhedron. With an active set ``A`` its KKT point is
``x = x_hat - G_A' lambda`` with ``(G_A G_A') lambda = G_A x_hat - b_A`` and ``lambda >= 0``;
it is the QP's solution when it is also feasible (KKT conditions of a strictly convex
QP are sufficient, and the solution is unique). This module tries the active sets of one
and two rows, exactly:

1. no row violated at ``x_hat``: ``x_hat`` itself (returned bit for bit);
2. for each violated row ``k``, the projection ``y_k = x_hat - (r_k / |g_k|^2) g_k`` onto
   its plane (``r_k = g_k . x_hat - b_k > 0``); feasible: the solution;
3. for each violated ``k`` and each row ``j`` that ``y_k`` violates, the 2 x 2 system;
   multipliers ``>= 0`` and feasible: the solution.

That search is complete for solutions with at most two active rows: at least one
active row is violated at ``x_hat`` (else ``x_hat`` would be feasible for the active
rows, hence optimal), and if ``{k, j}`` is the active set with ``k`` violated, ``y_k``
violates ``j`` (else ``y_k``, optimal under row ``k`` alone, would be feasible for both
and the solution, with ``lambda_j = 0``). When no candidate passes, more than two rows
are active (or the rows are infeasible) and the caller solves the QP.

Rows act on one or two robots: ``a . (u_i - u_j) <= b`` for a pair (``j >= 0``),
``a . u_i <= b`` for an obstacle piece or a side of the speed polygon (``j = -1``), so
``g_k . g_l`` is a sum over the robots two rows share. Rows: ``(M,)`` arrays ``ri``,
``rj``, ``rb`` and ``ra`` ``(M, d)``; commands ``(n, d)``, ``d`` = 2 in the plane and 3 in
space (the components in order, so the plane's sums are those of before, bit for bit).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["TOL", "closed_form"]

#: Relative tolerance of the feasibility checks (as the decentralized filter's).
TOL = 1e-10


@njit(cache=True, nogil=True, inline="always")
def _value(ri, rj, ra, k, u):
    """``g_k . x`` and the size ``|g_k| . |x|`` of its terms."""
    i = ri[k]
    j = rj[k]
    if j < 0:
        v = ra[k, 0] * u[i, 0]
        size = abs(ra[k, 0]) * abs(u[i, 0])
        for c in range(1, ra.shape[1]):
            v += ra[k, c] * u[i, c]
            size += abs(ra[k, c]) * abs(u[i, c])
        return v, size
    v = ra[k, 0] * (u[i, 0] - u[j, 0])
    size = abs(ra[k, 0]) * (abs(u[i, 0]) + abs(u[j, 0]))
    for c in range(1, ra.shape[1]):
        v += ra[k, c] * (u[i, c] - u[j, c])
        size += abs(ra[k, c]) * (abs(u[i, c]) + abs(u[j, c]))
    return v, size


@njit(cache=True, nogil=True, inline="always")
def _gram(ri, rj, ra, k, m):
    """``g_k . g_m``: the robots the two rows share (``+a`` on ``i``, ``-a`` on ``j``)."""
    dot = ra[k, 0] * ra[m, 0]
    for e in range(1, ra.shape[1]):
        dot += ra[k, e] * ra[m, e]
    c = 0.0
    if ri[k] == ri[m]:
        c += 1.0
    if rj[k] >= 0 and rj[k] == ri[m]:
        c -= 1.0
    if rj[m] >= 0 and ri[k] == rj[m]:
        c -= 1.0
    if rj[k] >= 0 and rj[k] == rj[m]:
        c += 1.0
    return c * dot


@njit(cache=True, nogil=True, inline="always")
def _shift(ri, rj, ra, k, lam, u):
    """``u -= lam g_k``."""
    i = ri[k]
    j = rj[k]
    for c in range(ra.shape[1]):
        u[i, c] -= lam * ra[k, c]
        if j >= 0:
            u[j, c] += lam * ra[k, c]


@njit(cache=True, nogil=True, inline="always")
def _copy(src, out):
    """``out[:] = src`` for commands ``(n, d)``."""
    for i in range(src.shape[0]):
        for c in range(src.shape[1]):
            out[i, c] = src[i, c]


@njit(cache=True, nogil=True)
def _feasible(ri, rj, ra, rb, u, uh) -> bool:
    for k in range(rb.shape[0]):
        v, size = _value(ri, rj, ra, k, u)
        size_h = _value(ri, rj, ra, k, uh)[1]
        if v - rb[k] > TOL * (abs(rb[k]) + size + size_h):
            return False
    return True


@njit(cache=True, nogil=True)
def closed_form(ri, rj, ra, rb, uh, out, lam):
    """The QP's solution into ``out`` ``(n, d)`` when at most two rows are active.

    Returns 0 (``u_hat`` feasible: ``out = u_hat`` bit for bit), 1 (solved; ``lam``
    ``(M,)`` holds the multipliers, non-zero on at most two rows) or -1 (no solution
    with one or two active rows: solve the QP; ``out`` and ``lam`` are then undefined).
    """
    m = rb.shape[0]
    _copy(uh, out)
    for k in range(m):
        lam[k] = 0.0
    resid = np.empty(m)
    any_violated = False
    for k in range(m):
        resid[k] = _value(ri, rj, ra, k, uh)[0] - rb[k]
        any_violated = any_violated or resid[k] > 0.0
    if not any_violated:
        return 0
    for k in range(m):  # one active row
        gkk = _gram(ri, rj, ra, k, k)
        if resid[k] <= 0.0 or gkk == 0.0:
            continue
        lk = resid[k] / gkk
        _shift(ri, rj, ra, k, lk, out)
        if _feasible(ri, rj, ra, rb, out, uh):
            lam[k] = lk
            return 1
        for j in range(m):  # two active rows: k and a row j that y_k violates
            if j == k:
                continue
            v, size = _value(ri, rj, ra, j, out)
            if v - rb[j] <= TOL * (abs(rb[j]) + size):
                continue
            gjj = _gram(ri, rj, ra, j, j)
            gkj = _gram(ri, rj, ra, k, j)
            det = gkk * gjj - gkj * gkj
            if det <= 1e-12 * gkk * gjj:
                continue  # parallel rows
            l1 = (gjj * resid[k] - gkj * resid[j]) / det
            l2 = (gkk * resid[j] - gkj * resid[k]) / det
            floor = -1e-12 * (abs(l1) + abs(l2))
            if l1 < floor or l2 < floor:
                continue
            trial = uh.copy()
            _shift(ri, rj, ra, k, l1, trial)
            _shift(ri, rj, ra, j, l2, trial)
            if _feasible(ri, rj, ra, rb, trial, uh):
                _copy(trial, out)
                lam[k] = max(l1, 0.0)
                lam[j] = max(l2, 0.0)
                return 1
        _copy(uh, out)  # back to u_hat for the next k
    return -1


def qp_rows(
    pairs: NDArray[np.int64],
    pair_a: NDArray[np.float64],
    pair_b: NDArray[np.float64],
    obs_a: NDArray[np.float64],
    obs_b: NDArray[np.float64],
    normals: NDArray[np.float64],
    vmax: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """``(ri, rj, ra, rb)`` of the centralized QP's rows, in :func:`barrier_constraints`' order.

    Pair rows ``(m, 2)``, ``(m, 2)``, ``(m,)``; obstacle rows ``(n, K, 2)``, ``(n, K)``
    (robot-major); speed rows: the polygon's ``(S, 2)`` normals and bound, robot-major.
    """
    n, k = obs_b.shape
    s = len(normals)
    robots = np.arange(n, dtype=np.int64)
    ri = np.concatenate([pairs[:, 0], np.repeat(robots, k), np.repeat(robots, s)])
    rj = np.concatenate([pairs[:, 1], np.full(n * (k + s), -1, np.int64)])
    ra = np.concatenate([pair_a, obs_a.reshape(-1, 2), np.tile(normals, (n, 1))])
    rb = np.concatenate([pair_b, obs_b.ravel(), np.full(n * s, vmax)])
    return (
        np.ascontiguousarray(ri, dtype=np.int64), np.ascontiguousarray(rj, dtype=np.int64),
        np.ascontiguousarray(ra, dtype=float).reshape(-1, 2), np.ascontiguousarray(rb, float),
    )  # fmt: skip
