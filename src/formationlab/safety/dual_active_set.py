"""The centralized barrier QP solved exactly in numba for any number of active rows.

The QP of :mod:`.barrier`, ``min 1/2 |x - x_hat|^2`` s.t. ``g_k . x <= b_k``
(``x = (u_1x, u_1y, u_2x, ...)``, ``d = 2 n`` unknowns in the plane and ``3 n`` in space,
rows as in :mod:`.closed_form`:
``a . (u_i - u_j) <= b`` for a pair, ``a . u_i <= b`` for an obstacle piece or a side of
the speed polygon), by the dual active-set method of Goldfarb and Idnani, "A
numerically stable dual method for solving strictly convex quadratic programs",
Mathematical Programming 27:1-33, 1983. With the identity Hessian its factor ``L`` is
the identity, so ``J = Q`` of the QR factorisation ``N = Q [R; 0]`` of the active rows
``N = [g_a1 ... g_aq]`` (``d x q``), updated by Givens rotations when a row enters or
leaves (their section 4, as in ``quadprog``'s ``qpgen2`` and ``eiquadprog``).

The method starts at the unconstrained optimum ``x = x_hat`` with no active row and,
while some row is violated, takes the most violated one ``p`` (largest
``(g_p . x - b_p) / |g_p|``) and steps along (eqs. 4.1-4.4 of the paper, with our sign
of the rows)

* ``z = J_2 J_2' g_p`` (the part of ``g_p`` off the active rows), ``r = R^{-1} J_1' g_p``
  (``N^+ g_p``);
* primal step ``x <- x - t z``, multipliers ``lambda_A <- lambda_A - t r``,
  ``lambda_p <- lambda_p + t``, so that ``x = x_hat - sum lambda_k g_k`` and the active rows
  keep holding with equality; ``t = min(t1, t2)``: ``t2 = (g_p . x - b_p) / (g_p . z)``
  makes row ``p`` hold (full step: ``p`` joins the active set), ``t1 = min lambda_j / r_j``
  over ``r_j > 0`` is where an active multiplier reaches 0 (partial step: that row
  leaves, and the step is taken again with the same ``p``);
* ``z = 0`` (``g_p`` depends on the active rows): a step in the multipliers alone
  (``t = t1``); ``z = 0`` and no ``r_j > 0``: the rows are infeasible (their Theorem 2:
  ``g_p = N r`` with ``r <= 0`` is Farkas' certificate).

Every iteration keeps the multipliers of the active rows ``>= 0`` and the dual objective
does not decrease (it increases on every step of positive length), so the method ends
after finitely many steps (their Theorem 3). Rounding is guarded by a relative
tolerance on violation (that of :mod:`.closed_form`, ``TOL``), a test of ``|z|``
relative to ``|g_p|`` for linear dependence, and an iteration limit (``-2``: a
numerical failure the caller hands to Clarabel). The answer is written as
``x_hat - sum lambda_k g_k`` on the active rows, so robots on no active row keep
``x_hat`` bit for bit. Nothing is allocated: the work arrays come from :func:`workspace`.

:func:`centralized_command` wraps it with the semantics of
:func:`~formationlab.safety.barrier_filter` for one trial: ``x_hat`` when feasible, the
closed form of one or two active rows (:func:`.closed_form.closed_form`, which is
cheaper), else this method; infeasible rows (only when some ``h < 0``) are relaxed to
bound 0 on the rows with ``h < 0`` and solved again (``RELAXED``); still infeasible, the
caller applies the decentralized filter (``FALLBACK``).

Why this and not Clarabel in the batch: Clarabel (an interior-point method, the solver
of the single-run filter and the tests' reference) costs a Python call and some hundred
microseconds per QP, which the batch paid between kernel calls at every step with three
or more active rows; this method solves the same QP in the kernel in a few microseconds
(``d = 20`` unknowns and about 65 rows for ten robots), exactly (it ends at a vertex of the
active set, KKT to rounding), and it does not fail on the badly scaled QPs that
Khatib's repulsion and far pairs (``gamma h^3`` up to 1e7) produce, on which Clarabel
gives up and ``barrier_filter`` falls back to the decentralized command.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from .closed_form import TOL, _copy, _feasible, _shift, _value, closed_form

__all__ = [
    "FALLBACK",
    "NUMERICAL",
    "centralized_command",
    "dual_active_set",
    "workspace",
]

#: ``|z|^2 <= DEPENDENT |g_p|^2``: ``g_p`` lies in the span of the active rows (angle
#: below 1e-10 rad; rounding leaves ``|z| / |g_p|`` near 1e-16 for a dependent row).
DEPENDENT = 1e-20
#: Codes of :func:`centralized_command` beyond :class:`~.result.FilterStatus` 0-2: the
#: relaxed rows are infeasible too (apply the decentralized filter), or the method failed
#: numerically (solve with Clarabel).
FALLBACK = 3
NUMERICAL = -2


def workspace(
    n: int, m: int, dim: int = 2
) -> tuple[
    NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64],
    NDArray[np.float64],
]:  # fmt: skip
    """Work arrays of :func:`dual_active_set` for ``n`` robots in ``dim`` dimensions (and
    ``m`` rows).

    ``(mats (2, d, d), vecs (5, d), lam (m,), act (d,), rb2 (m,))``, ``d = dim n``.
    """
    d = dim * n
    return (
        np.zeros((2, d, d)), np.zeros((5, d)), np.zeros(m), np.zeros(d, np.int64), np.zeros(m),
    )  # fmt: skip


@njit(cache=True, nogil=True, inline="always")
def _dot_x(ra, k, x, at):
    """``a_k . x[at : at + dim]`` and ``|a_k| . |x[at : at + dim]|``."""
    v = ra[k, 0] * x[at]
    size = abs(ra[k, 0]) * abs(x[at])
    for c in range(1, ra.shape[1]):
        v += ra[k, c] * x[at + c]
        size += abs(ra[k, c]) * abs(x[at + c])
    return v, size


@njit(cache=True, nogil=True, inline="always")
def _row_x(ri, rj, ra, k, x):
    """``g_k . x`` and ``|g_k| . |x|`` for the stacked ``x`` ``(d,)``."""
    dim = ra.shape[1]
    v, size = _dot_x(ra, k, x, dim * ri[k])
    if rj[k] >= 0:
        w, wsize = _dot_x(ra, k, x, dim * rj[k])
        v -= w
        size += wsize
    return v, size


@njit(cache=True, nogil=True, inline="always")
def _norm2(rj, ra, k):
    """``|g_k|^2``."""
    s = ra[k, 0] * ra[k, 0]
    for c in range(1, ra.shape[1]):
        s += ra[k, c] * ra[k, c]
    return 2.0 * s if rj[k] >= 0 else s


@njit(cache=True, nogil=True, inline="always")
def _jt_row(ri, rj, ra, k, J, dv):
    """``dv = J' g_k`` (``g_k`` has two or four non-zeros)."""
    d = J.shape[0]
    dim = ra.shape[1]
    i = dim * ri[k]
    for c in range(d):
        s = ra[k, 0] * J[i, c]
        for e in range(1, dim):
            s += ra[k, e] * J[i + e, c]
        dv[c] = s
    if rj[k] >= 0:
        j = dim * rj[k]
        for c in range(d):
            s = ra[k, 0] * J[j, c]
            for e in range(1, dim):
                s += ra[k, e] * J[j + e, c]
            dv[c] -= s


@njit(cache=True, nogil=True, inline="always")
def _add(J, R, dv, q) -> float:
    """Row with ``dv = J' g_p`` joins as column ``q`` of ``R``; returns ``|R[q, q]|``.

    Givens rotations zero ``dv[q+1:]`` and are applied to the columns of ``J``
    (Goldfarb and Idnani, section 4; the update of ``eiquadprog``'s ``add_constraint``).
    """
    d = J.shape[0]
    for j in range(d - 1, q, -1):
        cc = dv[j - 1]
        ss = dv[j]
        h = math.hypot(cc, ss)
        if h == 0.0:
            continue
        dv[j] = 0.0
        ss /= h
        cc /= h
        if cc < 0.0:
            cc = -cc
            ss = -ss
            dv[j - 1] = -h
        else:
            dv[j - 1] = h
        xny = ss / (1.0 + cc)
        for k in range(d):
            t1 = J[k, j - 1]
            t2 = J[k, j]
            J[k, j - 1] = t1 * cc + t2 * ss
            J[k, j] = xny * (t1 + J[k, j - 1]) - t2
    for i in range(q + 1):
        R[i, q] = dv[i]
    return abs(dv[q])


@njit(cache=True, nogil=True, inline="always")
def _drop(J, R, u, act, q, ell) -> None:
    """Active row at position ``ell`` leaves (``q`` rows before); ``R`` made triangular again."""
    d = J.shape[0]
    for i in range(ell, q - 1):
        act[i] = act[i + 1]
        u[i] = u[i + 1]
        for r in range(d):
            R[r, i] = R[r, i + 1]
    for r in range(d):
        R[r, q - 1] = 0.0
    q -= 1
    for j in range(ell, q):
        cc = R[j, j]
        ss = R[j + 1, j]
        h = math.hypot(cc, ss)
        if h == 0.0:
            continue
        cc /= h
        ss /= h
        R[j + 1, j] = 0.0
        if cc < 0.0:
            R[j, j] = -h
            cc = -cc
            ss = -ss
        else:
            R[j, j] = h
        xny = ss / (1.0 + cc)
        for k in range(j + 1, q):
            t1 = R[j, k]
            t2 = R[j + 1, k]
            R[j, k] = t1 * cc + t2 * ss
            R[j + 1, k] = xny * (t1 + R[j, k]) - t2
        for k in range(d):
            t1 = J[k, j]
            t2 = J[k, j + 1]
            J[k, j] = t1 * cc + t2 * ss
            J[k, j + 1] = xny * (J[k, j] + t1) - t2


@njit(cache=True, nogil=True)
def dual_active_set(ri, rj, ra, rb, uh, out, lam, mats, vecs, act) -> int:
    """The QP's solution into ``out`` ``(n, dim)`` and its multipliers into ``lam`` ``(M,)``.

    Rows ``ri``, ``rj``, ``ra`` ``(M, dim)``, ``rb`` as in :func:`.closed_form.closed_form`;
    ``uh`` ``(n, dim)``; work arrays from :func:`workspace` (``mats``, ``vecs``, ``act``).
    Returns 0 (``uh`` feasible: ``out = uh`` bit for bit), 1 (solved), -1 (the rows are
    infeasible; ``out`` undefined) or -2 (iteration limit or a failed final check, from
    rounding: ``out`` undefined).
    """
    m = rb.shape[0]
    n = uh.shape[0]
    dim = uh.shape[1]
    d = dim * n
    J = mats[0]
    R = mats[1]
    x = vecs[0]
    z = vecs[1]
    dv = vecs[2]
    rv = vecs[3]
    u = vecs[4]
    for i in range(d):
        for c in range(d):
            J[i, c] = 0.0
            R[i, c] = 0.0
        J[i, i] = 1.0
    for i in range(n):
        for c in range(dim):
            x[dim * i + c] = uh[i, c]
    for k in range(m):
        lam[k] = 0.0
    q = 0
    it = 0
    limit = 10 * (m + d) + 10
    while True:  # step 1: the most violated row (distance to its plane)
        p = -1
        worst = 0.0
        for k in range(m):
            v, size = _row_x(ri, rj, ra, k, x)
            s = v - rb[k]
            if s > TOL * (abs(rb[k]) + size + _value(ri, rj, ra, k, uh)[1]):  # (_feasible's)
                score = s / math.sqrt(_norm2(rj, ra, k))
                if score > worst:
                    worst = score
                    p = k
        if p < 0:
            break
        for i in range(q):
            if act[i] == p:
                return -2  # an active row violated: rounding
        lp = 0.0
        while True:  # step 2: steps towards row p
            it += 1
            if it > limit:
                return -2
            _jt_row(ri, rj, ra, p, J, dv)
            zz = 0.0
            for i in range(d):
                s = 0.0
                for c in range(q, d):
                    s += J[i, c] * dv[c]
                z[i] = s
                zz += s * s
            for i in range(q - 1, -1, -1):  # r = R^{-1} J_1' g_p
                s = dv[i]
                for c in range(i + 1, q):
                    s -= R[i, c] * rv[c]
                rv[i] = s / R[i, i]
            t1 = np.inf
            ell = -1
            for i in range(q):
                if rv[i] > 0.0 and u[i] / rv[i] < t1:
                    t1 = u[i] / rv[i]
                    ell = i
            t2 = np.inf
            if zz > DEPENDENT * _norm2(rj, ra, p):
                gz = _row_x(ri, rj, ra, p, z)[0]
                t2 = max(_row_x(ri, rj, ra, p, x)[0] - rb[p], 0.0) / gz
            if t1 == np.inf and t2 == np.inf:
                return -1  # g_p = N r with r <= 0: infeasible
            t = min(t1, t2)
            if t2 < np.inf:
                for i in range(d):
                    x[i] -= t * z[i]
            for i in range(q):
                u[i] -= t * rv[i]
            lp += t
            if t2 <= t1:  # full step: p joins
                if _add(J, R, dv, q) <= 1e-14 * math.sqrt(_norm2(rj, ra, p)):
                    return -2
                act[q] = p
                u[q] = lp
                q += 1
                break
            u[ell] = 0.0
            _drop(J, R, u, act, q, ell)
            q -= 1
    _copy(uh, out)  # x_hat - sum lambda_k g_k: robots on no active row keep x_hat
    if q == 0:
        return 0
    for a in range(q):
        k = act[a]
        lk = max(u[a], 0.0)
        lam[k] = lk
        _shift(ri, rj, ra, k, lk, out)
    if not _feasible(ri, rj, ra, rb, out, uh):
        return -2
    return 1


@njit(cache=True, nogil=True)
def centralized_command(ri, rj, ra, rb, rh, uh, out, lam, mats, vecs, act, rb2) -> int:
    """One trial's centralized command into ``out``, as :func:`~.barrier.barrier_filter`.

    Rows as in :func:`dual_active_set`, ``rh`` ``(M,)`` their barriers ``h`` (``inf`` for
    speed rows); ``rb2`` ``(M,)`` work. Returns the status: 0 ``UNCHANGED``, 1 ``SOLVED``,
    2 ``RELAXED`` (rows with ``h < 0`` relaxed to bound ``max(b, 0)``), :data:`FALLBACK`
    (the relaxed rows are infeasible too, or none has ``h < 0``: the caller applies the
    decentralized filter) or :data:`NUMERICAL` (rounding defeated the method: the caller
    solves the QP with Clarabel). ``out`` is undefined for the last two.
    """
    code = closed_form(ri, rj, ra, rb, uh, out, lam)  # x_hat, or one or two active rows
    if code >= 0:
        return code
    code = dual_active_set(ri, rj, ra, rb, uh, out, lam, mats, vecs, act)
    if code >= 0:
        return code
    if code == NUMERICAL:
        return NUMERICAL
    relaxed = 0
    for k in range(rb.shape[0]):  # barrier_filter's relaxation: h_dot >= 0 where h < 0
        rb2[k] = max(rb[k], 0.0) if rh[k] < 0.0 else rb[k]
        if rb2[k] != rb[k]:
            relaxed += 1
    if relaxed == 0:
        return FALLBACK
    code = dual_active_set(ri, rj, ra, rb2, uh, out, lam, mats, vecs, act)
    if code >= 0:
        return 2
    return FALLBACK if code == -1 else NUMERICAL
