"""The centralized barrier certificate: one QP over all robots per trial and step.

Wang, Ames and Egerstedt, "Safety barrier certificates for collisions-free
multirobot systems", IEEE Transactions on Robotics 33(3):661-674, 2017, as the
Robotarium runs it (``create_single_integrator_barrier_certificate``): with the
pair barrier ``h_ij = |q_i - q_j|^2 - D_s^2`` and single integrators ``q_dot = u``,

    ``min_u  sum_i |u_i - u_hat_i|^2``
    ``s.t.   -2 (q_i - q_j) . (u_i - u_j) <= gamma h_ij^3``   for pairs within the sensing radius
    ``       -2 (q_i - p*) . u_i <= gamma h_io^3``            for every obstacle piece
    ``       n_k . u_i <= max_speed cos(pi / S)``              (speed polygon, optional)

i.e. ``h_dot >= -gamma h^3`` for every barrier; under the discrete condition (the default)
every ``gamma h^3`` of a barrier ``h > 0`` is capped at ``h / dt``
(:func:`~formationlab.safety.condition.barrier_bound`). Written as a QP in the stacked
``x = (u_1x, u_1y, u_2x, ...)``: ``min 1/2 x'x - u_hat'x`` s.t. ``G x <= bound``, ``G``
sparse (``scipy.sparse``; four non-zeros per pair row, two per robot row), so a
thousand robots with a finite sensing radius pose a QP of a few thousand rows.

Solver: Clarabel through qpsolvers. It is an interior-point method: it reaches
the requested accuracy (1e-10 here) in a few tens of iterations whatever the
conditioning, and it returns a certificate when the problem is infeasible instead
of stopping at an iteration limit. OSQP (ADMM) is faster to warm-start but only
accurate to about 1e-3 at its defaults, which would let robots slip inside ``D_s``
by the solver's tolerance, and it reports infeasibility less reliably.

Exactness and decomposition. If ``u_hat`` satisfies every constraint it is the
optimum and is returned bit for bit. Otherwise the QP separates over the connected
components of the sensing graph (robots linked by a pair constraint); only the
components holding a violated constraint are solved, the others keep ``u_hat``
bit for bit.

Infeasibility. With every ``h >= 0`` the zero command is feasible, so the QP is
feasible. It can only be infeasible when some ``h < 0`` (the state is already inside
an unsafe set, e.g. an initial condition closer than ``D_s``). Then the rows with
``h < 0`` are relaxed to ``h_dot >= 0`` ("get no closer", bound 0) and the relaxed QP,
which the zero command satisfies, is solved: status ``RELAXED``. If the solver
still fails, the decentralized filter's command is returned (status ``FALLBACK``):
each robot's half-responsibility rows sum to the pair's row, so it is feasible for
the centralized constraints; only its optimality is lost.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components

from ..errors import require_extra
from .closed_form import closed_form
from .condition import barrier_bounds
from .config import SafetyFilter, register_filter
from .decentralized import decentralized_filter
from .obstacles import Obstacle, obstacle_barrier_rows
from .pairs import sensed_pairs
from .result import FilterResult, FilterStatus, summarise, unchanged

__all__ = [
    "BarrierConstraints",
    "QPSolution",
    "barrier_constraints",
    "barrier_filter",
    "pair_barrier_rows",
    "solve_barrier_qp",
    "unchanged",
]

PAIR, OBSTACLE, SPEED = 0, 1, 2
#: Clarabel's feasibility and gap tolerances.
SOLVER_TOL = 1e-10


def pair_barrier_rows(
    q: NDArray[np.float64],
    pairs: NDArray[np.int64],
    *,
    distance: float,
    gamma: float,
    step: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Rows ``a . u_i - a . u_j <= b`` of ``h_dot_ij >= -b(h_ij)`` for the given pairs.

    Parameters
    ----------
    q : ndarray, shape (n, d)
    pairs : ndarray of int, shape (m, 2)
        0-based ``(i, j)``.
    distance, gamma : float
        ``D_s`` and the gain.
    step : float
        The Euler step the rows guard (``SafetyFilter.rows_step``; 0: continuous rows).

    Returns
    -------
    a : ndarray, shape (m, d)
        ``-2 (q_i - q_j)``.
    b : ndarray, shape (m,)
        :func:`~formationlab.safety.condition.barrier_bound` of ``h_ij``: ``gamma h_ij^3``,
        capped at ``h_ij / step``.
    h : ndarray, shape (m,)
        ``h_ij = |q_i - q_j|^2 - D_s^2``.
    """
    w = q[pairs[:, 0]] - q[pairs[:, 1]]
    h = np.sum(w * w, axis=-1) - distance**2
    return -2.0 * w, barrier_bounds(h, gamma, step), h  # h_dot = 2 (q_i - q_j).(u_i - u_j)


@dataclass(frozen=True, kw_only=True, eq=False)
class BarrierConstraints:
    """The centralized QP's constraints ``G x <= bound`` for ``x = u.reshape(-1)``.

    Parameters
    ----------
    G : scipy.sparse.csr_matrix, shape (M, d n)
    bound : ndarray, shape (M,)
    barrier : ndarray, shape (M,)
        The row's ``h`` (``inf`` for speed rows).
    kind : ndarray of int8, shape (M,)
        0 pair, 1 obstacle, 2 speed.
    index : ndarray of int64, shape (M, 2)
        ``(i, j)`` for a pair row, ``(robot, obstacle)`` for an obstacle row,
        ``(robot, side)`` for a speed row (0-based).
    coef : ndarray, shape (M, d)
        The row's coefficients ``a`` on its first robot (a pair row has ``-a`` on ``j``).
    """

    G: sp.csr_matrix
    bound: NDArray[np.float64]
    barrier: NDArray[np.float64]
    kind: NDArray[np.int8]
    index: NDArray[np.int64]
    coef: NDArray[np.float64]

    @property
    def robots(self) -> NDArray[np.int64]:
        """The first robot of every row; shape ``(M,)``."""
        return self.index[:, 0]


def barrier_constraints(
    config: SafetyFilter,
    q: NDArray[np.float64],
    obstacles: Sequence[Obstacle] = (),
    pairs: NDArray[np.int64] | None = None,
) -> BarrierConstraints:
    """Assemble the sparse constraints of the centralized QP at positions ``q`` ``(n, d)``.

    ``pairs`` (``(m, 2)``, 0-based) defaults to the pairs within ``config.sensing_radius``.
    Robot ``i``'s command is ``x[d i : d i + d]``.
    """
    q = np.asarray(q, dtype=float)
    n, d = q.shape
    span = np.arange(d)
    if pairs is None:
        pairs = sensed_pairs(q, config.sensing_radius)[:, 1:]
    step = config.rows_step
    a, b, h = pair_barrier_rows(q, pairs, distance=config.distance, gamma=config.gamma, step=step)
    m = len(pairs)
    obs = obstacle_barrier_rows(
        q, obstacles, distance=config.d_obstacle, gamma=config.gamma, step=step
    )
    k = obs.b.shape[1]
    normals, vmax = config.speed_polygon(d)
    s = len(normals)
    robots = np.arange(n)
    # pair rows: +a on robot i's columns, -a on robot j's
    rows = [np.repeat(np.arange(m), 2 * d)]
    cols = [np.column_stack([d * pairs[:, :1] + span, d * pairs[:, 1:] + span]).ravel()]
    vals = [np.column_stack([a, -a]).ravel()]
    # obstacle rows (robot-major), then speed rows (robot-major)
    r0 = m
    for count, coef in ((k, obs.a.reshape(-1, d)), (s, np.tile(normals, (n, 1)))):
        who = np.repeat(robots, count)
        rows.append(np.repeat(r0 + np.arange(n * count), d))
        cols.append((d * who[:, None] + span).ravel())
        vals.append(coef.ravel())
        r0 += n * count
    G = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(r0, d * n)
    )
    bound = np.concatenate([b, obs.b.ravel(), np.full(n * s, vmax)])
    barrier = np.concatenate([h, obs.h.ravel(), np.full(n * s, np.inf)])
    kind = np.concatenate([np.full(m, PAIR), np.full(n * k, OBSTACLE), np.full(n * s, SPEED)])
    index = np.concatenate(
        [
            pairs.reshape(-1, 2),
            np.column_stack([np.repeat(robots, k), np.tile(obs.owner, n)]),
            np.column_stack([np.repeat(robots, s), np.tile(np.arange(s), n)]),
        ]
    ).astype(np.int64)
    coef = np.concatenate([a.reshape(-1, d), obs.a.reshape(-1, d), np.tile(normals, (n, 1))])
    return BarrierConstraints(
        G=G, bound=bound, barrier=barrier, kind=kind.astype(np.int8), index=index, coef=coef
    )


class QPSolution(NamedTuple):
    """A solve of :func:`solve_barrier_qp`.

    ``u`` ``(n, d)``; ``multipliers`` ``(M,)`` (``z >= 0`` with ``u - u_hat + G' z = 0``);
    ``bound`` ``(M,)`` the bounds actually imposed (relaxed rows at 0); ``status``.
    """

    u: NDArray[np.float64]
    multipliers: NDArray[np.float64]
    bound: NDArray[np.float64]
    status: FilterStatus
    message: str


def _solve(G: sp.csr_matrix, bound: NDArray, u_hat: NDArray) -> tuple[NDArray, NDArray] | None:
    """Clarabel on the QP preconditioned: ``x = s y`` with ``s = max |u_hat|``, every row
    scaled to a unit normal, and without the rows that cannot be active.

    When every bound is >= 0 the zero command is feasible, so the solution lies within
    ``|x - u_hat| <= |u_hat|``, hence ``|x| <= 2 |u_hat|``: a row with
    ``bound_k > 2 |G_k| |u_hat|`` holds strictly there and has multiplier 0 (far pairs,
    whose ``gamma h^3`` reaches 1e7). Unscaled, Clarabel failed on such feasible QPs at
    starts near a disc (commands up to 4e4).
    """
    G = sp.csr_matrix(G)
    norms = np.sqrt(np.asarray(G.multiply(G).sum(axis=1), dtype=float).ravel())
    norms = np.where(norms > 0.0, norms, 1.0)
    s = float(np.abs(u_hat).max()) or 1.0
    keep = np.ones(len(bound), dtype=bool)
    if np.all(bound >= 0.0):
        keep = bound <= norms * 2.0 * float(np.linalg.norm(u_hat)) * (1.0 + 1e-9)
    Gk = sp.diags(1.0 / norms[keep]) @ G[keep]
    qpsolvers: Any = require_extra("safety", ("qpsolvers", "clarabel"), "safety filters")
    problem = qpsolvers.Problem(
        sp.identity(G.shape[1], format="csc"), -u_hat / s, sp.csc_matrix(Gk),
        bound[keep] / (norms[keep] * s),
    )  # fmt: skip
    with warnings.catch_warnings():
        # qpsolvers warns on a non-solved status; the caller reads the status and acts on it
        warnings.filterwarnings("ignore", message="Clarabel.rs terminated", category=UserWarning)
        sol = qpsolvers.solve_problem(
            problem, solver="clarabel",
            tol_feas=SOLVER_TOL, tol_gap_abs=SOLVER_TOL, tol_gap_rel=SOLVER_TOL,
        )  # fmt: skip
    if not sol.found or sol.x is None:
        return None
    x = np.asarray(sol.x, dtype=float) * s
    scale = np.abs(bound) + abs(G) @ (np.abs(x) + np.abs(u_hat)) + 1e-300
    if np.any(G @ x - bound > 1e-7 * scale):
        return None
    z = np.zeros(len(bound))
    if sol.z is not None:  # multipliers of the scaled rows: z_k = s w_k / |G_k|
        z[keep] = np.maximum(np.asarray(sol.z, float), 0.0) * s / norms[keep]
    return x, z


def solve_barrier_qp(constraints: BarrierConstraints, u_hat: NDArray[np.float64]) -> QPSolution:
    """Solve ``min 1/2 |x - u_hat|^2`` s.t. ``G x <= bound`` with Clarabel (relaxing if infeasible).

    Parameters
    ----------
    constraints : BarrierConstraints
    u_hat : ndarray, shape (n, d)

    Returns
    -------
    QPSolution
        Status ``UNCHANGED`` (``u_hat`` feasible, returned bit for bit), ``SOLVED``,
        ``RELAXED`` (rows with ``h < 0`` relaxed to bound 0) or ``FAILED`` (``u`` is then
        ``u_hat`` and must not be used; :func:`barrier_filter` falls back).
    """
    u_hat = np.asarray(u_hat, dtype=float)
    x_hat = u_hat.reshape(-1)
    G, bound = constraints.G, constraints.bound
    if np.all(G @ x_hat <= bound):
        return QPSolution(u_hat.copy(), np.zeros(len(bound)), bound, FilterStatus.UNCHANGED, "")
    out = _solve(G, bound, x_hat)
    if out is not None:
        return QPSolution(out[0].reshape(u_hat.shape), out[1], bound, FilterStatus.SOLVED, "")
    relaxed = np.where(constraints.barrier < 0, np.maximum(bound, 0.0), bound)
    n_rel = int(np.count_nonzero(relaxed != bound))
    if n_rel:
        out = _solve(G, relaxed, x_hat)
        if out is not None:
            msg = f"{n_rel} constraints with h < 0 relaxed to h_dot >= 0"
            u = out[0].reshape(u_hat.shape)
            return QPSolution(u, out[1], relaxed, FilterStatus.RELAXED, msg)
    return QPSolution(
        u_hat.copy(), np.zeros(len(bound)), bound, FilterStatus.FAILED, "Clarabel found no solution"
    )


def _active_rows(c: BarrierConstraints, x: NDArray, bound: NDArray, x_hat: NDArray) -> NDArray:
    """Rows holding with equality at ``x`` (relative to the size of the command), not speed rows."""
    slack = bound - c.G @ x
    scale = np.abs(bound) + abs(c.G) @ (np.abs(x) + np.abs(x_hat)) + 1e-300
    return (slack <= 1e-7 * scale) & (c.kind != SPEED)


def _closed_form(c: BarrierConstraints, u_hat: NDArray[np.float64]) -> tuple[NDArray, int]:
    """:func:`~formationlab.safety.closed_form.closed_form` on the rows of ``c``."""
    ri = np.ascontiguousarray(c.index[:, 0])
    rj = np.where(c.kind == PAIR, c.index[:, 1], -1).astype(np.int64)
    out = np.empty_like(u_hat)
    code = closed_form(
        ri, rj, np.ascontiguousarray(c.coef), np.ascontiguousarray(c.bound),
        np.ascontiguousarray(u_hat), out, np.empty(len(c.bound)),
    )  # fmt: skip
    return out, int(code)


def _record_active(
    t: int, c: BarrierConstraints, x: NDArray, bound: NDArray, x_hat: NDArray,
    active: NDArray, act_pairs: list[NDArray[np.int64]], act_obs: list[NDArray[np.int64]],
) -> None:  # fmt: skip
    """Mark trial ``t``'s rows holding with equality at ``x`` (robots, pairs, obstacles)."""
    on = _active_rows(c, x, bound, x_hat)
    idx = c.index[on]
    kind = c.kind[on]
    pr = idx[kind == PAIR]
    ob = idx[kind == OBSTACLE]
    # index rows carry the original robot numbers (built before restricting)
    active[t, pr.ravel()] = True
    active[t, ob[:, 0]] = True
    act_pairs.append(_in_trial(t, pr))
    act_obs.append(np.unique(_in_trial(t, ob), axis=0).reshape(-1, 3))


def _in_trial(t: int, rows: NDArray[np.int64]) -> NDArray[np.int64]:
    """Prefix ``(k, 2)`` rows with the trial number: ``(k, 3)``."""
    return np.column_stack([np.full(len(rows), t, np.int64), rows]).astype(np.int64)


def _maybe_violated(
    config: SafetyFilter,
    q: NDArray[np.float64],
    u: NDArray[np.float64],
    obstacles: Sequence[Obstacle],
    pairs: NDArray[np.int64],
) -> NDArray[np.bool_]:
    """Trials ``(B,)`` whose command may violate a row, for all trials at once.

    The same rows as :func:`barrier_constraints`, evaluated vectorised with a margin of
    ``1e-9`` of the row's size, so that a trial left out cannot be violated whatever
    the order of the floating-point sums; the trials kept are tested exactly.
    """
    tol = 1e-9
    t, i, j = pairs[:, 0], pairs[:, 1], pairs[:, 2]
    w = q[t, i] - q[t, j]
    du = u[t, i] - u[t, j]
    h = np.sum(w * w, axis=-1) - config.distance**2
    bound = barrier_bounds(h, config.gamma, config.rows_step)
    lhs = -2.0 * np.sum(w * du, axis=-1)
    size = np.abs(bound) + 2.0 * np.sum(np.abs(w) * np.abs(du), axis=-1)
    out = np.zeros(q.shape[0], bool)
    np.logical_or.at(out, t[lhs > bound - tol * size], True)
    if obstacles:
        rows = obstacle_barrier_rows(
            q, obstacles, distance=config.d_obstacle, gamma=config.gamma, step=config.rows_step
        )
        lhs_o = np.sum(rows.a * u[:, :, None, :], axis=-1)
        size_o = np.abs(rows.b) + np.sum(np.abs(rows.a) * np.abs(u[:, :, None, :]), axis=-1)
        out |= np.any(lhs_o > rows.b - tol * size_o, axis=(-2, -1))
    normals, vmax = config.speed_polygon(q.shape[-1])
    if len(normals):
        lhs_s = u @ normals.T
        out |= np.any(lhs_s > vmax - tol * (vmax + np.abs(u).sum(-1, keepdims=True)), axis=(-2, -1))
    return out


def barrier_filter(
    config: SafetyFilter,
    q: NDArray[np.float64],
    u_hat: NDArray[np.float64],
    obstacles: Sequence[Obstacle] = (),
) -> FilterResult:
    """The centralized barrier certificate (module docstring), one QP per trial.

    Parameters
    ----------
    config : SafetyFilter
    q, u_hat : ndarray, shape (..., n, d)
        ``d`` = 2 in the plane, 3 in space.
    obstacles : sequence of Circle or Polygon (plane), Sphere or Box (space)

    Returns
    -------
    FilterResult
    """
    q = np.asarray(q, dtype=float)
    u_hat = np.asarray(u_hat, dtype=float)
    batch, n, d = q.shape[:-2], q.shape[-2], q.shape[-1]
    fq, fu = q.reshape(-1, n, d), u_hat.reshape(-1, n, d)
    trials = fq.shape[0]
    all_pairs = sensed_pairs(fq, config.sensing_radius)
    starts = np.searchsorted(all_pairs[:, 0], np.arange(trials + 1))
    out = fu.copy()
    status = np.zeros(trials, np.int8)
    active = np.zeros((trials, n), bool)
    act_pairs: list[NDArray[np.int64]] = []
    act_obs: list[NDArray[np.int64]] = []
    notes: list[str] = []
    for t in map(int, np.flatnonzero(_maybe_violated(config, fq, fu, obstacles, all_pairs))):
        pairs = all_pairs[starts[t] : starts[t + 1], 1:]
        c = barrier_constraints(config, fq[t], obstacles, pairs)
        x_hat = fu[t].reshape(-1)
        violated = c.G @ x_hat > c.bound
        if not violated.any():
            continue
        graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        _, label = connected_components(graph, directed=False)
        chosen = np.isin(label, np.unique(label[c.robots[violated]]))
        keep = chosen[c.robots]
        cols = np.flatnonzero(np.repeat(chosen, d))
        sub = BarrierConstraints(
            G=c.G[keep][:, cols], bound=c.bound[keep], barrier=c.barrier[keep],
            kind=c.kind[keep], index=c.index[keep], coef=c.coef[keep],
        )  # fmt: skip
        u_cf, code = _closed_form(c, fu[t])
        if code >= 0:  # one or two active rows (0: none, up to rounding): no solver call
            out[t] = u_cf
            status[t] = FilterStatus.SOLVED if code else FilterStatus.UNCHANGED
            x_sub = fu[t][chosen].reshape(-1)
            _record_active(t, sub, u_cf[chosen].reshape(-1), sub.bound, x_sub, active,
                           act_pairs, act_obs)  # fmt: skip
            continue
        sol = solve_barrier_qp(sub, fu[t][chosen])
        if sol.status == FilterStatus.FAILED:
            fb = decentralized_filter(config, fq[t], fu[t], obstacles)
            out[t] = fb.u
            status[t] = max(int(FilterStatus.FALLBACK), int(fb.status))
            active[t] = fb.active
            act_pairs.append(_in_trial(t, fb.active_pairs[:, 1:]))
            act_obs.append(_in_trial(t, fb.active_obstacles[:, 1:]))
            notes.append(f"trial {t + 1}: {sol.message}; decentralized fallback")
            continue
        out[t][chosen] = sol.u
        status[t] = sol.status
        if sol.message:
            notes.append(f"trial {t + 1}: {sol.message}")
        x_sub = fu[t][chosen].reshape(-1)
        _record_active(t, sub, sol.u.reshape(-1), sol.bound, x_sub, active, act_pairs, act_obs)
    msg = f"barrier: {summarise(status)}" + ("; " + "; ".join(notes) if notes else "")
    return FilterResult(
        u=out.reshape(u_hat.shape),
        status=status.reshape(batch),
        active=active.reshape((*batch, n)),
        active_pairs=np.concatenate([np.zeros((0, 3), np.int64), *act_pairs]),
        active_obstacles=np.concatenate([np.zeros((0, 3), np.int64), *act_obs]),
        message=msg,
    )


register_filter("barrier", barrier_filter)
