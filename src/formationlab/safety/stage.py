"""Obstacles and the safety filter as a stage of the compiled loop (:mod:`formationlab.engine`).

Per trial and step, after the law's control (as ``System.rhs`` does it):

1. plus Khatib's repulsion from the obstacles (:func:`.obstacle_terms.repel`);
2. then the filter: ``barrier-decentralized`` robot by robot, the rows of
   :func:`formationlab.safety.decentralized_filter` in its order solved by
   :func:`.projection.filter_robot`; ``barrier`` on the rows of
   :func:`formationlab.safety.barrier_constraints` by
   :func:`.dual_active_set.centralized_command`: the closed form of one or two active
   rows, else Goldfarb and Idnani's dual active-set method (exact for any number of
   active rows), with ``barrier_filter``'s relaxation of rows with ``h < 0`` and its
   decentralized fallback. Only if rounding defeats that method (rare: at the gap's starts
   with a robot near a disc, docs/safety.md) does :func:`filter_command` answer
   ``NUMERICAL``: the loop then pauses the trial, the host solves its QP with
   :func:`formationlab.safety.barrier_filter` (Clarabel) and the trial resumes with that
   command.

:func:`obstacle_contact` is the obstacles' part of the contact rule.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..neighbours.cell_grid import build_grid, neighbours_of
from .condition import barrier_bound
from .dual_active_set import FALLBACK, NUMERICAL, centralized_command
from .obstacle_terms import (
    barrier_row,
    hull_distance,
    piece_count,
    repel,
    signed_distance,
    swept_clearance,
)
from .pairs import DENSE_BELOW
from .projection import filter_robot, unchanged_robot

__all__ = [
    "CENTRALIZED",
    "DECENTRALIZED",
    "NONE",
    "FilterScratch",
    "FilterTerms",
    "filter_command",
    "filter_scratch",
    "filter_terms",
    "obstacle_contact",
]

NONE, DECENTRALIZED, CENTRALIZED = 0, 1, 2
#: what :func:`filter_command` answers
DONE, WAIT = 0, 1


class FilterTerms(NamedTuple):
    """The safety filter as numbers (:class:`formationlab.safety.SafetyFilter`)."""

    kind: int  #: NONE, DECENTRALIZED or CENTRALIZED
    d2: float  #: D_s^2
    gamma: float
    step: float  #: the Euler step the rows guard (0: the continuous rows)
    r2: float  #: sensing radius^2 (inf: every pair)
    speed_n: NDArray[np.float64]  #: (S, 2) normals of the speed polygon
    speed_b: float


class FilterScratch(NamedTuple):
    """One chunk's scratch space of the filter (allocated once per call of the loop)."""

    pq: NDArray[np.float64]  #: (n, 2) a trial's points
    uq: NDArray[np.float64]  #: (n, 2) its command before the filter
    uf: NDArray[np.float64]  #: (n, 2) after
    out: NDArray[np.float64]  #: (2,)
    A: NDArray[np.float64]
    bb: NDArray[np.float64]
    neg: NDArray[np.bool_]
    owner: NDArray[np.int64]
    nbr: NDArray[np.int64]
    ri: NDArray[np.int64]
    rj: NDArray[np.int64]
    ra: NDArray[np.float64]
    rb: NDArray[np.float64]
    rh: NDArray[np.float64]
    lam: NDArray[np.float64]
    rb2: NDArray[np.float64]
    mats: NDArray[np.float64]
    vecs: NDArray[np.float64]
    act: NDArray[np.int64]
    #: (1,) least squared distance of two points within the sensing radius at the trial's
    #: state (inf: no such pair), which the loop keeps as its least over the run
    least: NDArray[np.float64]


def filter_terms(safety: Any) -> FilterTerms:
    """The :class:`FilterTerms` of a :class:`~formationlab.safety.SafetyFilter` (or None)."""
    if safety is None or not safety.enabled:
        return FilterTerms(NONE, 0.0, 0.0, 0.0, 0.0, np.zeros((0, 2)), 0.0)
    normals, bound = safety.speed_polygon()
    kind = DECENTRALIZED if safety.filter == "barrier-decentralized" else CENTRALIZED
    return FilterTerms(
        kind, float(safety.distance) ** 2, float(safety.gamma), safety.rows_step,
        float(safety.sensing_radius) ** 2, np.ascontiguousarray(normals, dtype=float),
        float(bound),
    )  # fmt: skip


@njit(cache=True, nogil=True)
def filter_scratch(n, obs, flt):
    """The :class:`FilterScratch` of ``n`` robots among ``obs`` under ``flt``."""
    rows = (n - 1) + piece_count(obs) + flt.speed_n.shape[0]
    big = n * (n - 1) // 2 + n * (piece_count(obs) + flt.speed_n.shape[0])
    big = big if flt.kind == CENTRALIZED else 1
    dq = 2 * n if flt.kind == CENTRALIZED else 1  # the centralized QP's unknowns
    return FilterScratch(
        np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 2)), np.empty(2),
        np.empty((rows, 2)), np.empty(rows), np.empty(rows, dtype=np.bool_),
        np.empty(rows, dtype=np.int64), np.empty(max(n - 1, 1), dtype=np.int64),
        np.empty(big, dtype=np.int64), np.empty(big, dtype=np.int64), np.empty((big, 2)),
        np.empty(big), np.empty(big), np.empty(big), np.empty(big), np.empty((2, dq, dq)),
        np.empty((5, dq)), np.empty(dq, dtype=np.int64), np.full(1, np.inf),
    )  # fmt: skip


@njit(cache=True, nogil=True, inline="always")
def _decentralized(pq, uq, uf, obs, flt, nbr, A, bb, neg, owner, out, least) -> None:
    """``uf``: every robot's own rows (``decentralized_filter``'s) solved; ``least[0]``
    the least squared distance of the pairs that pose rows.

    A robot whose command satisfies its pair and speed rows (tested here, with the
    arithmetic of ``_project``'s first test) and has no obstacle near
    (:func:`unchanged_robot`) keeps it without building its rows.
    """
    n = pq.shape[0]
    d2 = flt.d2
    speed_n = flt.speed_n
    speed_b = flt.speed_b
    n_obs = obs.radius.shape[0]
    grid = n >= DENSE_BELOW and math.isfinite(flt.r2)  # else all pairs (decentralized.py's rule)
    if grid:  # (neighbours within the sensing radius from a grid of cells: O(n))
        x0, y0, side, gx, gy, start, order = build_grid(pq, math.sqrt(flt.r2))
    for r in range(n):
        x = pq[r, 0]
        y = pq[r, 1]
        uh0 = uq[r, 0]
        uh1 = uq[r, 1]
        uf[r, 0] = uh0
        uf[r, 1] = uh1
        deg = 0
        if grid:
            deg = neighbours_of(r, pq, flt.r2, x0, y0, side, gx, gy, start, order, nbr)
        else:
            for j in range(n):  # neighbours in ascending order
                if j == r:
                    continue
                dx = x - pq[j, 0]
                dy = y - pq[j, 1]
                if dx * dx + dy * dy <= flt.r2:
                    nbr[deg] = j
                    deg += 1
        inside = True
        for p in range(deg):  # (the first test of _project, row by row)
            dx = x - pq[nbr[p], 0]
            dy = y - pq[nbr[p], 1]
            least[0] = min(least[0], dx * dx + dy * dy)
            h = dx * dx + dy * dy - d2
            bound = 0.5 * barrier_bound(h, flt.gamma, flt.step)  # (half of the pair's)
            inside = inside and -2.0 * dx * uh0 + -2.0 * dy * uh1 <= bound
        for s in range(speed_n.shape[0]):
            inside = inside and speed_n[s, 0] * uh0 + speed_n[s, 1] * uh1 <= speed_b
        if inside and (n_obs == 0 or unchanged_robot(r, pq, uh0, uh1, nbr, 0, obs, d2, flt.gamma,
                                                     flt.step, speed_n, speed_b)):  # fmt: skip
            continue
        filter_robot(r, pq, uh0, uh1, nbr, deg, obs, d2, flt.gamma, flt.step, speed_n, speed_b,
                     A, bb, neg, owner, out)  # fmt: skip
        uf[r, 0] = out[0]
        uf[r, 1] = out[1]


@njit(cache=True, nogil=True, inline="always")
def _centralized(pq, uq, uf, obs, flt, ri, rj, ra, rb, rh, lam, mats, vecs, act, rb2,
                 least) -> int:  # fmt: skip
    """``uf`` by :func:`centralized_command` on the rows of ``barrier_constraints``;
    ``least[0]`` the least squared distance of the pairs that pose rows.

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
            least[0] = min(least[0], wx * wx + wy * wy)
            h = wx * wx + wy * wy - flt.d2
            ri[m] = i
            rj[m] = j
            ra[m, 0] = -2.0 * wx
            ra[m, 1] = -2.0 * wy
            rb[m] = barrier_bound(h, flt.gamma, flt.step)
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
def obstacle_contact(obs, radius, x, xn, b, margin, floor):
    """Least robot-obstacle clearance at ``xn[:, :, b]`` and along the step from ``x``.

    ``(end, swept)`` as ``System.step_verdict`` sees them, computed exactly only where
    they can matter: an obstacle whose enclosing disc is farther than ``floor`` (the
    least clearance already known), ``0`` and ``margin`` (a margin over the step's largest
    move: farther, the straight path cannot reach it) leaves both at ``inf``.
    """
    end = np.inf
    swept = np.inf
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


# (not inlined at numba's IR level: inlined into the loop, with its return inside a branch,
# it gave wrong commands under numba 0.68; LLVM still inlines what pays)
@njit(cache=True, error_model="numpy", nogil=True)
def filter_command(src, u, b, radius, obs, flt, given, given_u, S):
    """Trial ``b``'s command ``u[:, :, b]`` at its points ``src[:, :, b]`` with the obstacles'
    repulsion and through the filter, in place; ``WAIT`` when it needs Clarabel (its points
    and command are then in ``S.pq``, ``S.uq``). ``given``: the host's answer for this trial
    is in ``given_u`` ``(n, 2)``. ``S.least[0]`` becomes the least squared distance of two
    points within the sensing radius (the pairs the filter keeps ``D_s`` apart), measured
    when the filter is solved here (a trial given its answer was measured when it paused)."""
    n = src.shape[0]
    S.least[0] = np.inf
    for i in range(n):
        S.pq[i, 0] = src[i, 0, b]
        S.pq[i, 1] = src[i, 1, b]
        S.uq[i, 0] = u[i, 0, b]
        S.uq[i, 1] = u[i, 1, b]
    if obs.radius.shape[0] > 0:
        repel(obs, radius, S.pq, S.uq)
    if flt.kind == DECENTRALIZED:
        _decentralized(S.pq, S.uq, S.uf, obs, flt, S.nbr, S.A, S.bb, S.neg, S.owner, S.out,
                       S.least)  # fmt: skip
    elif flt.kind == CENTRALIZED and given:
        for i in range(n):
            S.uf[i, 0] = given_u[i, 0]
            S.uf[i, 1] = given_u[i, 1]
    elif flt.kind == CENTRALIZED:
        qp = _centralized(S.pq, S.uq, S.uf, obs, flt, S.ri, S.rj, S.ra, S.rb, S.rh, S.lam,
                          S.mats, S.vecs, S.act, S.rb2, S.least)  # fmt: skip
        if qp == FALLBACK:  # relaxed rows infeasible too: barrier_filter's fallback
            _decentralized(S.pq, S.uq, S.uf, obs, flt, S.nbr, S.A, S.bb, S.neg, S.owner, S.out,
                       S.least)  # fmt: skip
        elif qp == NUMERICAL:  # rounding defeated the exact method: Clarabel's turn
            return WAIT
    else:
        for i in range(n):
            S.uf[i, 0] = S.uq[i, 0]
            S.uf[i, 1] = S.uq[i, 1]
    for i in range(n):
        u[i, 0, b] = S.uf[i, 0]
        u[i, 1, b] = S.uf[i, 1]
    return DONE
