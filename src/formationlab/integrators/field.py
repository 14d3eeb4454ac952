"""The field ``u = f(q)`` of a law over its lists, compiled, in two passes: items, then robots.

The compiled single run (``integrators/compiled.py``) evaluates the law from its
:class:`~formationlab.integrators.layout.RunLayout` and a close-pair list
(:mod:`formationlab.verlet`) in two passes per step:

1. **items** (:func:`items_chunk`): each edge's force ``k_c phi'(r)/r r_ij`` (eqs. 7,
   8; or Krick et al.'s), each close pair's Khatib repulsion, each switching
   surface's decision (eq. 14) and each area triangle's error, computed once, with
   the least clearance and the least swept clearance of the step;
2. **robots** (:func:`robots_chunk`): each robot gathers its edges' and pairs'
   forces (with the sign of its end), its active restricted terms (eqs. 11, 13) and
   its area terms, in the fixed order of its rows, then takes the explicit Euler step.

Each pass is split into chunks of consecutive items or robots; a chunk's numbers
do not depend on the others (and the least clearances are minima, which do not
depend on order), so one thread or several give the same bits. :func:`items` and
:func:`robots` run the chunks on one thread, :func:`items_parallel` and
:func:`robots_parallel` with numba's ``prange``.
"""

from __future__ import annotations

import math
import os

import numpy as np
from numba import njit, prange

from ..controllers.kinds.edges import edge_gain
from ..controllers.kinds.khatib import repulsion_gain
from ..controllers.kinds.restriction import (
    restriction_force,
    switched_on,
    switching,
    triangle_product,
)
from ..controllers.kinds.signed_area import area_force, area_gain, signed_area

# numba's OpenMP threads wait for work asleep rather than spinning (unless the user says
# otherwise). A step launches two parallel passes; on a machine shared with other work a
# spinning thread holds a core the other thread needs, and the passes of a 10,000-robot
# step took 115 ms instead of 1 ms (load average 7 on 2 cores). Read by the OpenMP
# runtime when numba first starts its threads, so it is set on import.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__all__ = [
    "items",
    "items_chunk",
    "items_parallel",
    "robots",
    "robots_chunk",
    "robots_parallel",
]


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _swept(q, qp, i, j, a):
    """Least ``r_ij - a`` along the straight step ``qp -> q`` (``System.swept_clearance``)."""
    x0 = qp[j, 0] - qp[i, 0]
    y0 = qp[j, 1] - qp[i, 1]
    ex = (q[j, 0] - q[i, 0]) - x0
    ey = (q[j, 1] - q[i, 1]) - y0
    dd = ex * ex + ey * ey
    s = min(max(-(x0 * ex + y0 * ey) / (dd if dd > 0 else 1.0), 0.0), 1.0)
    mx = x0 + s * ex
    my = y0 + s * ey
    return math.sqrt(mx * mx + my * my) - a


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _part(c, chunks, size):
    return c * size // chunks, (c + 1) * size // chunks


@njit(cache=True, fastmath=False, error_model="numpy")
def _edges(lo, hi, q, qp, sweep, kind, gain, edge_i, edge_j, edge_a, edge_d, fe):
    """Edges ``lo:hi``: each force on its first robot into ``fe[0], fe[1]``, its clearance
    into ``fe[2]``; returns the least clearance and the least swept one.

    The differences are gathered first, so that the arithmetic runs over contiguous
    slices counted from 0 (which the compiler vectorises: the same operations, in about
    half the time).
    """
    ei, ej, ea, ed = edge_i[lo:hi], edge_j[lo:hi], edge_a[lo:hi], edge_d[lo:hi]
    fx, fy, clr = fe[0, lo:hi], fe[1, lo:hi], fe[2, lo:hi]
    for e in range(hi - lo):
        i = ei[e]
        j = ej[e]
        fx[e] = q[j, 0] - q[i, 0]
        fy[e] = q[j, 1] - q[i, 1]
    for e in range(hi - lo):
        dx = fx[e]
        dy = fy[e]
        r2 = dx * dx + dy * dy
        g = edge_gain(kind, r2, ed[e], ea[e], gain)  # eq. (8), or Krick et al.'s
        fx[e] = g * dx
        fy[e] = g * dy
        clr[e] = math.sqrt(r2) - ea[e]
    g_min = np.inf
    w_min = np.inf
    for e in range(hi - lo):
        g_min = min(g_min, clr[e])
        if clr[e] <= sweep:  # tested along the step
            w_min = min(w_min, _swept(q, qp, ei[e], ej[e], ea[e]))
    return g_min, w_min


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _pair(p, q, radius, s0, gain, eta, pairs, fp):
    """Close pair ``p``'s Khatib repulsion on its first robot into ``fp[p]`` (zero beyond
    ``s0``); returns its clearance."""
    i = pairs[p, 0]
    j = pairs[p, 1]
    a = radius[i] + radius[j]
    dx = q[j, 0] - q[i, 0]
    dy = q[j, 1] - q[i, 1]
    r = math.sqrt(dx * dx + dy * dy)
    clr = r - a
    g = repulsion_gain(r, clr, gain, eta, s0)  # k_r gamma'(s) / r, Khatib
    fp[p, 0] = g * dx
    fp[p, 1] = g * dy
    return clr


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _pair_swept(p, q, qp, radius, pairs):
    """Least clearance of close pair ``p`` along the step."""
    i = pairs[p, 0]
    j = pairs[p, 1]
    return _swept(q, qp, i, j, radius[i] + radius[j])


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
def _robot(i, q, qn, qb, dt, R, p_ptr, p_rows, fe, fp, on, area_g, u):
    """Robot ``i``'s ``u_i`` gathered from its rows, and its Euler step into ``qn``.

    Returns its squared move, its squared distance from ``qb`` and whether ``qn_i`` is
    finite.
    """
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
    x = q[i, 0] + dt * ux  # explicit Euler
    y = q[i, 1] + dt * uy
    qn[i, 0] = x
    qn[i, 1] = y
    ex = x - q[i, 0]
    ey = y - q[i, 1]
    bx = x - qb[i, 0]
    by = y - qb[i, 1]
    return ex * ex + ey * ey, bx * bx + by * by, math.isfinite(x) and math.isfinite(y)


@njit(cache=True, fastmath=False, error_model="numpy")
def items_chunk(c, chunks, q, qp, sweep, L, pairs, n_pairs, fe, fp, on, area_g, least):
    """Chunk ``c`` of ``chunks`` of every kind of item at positions ``q`` ``(n, 2)``.

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
    g_min, w_min = _edges(lo, hi, q, qp, sweep, kind, gain, ei, ej, ea, ed, fe)
    lo, hi = _part(c, chunks, n_pairs)
    for p in range(lo, hi):
        clr = _pair(p, q, radius, s0, k_r, eta, pairs, fp)
        g_min = min(g_min, clr)
        if clr <= sweep:
            w_min = min(w_min, _pair_swept(p, q, qp, radius, pairs))
    lo, hi = _part(c, chunks, L.surf_a.shape[0])
    for s in range(lo, hi):
        _surface(s, q, sa, sb, sc, beta, stride, theta, on)
    lo, hi = _part(c, chunks, L.area_a.shape[0])
    for mm in range(lo, hi):
        _area(mm, q, aa, ab, ac, target, a_gain, area_g)
    least[c, 0] = g_min
    least[c, 1] = w_min


@njit(cache=True, fastmath=False, error_model="numpy")
def robots_chunk(c, chunks, q, qn, qb, dt, L, p_ptr, p_rows, fe, fp, on, area_g, u, moves):
    """Chunk ``c`` of the robots: ``u = f(q)`` gathered, and the Euler step ``qn = q + dt u``.

    ``moves[c]`` gets the largest squared move of the step (infinite if a robot's
    next position is not finite) and the largest squared distance of ``qn`` from ``qb``
    (the state the close list was built at).
    """
    R = (
        L.nbr_ptr, L.nbr_edge, L.term_ptr, L.term_s, L.term_w, L.term_stride, L.term_j, L.term_k,
        L.area_ptr, L.area_rows, L.area_a, L.area_b, L.area_c,
    )  # fmt: skip
    big = 0.0
    far = 0.0
    bad = False
    lo, hi = _part(c, chunks, q.shape[0])
    for i in range(lo, hi):
        move, drift, ok = _robot(i, q, qn, qb, dt, R, p_ptr, p_rows, fe, fp, on, area_g, u)
        big = max(big, move)
        far = max(far, drift)
        bad = bad or not ok  # judged before anything else sees it
    moves[c, 0] = np.inf if bad else big
    moves[c, 1] = far


@njit(cache=True, fastmath=False, error_model="numpy")
def items(q, qp, sweep, L, pairs, n_pairs, fe, fp, on, area_g, least):
    """:func:`items_chunk` over everything, on one thread (into ``least[0]``)."""
    items_chunk(0, 1, q, qp, sweep, L, pairs, n_pairs, fe, fp, on, area_g, least)


@njit(cache=True, fastmath=False, error_model="numpy", parallel=True)
def items_parallel(q, qp, sweep, L, pairs, n_pairs, fe, fp, on, area_g, least, chunks):
    """:func:`items_chunk` in ``chunks`` chunks on numba's threads."""
    for c in prange(chunks):
        items_chunk(c, chunks, q, qp, sweep, L, pairs, n_pairs, fe, fp, on, area_g, least)


@njit(cache=True, fastmath=False, error_model="numpy")
def robots(q, qn, qb, dt, L, p_ptr, p_rows, fe, fp, on, area_g, u, moves):
    """:func:`robots_chunk` over every robot, on one thread (into ``moves[0]``)."""
    robots_chunk(0, 1, q, qn, qb, dt, L, p_ptr, p_rows, fe, fp, on, area_g, u, moves)


@njit(cache=True, fastmath=False, error_model="numpy", parallel=True)
def robots_parallel(q, qn, qb, dt, L, p_ptr, p_rows, fe, fp, on, area_g, u, moves, chunks):
    """:func:`robots_chunk` in ``chunks`` chunks on numba's threads."""
    for c in prange(chunks):
        robots_chunk(c, chunks, q, qn, qb, dt, L, p_ptr, p_rows, fe, fp, on, area_g, u, moves)
