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
   :func:`~formationlab.safety.decentralized.solve_rows`; ``barrier`` on the rows of
   :func:`formationlab.safety.barrier_constraints` by
   :func:`formationlab.safety.dual_active_set.centralized_command`: the closed form of
   one or two active rows, else Goldfarb and Idnani's dual active-set method (exact for
   any number of active rows), with ``barrier_filter``'s relaxation of rows with
   ``h < 0`` and its decentralized fallback. Only if rounding defeats that method (rare:
   at the gap's starts with a robot near a disc, docs/safety.md) does the trial pause;
   :func:`run_safety` then solves its QP with :func:`formationlab.safety.barrier_filter`
   (Clarabel) and the trial resumes with that command;
4. the robot model's rates, the stop rule, and the Euler step judged by the contact
   rule (``System.step_verdict``): not finite, contact between robots (``.kernels``'
   ``_contact``) or with an obstacle at the end of the step, or along it.

Trials run in parallel (``prange``), each from its start (or its pause) to its end.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numba
import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from ..analysis import Tolerances
from ..controllers import Law
from ..dynamics import System
from ..models import RobotModel
from ..safety.dual_active_set import FALLBACK, NUMERICAL, centralized_command
from ..safety.obstacle_terms import (
    barrier_row,
    hull_distance,
    obstacle_terms,
    piece_count,
    repel,
    signed_distance,
    swept_clearance,
)
from ..safety.projection import filter_robot, unchanged_robot
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
#: A chunk's status while some of its trials wait for a QP solve (-1: running, 0: done).
_PAUSED = -2
#: Most trials per chunk (the unit of parallel work; fewer so that every thread gets four).
CHUNK = 256


class FilterTerms(NamedTuple):
    """The safety filter as numbers (:class:`formationlab.safety.SafetyFilter`)."""

    kind: int  #: NONE, DECENTRALIZED or CENTRALIZED
    d2: float  #: D_s^2
    gamma: float
    r2: float  #: sensing radius^2 (inf: every pair)
    speed_n: NDArray[np.float64]  #: (S, 2) normals of the speed polygon
    speed_b: float


class ChunkState(NamedTuple):
    """What every chunk of ``C`` trials carries across a pause (``G`` chunks).

    ``x`` and ``xn`` are the double buffer of the states (which holds the current states:
    ``meta[c, 3]``); ``meta[c]`` is ``(live trials, step, step of the previous check,
    current buffer, status)`` with status -1 running, -2 paused for QPs, 0 done.
    """

    x: NDArray[np.float64]  #: (G, n, k, C)
    xn: NDArray[np.float64]  #: (G, n, k, C)
    qc: NDArray[np.float64]  #: (G, n, 2, C) positions at the previous check
    ids: NDArray[np.int64]  #: (G, C) the trial in each slot
    mc: NDArray[np.float64]  #: (G, C) least clearance over accepted states
    ns: NDArray[np.float64]  #: (G, C) net speed over the last check interval
    meta: NDArray[np.int64]  #: (G, 5)
    need: NDArray[np.bool_]  #: (G, C) the slot's trial waits for a QP solve
    need_p: NDArray[np.float64]  #: (G, C, n, 2) its points
    need_u: NDArray[np.float64]  #: (G, C, n, 2) its command before the filter
    given: NDArray[np.bool_]  #: (G, C) the QP's answer is in given_u
    given_u: NDArray[np.float64]  #: (G, C, n, 2)


class Outputs(NamedTuple):
    x: NDArray[np.float64]  #: (B, n, k) final states
    v: NDArray[np.float64]  #: (B, n, k) their rates
    steps: NDArray[np.int64]  #: (B,)
    status: NDArray[np.int8]  #: (B,)
    mc: NDArray[np.float64]  #: (B,) least clearance
    ns: NDArray[np.float64]  #: (B,) net speed
    qw: NDArray[np.float64]  #: (B, n, 2) positions at the start of the drift window


@njit(cache=True, nogil=True, inline="always")
def _decentralized(pq, uq, uf, obs, flt, nbr, A, bb, neg, owner, out) -> None:
    """``uf``: every robot's own rows (``decentralized_filter``'s) solved.

    A robot whose command satisfies its pair and speed rows (tested here, with the
    arithmetic of ``_project``'s first test) and has no obstacle near
    (:func:`unchanged_robot`) keeps it without building its rows.
    """
    n = pq.shape[0]
    d2 = flt.d2
    half = 0.5 * flt.gamma
    speed_n = flt.speed_n
    speed_b = flt.speed_b
    n_obs = obs.radius.shape[0]
    for r in range(n):
        x = pq[r, 0]
        y = pq[r, 1]
        uh0 = uq[r, 0]
        uh1 = uq[r, 1]
        uf[r, 0] = uh0
        uf[r, 1] = uh1
        deg = 0
        inside = True
        for j in range(n):  # neighbours in ascending order
            if j == r:
                continue
            dx = x - pq[j, 0]
            dy = y - pq[j, 1]
            if dx * dx + dy * dy <= flt.r2:
                nbr[deg] = j
                deg += 1
                h = dx * dx + dy * dy - d2
                inside = inside and -2.0 * dx * uh0 + -2.0 * dy * uh1 <= half * h * h * h
        for s in range(speed_n.shape[0]):
            inside = inside and speed_n[s, 0] * uh0 + speed_n[s, 1] * uh1 <= speed_b
        if inside and (n_obs == 0 or unchanged_robot(r, pq, uh0, uh1, nbr, 0, obs, d2,
                                                     flt.gamma, speed_n, speed_b)):  # fmt: skip
            continue
        filter_robot(r, pq, uh0, uh1, nbr, deg, obs, d2, flt.gamma, speed_n, speed_b, A, bb,
                     neg, owner, out)  # fmt: skip
        uf[r, 0] = out[0]
        uf[r, 1] = out[1]


@njit(cache=True, nogil=True, inline="always")
def _centralized(pq, uq, uf, obs, flt, ri, rj, ra, rb, rh, lam, mats, vecs, act, rb2) -> int:
    """``uf`` by :func:`centralized_command` on the rows of ``barrier_constraints``.

    Returns its status (``FALLBACK``: apply the decentralized filter; ``NUMERICAL``: solve
    the QP with Clarabel).
    """
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
            rh[m] = h
            m += 1
    for i in range(n):  # obstacle rows, robot-major
        for o in range(obs.radius.shape[0]):
            pieces = 1 if obs.radius[o] > 0 else obs.start[o + 1] - obs.start[o]
            for k in range(pieces):
                a0, a1, b, h = barrier_row(obs, o, k, pq[i, 0], pq[i, 1])
                ri[m] = i
                rj[m] = -1
                ra[m, 0] = a0
                ra[m, 1] = a1
                rb[m] = b
                rh[m] = h
                m += 1
    for i in range(n):  # speed rows, robot-major
        for s in range(flt.speed_n.shape[0]):
            ri[m] = i
            rj[m] = -1
            ra[m, 0] = flt.speed_n[s, 0]
            ra[m, 1] = flt.speed_n[s, 1]
            rb[m] = flt.speed_b
            rh[m] = np.inf
            m += 1
    return centralized_command(ri[:m], rj[:m], ra[:m], rb[:m], rh[:m], uq, uf, lam[:m], mats,
                               vecs, act, rb2[:m])  # fmt: skip


@njit(cache=True, nogil=True, inline="always")
def _obstacle_contact(obs, radius, x, xn, b, disp, floor):
    """Least robot-obstacle clearance at ``xn[:, :, b]`` and along the step from ``x``.

    ``(end, swept)`` as ``System.step_verdict`` sees them, computed exactly only where
    they can matter: an obstacle whose enclosing disc is farther than ``floor`` (the
    least clearance already known), ``0`` and ``_SWEPT_MARGIN disp`` (the step's largest
    move: farther, the straight path cannot reach it) leaves both at ``inf``.
    """
    end = np.inf
    swept = np.inf
    margin = _SWEPT_MARGIN * disp
    for i in range(xn.shape[0]):
        x1 = xn[i, 0, b]
        y1 = xn[i, 1, b]
        for o in range(obs.radius.shape[0]):
            low = hull_distance(obs, o, x1, y1)[0] - radius[i]
            if low > 0.0 and low > margin and low >= floor:
                continue
            s = signed_distance(obs, o, x1, y1)[0] - radius[i]
            end = min(end, s)
            if s <= margin:  # (|grad delta| = 1: farther is clear along the step)
                sw = swept_clearance(obs, o, x[i, 0, b], x[i, 1, b], x1, y1, radius[i])
                swept = min(swept, sw)
    return end, swept


@njit(cache=True, error_model="numpy", nogil=True)
def _chunk(c, terms, model, obs, flt, st, out, dt, n_steps, check_every, speed, window_step):
    """Steps of chunk ``c`` until every trial has ended or some trial needs a QP."""
    n = st.x.shape[1]
    kk = st.x.shape[2]
    C = st.x.shape[3]
    hand = model.kind == NEAR_IDENTITY
    turns = hand or model.kind == HEADING
    ids = st.ids[c]
    mc = st.mc[c]
    ns = st.ns[c]
    qc = st.qc[c]
    x, xn = (st.x[c], st.xn[c]) if st.meta[c, 3] == 0 else (st.xn[c], st.x[c])
    f = np.empty((n, kk, C))
    u = np.empty((n, 2, C))
    p = np.empty((n, 2, C) if hand else (1, 2, 1))
    # cos theta, sin theta of the unicycles (n, C), from the library at every step here
    hshape = (n, C) if turns else (1, 1)
    hc = np.empty(hshape)
    hs = np.empty(hshape)
    hcl = np.empty(hshape)
    hsl = np.empty(hshape)
    vel = np.empty(C)  # the unicycles' speeds (_rates)
    sigma = np.empty(C)
    gap = np.empty(C)
    swept = np.empty(C)
    near = np.empty(C)
    disp = np.zeros(C)
    code = np.full(C, -1, dtype=np.int8)
    pq = np.empty((n, 2))
    uq = np.empty((n, 2))
    uf = np.empty((n, 2))
    out2 = np.empty(2)
    n_obs = obs.radius.shape[0]
    rows = (n - 1) + piece_count(obs) + flt.speed_n.shape[0]
    A = np.empty((rows, 2))
    bb = np.empty(rows)
    neg = np.empty(rows, dtype=np.bool_)
    owner = np.empty(rows, dtype=np.int64)
    nbr = np.empty(max(n - 1, 1), dtype=np.int64)
    big = n * (n - 1) // 2 + n * (piece_count(obs) + flt.speed_n.shape[0]) if flt.kind == 2 else 1
    ri = np.empty(big, dtype=np.int64)
    rj = np.empty(big, dtype=np.int64)
    ra = np.empty((big, 2))
    rb = np.empty(big)
    rh = np.empty(big)
    lam = np.empty(big)
    rb2 = np.empty(big)
    dq = 2 * n if flt.kind == 2 else 1  # the centralized QP's unknowns (dual_active_set)
    mats = np.empty((2, dq, dq))
    vecs = np.empty((5, dq))
    act = np.empty(dq, dtype=np.int64)
    nact = st.meta[c, 0]
    step = st.meta[c, 1]
    kc = st.meta[c, 2]
    while nact > 0:
        k = step
        if turns:
            _headings(x, hc, hs, hcl, hsl, nact)
        src = p if hand else x
        if hand:
            _points(x, hc, hs, p, nact, model)
        _controls(src, u, sigma, nact, terms)
        pause = False
        for b in range(nact):  # obstacles' repulsion and the filter, trial by trial
            if n_obs == 0 and flt.kind == NONE:
                break
            for i in range(n):
                pq[i, 0] = src[i, 0, b]
                pq[i, 1] = src[i, 1, b]
                uq[i, 0] = u[i, 0, b]
                uq[i, 1] = u[i, 1, b]
            if n_obs > 0:
                repel(obs, terms.radius, pq, uq)
            if flt.kind == DECENTRALIZED:
                _decentralized(pq, uq, uf, obs, flt, nbr, A, bb, neg, owner, out2)
            elif flt.kind == CENTRALIZED and st.given[c, b]:
                st.given[c, b] = False
                for i in range(n):
                    uf[i, 0] = st.given_u[c, b, i, 0]
                    uf[i, 1] = st.given_u[c, b, i, 1]
            elif flt.kind == CENTRALIZED:
                qp = _centralized(pq, uq, uf, obs, flt, ri, rj, ra, rb, rh, lam, mats, vecs,
                                  act, rb2)  # fmt: skip
                if qp == FALLBACK:  # relaxed rows infeasible too: barrier_filter's fallback
                    _decentralized(pq, uq, uf, obs, flt, nbr, A, bb, neg, owner, out2)
                elif qp == NUMERICAL:
                    st.need[c, b] = True  # rounding defeated the exact method: Clarabel's turn
                    for i in range(n):
                        st.need_p[c, b, i, 0] = pq[i, 0]
                        st.need_p[c, b, i, 1] = pq[i, 1]
                        st.need_u[c, b, i, 0] = uq[i, 0]
                        st.need_u[c, b, i, 1] = uq[i, 1]
                    pause = True
                    continue
            else:
                for i in range(n):
                    uf[i, 0] = uq[i, 0]
                    uf[i, 1] = uq[i, 1]
            for i in range(n):
                u[i, 0, b] = uf[i, 0]
                u[i, 1, b] = uf[i, 1]
        if pause:  # the step is computed again, with the QPs' answers, when resumed
            for b in range(nact):
                st.given[c, b] = False
            st.meta[c, 0] = nact
            st.meta[c, 1] = step
            st.meta[c, 2] = kc
            st.meta[c, 4] = _PAUSED
            return
        _rates(x, hc, hs, u, f, vel, nact, model)
        if k == window_step:  # start of the drift window (the driver's q_window)
            for b in range(nact):
                for i in range(n):
                    out.qw[ids[b], i, 0] = x[i, 0, b]
                    out.qw[ids[b], i, 1] = x[i, 1, b]
        for b in range(nact):
            code[b] = -1
        if k % check_every == 0 or k == n_steps:  # StopRule
            for b in range(nact):
                nan = False
                for i in range(n):
                    for d in range(kk):
                        nan = nan or f[i, d, b] != f[i, d, b]
                still = (not nan) and _speed(f, b, model) <= speed
                if kc >= 0:
                    dd = 0.0
                    for i in range(n):
                        dx = x[i, 0, b] - qc[i, 0, b]
                        dy = x[i, 1, b] - qc[i, 1, b]
                        dd = max(dd, dx * dx + dy * dy)
                    net = math.sqrt(dd) / ((k - kc) * dt)
                    ns[b] = net
                    still = still or net <= speed
                for i in range(n):
                    qc[i, 0, b] = x[i, 0, b]
                    qc[i, 1, b] = x[i, 1, b]
                if still:
                    code[b] = _CONVERGED
            kc = k
        if k == n_steps:
            for b in range(nact):
                if code[b] < 0:
                    code[b] = _END
        else:  # explicit Euler, judged by the contact rule (System.step_verdict)
            for b in range(nact):
                disp[b] = 0.0
                near[b] = 0.0  # (here: 1 when the step is not finite)
            for i in range(n):
                for b in range(nact):
                    ex = dt * f[i, 0, b]
                    ey = dt * f[i, 1, b]
                    nx = x[i, 0, b] + ex
                    ny = x[i, 1, b] + ey
                    xn[i, 0, b] = nx
                    xn[i, 1, b] = ny
                    ex = nx - x[i, 0, b]
                    ey = ny - x[i, 1, b]
                    disp[b] = max(disp[b], ex * ex + ey * ey)
                for d in range(2, kk):
                    for b in range(nact):
                        xn[i, d, b] = x[i, d, b] + dt * f[i, d, b]
            for b in range(nact):
                disp[b] = math.sqrt(disp[b])
                for i in range(n):
                    for d in range(kk):
                        if not math.isfinite(xn[i, d, b]):
                            near[b] = 1.0
            bad = np.empty(C)
            for b in range(nact):
                bad[b] = near[b]
            _contact(xn, x, disp, gap, swept, near, nact, terms)
            for b in range(nact):
                if code[b] >= 0:
                    continue
                if bad[b] != 0.0:
                    code[b] = _NON_FINITE
                    continue
                if n_obs > 0:
                    end, sw = _obstacle_contact(obs, terms.radius, x, xn, b, disp[b],
                                                min(mc[b], gap[b]))  # fmt: skip
                    gap[b] = min(gap[b], end)
                    swept[b] = min(swept[b], sw)
                if not gap[b] > 0.0:
                    code[b] = _COLLISION
                elif not swept[b] > 0.0:
                    code[b] = _TOO_LARGE
                else:
                    mc[b] = min(mc[b], gap[b])
        # trials that end here end at x (a rejected step is not taken), with the rates f
        for b in range(nact):
            if code[b] >= 0:
                g = ids[b]
                for i in range(n):
                    for d in range(kk):
                        out.x[g, i, d] = x[i, d, b]
                        out.v[g, i, d] = f[i, d, b]
                out.steps[g] = k
                out.status[g] = code[b]
                out.mc[g] = mc[b]
                out.ns[g] = ns[b]
        x, xn = xn, x  # the live trials' next states are current now
        st.meta[c, 3] = 1 - st.meta[c, 3]
        for b in range(nact - 1, -1, -1):  # compact the live range
            if code[b] < 0:
                continue
            last = nact - 1
            if b != last:
                for i in range(n):
                    for d in range(kk):
                        x[i, d, b] = x[i, d, last]
                    qc[i, 0, b] = qc[i, 0, last]
                    qc[i, 1, b] = qc[i, 1, last]
                ids[b] = ids[last]
                mc[b] = mc[last]
                ns[b] = ns[last]
                code[b] = code[last]
            nact -= 1
        step += 1
    st.meta[c, 0] = 0
    st.meta[c, 4] = 0


@njit(cache=True, error_model="numpy", nogil=True, parallel=True)
def run_chunks(terms, model, obs, flt, st, out, dt, n_steps, check_every, speed, window_step):
    """Every running chunk until it ends or pauses, chunks in parallel."""
    for c in prange(st.x.shape[0]):
        if st.meta[c, 4] == -1:
            _chunk(c, terms, model, obs, flt, st, out, dt, n_steps, check_every, speed,
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
    C = int(min(CHUNK, max(1, -(-B // (4 * numba.get_num_threads())))))
    G = -(-B // C)
    window_step = n_steps - tol.drift_steps(dt)  # negative: never reached
    x = np.zeros((G, n, k, C))
    ids = np.zeros((G, C), np.int64)
    mc0 = system.clearance(q0)
    mc = np.full((G, C), np.inf)
    meta = np.zeros((G, 5), np.int64)
    for g in range(G):
        sel = np.arange(g * C, min(B, (g + 1) * C))
        x[g, :, :, : sel.size] = np.moveaxis(q0[sel], 0, -1)
        ids[g, : sel.size] = sel
        mc[g, : sel.size] = mc0[sel]
        meta[g] = (sel.size, 0, -1, 0, -1)
    st = ChunkState(
        x=x, xn=np.zeros_like(x), qc=np.array(x[:, :, :2], order="C"), ids=ids, mc=mc,
        ns=np.full((G, C), np.nan), meta=meta, need=np.zeros((G, C), bool),
        need_p=np.zeros((G, C, n, 2)), need_u=np.zeros((G, C, n, 2)),
        given=np.zeros((G, C), bool), given_u=np.zeros((G, C, n, 2)),
    )  # fmt: skip
    out = Outputs(
        x=np.empty((B, n, k)), v=np.full((B, n, k), np.nan), steps=np.zeros(B, np.int64),
        status=np.zeros(B, np.int8), mc=np.full(B, np.inf), ns=np.full(B, np.nan),
        qw=np.full((B, n, 2), np.nan),
    )  # fmt: skip
    while True:
        run_chunks(terms, robots, obs, flt, st, out, float(dt), int(n_steps), int(check_every),
                   float(tol.speed), int(window_step))  # fmt: skip
        wait_g, wait_b = np.nonzero(st.need)  # chunks paused, and their slots needing a QP
        if wait_g.size == 0:
            break
        res = barrier_filter(safety, st.need_p[wait_g, wait_b], st.need_u[wait_g, wait_b],
                             obstacles)  # fmt: skip
        st.given_u[wait_g, wait_b] = res.u
        st.given[wait_g, wait_b] = True
        st.need[wait_g, wait_b] = False
        st.meta[np.unique(wait_g), 4] = -1
    return out.x, out.v, out.status, out.steps, out.mc, out.ns, out.qw, window_step
