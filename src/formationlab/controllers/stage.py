"""A law's field ``u = f(q)`` over every pair, as a stage of the compiled loop.

Two forms: :func:`law_field`, the field of the true positions for a chunk of trials, and
:func:`local_field`, every robot's command from its own measurements (one trial; the
sensing stage, :mod:`formationlab.sensing.stage`, measures and delivers them).

The law enters as a :class:`~formationlab.controllers.terms.KernelTerms`, the named arrays
and numbers each law builds (``Law.kernel_terms``), so one compiled loop serves every law
and formation. Each pair contributes ``u_i += f``, ``u_j -= f`` with the edge's force
(:func:`.kinds.edges.edge_force`) or Khatib's ``g r_ij`` (:mod:`.kinds`); each switching
surface is decided once (:func:`.kinds.restriction.switching`) and switches its restricted
terms; each area triangle adds its penalty's force. States are ``(n, k, C)`` with the
trials innermost, so that each loop over trials is a plain SIMD loop.
"""

from __future__ import annotations

import math

from numba import njit

from .kinds.edges import BEARING, LOG_BARRIER, SQUARED, edge_force, edge_force_at, edge_gain
from .kinds.khatib import repulsion_gain
from .kinds.restriction import restriction_force, switched_on, switching, triangle_product
from .kinds.signed_area import area_force, area_gain, signed_area

__all__ = ["law_field", "local_field"]


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def law_field(q, u, sigma, nact, terms, rr, known, axes):
    """``u = f(q)`` for the first ``nact`` trials of a chunk.

    ``rr[p, b]`` is pair ``p``'s length ``r_ij`` in trial ``b``: given when ``known`` (the
    contact rule of the step that led to ``q`` computed it, :func:`formationlab.engine.
    contact.contact`), else computed here first, so that each state's square roots are taken
    once. Plain arithmetic, no branch that calls: every loop over trials is vectorised (the
    engine decides contact, in loops of its own). ``axes``: the positions' axes, whose
    length (2 or 3, a constant where numba compiles it) is the dimension; in space the law
    is its edges and pairs (:func:`_pairs_in_space`).
    """
    t = terms
    n = q.shape[0]
    if axes.ndim == 3:  # (a constant: the plane's code below is compiled as it was)
        _pairs_in_space(q, u, nact, t, rr, known, axes)
        return
    for i in range(n):
        for b in range(nact):
            u[i, 0, b] = 0.0
            u[i, 1, b] = 0.0
    s0 = t.repulsion_influence
    # (arrays are indexed directly, without views: a view costs reference counting; one
    # loop over trials per kind of pair, so that each is a plain loop)
    for p in range(t.pair_i.shape[0]):
        i = t.pair_i[p]
        j = t.pair_j[p]
        a = t.pair_contact[p]
        if not known:
            _lengths(q, rr, p, i, j, nact, axes)
        if t.pair_is_edge[p]:  # (one loop per kind, whose branch numba folds away: the
            # loop over trials then holds one kind's arithmetic and no test)
            if t.kind == LOG_BARRIER:
                _edge(q, u, rr, p, i, j, a, nact, t, LOG_BARRIER)
            elif t.kind == SQUARED:
                _edge(q, u, rr, p, i, j, a, nact, t, SQUARED)
            else:
                _edge(q, u, rr, p, i, j, a, nact, t, BEARING)
        else:
            for b in range(nact):
                dx = q[j, 0, b] - q[i, 0, b]
                dy = q[j, 1, b] - q[i, 1, b]
                r = rr[p, b]
                g = repulsion_gain(r, r - a, t.repulsion_gain, t.repulsion_eta, s0)  # Khatib
                u[i, 0, b] += g * dx
                u[i, 1, b] += g * dy
                u[j, 0, b] -= g * dx
                u[j, 1, b] -= g * dy
    # eqs. (11), (13), (14), (23): per switching surface sigma = beta c_abc + theta; each
    # term (i, j, k) of the surface adds -w Upsilon(sigma) k x r_jk to u_i,
    # w = 2 k_a alpha_ijk (eq. 13's pairs (j, k), (k, j))
    for sf in range(t.surface_a.shape[0]):
        ia = t.surface_a[sf]
        ib = t.surface_b[sf]
        ic = t.surface_c[sf]
        beta = t.surface_beta[sf]
        for b in range(nact):
            cab = triangle_product(
                q[ia, 0, b], q[ia, 1, b], q[ib, 0, b], q[ib, 1, b], q[ic, 0, b], q[ic, 1, b]
            )
            sigma[b] = switched_on(switching(beta, cab, t.theta))  # eq. (14)
        for v in range(t.term_start[sf], t.term_start[sf + 1]):
            i = t.term_i[v]
            j = t.term_j[v]
            k = t.term_k[v]
            w0 = t.term_weight[v]
            for b in range(nact):
                fx, fy = restriction_force(
                    w0 * sigma[b], q[k, 0, b] - q[j, 0, b], q[k, 1, b] - q[j, 1, b]
                )  # eq. (23)
                u[i, 0, b] += fx
                u[i, 1, b] += fy
    for m in range(t.area_a.shape[0]):  # signed-area penalty, grad_a A_abc = 1/2 k x r_bc
        ia = t.area_a[m]
        ib = t.area_b[m]
        ic = t.area_c[m]
        target = t.area_target[m]
        for b in range(nact):
            xa, ya = q[ia, 0, b], q[ia, 1, b]
            xb, yb = q[ib, 0, b], q[ib, 1, b]
            xc, yc = q[ic, 0, b], q[ic, 1, b]
            g = area_gain(signed_area(xa, ya, xb, yb, xc, yc), target, t.area_gain)
            fx, fy = area_force(g, xb, yb, xc, yc)
            u[ia, 0, b] += fx
            u[ia, 1, b] += fy
            fx, fy = area_force(g, xc, yc, xa, ya)
            u[ib, 0, b] += fx
            u[ib, 1, b] += fy
            fx, fy = area_force(g, xa, ya, xb, yb)
            u[ic, 0, b] += fx
            u[ic, 1, b] += fy


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _edge(q, u, rr, p, i, j, a, nact, t, kind):
    """Edge ``p = (i, j)``'s terms in the first ``nact`` trials, ``kind`` a constant where
    numba compiles it (:func:`.kinds.edges.edge_force_at`)."""
    d = t.pair_distance[p]
    bx = t.pair_bearing[p * t.bearing_stride, 0]
    by = t.pair_bearing[p * t.bearing_stride, 1]
    for b in range(nact):
        dx = q[j, 0, b] - q[i, 0, b]
        dy = q[j, 1, b] - q[i, 1, b]
        fx, fy = edge_force_at(kind, dx, dy, rr[p, b], d, a, t.edge_gain, bx, by)
        u[i, 0, b] += fx  # eq. (8)
        u[i, 1, b] += fy
        u[j, 0, b] -= fx
        u[j, 1, b] -= fy


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _lengths(q, rr, p, i, j, nact, axes):
    """``rr[p, b] = |q_j - q_i|`` in each of the first ``nact`` trials (``axes.ndim``: 2 or 3
    coordinates)."""
    for b in range(nact):
        dx = q[j, 0, b] - q[i, 0, b]
        dy = q[j, 1, b] - q[i, 1, b]
        if axes.ndim == 3:  # (a constant: compiled for one dimension)
            dz = q[j, 2, b] - q[i, 2, b]
            rr[p, b] = math.sqrt(dx * dx + dy * dy + dz * dz)
        else:
            rr[p, b] = math.sqrt(dx * dx + dy * dy)


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _pairs_in_space(q, u, nact, t, rr, known, axes):
    """:func:`law_field` of a formation in space (``q`` ``(n, 3, C)``): each edge's force
    ``g r_ij`` (:func:`.kinds.edges.edge_gain`: eq. 8, or Krick et al.'s) and Khatib's
    repulsion between the other pairs; the laws with these terms only compile in space
    (``Law.compiled_dims``)."""
    n = q.shape[0]
    for i in range(n):
        for b in range(nact):
            u[i, 0, b] = 0.0
            u[i, 1, b] = 0.0
            u[i, 2, b] = 0.0
    s0 = t.repulsion_influence
    for p in range(t.pair_i.shape[0]):
        i = t.pair_i[p]
        j = t.pair_j[p]
        a = t.pair_contact[p]
        if not known:
            _lengths(q, rr, p, i, j, nact, axes)
        d = t.pair_distance[p]
        edge = t.pair_is_edge[p]
        for b in range(nact):
            dx = q[j, 0, b] - q[i, 0, b]
            dy = q[j, 1, b] - q[i, 1, b]
            dz = q[j, 2, b] - q[i, 2, b]
            r = rr[p, b]
            if edge:
                g = edge_gain(t.kind, r, dx * dx + dy * dy + dz * dz, d, a, t.edge_gain)  # (8)
            else:
                g = repulsion_gain(r, r - a, t.repulsion_gain, t.repulsion_eta, s0)  # Khatib
            u[i, 0, b] += g * dx
            u[i, 1, b] += g * dy
            u[i, 2, b] += g * dz
            u[j, 0, b] -= g * dx
            u[j, 1, b] -= g * dy
            u[j, 2, b] -= g * dz


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def local_field(z, seen, own, terms, u):
    """Every robot's command ``u`` ``(n, 2)`` in its own frame from its measurements.

    ``z[i, j]`` is robot ``i``'s measurement of ``p_j - p_i`` and ``seen[i, j]`` whether it
    has one; ``own[e]`` the desired distance of edge ``e`` as its robots ``edge_i[e]``,
    ``edge_j[e]`` hold it. The compiled twin of :func:`formationlab.sensing.local_controls`,
    term by term in its order: each edge from each end; Khatib's repulsion between
    non-neighbours, each from its end; each restricted triple ``(i, j, k)`` from robot
    ``i``'s view of its surface (eqs. 11, 13, 14, 23); the signed-area penalty per vertex.
    A term that needs a robot its robot does not see is left out.
    """
    t = terms
    n = u.shape[0]
    for i in range(n):
        u[i, 0] = 0.0
        u[i, 1] = 0.0
    for side in range(2):  # each edge from each end, with that robot's own d_ij
        sign = 1.0 - 2.0 * side  # g*_ji = -g*_ij
        for e in range(t.edge_i.shape[0]):
            obs = t.edge_i[e] if side == 0 else t.edge_j[e]
            tgt = t.edge_j[e] if side == 0 else t.edge_i[e]
            if not seen[obs, tgt]:
                continue
            vx = z[obs, tgt, 0]
            vy = z[obs, tgt, 1]
            bx = sign * t.edge_bearing[e * t.bearing_stride, 0]
            by = sign * t.edge_bearing[e * t.bearing_stride, 1]
            fx, fy = edge_force(
                t.kind, vx, vy, own[e, side], t.edge_contact[e], t.edge_gain, bx, by
            )  # eq. (8)
            u[obs, 0] += fx
            u[obs, 1] += fy
    if t.repulsion_gain != 0:  # Khatib's repulsion between non-neighbours, each from its end
        for side in range(2):
            for p in range(t.pair_i.shape[0]):
                if t.pair_is_edge[p]:
                    continue
                obs = t.pair_i[p] if side == 0 else t.pair_j[p]
                tgt = t.pair_j[p] if side == 0 else t.pair_i[p]
                if not seen[obs, tgt]:
                    continue
                vx = z[obs, tgt, 0]
                vy = z[obs, tgt, 1]
                r = math.sqrt(vx * vx + vy * vy)
                g = repulsion_gain(
                    r, r - t.pair_contact[p], t.repulsion_gain, t.repulsion_eta,
                    t.repulsion_influence,
                )  # fmt: skip
                u[obs, 0] += g * vx
                u[obs, 1] += g * vy
    for v in range(t.term_i.shape[0]):  # eqs. (11), (13), (14), (23), from robot i's view
        i = t.term_i[v]
        j = t.term_j[v]
        k = t.term_k[v]
        if not (seen[i, j] and seen[i, k]):
            continue
        sf = t.term_surface[v]
        ia = t.surface_a[sf]
        ib = t.surface_b[sf]
        ic = t.surface_c[sf]
        cab = triangle_product(z[i, ia, 0], z[i, ia, 1], z[i, ib, 0], z[i, ib, 1], z[i, ic, 0],
                               z[i, ic, 1])  # fmt: skip
        on = switched_on(switching(t.surface_beta[sf], cab, t.theta))  # eq. (14)
        fx, fy = restriction_force(
            t.term_weight[v] * on, z[i, k, 0] - z[i, j, 0], z[i, k, 1] - z[i, j, 1]
        )  # eq. (23)
        u[i, 0] += fx
        u[i, 1] += fy
    for rot in range(3):  # signed-area penalty, grad_a A_abc = 1/2 k x r_bc, per vertex
        for m in range(t.area_a.shape[0]):
            a0, a1, a2 = t.area_a[m], t.area_b[m], t.area_c[m]
            if rot == 1:
                a0, a1, a2 = a1, a2, a0
            elif rot == 2:
                a0, a1, a2 = a2, a0, a1
            if not (seen[a0, a1] and seen[a0, a2]):
                continue
            p1x, p1y = z[a0, a1, 0], z[a0, a1, 1]
            p2x, p2y = z[a0, a2, 0], z[a0, a2, 1]
            area = signed_area(0.0, 0.0, p1x, p1y, p2x, p2y)  # the vertex at 0
            fx, fy = area_force(area_gain(area, t.area_target[m], t.area_gain), p1x, p1y, p2x, p2y)
            u[a0, 0] += fx
            u[a0, 1] += fy
