"""The lists layout of the compiled loop: a law's field and contact over a close-pair list.

For runs of many robots (one trial, ``C = 1``) the loop (:func:`.loop.step_chunk`) takes the
law from its :class:`~formationlab.engine.layout.RunLayout` (lists by robot) instead of its
pairs, and finds the pairs that can repel or touch in a close-pair (Verlet) list on a cell
grid (:mod:`formationlab.neighbours.close_list`). Nothing in it is ``n x n`` and nothing
is allocated per step:

1. **items** (:func:`items_chunk`), at each new state: each edge's force ``k_c phi'(r)/r
   r_ij`` (eqs. 7, 8; or Krick et al.'s), each close pair's Khatib repulsion, each switching
   surface's decision (eq. 14) and each area triangle's error, computed once, with the least
   clearance and the least swept clearance of the step that led there (the contact rule,
   :mod:`.contact`);
2. **gather** (:func:`gather_chunk`): each robot sums its edges' and pairs' forces (with the
   sign of its end), its active restricted terms (eqs. 11, 13) and its area terms, in the
   fixed order of its rows;
3. **step** (:func:`advance_parallel`, or :func:`.euler.euler` on one thread): the Euler
   step with each robot's move and its drift since the list was built.

The stage (:class:`ListStage`): :func:`list_field` is the law's field at the current state
(the items were computed when the step that led there was judged), :func:`list_step` the
Euler step and :func:`list_contact` the verdict on it: the close list rebuilt if it may miss
a pair that matters (Khatib's ``gamma_ij`` acts only within clearance ``s0``, and a step can
only carry two robots through each other if they end closer than twice its largest move,
so every step needs the pairs of clearance below ``max(s0, 2.01 move)``: the list holds
those plus a skin of ``(s0 + max a_ij) / 2``, and is rebuilt when a robot has moved more
than half the skin since, :func:`~formationlab.neighbours.close_list.list_holds`), then the
items at the new state.
A list that needs more room than its buffers stops the loop (``GROW``): the host grows them
(:func:`grow`) and the step is taken again.

Each pass is split into chunks of consecutive items or robots; a chunk's numbers do not
depend on the others (and the least clearances are minima, which do not depend on order), so
one thread or several give the same bits.
"""

from __future__ import annotations

import math
import os
from typing import NamedTuple

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from ..controllers.kinds.edges import edge_force_at, edge_gain
from ..controllers.kinds.khatib import repulsion_gain
from ..controllers.kinds.restriction import (
    restriction_force,
    switched_on,
    switching,
    triangle_product,
)
from ..controllers.kinds.signed_area import area_force, area_gain, signed_area
from ..neighbours.close_list import build_close_list, grown, list_holds, pair_rows
from .contact import SWEPT_MARGIN, segment_clearance, segment_clearance_in_space
from .euler import PLANE, SPACE, euler
from .layout import RunLayout

# numba's OpenMP threads wait for work asleep rather than spinning (unless the user says
# otherwise). A step launches two parallel passes; on a machine shared with other work a
# spinning thread holds a core the other thread needs, and the passes of a 10,000-robot
# step took 115 ms instead of 1 ms (load average 7 on 2 cores). Read by the OpenMP
# runtime when numba first starts its threads, so it is set on import.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__all__ = [
    "ListStage",
    "advance_parallel",
    "gather_chunk",
    "gather_parallel",
    "grow",
    "items",
    "items_chunk",
    "items_parallel",
    "list_contact",
    "list_field",
    "list_stage",
    "list_step",
]

#: what ``ListStage.kept`` holds, by index: the list's reach, the largest drift since it was
#: built, its pairs, whether the items are those of the current state (1) or not yet (0),
#: the pairs a list that did not fit needs, and how much farther apart the law's points
#: can be than the robots' centres (twice the near-identity offset; else 0)
REACH, DRIFT, PAIRS, FRESH, NEED, EXTRA = range(6)


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _swept(q, qp, i, j, a, axes):
    """Least ``r_ij - a`` along the straight step ``qp -> q`` (``System.swept_clearance``),
    positions ``(n, axes.ndim)``."""
    x0 = qp[j, 0] - qp[i, 0]
    y0 = qp[j, 1] - qp[i, 1]
    ex = (q[j, 0] - q[i, 0]) - x0
    ey = (q[j, 1] - q[i, 1]) - y0
    if axes.ndim == 2:
        return segment_clearance(x0, y0, ex, ey, a)
    z0 = qp[j, 2] - qp[i, 2]
    ez = (q[j, 2] - q[i, 2]) - z0
    return segment_clearance_in_space(x0, y0, z0, ex, ey, ez, a)


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _part(c, chunks, size):
    return c * size // chunks, (c + 1) * size // chunks


@njit(cache=True, fastmath=False, error_model="numpy")
def _edges(lo, hi, q, qp, sweep, kind, gain, edge_i, edge_j, edge_a, edge_d, bearing, fe):
    """Edges ``lo:hi``: each force on its first robot into ``fe[0], fe[1]``, its clearance
    into ``fe[2]``; returns the least clearance and the least swept one.

    The differences are gathered first, so that the arithmetic runs over contiguous
    slices counted from 0 (which the compiler vectorises: the same operations, in about
    half the time). ``bearing`` is ``(edge_bx, edge_by, stride)``: the desired bearings of
    a bearing term, edge ``e`` at row ``e * stride`` (one unused row, stride 0, otherwise).
    """
    ei, ej, ea, ed = edge_i[lo:hi], edge_j[lo:hi], edge_a[lo:hi], edge_d[lo:hi]
    edge_bx, edge_by, step = bearing
    bx = edge_bx[lo * step :]
    by = edge_by[lo * step :]
    fx, fy, clr = fe[0, lo:hi], fe[1, lo:hi], fe[2, lo:hi]
    for e in range(hi - lo):
        i = ei[e]
        j = ej[e]
        fx[e] = q[j, 0] - q[i, 0]
        fy[e] = q[j, 1] - q[i, 1]
    for e in range(hi - lo):
        dx = fx[e]
        dy = fy[e]
        r = math.sqrt(dx * dx + dy * dy)  # (once: the force's and the clearance's)
        f0, f1 = edge_force_at(kind, dx, dy, r, ed[e], ea[e], gain, bx[e * step], by[e * step])
        fx[e] = f0  # eq. (8), Krick et al.'s, or Zhao and Zelazo's (its kind)
        fy[e] = f1
        clr[e] = r - ea[e]
    return _least(hi - lo, q, qp, sweep, ei, ej, ea, clr, PLANE)


@njit(cache=True, fastmath=False, error_model="numpy")
def _edges_in_space(lo, hi, q, qp, sweep, kind, gain, edge_i, edge_j, edge_a, edge_d, fe):
    """:func:`_edges` in space (``q`` ``(n, 3)``, ``fe`` ``(4, m)``: x, y, z, clearance), for
    the edge terms along ``r_ij`` (:func:`~formationlab.controllers.kinds.edges.edge_gain`)."""
    ei, ej, ea, ed = edge_i[lo:hi], edge_j[lo:hi], edge_a[lo:hi], edge_d[lo:hi]
    fx, fy, fz, clr = fe[0, lo:hi], fe[1, lo:hi], fe[2, lo:hi], fe[3, lo:hi]
    for e in range(hi - lo):
        i = ei[e]
        j = ej[e]
        fx[e] = q[j, 0] - q[i, 0]
        fy[e] = q[j, 1] - q[i, 1]
        fz[e] = q[j, 2] - q[i, 2]
    for e in range(hi - lo):
        dx = fx[e]
        dy = fy[e]
        dz = fz[e]
        r2 = dx * dx + dy * dy + dz * dz
        r = math.sqrt(r2)
        g = edge_gain(kind, r, r2, ed[e], ea[e], gain)  # eq. (8), or Krick et al.'s
        fx[e] = g * dx
        fy[e] = g * dy
        fz[e] = g * dz
        clr[e] = r - ea[e]
    g_min = _smallest(hi - lo, clr)
    if g_min > sweep:  # (no edge to test along the step: the common case)
        return g_min, np.inf
    return _least(hi - lo, q, qp, sweep, ei, ej, ea, clr, SPACE)


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _smallest(m, clr):
    """The least of ``clr[:m]`` (finite numbers: the same in any order), in four running
    minima, so that the comparisons of four items overlap instead of waiting on each other."""
    m0 = np.inf
    m1 = np.inf
    m2 = np.inf
    m3 = np.inf
    top = m - m % 4
    for e in range(0, top, 4):
        m0 = min(m0, clr[e])
        m1 = min(m1, clr[e + 1])
        m2 = min(m2, clr[e + 2])
        m3 = min(m3, clr[e + 3])
    for e in range(top, m):
        m0 = min(m0, clr[e])
    return min(min(m0, m1), min(m2, m3))


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _least(m, q, qp, sweep, ei, ej, ea, clr, axes):
    """The least clearance of ``m`` edges (``clr``) and the least along the step of those
    within ``sweep``."""
    g_min = np.inf
    w_min = np.inf
    for e in range(m):
        g_min = min(g_min, clr[e])
        if clr[e] <= sweep:  # tested along the step
            w_min = min(w_min, _swept(q, qp, ei[e], ej[e], ea[e], axes))
    return g_min, w_min


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _pair(p, q, radius, s0, gain, eta, pairs, fp, axes):
    """Close pair ``p``'s Khatib repulsion on its first robot into ``fp[p]`` (zero beyond
    ``s0``); returns its clearance."""
    i = pairs[p, 0]
    j = pairs[p, 1]
    a = radius[i] + radius[j]
    dx = q[j, 0] - q[i, 0]
    dy = q[j, 1] - q[i, 1]
    if axes.ndim == 3:  # (a constant: compiled for one dimension)
        dz = q[j, 2] - q[i, 2]
        r = math.sqrt(dx * dx + dy * dy + dz * dz)
        fp[p, 2] = dz  # (scaled below)
    else:
        r = math.sqrt(dx * dx + dy * dy)
    clr = r - a
    g = repulsion_gain(r, clr, gain, eta, s0)  # k_r gamma'(s) / r, Khatib
    fp[p, 0] = g * dx
    fp[p, 1] = g * dy
    if axes.ndim == 3:
        fp[p, 2] *= g
    return clr


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _pair_swept(p, q, qp, radius, pairs, axes):
    """Least clearance of close pair ``p`` along the step."""
    i = pairs[p, 0]
    j = pairs[p, 1]
    return _swept(q, qp, i, j, radius[i] + radius[j], axes)


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _surface(s, q, surf_a, surf_b, surf_c, surf_beta, stride, theta, on):
    """Whether surface ``s`` switches its restrictions on: eq. (14), as triangle_products
    (its ``beta`` is ``surf_beta[s * stride]``)."""
    ia, ib, ic = surf_a[s], surf_b[s], surf_c[s]
    cab = triangle_product(q[ia, 0], q[ia, 1], q[ib, 0], q[ib, 1], q[ic, 0], q[ic, 1])
    on[s] = switched_on(switching(surf_beta[s * stride], cab, theta))  # eq. (14)


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _area(mm, q, area_a, area_b, area_c, area_target, gain, area_g):
    """Area triangle ``mm``'s error term of the signed-area penalty."""
    ia, ib, ic = area_a[mm], area_b[mm], area_c[mm]
    area = signed_area(q[ia, 0], q[ia, 1], q[ib, 0], q[ib, 1], q[ic, 0], q[ic, 1])
    area_g[mm] = area_gain(area, area_target[mm], gain)


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _gather(i, q, R, p_ptr, p_rows, fe, fp, on, area_g, u):
    """Robot ``i``'s ``u_i`` gathered from its rows, in their fixed order."""
    nbr_ptr, nbr_edge, term_ptr, term_s, term_w, stride, term_j, term_k = R[:8]
    area_ptr, area_rows, area_a, area_b, area_c = R[8:]
    ux = 0.0
    uy = 0.0
    for p in range(nbr_ptr[i], nbr_ptr[i + 1]):  # edges, eq. (8)
        e = nbr_edge[p]
        if e >= 0:
            ux += fe[0, e]
            uy += fe[1, e]
        else:
            ux -= fe[0, ~e]
            uy -= fe[1, ~e]
    for p in range(p_ptr[i], p_ptr[i + 1]):  # Khatib's repulsion
        e = p_rows[p]
        if e >= 0:
            ux += fp[e, 0]
            uy += fp[e, 1]
        else:
            ux -= fp[~e, 0]
            uy -= fp[~e, 1]
    for p in range(term_ptr[i], term_ptr[i + 1]):  # eqs. (11), (13), (23)
        if on[term_s[p]]:
            j, k = term_j[p], term_k[p]
            fx, fy = restriction_force(term_w[p * stride], q[k, 0] - q[j, 0], q[k, 1] - q[j, 1])
            ux += fx
            uy += fy
    for p in range(area_ptr[i], area_ptr[i + 1]):  # signed-area penalty
        mm = area_rows[p] // 3
        corner = area_rows[p] - 3 * mm
        ia, ib, ic = area_a[mm], area_b[mm], area_c[mm]
        if corner == 1:  # (the vertex at 0, its two others in turn)
            ia, ib, ic = ib, ic, ia
        elif corner == 2:
            ia, ib, ic = ic, ia, ib
        fx, fy = area_force(area_g[mm], q[ib, 0], q[ib, 1], q[ic, 0], q[ic, 1])
        ux += fx
        uy += fy
    u[i, 0] = ux
    u[i, 1] = uy


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _gather_in_space(i, nbr_ptr, nbr_edge, p_ptr, p_rows, fe, fp, u):
    """:func:`_gather` in space: robot ``i``'s edges and close pairs (the terms that compile
    there), in the fixed order of its rows."""
    ux = 0.0
    uy = 0.0
    uz = 0.0
    for p in range(nbr_ptr[i], nbr_ptr[i + 1]):  # edges, eq. (8)
        e = nbr_edge[p]
        if e >= 0:
            ux += fe[0, e]
            uy += fe[1, e]
            uz += fe[2, e]
        else:
            ux -= fe[0, ~e]
            uy -= fe[1, ~e]
            uz -= fe[2, ~e]
    for p in range(p_ptr[i], p_ptr[i + 1]):  # Khatib's repulsion
        e = p_rows[p]
        if e >= 0:
            ux += fp[e, 0]
            uy += fp[e, 1]
            uz += fp[e, 2]
        else:
            ux -= fp[~e, 0]
            uy -= fp[~e, 1]
            uz -= fp[~e, 2]
    u[i, 0] = ux
    u[i, 1] = uy
    u[i, 2] = uz


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def items_chunk(c, chunks, q, qp, sweep, L, pairs, n_pairs, fe, fp, on, area_g, least, axes):
    """Chunk ``c`` of ``chunks`` of every kind of item at positions ``q`` ``(n, d)``
    (``d = axes.ndim``; in space the edges and close pairs).

    ``qp`` is the state the step came from and ``sweep`` twice its largest move
    (with a margin): pairs closer than that are tested along the step. Writes the
    forces ``fe`` ``(3, m)`` (x, y, and the clearance) and ``fp`` ``(p, 2)`` (on robot
    ``i`` of each pair ``i < j``; robot ``j`` takes the opposite), the surfaces'
    decisions ``on`` ``(s,)`` and the area errors ``area_g``; ``least[c]`` gets the least
    clearance and the least swept clearance of the chunk's edges and pairs.
    """
    kind, gain, ei, ej, ea, ed = L.kind, L.edge_gain, L.edge_i, L.edge_j, L.edge_a, L.edge_d
    radius, s0, k_r, eta = L.radius, L.influence, L.repulsion_gain, L.eta
    sa, sb, sc, beta, theta = L.surf_a, L.surf_b, L.surf_c, L.surf_beta, L.theta
    stride = L.surf_stride
    aa, ab, ac, target, a_gain = L.area_a, L.area_b, L.area_c, L.area_target, L.area_gain
    lo, hi = _part(c, chunks, L.edge_i.shape[0])
    if axes.ndim == 3:  # (a constant: compiled for one dimension)
        g_min, w_min = _edges_in_space(lo, hi, q, qp, sweep, kind, gain, ei, ej, ea, ed, fe)
    else:
        g_min, w_min = _edges(
            lo,
            hi,
            q,
            qp,
            sweep,
            kind,
            gain,
            ei,
            ej,
            ea,
            ed,
            (L.edge_bx, L.edge_by, L.edge_b_stride),
            fe,
        )
    lo, hi = _part(c, chunks, n_pairs)
    for p in range(lo, hi):
        clr = _pair(p, q, radius, s0, k_r, eta, pairs, fp, axes)
        g_min = min(g_min, clr)
        if clr <= sweep:
            w_min = min(w_min, _pair_swept(p, q, qp, radius, pairs, axes))
    lo, hi = _part(c, chunks, L.surf_a.shape[0])
    for s in range(lo, hi):
        _surface(s, q, sa, sb, sc, beta, stride, theta, on)
    lo, hi = _part(c, chunks, L.area_a.shape[0])
    for mm in range(lo, hi):
        _area(mm, q, aa, ab, ac, target, a_gain, area_g)
    least[c, 0] = g_min
    least[c, 1] = w_min


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def gather_chunk(c, chunks, q, L, p_ptr, p_rows, fe, fp, on, area_g, u, axes):
    """Chunk ``c`` of the robots: ``u = f(q)`` ``(n, d)`` gathered from the items."""
    R = (
        L.nbr_ptr, L.nbr_edge, L.term_ptr, L.term_s, L.term_w, L.term_stride, L.term_j, L.term_k,
        L.area_ptr, L.area_rows, L.area_a, L.area_b, L.area_c,
    )  # fmt: skip
    lo, hi = _part(c, chunks, q.shape[0])
    for i in range(lo, hi):
        if axes.ndim == 3:  # (a constant: compiled for one dimension)
            _gather_in_space(i, L.nbr_ptr, L.nbr_edge, p_ptr, p_rows, fe, fp, u)
        else:
            _gather(i, q, R, p_ptr, p_rows, fe, fp, on, area_g, u)


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def items(q, qp, sweep, L, pairs, n_pairs, fe, fp, on, area_g, least, axes):
    """:func:`items_chunk` over everything, on one thread (into ``least[0]``)."""
    items_chunk(0, 1, q, qp, sweep, L, pairs, n_pairs, fe, fp, on, area_g, least, axes)


@njit(cache=True, fastmath=False, error_model="numpy", parallel=True)
def items_parallel(q, qp, sweep, L, pairs, n_pairs, fe, fp, on, area_g, least, chunks, axes):
    """:func:`items_chunk` in ``chunks`` chunks on numba's threads."""
    for c in prange(chunks):
        items_chunk(c, chunks, q, qp, sweep, L, pairs, n_pairs, fe, fp, on, area_g, least, axes)


@njit(cache=True, fastmath=False, error_model="numpy", parallel=True)
def gather_parallel(q, L, p_ptr, p_rows, fe, fp, on, area_g, u, chunks, axes):
    """:func:`gather_chunk` in ``chunks`` chunks on numba's threads."""
    for c in prange(chunks):
        gather_chunk(c, chunks, q, L, p_ptr, p_rows, fe, fp, on, area_g, u, axes)


@njit(cache=True, fastmath=False, error_model="numpy", parallel=True)
def advance_parallel(x, f, xn, qb, dt, moves, chunks, axes):
    """The Euler step (:func:`.euler.euler`) of one trial ``x`` ``(n, k, 1)`` in ``chunks``
    chunks of robots on numba's threads: ``moves[c]`` gets chunk ``c``'s largest squared move,
    its largest squared distance of ``xn`` from ``qb`` and its finiteness (0: finite)."""
    for c in prange(chunks):
        lo, hi = _part(c, chunks, x.shape[0])
        moves[c, 0] = 0.0
        moves[c, 2] = 0.0
        euler(x, f, xn, dt, lo, hi, 1, moves[c, 0:1], moves[c, 2:3], axes)
        moves[c, 1] = _drift(xn, qb, lo, hi, axes)


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _drift(xn, qb, lo, hi, axes):
    """Largest squared distance of robots ``lo:hi`` of ``xn`` ``(n, k, 1)`` from ``qb``."""
    far = 0.0
    for i in range(lo, hi):
        bx = xn[i, 0, 0] - qb[i, 0]
        by = xn[i, 1, 0] - qb[i, 1]
        if axes.ndim == 3:  # (a constant: compiled for one dimension)
            bz = xn[i, 2, 0] - qb[i, 2]
            far = max(far, bx * bx + by * by + bz * bz)
        else:
            far = max(far, bx * bx + by * by)
    return far


class ListStage(NamedTuple):
    """What a run on the lists layout carries from step to step (allocated once; the close
    list's buffers grow when it must, :func:`grow`)."""

    fe: NDArray[np.float64]  #: (d + 1, m) edge forces (x, y[, z]) and clearances
    fp: NDArray[np.float64]  #: (cap, d) close pairs' repulsion on their first robot
    on: NDArray[np.uint8]  #: (s,) surfaces switched on
    area_g: NDArray[np.float64]  #: (r,) area triangles' error terms
    least: NDArray[np.float64]  #: (chunks, 2) least clearance and least swept clearance
    moves: NDArray[np.float64]  #: (chunks, 3) largest squared move, drift, finiteness
    qb: NDArray[np.float64]  #: (n, d) the positions the close list was built at
    pairs: NDArray[np.int32]  #: (cap, 2) the close list
    p_ptr: NDArray[np.int32]  #: (n + 1,) each robot's row of it
    p_rows: NDArray[np.int32]  #: (2 cap,)
    cell_of: NDArray[np.int32]  #: (n,) cell grid scratch
    items: NDArray[np.int32]
    start: NDArray[np.int32]  #: (4 n + 17,)
    stamp: NDArray[np.int32]
    cand: NDArray[np.int32]
    kept: NDArray[np.float64]  #: (6,) REACH, DRIFT, PAIRS, FRESH, NEED, EXTRA


def list_stage(
    layout: RunLayout, n: int, chunks: int, extra: float = 0.0, dim: int = 2
) -> ListStage:
    """A fresh stage for ``n`` robots of ``layout`` in ``dim`` dimensions, with room for
    passes of up to ``chunks`` chunks (the first step builds the list); ``extra``: how much
    closer the law's points can be than the robots' centres (twice a near-identity offset)."""
    kept = np.zeros(6)
    kept[DRIFT] = np.inf  # no list yet
    kept[EXTRA] = extra
    return ListStage(
        fe=np.zeros((dim + 1, layout.edge_i.size)), fp=np.zeros((16, dim)),
        on=np.zeros(layout.surf_a.size, np.uint8), area_g=np.zeros(layout.area_a.size),
        least=np.zeros((chunks, 2)), moves=np.zeros((chunks, 3)), qb=np.zeros((n, dim)),
        pairs=np.zeros((16, 2), np.int32), p_ptr=np.zeros(n + 1, np.int32),
        p_rows=np.zeros(32, np.int32), cell_of=np.zeros(n, np.int32),
        items=np.zeros(n, np.int32), start=np.zeros(4 * n + 17, np.int32),
        stamp=np.zeros(n, np.int32), cand=np.zeros(n, np.int32), kept=kept,
    )  # fmt: skip


def grow(ls: ListStage) -> ListStage:
    """``ls`` with room for the list that did not fit (``kept[NEED]`` pairs), what the
    current list's rows and forces hold kept (the step is taken again from them)."""
    need = int(ls.kept[NEED])
    return ls._replace(
        pairs=grown(ls.pairs, need), fp=grown(ls.fp, need), p_rows=grown(ls.p_rows, 2 * need)
    )


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _rebuild(q, disp, ls, L):
    """Build the close list at ``q`` ``(n, d)`` unless the one there holds every pair of
    clearance below ``max(s0, 2.01 disp)``; False when it needs more room (nothing kept)."""
    kept = ls.kept
    need = max(L.influence + kept[EXTRA], SWEPT_MARGIN * disp)
    if list_holds(kept[DRIFT], kept[REACH], need):
        return True
    reach = need + L.skin
    count = build_close_list(
        q, L.radius, reach, L.nbr_ptr, L.nbr, ls.pairs, ls.cell_of, ls.items, ls.start,
        ls.stamp, ls.cand,
    )  # fmt: skip
    if count > ls.pairs.shape[0] or count > ls.fp.shape[0] or 2 * count > ls.p_rows.shape[0]:
        kept[NEED] = count
        return False
    pair_rows(ls.pairs, count, q.shape[0], ls.p_ptr, ls.p_rows)
    for i in range(q.shape[0]):  # (a loop: a slice assignment compiles its shape check)
        for d in range(q.shape[1]):
            ls.qb[i, d] = q[i, d]
    kept[REACH] = reach
    kept[DRIFT] = 0.0
    kept[PAIRS] = count
    return True


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _items(q, qp, sweep, ls, L, par, axes):
    """The items at ``q`` (module docstring), the step from ``qp``; returns the least
    clearance and the least swept clearance. ``par``: the passes' chunks on numba's threads,
    or None for one thread (then the threads' code is not compiled)."""
    n_pairs = int(ls.kept[PAIRS])
    chunks = 1
    if par is not None:
        chunks = par
        items_parallel(
            q, qp, sweep, L, ls.pairs, n_pairs, ls.fe, ls.fp, ls.on, ls.area_g, ls.least, chunks,
            axes,
        )  # fmt: skip
    else:
        items(q, qp, sweep, L, ls.pairs, n_pairs, ls.fe, ls.fp, ls.on, ls.area_g, ls.least, axes)
    gap = np.inf
    swept = np.inf
    for c in range(chunks):  # (a loop: minima are the same in any order)
        gap = min(gap, ls.least[c, 0])
        swept = min(swept, ls.least[c, 1])
    return gap, swept


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def list_field(x, src, u, ls, L, par, hand, axes):
    """``u = f(src)`` over the lists, for the one trial of states ``x`` ``(n, k, 1)`` (centres
    first) whose law acts on the points ``src`` (``x`` itself, or the hand points
    ``(n, 2, 1)`` when ``hand``); ``u`` ``(n, 2, 1)``. The items at ``x`` first if they are
    not yet there (the run's first step), at the hand points at every step (the verdict
    computed them at the centres). Returns whether the list had room and the least
    clearance of the centres when the items were computed here (else +inf). ``par`` as for
    :func:`_items`; ``axes``: the positions' (2 or 3, :mod:`.euler`)."""
    q = x[:, : axes.ndim, 0]  # (views: the centres and the law's points of the one trial)
    p = src[:, : axes.ndim, 0]
    least = np.inf
    if ls.kept[FRESH] == 0.0:
        if not _rebuild(q, 0.0, ls, L):
            return False, least
        least = _items(q, q, 0.0, ls, L, par, axes)[0]
        ls.kept[FRESH] = 1.0
    if hand:  # (the list holds the points' close pairs too: kept[EXTRA])
        _items(p, p, 0.0, ls, L, par, axes)
    uq = u[:, :, 0]
    if par is not None:
        gather_parallel(
            p, L, ls.p_ptr, ls.p_rows, ls.fe, ls.fp, ls.on, ls.area_g, uq, par, axes
        )  # fmt: skip
    else:
        gather_chunk(0, 1, p, L, ls.p_ptr, ls.p_rows, ls.fe, ls.fp, ls.on, ls.area_g, uq, axes)
    return True, least


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def list_step(x, f, xn, dt, ls, disp, fin, par, axes):
    """The Euler step ``xn = x + dt f`` of the one trial (:func:`.euler.euler`), on the
    stage's chunks, and the robots' drift since the list was built (``kept[DRIFT]``)."""
    n = x.shape[0]
    if par is not None:
        advance_parallel(x, f, xn, ls.qb, dt, ls.moves, par, axes)
        far = 0.0
        for c in range(par):
            disp[0] = max(disp[0], ls.moves[c, 0])
            fin[0] += ls.moves[c, 2]
            far = max(far, ls.moves[c, 1])
    else:
        euler(x, f, xn, dt, 0, n, 1, disp, fin, axes)
        far = _drift(xn, ls.qb, 0, n, axes)
    ls.kept[DRIFT] = math.sqrt(far)


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def list_contact(xn, x, disp, ls, L, par, axes):
    """The verdict's clearances of the step ``x -> xn`` (finite; ``disp`` its largest move):
    the close list made to hold at ``xn``, then the items there. Returns whether the list
    had room, the least clearance at ``xn`` and the least along the step."""
    q = xn[:, : axes.ndim, 0]
    if not _rebuild(q, disp, ls, L):
        return False, 0.0, 0.0
    gap, swept = _items(q, x[:, : axes.ndim, 0], SWEPT_MARGIN * disp, ls, L, par, axes)
    return True, gap, swept
