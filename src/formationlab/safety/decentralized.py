"""The decentralized barrier certificate: every robot filters its own command.

Wang, Ames and Egerstedt ("Safety barrier certificates for collisions-free
multirobot systems", IEEE T-RO 33(3), 2017, section IV-B) split each pair's
condition ``2 (q_i - q_j) . (u_i - u_j) >= -b(h_ij)`` (``b = gamma h^3``, capped at
``h / dt`` under the discrete condition: :func:`~formationlab.safety.condition.barrier_bound`)
into two halves, one per robot: robot ``i`` requires

    ``-2 (q_i - q_j) . u_i <= b(h_ij) / 2``                                (half responsibility)

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
multipliers (a 2 x 2 solve) are non-negative and which is feasible, trying the rows
``k`` violated at ``u_hat`` with the rows ``j`` violated at ``k``'s projection (one of two
active rows is violated at ``u_hat``, and the other at the first one's projection, else
that projection would be the answer): ``O(v m)`` candidates of ``O(m)`` checks for ``v``
violated rows out of ``m``, a few dozen flops per robot for the usual handful of
neighbours (:mod:`.projection`). It runs batched over
trials and robots in one serial numba loop (``nogil``, so callers may run chunks in
threads; a ``prange`` launch cost more than the whole loop below a few thousand robots
when benchmarked), each robot's neighbours found by a grid of cells of the sensing
radius (:mod:`formationlab.neighbours.cell_grid`; all robots when the radius is infinite or below
``DENSE_BELOW`` robots), and a robot whose command satisfies its rows is settled
without building them (:func:`~.projection.unchanged_robot`).
:func:`decentralized_commands` returns the commands only (what the closed loop needs);
:func:`decentralized_filter` adds the statuses and the active set, found again for
the robots whose command changed. If no candidate exists, the constraints are infeasible (only
possible when some ``h < 0``); those rows are relaxed to ``h_dot >= 0`` (bound 0, which
the zero command satisfies) and the projection is solved again (status
``RELAXED``). :func:`decentralized_reference` solves the same per-robot QPs with
Clarabel, for the tests.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..neighbours.cell_grid import build_grid, neighbours_of
from .condition import barrier_bounds
from .config import SafetyFilter, register_filter
from .decentralized_space import robot_clarabel, space_filter
from .obstacle_terms import obstacle_terms
from .obstacles import Obstacle, obstacle_barrier_rows
from .pairs import DENSE_BELOW, sensed_pairs
from .projection import _project, _row_tol, filter_robot, unchanged_robot
from .result import FilterResult, summarise

__all__ = [
    "decentralized_commands",
    "decentralized_filter",
    "decentralized_reference",
    "project_onto_halfplanes",
]


@njit(cache=True, nogil=True, inline="always")
def _robot(t, r, q, uh, radius, dense, grid, obs, d2, gamma, step, speed_n, speed_b, nbr, A, b,
           neg, owner, out):  # fmt: skip
    """Robot ``r`` of trial ``t``: its neighbours, then unchanged or :func:`filter_robot`.

    Returns ``(code, m, deg)``: the robot's code (0 unchanged, 1 solved, 2 relaxed, 4
    failed), its rows ``A[:m]`` (-1 when not built) and its neighbours ``nbr[:deg]``.
    """
    n = q.shape[1]
    qt = q[t]
    deg = 0
    if dense:
        for j in range(n):  # neighbours in ascending order
            if j == r:
                continue
            dx = qt[r, 0] - qt[j, 0]
            dy = qt[r, 1] - qt[j, 1]
            if dx * dx + dy * dy <= radius * radius:
                nbr[deg] = j
                deg += 1
    else:
        x0, y0, side, nx, ny, start, order = grid
        deg = neighbours_of(r, qt, radius * radius, x0, y0, side, nx, ny, start, order, nbr)
    uh0 = uh[t, r, 0]
    uh1 = uh[t, r, 1]
    if unchanged_robot(r, qt, uh0, uh1, nbr, deg, obs, d2, gamma, step, speed_n, speed_b):
        out[0] = uh0
        out[1] = uh1
        return 0, -1, deg
    code, m = filter_robot(r, qt, uh0, uh1, nbr, deg, obs, d2, gamma, step, speed_n, speed_b, A,
                           b, neg, owner, out)  # fmt: skip
    return code, m, deg


@njit(cache=True, nogil=True)
def _grid(q, radius, dense):
    if dense:
        return 0.0, 0.0, 1.0, 1, 1, np.zeros(2, np.int64), np.zeros(q.shape[0], np.int64)
    return build_grid(q, radius)


@njit(cache=True, nogil=True)
def _scratch(n, obs, speed_n):
    """One robot's work arrays for :func:`_robot`: neighbours, rows ``A``, bounds ``b``,
    relaxed flags, row owners and the command, sized for every row it can have."""
    rows = n + obs.vertices.shape[0] + obs.radius.shape[0] + speed_n.shape[0]
    return (np.empty(max(n, 1), np.int64), np.empty((rows, 2)), np.empty(rows),
            np.empty(rows, np.bool_), np.empty(rows, np.int64), np.empty(2))  # fmt: skip


@njit(cache=True, nogil=True)
def _commands(q, uh, radius, dense, obs, d2, gamma, step, speed_n, speed_b, out_u, out_code,
              out_rows):  # fmt: skip
    """Pass 1: every robot's filtered command, code and rows (``m``, 0 when unchanged)."""
    T, n = q.shape[0], q.shape[1]
    nbr, A, b, neg, owner, out = _scratch(n, obs, speed_n)
    for t in range(T):
        grid = _grid(q[t], radius, dense)
        for r in range(n):
            code, m, _ = _robot(t, r, q, uh, radius, dense, grid, obs, d2, gamma, step, speed_n,
                                speed_b, nbr, A, b, neg, owner, out)  # fmt: skip
            out_u[t, r, 0] = out[0]
            out_u[t, r, 1] = out[1]
            out_code[t, r] = code
            out_rows[t, r] = max(m, 0)


@njit(cache=True, nogil=True)
def _activity(q, uh, radius, dense, obs, d2, gamma, step, speed_n, speed_b, code, pairs,
              obstacles):  # fmt: skip
    """Pass 2, for the robots whose command changed: the rows holding with equality.

    Fills ``pairs`` ``(K, 3)`` with ``(trial, i, j)`` (robot ``i``'s half active) and
    ``obstacles`` ``(K, 3)`` with ``(trial, robot, obstacle)``; returns their counts.
    """
    T, n = q.shape[0], q.shape[1]
    nbr, A, b, neg, owner, out = _scratch(n, obs, speed_n)
    n_pairs = 0
    n_obs = 0
    for t in range(T):
        changed = False
        for r in range(n):
            changed = changed or code[t, r] != 0
        if not changed:
            continue
        grid = _grid(q[t], radius, dense)
        for r in range(n):
            if code[t, r] == 0:
                continue
            _, m, deg = _robot(t, r, q, uh, radius, dense, grid, obs, d2, gamma, step, speed_n,
                               speed_b, nbr, A, b, neg, owner, out)  # fmt: skip
            scale = abs(out[0]) + abs(out[1]) + abs(uh[t, r, 0]) + abs(uh[t, r, 1])
            for k in range(m):
                slack = b[k] - A[k, 0] * out[0] - A[k, 1] * out[1]
                if slack > 1e3 * _row_tol(A[k, 0], A[k, 1], b[k], scale):
                    continue
                if k < deg:
                    pairs[n_pairs, 0] = t
                    pairs[n_pairs, 1] = r
                    pairs[n_pairs, 2] = nbr[k]
                    n_pairs += 1
                elif k >= deg and owner[k] >= 0:
                    obstacles[n_obs, 0] = t
                    obstacles[n_obs, 1] = r
                    obstacles[n_obs, 2] = owner[k]
                    n_obs += 1
    return n_pairs, n_obs


def _setup(config: SafetyFilter, q: NDArray, u_hat: NDArray, obstacles: Sequence[Obstacle]):  # type: ignore[no-untyped-def]
    n = q.shape[-2]
    fq = np.ascontiguousarray(q.reshape(-1, n, 2), dtype=float)
    fu = np.ascontiguousarray(u_hat.reshape(-1, n, 2), dtype=float)
    radius = float(config.sensing_radius)
    dense = (not math.isfinite(radius)) or n < DENSE_BELOW or not np.all(np.isfinite(fq))
    step = config.rows_step
    obs = obstacle_terms(obstacles, d_obstacle=config.d_obstacle, gamma=config.gamma, step=step)
    normals, bound = config.speed_polygon()
    args = (radius, dense, obs, float(config.distance) ** 2, float(config.gamma), step,
            np.ascontiguousarray(normals, dtype=float), float(bound))  # fmt: skip
    return fq, fu, args


def decentralized_commands(
    config: SafetyFilter,
    q: NDArray[np.float64],
    u_hat: NDArray[np.float64],
    obstacles: Sequence[Obstacle] = (),
) -> NDArray[np.float64]:
    """The decentralized filter's commands only (``(..., n, 2)``), as :func:`decentralized_filter`.

    What the closed loop needs at every step: no status, no active set.
    """
    q = np.asarray(q, dtype=float)
    u_hat = np.asarray(u_hat, dtype=float)
    if q.shape[-1] != 2:  # in space: each robot's QP over its 3-D command
        return space_filter(config, q, u_hat, obstacles)[0]
    fq, fu, args = _setup(config, q, u_hat, obstacles)
    out_u = np.empty_like(fu)
    code = np.empty(fu.shape[:2], np.int8)
    _commands(fq, fu, *args, out_u, code, np.empty(fu.shape[:2], np.int64))  # type: ignore[call-arg]
    return out_u.reshape(u_hat.shape)


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
    if q.shape[-1] != 2:  # in space: each robot's QP over its 3-D command
        u, code, robot_active, active_pairs, active_obs = space_filter(config, q, u_hat, obstacles)
        status = code.max(axis=1, initial=0).astype(np.int8)
        return FilterResult(
            u=u, status=status.reshape(batch), active=robot_active.reshape((*batch, n)),
            active_pairs=active_pairs, active_obstacles=active_obs,
            message=f"barrier-decentralized: {summarise(status)}",
        )  # fmt: skip
    fq, fu, args = _setup(config, q, u_hat, obstacles)
    trials = fq.shape[0]
    out_u = np.empty_like(fu)
    code = np.empty((trials, n), np.int8)
    m = np.empty((trials, n), np.int64)
    _commands(fq, fu, *args, out_u, code, m)  # type: ignore[call-arg]
    status = code.max(axis=1, initial=0).astype(np.int8)
    changed = int(np.count_nonzero(code))
    rows = int(m.sum())  # at most one active row each
    pairs = np.empty((rows, 3), np.int64)
    obs_rows = np.empty((rows, 3), np.int64)
    n_p, n_o = (_activity(fq, fu, *args, code, pairs, obs_rows) if changed  # type: ignore[call-arg]
                else (0, 0))  # fmt: skip
    halves = pairs[:n_p]
    active_pairs = halves[halves[:, 1] < halves[:, 2]]  # each pair once, i < j
    active_obs = np.unique(obs_rows[:n_o], axis=0).reshape(-1, 3)
    robot_active = np.zeros((trials, n), bool)
    robot_active[halves[:, 0], halves[:, 1]] = True
    robot_active[active_obs[:, 0], active_obs[:, 1]] = True
    return FilterResult(
        u=out_u.reshape(u_hat.shape),
        status=status.reshape(batch),
        active=robot_active.reshape((*batch, n)),
        active_pairs=active_pairs,
        active_obstacles=active_obs,
        message=f"barrier-decentralized: {summarise(status)}",
    )


def decentralized_reference(
    config: SafetyFilter,
    q: NDArray[np.float64],
    u_hat: NDArray[np.float64],
    obstacles: Sequence[Obstacle] = (),
) -> tuple[NDArray[np.float64], NDArray[np.int8]]:
    """Plain reference of :func:`decentralized_filter`: each robot's QP solved by Clarabel.

    The same rows (half responsibility per pair, full per obstacle, speed polygon),
    assembled robot by robot in numpy, and each robot's QP (2 variables in the plane, 3 in
    space) handed to qpsolvers (:func:`~.decentralized_space.robot_clarabel`). Slow; for
    tests.

    Returns
    -------
    u : ndarray, shape (..., n, d)
    code : ndarray of int8, shape (..., n)
        Per robot: 0 unchanged, 1 solved, 2 relaxed, 4 failed.
    """
    q = np.asarray(q, dtype=float)
    u_hat = np.asarray(u_hat, dtype=float)
    n, d = q.shape[-2:]
    fq, fu = q.reshape(-1, n, d), u_hat.reshape(-1, n, d)
    out, codes = fu.copy(), np.zeros(fu.shape[:2], np.int8)
    normals, bound = config.speed_polygon(d)
    for t in range(fq.shape[0]):
        pairs = sensed_pairs(fq[t], config.sensing_radius)[:, 1:]
        obs = obstacle_barrier_rows(
            fq[t], obstacles, distance=config.d_obstacle, gamma=config.gamma,
            step=config.rows_step,
        )  # fmt: skip
        for i in range(n):
            js = np.concatenate([pairs[pairs[:, 0] == i, 1], pairs[pairs[:, 1] == i, 0]])
            w = fq[t, i] - fq[t, js]
            hp = np.sum(w * w, axis=1) - config.distance**2
            A = np.vstack([-2.0 * w, obs.a[i], normals])
            half = 0.5 * barrier_bounds(hp, config.gamma, config.rows_step)
            b = np.concatenate([half, obs.b[i], np.full(len(normals), bound)])
            hs = np.concatenate([hp, obs.h[i], np.ones(len(normals))])
            out[t, i], codes[t, i] = robot_clarabel(A, b, hs, fu[t, i])
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


register_filter("barrier-decentralized", decentralized_filter, decentralized_commands)
