"""The decentralized barrier certificate: every robot filters its own command.

Wang, Ames and Egerstedt ("Safety barrier certificates for collisions-free
multirobot systems", IEEE T-RO 33(3), 2017, section IV-B) split each pair's
condition ``2 (q_i - q_j) . (u_i - u_j) >= -gamma h_ij^3`` into two halves, one per
robot: robot ``i`` requires

    ``-2 (q_i - q_j) . u_i <= gamma h_ij^3 / 2``                           (half responsibility)

and robot ``j`` the mirror condition; their sum is the pair's condition, so the
decentralized command is feasible for the centralized QP. Obstacle rows (the
robot alone is responsible) and the speed polygon are added. Each robot then
projects its command ``u_hat_i`` onto its polygon of admissible velocities in the
plane: ``min |u_i - u_hat_i|^2`` subject to ``A u_i <= b``.

That small QP is solved exactly by enumeration. In ``R^2`` a strictly convex QP has
an optimal multiplier vector with at most two non-zero entries (Caratheodory), and
the unique point that satisfies the KKT conditions is the optimum, so: return
``u_hat_i`` unchanged if it is feasible; else the projection onto the line of one
violated constraint if it is feasible (closed form, multiplier
``(a . u_hat - b) / |a|^2 > 0``); else the first point on two lines whose two
multipliers (a 2 x 2 solve) are non-negative and which is feasible. That is
``O(m^2)`` candidates of ``O(m)`` checks for ``m`` constraints, a few dozen flops per
robot for the usual handful of neighbours, and it runs batched over trials and
robots in one serial numba loop (``nogil``, so callers may run chunks in threads;
a ``prange`` launch cost more than the whole loop below a few thousand robots when
benchmarked). If no candidate exists, the constraints are infeasible (only
possible when some ``h < 0``); those rows are relaxed to ``h_dot >= 0`` (bound 0, which
the zero command satisfies) and the projection is solved again (status
``RELAXED``). :func:`decentralized_reference` solves the same per-robot QPs with
Clarabel, for the tests.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np
import qpsolvers
import scipy.sparse as sp
from numba import njit
from numpy.typing import NDArray

from .config import SafetyFilter
from .obstacle_terms import barrier_row, hull_distance
from .obstacles import Obstacle, obstacle_barrier_rows
from .pairs import neighbour_lists, sensed_pairs
from .result import FilterResult, summarise

__all__ = ["decentralized_filter", "decentralized_reference", "project_onto_halfplanes"]

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
    for k in range(m):  # two active constraints: a 2 x 2 solve for the multipliers
        gkk = A[k, 0] * A[k, 0] + A[k, 1] * A[k, 1]
        rk = A[k, 0] * uh0 + A[k, 1] * uh1 - b[k]
        for j in range(k + 1, m):
            gjj = A[j, 0] * A[j, 0] + A[j, 1] * A[j, 1]
            gkj = A[k, 0] * A[j, 0] + A[k, 1] * A[j, 1]
            det = gkk * gjj - gkj * gkj
            if det <= 1e-12 * gkk * gjj:
                continue  # parallel rows: a single constraint covers them
            rj = A[j, 0] * uh0 + A[j, 1] * uh1 - b[j]
            lk = (gjj * rk - gkj * rj) / det
            lj = (gkk * rj - gkj * rk) / det
            floor = -1e-12 * (abs(lk) + abs(lj))
            if lk < floor or lj < floor:
                continue
            u0 = uh0 - lk * A[k, 0] - lj * A[j, 0]
            u1 = uh1 - lk * A[k, 1] - lj * A[j, 1]
            if _feasible(u0, u1, A, b, m, base + abs(u0) + abs(u1)):
                out[0] = u0
                out[1] = u1
                return 1
    return -1


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
def unchanged_robot(r, q, uh0, uh1, nbr, deg, obs, d2, gamma, speed_n, speed_b) -> bool:
    """Whether ``u_hat_r`` satisfies every row :func:`filter_robot` would build.

    The same arithmetic as :func:`filter_robot` and :func:`_project`'s first test, so
    ``True`` here is exactly the case where :func:`filter_robot` returns ``u_hat_r`` (code
    0), found without building the rows; a polygon is settled by its enclosing disc when
    that is far enough (``2 high |u_hat| < gamma (low^2 - D_o^2)^3``), else by its rows.
    """
    x = q[r, 0]
    y = q[r, 1]
    for t in range(deg):
        j = nbr[t]
        dx = x - q[j, 0]
        dy = y - q[j, 1]
        h = dx * dx + dy * dy - d2
        if -2.0 * dx * uh0 + -2.0 * dy * uh1 > 0.5 * gamma * h * h * h:
            return False
    unorm = math.sqrt(uh0 * uh0 + uh1 * uh1)
    for o in range(obs.radius.shape[0]):
        polygon = obs.radius[o] <= 0
        if polygon:
            low, high = hull_distance(obs, o, x, y)
            rho = obs.d_obstacle
            if low > rho and 2.0 * high * unorm < gamma * (low * low - rho * rho) ** 3:
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
def filter_robot(r, q, uh0, uh1, nbr, deg, obs, d2, gamma, speed_n, speed_b, A, b, neg, owner,
                 out) -> tuple[int, int]:  # fmt: skip
    """Robot ``r``'s filtered command into ``out``: its rows built, then :func:`solve_rows`.

    Rows in order: its ``deg`` neighbours ``nbr[:deg]`` (half responsibility, module
    docstring), the barrier pieces of every obstacle (``obs``, an
    :class:`~formationlab.safety.obstacle_terms.ObstacleTerms`), the speed polygon.
    A polygon whose enclosing disc is so far that no command of norm ``<= |u_hat_r|`` can
    violate its rows (``2 high |u_hat| < gamma (low^2 - D_o^2)^3``) is left out, and checked
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
            b[m] = 0.5 * gamma * h * h * h  # half of the pair's -gamma h^3
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
                    floor = gamma * (low * low - rho * rho) ** 3
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


@njit(cache=True, nogil=True)
def _kernel(
    q: NDArray,
    uh: NDArray,
    ptr: NDArray,
    nbr: NDArray,
    obs_a: NDArray,
    obs_b: NDArray,
    speed_n: NDArray,
    speed_b: float,
    d2: float,
    gamma: float,
    out_u: NDArray,
    out_code: NDArray,
    out_nbr_active: NDArray,
    out_obs_active: NDArray,
) -> None:
    n_rob = q.shape[0]
    n_obs = obs_b.shape[1]
    n_spd = speed_n.shape[0]
    for r in range(n_rob):
        start = ptr[r]
        deg = ptr[r + 1] - start
        m = deg + n_obs + n_spd
        A = np.empty((m, 2))
        b = np.empty(m)
        neg = np.zeros(m, dtype=np.bool_)
        for t in range(deg):
            j = nbr[start + t]
            dx = q[r, 0] - q[j, 0]
            dy = q[r, 1] - q[j, 1]
            h = dx * dx + dy * dy - d2
            A[t, 0] = -2.0 * dx
            A[t, 1] = -2.0 * dy
            b[t] = 0.5 * gamma * h * h * h  # half of the pair's -gamma h^3
            neg[t] = h < 0.0
        for k in range(n_obs):
            A[deg + k, 0] = obs_a[r, k, 0]
            A[deg + k, 1] = obs_a[r, k, 1]
            b[deg + k] = obs_b[r, k]
            neg[deg + k] = obs_b[r, k] < 0.0
        for s in range(n_spd):
            A[deg + n_obs + s, 0] = speed_n[s, 0]
            A[deg + n_obs + s, 1] = speed_n[s, 1]
            b[deg + n_obs + s] = speed_b
        u = np.empty(2)
        code = solve_rows(uh[r, 0], uh[r, 1], A, b, neg, m, u)
        out_u[r, 0] = u[0]
        out_u[r, 1] = u[1]
        out_code[r] = code
        if code == 0:
            continue
        scale = abs(u[0]) + abs(u[1]) + abs(uh[r, 0]) + abs(uh[r, 1])
        for k in range(m):
            slack = b[k] - A[k, 0] * u[0] - A[k, 1] * u[1]
            on = slack <= 1e3 * _row_tol(A[k, 0], A[k, 1], b[k], scale)
            if k < deg:
                out_nbr_active[start + k] = on
            elif k < deg + n_obs:
                out_obs_active[r, k - deg] = on


def decentralized_filter(
    config: SafetyFilter,
    q: NDArray[np.float64],
    u_hat: NDArray[np.float64],
    obstacles: Sequence[Obstacle] = (),
) -> FilterResult:
    """The decentralized barrier certificate (module docstring), batched over trials and robots.

    Parameters
    ----------
    config : SafetyFilter
        ``distance``, ``gamma``, ``max_speed``, ``sensing_radius``, ``obstacle_distance``.
    q, u_hat : ndarray, shape (..., n, 2)
        Positions and commands.
    obstacles : sequence of Circle or Polygon

    Returns
    -------
    FilterResult
        ``u`` of shape ``(..., n, 2)``; a robot whose constraints ``u_hat_i`` satisfies gets
        ``u_hat_i`` bit for bit. The status of a trial is the worst over its robots.
    """
    q = np.asarray(q, dtype=float)
    u_hat = np.asarray(u_hat, dtype=float)
    batch, n = q.shape[:-2], q.shape[-2]
    flat_q = np.ascontiguousarray(q.reshape(-1, 2))
    flat_u = np.ascontiguousarray(u_hat.reshape(-1, 2))
    trials = flat_q.shape[0] // n
    pairs = sensed_pairs(q, config.sensing_radius)
    ptr, nbr = neighbour_lists(pairs, trials, n)
    rows = obstacle_barrier_rows(
        flat_q.reshape(trials, n, 2), obstacles, distance=config.d_obstacle, gamma=config.gamma
    )
    k = rows.b.shape[-1]
    obs_a = np.ascontiguousarray(rows.a.reshape(trials * n, k, 2))
    obs_b = np.ascontiguousarray(rows.b.reshape(trials * n, k))
    normals, bound = config.speed_polygon()
    out_u = np.empty_like(flat_u)
    code = np.empty(flat_u.shape[0], np.int8)
    nbr_active = np.zeros(nbr.shape[0], np.bool_)
    obs_active = np.zeros((flat_u.shape[0], k), np.bool_)
    _kernel(
        flat_q, flat_u, ptr, nbr, obs_a, obs_b, np.ascontiguousarray(normals), bound,
        config.distance**2, config.gamma, out_u, code, nbr_active, obs_active,
    )  # fmt: skip
    code_t = code.reshape(trials, n)
    status = code_t.max(axis=1).astype(np.int8)
    src = np.repeat(np.arange(trials * n), np.diff(ptr))
    sel = nbr_active & (src < nbr)  # report each pair once, i < j
    active_pairs = np.column_stack([src[sel] // n, src[sel] % n, nbr[sel] % n]).astype(np.int64)
    r_o, piece = np.nonzero(obs_active)
    active_obs = np.unique(
        np.column_stack([r_o // n, r_o % n, rows.owner[piece]]).astype(np.int64), axis=0
    ).reshape(-1, 3)
    robot_active = np.zeros(trials * n, bool)
    np.logical_or.at(robot_active, src[nbr_active], True)
    robot_active |= obs_active.any(axis=1)
    return FilterResult(
        u=out_u.reshape(u_hat.shape),
        status=status.reshape(batch),
        active=robot_active.reshape((*batch, n)),
        active_pairs=active_pairs,
        active_obstacles=active_obs,
        message=f"barrier-decentralized: {summarise(status)}",
    )


def _clarabel(P, c, G, h) -> NDArray[np.float64] | None:  # type: ignore[no-untyped-def]
    problem = qpsolvers.Problem(P, c, G, h)
    with warnings.catch_warnings():
        # qpsolvers warns on a non-solved status; the caller reads sol.found
        warnings.filterwarnings("ignore", message="Clarabel.rs terminated", category=UserWarning)
        sol = qpsolvers.solve_problem(
            problem, solver="clarabel", tol_feas=1e-11, tol_gap_abs=1e-11, tol_gap_rel=1e-11
        )
    return np.asarray(sol.x) if sol.found else None


def decentralized_reference(
    config: SafetyFilter,
    q: NDArray[np.float64],
    u_hat: NDArray[np.float64],
    obstacles: Sequence[Obstacle] = (),
) -> tuple[NDArray[np.float64], NDArray[np.int8]]:
    """Plain reference of :func:`decentralized_filter`: each robot's QP solved by Clarabel.

    The same rows (half responsibility per pair, full per obstacle, speed polygon),
    assembled robot by robot in numpy, and each robot's 2-variable QP handed to
    qpsolvers. Slow; for tests.

    Returns
    -------
    u : ndarray, shape (..., n, 2)
    code : ndarray of int8, shape (..., n)
        Per robot: 0 unchanged, 1 solved, 2 relaxed, 4 failed.
    """
    q = np.asarray(q, dtype=float)
    u_hat = np.asarray(u_hat, dtype=float)
    n = q.shape[-2]
    fq, fu = q.reshape(-1, n, 2), u_hat.reshape(-1, n, 2)
    out, codes = fu.copy(), np.zeros(fu.shape[:2], np.int8)
    normals, bound = config.speed_polygon()
    for t in range(fq.shape[0]):
        pairs = sensed_pairs(fq[t], config.sensing_radius)[:, 1:]
        obs = obstacle_barrier_rows(
            fq[t], obstacles, distance=config.d_obstacle, gamma=config.gamma
        )
        for i in range(n):
            js = np.concatenate([pairs[pairs[:, 0] == i, 1], pairs[pairs[:, 1] == i, 0]])
            w = fq[t, i] - fq[t, js]
            hp = np.sum(w * w, axis=1) - config.distance**2
            A = np.vstack([-2.0 * w, obs.a[i], normals])
            b = np.concatenate([0.5 * config.gamma * hp**3, obs.b[i], np.full(len(normals), bound)])
            hs = np.concatenate([hp, obs.h[i], np.ones(len(normals))])
            if np.all(A @ fu[t, i] <= b):
                continue
            x = _clarabel(sp.identity(2, format="csc"), -fu[t, i], sp.csc_matrix(A), b)
            code = 1
            if x is None:
                x = _clarabel(
                    sp.identity(2, format="csc"), -fu[t, i], sp.csc_matrix(A),
                    np.where(hs < 0, np.maximum(b, 0.0), b),
                )  # fmt: skip
                code = 2 if x is not None else 4
            out[t, i] = x if x is not None else 0.0
            codes[t, i] = code
    return out.reshape(u_hat.shape), codes.reshape(u_hat.shape[:-1])


def project_onto_halfplanes(
    u_hat: NDArray[np.float64], A: NDArray[np.float64], b: NDArray[np.float64]
) -> tuple[NDArray[np.float64], int]:
    """``argmin |u - u_hat|^2`` s.t. ``A u <= b`` in the plane, by the kernel's enumeration.

    Parameters
    ----------
    u_hat : ndarray, shape (2,)
    A : ndarray, shape (m, 2)
    b : ndarray, shape (m,)

    Returns
    -------
    u : ndarray, shape (2,)
    code : int
        0 unchanged, 1 solved, -1 infeasible.
    """
    u = np.empty(2)
    A = np.ascontiguousarray(A, dtype=float).reshape(-1, 2)
    b = np.ascontiguousarray(b, dtype=float).reshape(-1)
    code = _project(float(u_hat[0]), float(u_hat[1]), A, b, len(b), u)
    return u, int(code)
