"""A law's field ``u = f(q)`` over every pair, as a stage of the compiled loop.

The law enters as a :class:`~formationlab.controllers.terms.KernelTerms`, the named arrays
and numbers each law builds (``Law.kernel_terms``), so one compiled loop serves every law
and formation. Each pair contributes ``u_i += g r_ij``, ``u_j -= g r_ij`` with the edge's
or Khatib's ``g`` (:mod:`.kinds`); each switching surface is decided once
(:func:`.kinds.restriction.switching`) and switches its restricted terms; each area triangle
adds its penalty's force. States are ``(n, k, C)`` with the trials innermost, so that each
loop over trials is a plain SIMD loop.
"""

from __future__ import annotations

import math

from numba import njit

from .kinds.edges import edge_gain
from .kinds.khatib import repulsion_gain
from .kinds.restriction import restriction_force, switched_on, switching, triangle_product
from .kinds.signed_area import area_force, area_gain, signed_area

__all__ = ["law_field"]


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def law_field(q, u, sigma, nact, terms):
    """``u = f(q)`` for the first ``nact`` trials of a chunk.

    Plain arithmetic, no branch that calls: every loop over trials is vectorised
    (the engine decides contact, in loops of its own).
    """
    t = terms
    n = q.shape[0]
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
        if t.pair_is_edge[p]:
            d = t.pair_distance[p]
            for b in range(nact):
                dx = q[j, 0, b] - q[i, 0, b]
                dy = q[j, 1, b] - q[i, 1, b]
                g = edge_gain(t.kind, dx * dx + dy * dy, d, a, t.edge_gain)  # eq. (8)
                u[i, 0, b] += g * dx
                u[i, 1, b] += g * dy
                u[j, 0, b] -= g * dx
                u[j, 1, b] -= g * dy
        else:
            for b in range(nact):
                dx = q[j, 0, b] - q[i, 0, b]
                dy = q[j, 1, b] - q[i, 1, b]
                r = math.sqrt(dx * dx + dy * dy)
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
