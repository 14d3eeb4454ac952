"""The decentralized barrier certificate in space: each robot's QP over its 3-D command.

The rows are those of the plane (:mod:`.decentralized`, after Wang, Ames and Egerstedt,
IEEE T-RO 33(3), 2017, section IV-B): robot ``i`` takes half of each pair's condition,
``-2 (q_i - q_j) . u_i <= b(h_ij) / 2``, and the whole of each obstacle piece's,
``-2 (q_i - p*) . u_i <= b(h_io)`` (spheres and boxes, :mod:`.solids`), with ``b`` the
bound of :func:`~formationlab.safety.condition.barrier_bound`. In the plane a robot's QP
has at most two active rows and is enumerated (:mod:`.projection`); in space it may have
three, and each robot's QP, ``min |u_i - u_hat_i|^2`` s.t. ``A u_i <= b`` over ``u_i`` in
``R^3``, is solved by the dual active-set method of Goldfarb and Idnani
(:func:`~formationlab.safety.dual_active_set.centralized_command` on one robot: the closed
form of one or two active rows first, the relaxation of rows with ``h < 0`` when the rows
are infeasible), and by Clarabel (:func:`robot_clarabel`) when rounding defeats it.

The rows are built and checked in numpy for every robot at once; only the robots whose
``u_hat_i`` violates a row are solved (the others keep it bit for bit). Each robot's rows
sum, over a pair, to the pair's row of the centralized QP, so the commands are feasible
for it (the centralized filter's fallback).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..errors import require_extra
from .closed_form import TOL
from .condition import barrier_bounds
from .config import SafetyFilter
from .dual_active_set import FALLBACK, NUMERICAL, centralized_command, workspace
from .obstacles import Obstacle, obstacle_barrier_rows
from .pairs import sensed_pairs

__all__ = ["robot_clarabel", "space_filter"]


def _clarabel(P, c, G, h) -> NDArray[np.float64] | None:  # type: ignore[no-untyped-def]
    qpsolvers: Any = require_extra("safety", ("qpsolvers", "clarabel"), "safety filters")
    problem = qpsolvers.Problem(P, c, G, h)
    with warnings.catch_warnings():
        # qpsolvers warns on a non-solved status; the caller reads sol.found
        warnings.filterwarnings("ignore", message="Clarabel.rs terminated", category=UserWarning)
        sol = qpsolvers.solve_problem(
            problem, solver="clarabel", tol_feas=1e-11, tol_gap_abs=1e-11, tol_gap_rel=1e-11
        )
    return np.asarray(sol.x) if sol.found else None


def robot_clarabel(
    A: NDArray[np.float64], b: NDArray[np.float64], h: NDArray[np.float64], u_hat: NDArray
) -> tuple[NDArray[np.float64], int]:
    """One robot's QP ``min |u - u_hat|^2`` s.t. ``A u <= b`` by Clarabel, relaxing the rows
    with ``h < 0`` to bound ``max(b, 0)`` when infeasible.

    Parameters
    ----------
    A : ndarray, shape (m, d)
    b, h : ndarray, shape (m,)
        Bounds and the rows' barriers.
    u_hat : ndarray, shape (d,)

    Returns
    -------
    u : ndarray, shape (d,)
        ``u_hat`` when feasible; 0 when even the relaxed rows have no solution.
    code : int
        0 unchanged, 1 solved, 2 relaxed, 4 failed.
    """
    if np.all(A @ u_hat <= b):
        return u_hat.copy(), 0
    eye = sp.identity(len(u_hat), format="csc")
    x = _clarabel(eye, -u_hat, sp.csc_matrix(A), b)
    if x is not None:
        return x, 1
    x = _clarabel(eye, -u_hat, sp.csc_matrix(A), np.where(h < 0, np.maximum(b, 0.0), b))
    return (x, 2) if x is not None else (np.zeros_like(u_hat), 4)


def _robot_qp(
    A: NDArray[np.float64], b: NDArray[np.float64], h: NDArray[np.float64], u_hat: NDArray
) -> tuple[NDArray[np.float64], int]:
    """:func:`robot_clarabel`'s answer by the dual active set (Clarabel only when rounding
    defeats it)."""
    m, d = A.shape
    mats, vecs, lam, act, rb2 = workspace(1, m, d)
    out = np.empty((1, d))
    code = centralized_command(
        np.zeros(m, np.int64), np.full(m, -1, np.int64), np.ascontiguousarray(A),
        np.ascontiguousarray(b), np.ascontiguousarray(h), np.ascontiguousarray(u_hat[None]),
        out, lam, mats, vecs, act, rb2,
    )  # fmt: skip
    if code == NUMERICAL:
        return robot_clarabel(A, b, h, u_hat)
    if code == FALLBACK:  # the relaxed rows are infeasible too
        return np.zeros(d), 4
    return out[0], int(code)


def space_filter(
    config: SafetyFilter,
    q: NDArray[np.float64],
    u_hat: NDArray[np.float64],
    obstacles: Sequence[Obstacle] = (),
) -> tuple[NDArray[np.float64], NDArray[np.int8], NDArray[np.bool_], NDArray[np.int64], NDArray]:
    """The decentralized filter (module docstring) for any dimension, batched over trials.

    Parameters
    ----------
    config : SafetyFilter
    q, u_hat : ndarray, shape (..., n, d)
    obstacles : sequence of Sphere or Box (Circle or Polygon when ``d = 2``)

    Returns
    -------
    u : ndarray, shape (..., n, d)
    code : ndarray of int8, shape (T, n)
        Per robot of the flattened trials: 0 unchanged, 1 solved, 2 relaxed, 4 failed.
    active : ndarray of bool, shape (T, n)
        Robots with a row holding with equality.
    active_pairs : ndarray of int64, shape (k, 3)
        ``(trial, i, j)``, ``i < j``, whose half on robot ``i`` holds with equality.
    active_obstacles : ndarray of int64, shape (k, 3)
        ``(trial, robot, obstacle)`` of the obstacle rows holding with equality.
    """
    n, d = q.shape[-2:]
    fq = np.asarray(q, dtype=float).reshape(-1, n, d)
    fu = np.asarray(u_hat, dtype=float).reshape(-1, n, d)
    config.speed_polygon(d)  # (refuses a speed limit in space)
    step = config.rows_step
    pairs = sensed_pairs(fq, config.sensing_radius)
    t, i, j = pairs[:, 0], pairs[:, 1], pairs[:, 2]
    w = fq[t, i] - fq[t, j]
    h = np.sum(w * w, axis=-1) - config.distance**2
    half = 0.5 * barrier_bounds(h, config.gamma, step)  # half of the pair's bound
    obs = obstacle_barrier_rows(fq, obstacles, distance=config.d_obstacle, gamma=config.gamma,
                                step=step)  # fmt: skip
    violated = np.zeros(fu.shape[:2], bool)
    np.logical_or.at(violated, (t, i), np.sum(-2.0 * w * fu[t, i], axis=-1) > half)
    np.logical_or.at(violated, (t, j), np.sum(2.0 * w * fu[t, j], axis=-1) > half)
    violated |= np.any(np.sum(obs.a * fu[:, :, None, :], axis=-1) > obs.b, axis=-1)
    out = fu.copy()
    code = np.zeros(fu.shape[:2], np.int8)
    active = np.zeros(fu.shape[:2], bool)
    act_pairs, act_obs = [np.zeros((0, 3), np.int64)], [np.zeros((0, 3), np.int64)]
    for tt, r in np.argwhere(violated):
        first, second = (t == tt) & (i == r), (t == tt) & (j == r)
        A = np.concatenate([-2.0 * w[first], 2.0 * w[second], obs.a[tt, r]])
        b = np.concatenate([half[first], half[second], obs.b[tt, r]])
        hs = np.concatenate([h[first], h[second], obs.h[tt, r]])
        out[tt, r], code[tt, r] = _robot_qp(A, b, hs, fu[tt, r])
        scale = np.sum(np.abs(out[tt, r])) + np.sum(np.abs(fu[tt, r]))
        slack = b - A @ out[tt, r]
        on = slack <= 1e3 * TOL * (np.abs(b) + np.sum(np.abs(A), axis=-1) * scale)
        active[tt, r] = bool(on.any())
        nbr = np.concatenate([j[first], i[second]])
        mine = on[: len(nbr)] & (nbr > r)  # each pair once, from its lower robot
        act_pairs.append(np.column_stack([np.full(mine.sum(), tt), np.full(mine.sum(), r),
                                          nbr[mine]]))  # fmt: skip
        owners = np.unique(obs.owner[on[len(nbr) :]])
        act_obs.append(np.column_stack([np.full(len(owners), tt), np.full(len(owners), r),
                                        owners]))  # fmt: skip
    return (
        out.reshape(np.shape(u_hat)), code, active, np.concatenate(act_pairs).astype(np.int64),
        np.concatenate(act_obs).astype(np.int64),
    )  # fmt: skip
