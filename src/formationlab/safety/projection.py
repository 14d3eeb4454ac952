"""One robot's decentralized barrier QP in the plane: rows built, then projected exactly.

The per-robot part of :mod:`.decentralized` (see its docstring for the mathematics):
:func:`filter_robot` builds robot ``r``'s rows (half responsibility per neighbour,
obstacle pieces, speed polygon) and solves ``min |u - u_hat|^2`` s.t. ``A u <= b`` by
enumeration (:func:`_project`: unchanged, one active row in closed form, two by a 2 x 2
solve), relaxing rows with ``h < 0`` when infeasible (:func:`solve_rows`);
:func:`unchanged_robot` tells, without building the rows, when ``u_hat`` already
satisfies them. Compiled (numba, ``nogil``); used by :mod:`.decentralized` and by the
compiled loop (:mod:`formationlab.safety.stage`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from .condition import barrier_bound
from .obstacle_terms import barrier_row, hull_distance

__all__ = ["TOL", "filter_robot", "solve_rows", "unchanged_robot"]

#: Relative tolerance of the feasibility and activity checks of a candidate.
TOL = 1e-10


@njit(cache=True, nogil=True)
def _row_tol(a0: float, a1: float, b: float, u_scale: float) -> float:
    return TOL * (abs(b) + (abs(a0) + abs(a1)) * u_scale)


@njit(cache=True, nogil=True)
def _feasible(u0: float, u1: float, A: NDArray, b: NDArray, m: int, scale: float) -> bool:
    for k in range(m):
        if A[k, 0] * u0 + A[k, 1] * u1 - b[k] > _row_tol(A[k, 0], A[k, 1], b[k], scale):
            return False
    return True


@njit(cache=True, nogil=True)
def _project(uh0: float, uh1: float, A: NDArray, b: NDArray, m: int, out: NDArray) -> int:
    """``argmin |u - u_hat|^2`` s.t. ``A[:m] u <= b[:m]`` in ``R^2`` into ``out``.

    Returns 0 (``u_hat`` feasible, copied unchanged), 1 (solved) or -1 (no feasible
    KKT point: the constraints are infeasible, up to the tolerance).
    """
    inside = True
    for k in range(m):
        if A[k, 0] * uh0 + A[k, 1] * uh1 > b[k]:
            inside = False
            break
    if inside:
        out[0] = uh0
        out[1] = uh1
        return 0
    base = abs(uh0) + abs(uh1)
    for k in range(m):  # one active constraint: closed form
        nn = A[k, 0] * A[k, 0] + A[k, 1] * A[k, 1]
        viol = A[k, 0] * uh0 + A[k, 1] * uh1 - b[k]
        if viol <= 0.0 or nn == 0.0:
            continue
        lam = viol / nn
        u0 = uh0 - lam * A[k, 0]
        u1 = uh1 - lam * A[k, 1]
        if _feasible(u0, u1, A, b, m, base + abs(u0) + abs(u1)):
            out[0] = u0
            out[1] = u1
            return 1
    for k in range(m):  # two active rows: k violated at u_hat, j violated at y_k (first)
        nn = A[k, 0] * A[k, 0] + A[k, 1] * A[k, 1]
        rk = A[k, 0] * uh0 + A[k, 1] * uh1 - b[k]
        if rk <= 0.0 or nn == 0.0:
            continue
        y0 = uh0 - rk / nn * A[k, 0]
        y1 = uh1 - rk / nn * A[k, 1]
        scale = base + abs(y0) + abs(y1)
        for j in range(m):
            if j == k or A[j, 0] * y0 + A[j, 1] * y1 - b[j] <= -_row_tol(A[j, 0], A[j, 1], b[j],
                                                                         scale):  # fmt: skip
                continue
            if _pair(uh0, uh1, A, b, m, k, j, base, out):
                return 1
    feasible = True  # (every bound >= 0: u = 0 is feasible, so an answer exists)
    for k in range(m):
        feasible = feasible and b[k] >= 0.0
    for k in range(m if feasible else 0):  # any two rows: only when rounding hid them above
        for j in range(k + 1, m):
            if _pair(uh0, uh1, A, b, m, k, j, base, out):
                return 1
    return -1


@njit(cache=True, nogil=True)
def _pair(uh0, uh1, A, b, m, k, j, base, out) -> bool:
    """The KKT point of rows ``k`` and ``j`` active into ``out``, if it is the answer.

    Multipliers from the 2 x 2 system ``G lambda = A u_hat - b`` of the two rows; the
    answer when both are ``>= 0`` and the point is feasible.
    """
    gkk = A[k, 0] * A[k, 0] + A[k, 1] * A[k, 1]
    rk = A[k, 0] * uh0 + A[k, 1] * uh1 - b[k]
    gjj = A[j, 0] * A[j, 0] + A[j, 1] * A[j, 1]
    gkj = A[k, 0] * A[j, 0] + A[k, 1] * A[j, 1]
    det = gkk * gjj - gkj * gkj
    if det <= 1e-12 * gkk * gjj:
        return False  # parallel rows: a single constraint covers them
    rj = A[j, 0] * uh0 + A[j, 1] * uh1 - b[j]
    lk = (gjj * rk - gkj * rj) / det
    lj = (gkk * rj - gkj * rk) / det
    floor = -1e-12 * (abs(lk) + abs(lj))
    if lk < floor or lj < floor:
        return False
    u0 = uh0 - lk * A[k, 0] - lj * A[j, 0]
    u1 = uh1 - lk * A[k, 1] - lj * A[j, 1]
    if _feasible(u0, u1, A, b, m, base + abs(u0) + abs(u1)):
        out[0] = u0
        out[1] = u1
        return True
    return False


@njit(cache=True, nogil=True)
def solve_rows(uh0: float, uh1: float, A: NDArray, b: NDArray, neg: NDArray, m: int,
               out: NDArray) -> int:  # fmt: skip
    """One robot's filtered command into ``out`` from its rows ``A[:m] u <= b[:m]``.

    The projection (:func:`_project`); if it finds no feasible point, the rows flagged
    ``neg`` (``h < 0``) are relaxed to bound 0 and it runs again. Returns the robot's
    code: 0 unchanged (``out = u_hat``), 1 solved, 2 relaxed, 4 failed (``out = 0``).
    ``b`` is changed in place by a relaxation.
    """
    code = _project(uh0, uh1, A, b, m, out)
    if code >= 0:
        return code
    for k in range(m):
        if neg[k]:
            b[k] = 0.0
    if _project(uh0, uh1, A, b, m, out) >= 0:
        return 2
    out[0] = 0.0
    out[1] = 0.0
    return 4


@njit(cache=True, nogil=True, inline="always")
def unchanged_robot(r, q, uh0, uh1, nbr, deg, obs, d2, gamma, step, speed_n, speed_b) -> bool:
    """Whether ``u_hat_r`` satisfies every row :func:`filter_robot` would build.

    The same arithmetic as :func:`filter_robot` and :func:`_project`'s first test, so
    ``True`` here is exactly the case where :func:`filter_robot` returns ``u_hat_r`` (code
    0), found without building the rows; a polygon is settled by its enclosing disc when
    that is far enough (``2 high |u_hat| < b(low^2 - D_o^2)``, ``b`` the rows' bound, which
    grows with ``h``), else by its rows.
    """
    x = q[r, 0]
    y = q[r, 1]
    for t in range(deg):
        j = nbr[t]
        dx = x - q[j, 0]
        dy = y - q[j, 1]
        h = dx * dx + dy * dy - d2
        if -2.0 * dx * uh0 + -2.0 * dy * uh1 > 0.5 * barrier_bound(h, gamma, step):
            return False
    unorm = math.sqrt(uh0 * uh0 + uh1 * uh1)
    for o in range(obs.radius.shape[0]):
        polygon = obs.radius[o] <= 0
        if polygon:
            low, high = hull_distance(obs, o, x, y)
            rho = obs.d_obstacle
            if low > rho and 2.0 * high * unorm < barrier_bound(low * low - rho * rho, gamma, step):
                continue
        pieces = obs.start[o + 1] - obs.start[o] if polygon else 1
        for k in range(pieces):
            a0, a1, bk, _ = barrier_row(obs, o, k, x, y)
            if a0 * uh0 + a1 * uh1 > bk:
                return False
    for s in range(speed_n.shape[0]):
        if speed_n[s, 0] * uh0 + speed_n[s, 1] * uh1 > speed_b:
            return False
    return True


@njit(cache=True, nogil=True)
def filter_robot(r, q, uh0, uh1, nbr, deg, obs, d2, gamma, step, speed_n, speed_b, A, b, neg,
                 owner, out) -> tuple[int, int]:  # fmt: skip
    """Robot ``r``'s filtered command into ``out``: its rows built, then :func:`solve_rows`.

    Rows in order: its ``deg`` neighbours ``nbr[:deg]`` (half responsibility, module
    docstring), the barrier pieces of every obstacle (``obs``, an
    :class:`~formationlab.safety.obstacle_terms.ObstacleTerms`), the speed polygon.
    A polygon whose enclosing disc is so far that no command of norm ``<= |u_hat_r|`` can
    violate its rows (``2 high |u_hat| < b(low^2 - D_o^2)``) is left out, and checked
    at the answer: if the answer is longer than that bound allows, the rows are built
    again in full and solved again. (The answer is the projection onto a set holding
    ``0`` when no bound is negative, so it is no longer than ``u_hat``.) ``owner[k]``: the
    obstacle of row ``k`` (-1 for other rows). Returns :func:`solve_rows`' code and the
    number of rows ``m`` (``A[:m]``, ``b[:m]``, as solved).
    """
    unorm = math.sqrt(uh0 * uh0 + uh1 * uh1)
    x = q[r, 0]
    y = q[r, 1]
    for attempt in range(2):
        m = 0
        for t in range(deg):
            j = nbr[t]
            dx = x - q[j, 0]
            dy = y - q[j, 1]
            h = dx * dx + dy * dy - d2
            A[m, 0] = -2.0 * dx
            A[m, 1] = -2.0 * dy
            b[m] = 0.5 * barrier_bound(h, gamma, step)  # half of the pair's bound
            neg[m] = h < 0.0
            owner[m] = -1
            m += 1
        limit = np.inf
        for o in range(obs.radius.shape[0]):
            polygon = obs.radius[o] <= 0
            if polygon and attempt == 0:
                low, high = hull_distance(obs, o, x, y)
                rho = obs.d_obstacle
                if low > rho:
                    floor = barrier_bound(low * low - rho * rho, gamma, step)
                    if 2.0 * high * unorm < floor:
                        limit = min(limit, floor / (2.0 * high))
                        continue
            pieces = obs.start[o + 1] - obs.start[o] if polygon else 1
            for k in range(pieces):
                a0, a1, bk, _ = barrier_row(obs, o, k, x, y)
                A[m, 0] = a0
                A[m, 1] = a1
                b[m] = bk
                neg[m] = bk < 0.0
                owner[m] = o
                m += 1
        for s in range(speed_n.shape[0]):
            A[m, 0] = speed_n[s, 0]
            A[m, 1] = speed_n[s, 1]
            b[m] = speed_b
            neg[m] = False
            owner[m] = -1
            m += 1
        code = solve_rows(uh0, uh1, A, b, neg, m, out)
        if math.sqrt(out[0] * out[0] + out[1] * out[1]) < limit:
            return code, m
    return code, m
