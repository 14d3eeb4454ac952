"""Numba kernel of batches with obstacles and a safety filter, trial by trial the driver's run.

The compiled twin of the stepping driver (:func:`formationlab.integrators.drive`) with
explicit Euler for a closed loop (:class:`~formationlab.dynamics.System`) with static
obstacles and a safety filter (:mod:`formationlab.safety`). Per step ``k`` of a trial,
as ``System.rhs`` and the driver do it:

1. the law's control at the law's points (``model.points``), by the batch kernel's
   own functions (:mod:`.kernels`: ``_controls``, the robot model's ``_headings``,
   ``_points``, ``_rates`` and ``_speed``), on the trial alone;
2. plus Khatib's repulsion from the obstacles
   (:func:`formationlab.safety.obstacle_terms.repel`);
3. then the filter: ``barrier-decentralized`` robot by robot, the rows of
   :func:`formationlab.safety.decentralized_filter` in its order solved by its
   :func:`~formationlab.safety.decentralized.solve_rows`; ``barrier`` by the closed form
   of one or two active rows (:func:`formationlab.safety.closed_form.closed_form`) on
   the rows of :func:`formationlab.safety.barrier_constraints`. When more rows are
   active the trial pauses; :func:`run_safety` solves its QP with
   :func:`formationlab.safety.barrier_filter` (Clarabel, as the driver's closed loop
   does) and the trial resumes with that command;
4. the robot model's rates, the stop rule, and the Euler step judged by the contact
   rule (``System.step_verdict``): not finite, contact between robots (``.kernels``'
   ``_contact``) or with an obstacle at the end of the step, or along it.

Trials run in parallel (``prange``), each from its start (or its pause) to its end.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from ..analysis import Tolerances
from ..controllers import Law
from ..dynamics import System
from ..models import RobotModel
from ..safety.closed_form import closed_form
from ..safety.decentralized import solve_rows
from ..safety.obstacle_terms import (
    barrier_row,
    obstacle_terms,
    piece_count,
    repel,
    signed_distance,
    swept_clearance,
)
from ..spec import Formation
from .kernels import (
    _COLLISION,
    _CONVERGED,
    _END,
    _NON_FINITE,
    _SWEPT_MARGIN,
    _TOO_LARGE,
    _contact,
    _controls,
    _headings,
    _points,
    _rates,
    _speed,
)
from .model_terms import HEADING, NEAR_IDENTITY, model_terms

__all__ = ["FilterTerms", "run_safety"]

NONE, DECENTRALIZED, CENTRALIZED = 0, 1, 2
#: A trial's code while it waits for a QP solve (-1: running).
_PAUSED = -2


class FilterTerms(NamedTuple):
    """The safety filter as numbers (:class:`formationlab.safety.SafetyFilter`)."""

    kind: int  #: NONE, DECENTRALIZED or CENTRALIZED
    d2: float  #: D_s^2
    gamma: float
    r2: float  #: sensing radius^2 (inf: every pair)
    speed_n: NDArray[np.float64]  #: (S, 2) normals of the speed polygon
    speed_b: float


class TrialState(NamedTuple):
    """What a trial carries across a pause (``B`` trials)."""

    x: NDArray[np.float64]  #: (B, n, k) state now
    qc: NDArray[np.float64]  #: (B, n, 2) positions at the previous check
    kc: NDArray[np.int64]  #: (B,) step of the previous check (-1: none)
    k: NDArray[np.int64]  #: (B,) step to compute next
    mc: NDArray[np.float64]  #: (B,) least clearance over accepted states
    ns: NDArray[np.float64]  #: (B,) net speed over the last check interval
    code: NDArray[np.int8]  #: (B,) -1 running, -2 paused for a QP, else the Status code
    need_p: NDArray[np.float64]  #: (B, n, 2) a paused trial's points
    need_u: NDArray[np.float64]  #: (B, n, 2) and its command before the filter
    given: NDArray[np.bool_]  #: (B,) the QP's answer is in given_u
    given_u: NDArray[np.float64]  #: (B, n, 2)


class Outputs(NamedTuple):
    x: NDArray[np.float64]  #: (B, n, k) final states
    v: NDArray[np.float64]  #: (B, n, k) their rates
    steps: NDArray[np.int64]  #: (B,)
    qw: NDArray[np.float64]  #: (B, n, 2) positions at the start of the drift window


@njit(cache=True, nogil=True)
def _decentralized(pq, uq, uf, obs, flt, A, bb, neg) -> None:
    """``uf``: every robot's own rows (``decentralized_filter``'s order) solved."""
    n = pq.shape[0]
    n_obs = obs.radius.shape[0]
    n_spd = flt.speed_n.shape[0]
    out = np.empty(2)
    for r in range(n):
        m = 0
        for j in range(n):  # neighbours in ascending order
            if j == r:
                continue
            dx = pq[r, 0] - pq[j, 0]
            dy = pq[r, 1] - pq[j, 1]
            if not dx * dx + dy * dy <= flt.r2:
                continue
            h = dx * dx + dy * dy - flt.d2
            A[m, 0] = -2.0 * dx
            A[m, 1] = -2.0 * dy
            bb[m] = 0.5 * flt.gamma * h * h * h  # half of the pair's -gamma h^3
            neg[m] = h < 0.0
            m += 1
        for o in range(n_obs):
            pieces = 1 if obs.radius[o] > 0 else obs.start[o + 1] - obs.start[o]
            for k in range(pieces):
                a0, a1, b, _ = barrier_row(obs, o, k, pq[r, 0], pq[r, 1])
                A[m, 0] = a0
                A[m, 1] = a1
                bb[m] = b
                neg[m] = b < 0.0
                m += 1
        for s in range(n_spd):
            A[m, 0] = flt.speed_n[s, 0]
            A[m, 1] = flt.speed_n[s, 1]
            bb[m] = flt.speed_b
            neg[m] = False
            m += 1
        solve_rows(uq[r, 0], uq[r, 1], A, bb, neg, m, out)
        uf[r, 0] = out[0]
        uf[r, 1] = out[1]


@njit(cache=True, nogil=True)
def _centralized(pq, uq, uf, obs, flt, ri, rj, ra, rb, lam) -> int:
    """``uf`` by the closed form on the rows of ``barrier_constraints``; -1: needs the QP."""
    n = pq.shape[0]
    m = 0
    for i in range(n):  # pair rows, (i, j) in lexicographic order
        for j in range(i + 1, n):
            wx = pq[i, 0] - pq[j, 0]
            wy = pq[i, 1] - pq[j, 1]
            if not wx * wx + wy * wy <= flt.r2:
                continue
            h = wx * wx + wy * wy - flt.d2
            ri[m] = i
            rj[m] = j
            ra[m, 0] = -2.0 * wx
            ra[m, 1] = -2.0 * wy
            rb[m] = flt.gamma * h**3
            m += 1
    for i in range(n):  # obstacle rows, robot-major
        for o in range(obs.radius.shape[0]):
            pieces = 1 if obs.radius[o] > 0 else obs.start[o + 1] - obs.start[o]
            for k in range(pieces):
                a0, a1, b, _ = barrier_row(obs, o, k, pq[i, 0], pq[i, 1])
                ri[m] = i
                rj[m] = -1
                ra[m, 0] = a0
                ra[m, 1] = a1
                rb[m] = b
                m += 1
    for i in range(n):  # speed rows, robot-major
        for s in range(flt.speed_n.shape[0]):
            ri[m] = i
            rj[m] = -1
            ra[m, 0] = flt.speed_n[s, 0]
            ra[m, 1] = flt.speed_n[s, 1]
            rb[m] = flt.speed_b
            m += 1
    return closed_form(ri[:m], rj[:m], ra[:m], rb[:m], uq, uf, lam[:m])


@njit(cache=True, error_model="numpy", nogil=True)
def _trial(b, terms, model, obs, flt, st, out, dt, n_steps, check_every, speed, window_step):
    """Steps of trial ``b`` from ``st.k[b]`` until it ends or pauses (module docstring)."""
    n = st.x.shape[1]
    kk = st.x.shape[2]
    hand = model.kind == NEAR_IDENTITY
    turns = hand or model.kind == HEADING
    x = np.empty((n, kk, 1))
    xn = np.empty((n, kk, 1))
    f = np.empty((n, kk, 1))
    u = np.empty((n, 2, 1))
    p = np.empty((n, 2, 1) if hand else (1, 2, 1))
    h = np.empty((n, 2, 1) if turns else (1, 2, 1))
    sigma = np.empty(1)
    gap = np.empty(1)
    swept = np.empty(1)
    near = np.empty(1)
    disp = np.zeros(1)
    pq = np.empty((n, 2))
    uq = np.empty((n, 2))
    uf = np.empty((n, 2))
    n_obs = obs.radius.shape[0]
    rows = (n - 1) + piece_count(obs) + flt.speed_n.shape[0]
    A = np.empty((rows, 2))
    bb = np.empty(rows)
    neg = np.empty(rows, dtype=np.bool_)
    big = n * (n - 1) // 2 + n * (piece_count(obs) + flt.speed_n.shape[0]) if flt.kind == 2 else 1
    ri = np.empty(big, dtype=np.int64)
    rj = np.empty(big, dtype=np.int64)
    ra = np.empty((big, 2))
    rb = np.empty(big)
    lam = np.empty(big)
    for i in range(n):
        for d in range(kk):
            x[i, d, 0] = st.x[b, i, d]
    for k in range(st.k[b], n_steps + 1):
        if turns:
            _headings(x, h, 1)
        if hand:
            _points(x, h, p, 1, model)
            _controls(p, u, sigma, 1, terms)
            for i in range(n):
                pq[i, 0] = p[i, 0, 0]
                pq[i, 1] = p[i, 1, 0]
        else:
            _controls(x, u, sigma, 1, terms)
            for i in range(n):
                pq[i, 0] = x[i, 0, 0]
                pq[i, 1] = x[i, 1, 0]
        for i in range(n):
            uq[i, 0] = u[i, 0, 0]
            uq[i, 1] = u[i, 1, 0]
        if n_obs > 0:
            repel(obs, terms.radius, pq, uq)
        if flt.kind == DECENTRALIZED:
            _decentralized(pq, uq, uf, obs, flt, A, bb, neg)
        elif flt.kind == CENTRALIZED and st.given[b]:
            st.given[b] = False
            for i in range(n):
                uf[i, 0] = st.given_u[b, i, 0]
                uf[i, 1] = st.given_u[b, i, 1]
        elif flt.kind == CENTRALIZED:
            if _centralized(pq, uq, uf, obs, flt, ri, rj, ra, rb, lam) < 0:  # pause for the QP
                for i in range(n):
                    st.need_p[b, i, 0] = pq[i, 0]
                    st.need_p[b, i, 1] = pq[i, 1]
                    st.need_u[b, i, 0] = uq[i, 0]
                    st.need_u[b, i, 1] = uq[i, 1]
                    for d in range(kk):
                        st.x[b, i, d] = x[i, d, 0]
                st.k[b] = k
                st.code[b] = _PAUSED
                return
        else:
            for i in range(n):
                uf[i, 0] = uq[i, 0]
                uf[i, 1] = uq[i, 1]
        for i in range(n):
            u[i, 0, 0] = uf[i, 0]
            u[i, 1, 0] = uf[i, 1]
        _rates(x, h, u, f, 1, model)
        if k == window_step:  # start of the drift window (the driver's q_window)
            for i in range(n):
                out.qw[b, i, 0] = x[i, 0, 0]
                out.qw[b, i, 1] = x[i, 1, 0]
        code = -1
        if k % check_every == 0 or k == n_steps:  # StopRule
            nan = False
            for i in range(n):
                for d in range(kk):
                    nan = nan or f[i, d, 0] != f[i, d, 0]
            still = (not nan) and _speed(f, 0, model) <= speed
            kc = st.kc[b]
            if kc >= 0:
                dd = 0.0
                for i in range(n):
                    dx = x[i, 0, 0] - st.qc[b, i, 0]
                    dy = x[i, 1, 0] - st.qc[b, i, 1]
                    dd = max(dd, dx * dx + dy * dy)
                net = math.sqrt(dd) / ((k - kc) * dt)
                st.ns[b] = net
                still = still or net <= speed
            for i in range(n):
                st.qc[b, i, 0] = x[i, 0, 0]
                st.qc[b, i, 1] = x[i, 1, 0]
            st.kc[b] = k
            if still:
                code = _CONVERGED
        if code < 0 and k == n_steps:
            code = _END
        if code < 0:  # explicit Euler, judged by the contact rule (System.step_verdict)
            finite = True
            top = 0.0
            for i in range(n):
                for d in range(kk):
                    z = x[i, d, 0] + dt * f[i, d, 0]
                    xn[i, d, 0] = z
                    finite = finite and math.isfinite(z)
                ex = xn[i, 0, 0] - x[i, 0, 0]
                ey = xn[i, 1, 0] - x[i, 1, 0]
                top = max(top, ex * ex + ey * ey)
            disp[0] = math.sqrt(top)
            if finite:
                _contact(xn, x, disp, gap, swept, near, 1, terms)
                for i in range(n):
                    for o in range(n_obs):
                        s = signed_distance(obs, o, xn[i, 0, 0], xn[i, 1, 0])[0] - terms.radius[i]
                        gap[0] = min(gap[0], s)
                        if s <= _SWEPT_MARGIN * disp[0]:  # (|grad delta| = 1: farther is clear)
                            sw = swept_clearance(obs, o, x[i, 0, 0], x[i, 1, 0], xn[i, 0, 0],
                                                 xn[i, 1, 0], terms.radius[i])  # fmt: skip
                            swept[0] = min(swept[0], sw)
            if not finite:
                code = _NON_FINITE
            elif not gap[0] > 0.0:
                code = _COLLISION
            elif not swept[0] > 0.0:
                code = _TOO_LARGE
            else:
                st.mc[b] = min(st.mc[b], gap[0])
                x, xn = xn, x
                continue
        # the trial ends at x_k (a rejected step is not taken), with the rates f
        for i in range(n):
            for d in range(kk):
                out.x[b, i, d] = x[i, d, 0]
                out.v[b, i, d] = f[i, d, 0]
        out.steps[b] = k
        st.code[b] = code
        return


@njit(cache=True, error_model="numpy", nogil=True, parallel=True)
def run_trials(terms, model, obs, flt, st, out, dt, n_steps, check_every, speed, window_step):
    """Every running trial until it ends or pauses, in parallel over trials."""
    for b in prange(st.x.shape[0]):
        if st.code[b] == -1:
            _trial(b, terms, model, obs, flt, st, out, dt, n_steps, check_every, speed,
                   window_step)  # fmt: skip


def filter_terms(safety: Any) -> FilterTerms:
    """The :class:`FilterTerms` of a :class:`~formationlab.safety.SafetyFilter` (or None)."""
    if safety is None or not safety.enabled:
        return FilterTerms(NONE, 0.0, 0.0, 0.0, np.zeros((0, 2)), 0.0)
    normals, bound = safety.speed_polygon()
    kind = DECENTRALIZED if safety.filter == "barrier-decentralized" else CENTRALIZED
    return FilterTerms(
        kind, float(safety.distance) ** 2, float(safety.gamma),
        float(safety.sensing_radius) ** 2, np.ascontiguousarray(normals, dtype=float),
        float(bound),
    )  # fmt: skip


def run_safety(
    formation: Formation,
    law: Law,
    model: RobotModel,
    q0: NDArray[np.float64],
    dt: float,
    n_steps: int,
    check_every: int,
    tol: Tolerances,
    obstacles: Sequence[Any],
    safety: Any,
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray, NDArray, NDArray, int]:
    """Step the trials ``q0`` ``(B, n, k)``; what ``batch._run_numba`` returns.

    ``(x, v, status, steps, min_clearance, net_speed, q_window, window_step)``, trial by
    trial those of the stepping driver with a :class:`StopRule` (module docstring).
    """
    from ..safety import barrier_filter

    obstacles = tuple(obstacles)
    system = System(formation=formation, law=law, model=model, obstacles=obstacles, safety=safety)
    terms = law.compiled_terms(formation).writable()
    robots = model_terms(model)
    d_o, gamma = (safety.d_obstacle, safety.gamma) if safety is not None else (0.0, 0.0)
    rep = law.obstacle_repulsion() if obstacles else None
    obs = obstacle_terms(
        obstacles, d_obstacle=d_o, gamma=gamma,
        gain=rep.gain if rep else 0.0, eta=rep.repulsion.eta if rep else 1.0,
        influence=rep.repulsion.influence if rep else 1.0,
    )  # fmt: skip
    flt = filter_terms(safety)
    B, n, k = q0.shape
    window_step = n_steps - tol.drift_steps(dt)  # negative: never reached
    st = TrialState(
        x=q0.copy(), qc=np.array(q0[..., :2]), kc=np.full(B, -1, np.int64),
        k=np.zeros(B, np.int64), mc=system.clearance(q0), ns=np.full(B, np.nan),
        code=np.full(B, -1, np.int8), need_p=np.zeros((B, n, 2)), need_u=np.zeros((B, n, 2)),
        given=np.zeros(B, bool), given_u=np.zeros((B, n, 2)),
    )  # fmt: skip
    out = Outputs(x=np.empty((B, n, k)), v=np.full((B, n, k), np.nan),
                  steps=np.zeros(B, np.int64), qw=np.full((B, n, 2), np.nan))  # fmt: skip
    while True:
        run_trials(terms, robots, obs, flt, st, out, float(dt), int(n_steps), int(check_every),
                   float(tol.speed), int(window_step))  # fmt: skip
        paused = np.flatnonzero(st.code == _PAUSED)
        if paused.size == 0:
            break
        res = barrier_filter(safety, st.need_p[paused], st.need_u[paused], obstacles)
        st.given_u[paused] = res.u
        st.given[paused] = True
        st.code[paused] = -1
    return out.x, out.v, st.code.copy(), out.steps, st.mc, st.ns, out.qw, window_step
