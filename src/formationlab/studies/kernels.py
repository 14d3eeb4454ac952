"""Numba kernels of the batched Euler stepping (the numpy specification is ``reference``).

Layout: every chunk of trials keeps its positions as ``(n, 2, C)`` with the
trials on the innermost, contiguous axis, so that each loop over trials is a
plain SIMD loop. Chunks run in parallel (``prange``); inside a chunk, trials
that stop are swapped out of the live range (compaction), so that early
stopping saves work instead of masking it.

The law enters as plain arrays and numbers (built from the formation and the
law object by :mod:`formationlab.studies.batch`), so one compiled kernel serves
every law and formation:

* every pair ``i < j``: edge (``d_ij``, ``a_ij``) or not (Khatib's repulsion);
  on an edge either the paper's ``phi_ij`` (``kind = LOG_BARRIER``, eqs. 5, 7)
  or ``1/4 (r^2 - d^2)^2`` (``kind = SQUARED``, Krick et al. 2009);
* the restricted triangles ``(a, b, c)`` of eq. (14) and, per triangle, the terms
  ``(i, j, k)``, ``j < k``, with ``alpha_ijk``, the parity of ``c_ijk = par c_abc``
  and the weight ``2 k_a alpha_ijk`` (``psi_ikj = psi_ijk``), and ``theta``;
* the triangles ``(a, b, c, A*)`` of the signed-area penalty with its gain.

Each pair contributes ``u_i += g (q_j - q_i)``, ``u_j -= g (q_j - q_i)``:
``g = k_c phi'(r) / r`` (eq. 8), ``g = k (r^2 - d^2)`` (squared distance) or
``g = k_r gamma'(r - a) / r`` (repulsion). The arithmetic follows the numpy
laws operation by operation where it decides a branch (``alpha c + theta``,
``r - a``), so that trajectories agree with :func:`formationlab.simulate` to
rounding.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .reference import STATUS_COLLISION, STATUS_CONVERGED, STATUS_END, STATUS_NON_FINITE

__all__ = ["LOG_BARRIER", "SQUARED", "run_chunks"]

#: Edge potential of the law: the paper's phi (eq. 5) or Krick et al.'s squared distance.
LOG_BARRIER, SQUARED = 0, 1


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _controls(
    q, u, gap, cbuf, nact, kind, pi, pj, pedge, pd, pa, gain_edge, gain_rep, eta, s0,
    ra, rb, rc, roff, vi, vj, vk, valpha, vpar, vw, theta, sa, sb, sc, starget, k_area,
):  # fmt: skip
    """``u = f(q)`` for the first ``nact`` trials of a chunk; ``gap``: least ``r_ij - a_ij``."""
    n = q.shape[0]
    for i in range(n):
        for b in range(nact):
            u[i, 0, b] = 0.0
            u[i, 1, b] = 0.0
    for b in range(nact):
        gap[b] = np.inf
    rep = -gain_rep * eta / s0
    # (arrays are indexed directly, without views: a view costs reference counting)
    for p in range(pi.shape[0]):
        i = pi[p]
        j = pj[p]
        a = pa[p]
        if pedge[p] and kind == LOG_BARRIER:
            inv_da = 1.0 / (pd[p] - a)
            for b in range(nact):
                dx = q[j, 0, b] - q[i, 0, b]
                dy = q[j, 1, b] - q[i, 1, b]
                r = math.sqrt(dx * dx + dy * dy)
                clr = r - a
                gap[b] = min(gap[b], clr)
                g = gain_edge * (clr * inv_da - 1.0) / (clr * r)  # k_c phi'(r) / r, eqs. (7), (8)
                u[i, 0, b] += g * dx
                u[i, 1, b] += g * dy
                u[j, 0, b] -= g * dx
                u[j, 1, b] -= g * dy
        elif pedge[p]:
            d2 = pd[p] * pd[p]
            for b in range(nact):
                dx = q[j, 0, b] - q[i, 0, b]
                dy = q[j, 1, b] - q[i, 1, b]
                r2 = dx * dx + dy * dy
                gap[b] = min(gap[b], math.sqrt(r2) - a)
                g = gain_edge * (r2 - d2)  # Krick et al. 2009
                u[i, 0, b] += g * dx
                u[i, 1, b] += g * dy
                u[j, 0, b] -= g * dx
                u[j, 1, b] -= g * dy
        else:
            for b in range(nact):
                dx = q[j, 0, b] - q[i, 0, b]
                dy = q[j, 1, b] - q[i, 1, b]
                r = math.sqrt(dx * dx + dy * dy)
                s = r - a
                gap[b] = min(gap[b], s)
                # k_r gamma'(s) / r with gamma'(s) = -eta (1/s - 1/s0) / s^2 (Khatib)
                g = rep * (s0 - s) / (s * s * s * r) if s < s0 else 0.0
                u[i, 0, b] += g * dx
                u[i, 1, b] += g * dy
                u[j, 0, b] -= g * dx
                u[j, 1, b] -= g * dy
    # eqs. (11), (13), (14), (23): per restricted triangle (a, b, c), c_abc once; a term
    # (i, j, k) with c_ijk = par c_abc adds -w Upsilon(alpha_ijk c_ijk + theta) k x r_jk
    # to u_i, w = 2 k_a alpha_ijk (the ordered pairs (j, k), (k, j) of eq. 13 are equal).
    for t in range(ra.shape[0]):
        ia = ra[t]
        ib = rb[t]
        ic = rc[t]
        for b in range(nact):
            cbuf[b] = (q[ib, 0, b] - q[ia, 0, b]) * (q[ic, 1, b] - q[ia, 1, b]) - (
                q[ib, 1, b] - q[ia, 1, b]
            ) * (q[ic, 0, b] - q[ia, 0, b])
        for v in range(roff[t], roff[t + 1]):
            i = vi[v]
            j = vj[v]
            k = vk[v]
            al = valpha[v]
            par = vpar[v]
            w0 = vw[v]
            for b in range(nact):
                w = w0 if al * (par * cbuf[b]) + theta >= 0.0 else 0.0  # Upsilon(0) = 1
                u[i, 0, b] += w * (q[k, 1, b] - q[j, 1, b])
                u[i, 1, b] -= w * (q[k, 0, b] - q[j, 0, b])
    for t in range(sa.shape[0]):  # signed-area penalty, grad_a A_abc = 1/2 k x r_bc
        ia = sa[t]
        ib = sb[t]
        ic = sc[t]
        target = starget[t]
        for b in range(nact):
            xa, ya = q[ia, 0, b], q[ia, 1, b]
            xb, yb = q[ib, 0, b], q[ib, 1, b]
            xc, yc = q[ic, 0, b], q[ic, 1, b]
            area = 0.5 * ((xb - xa) * (yc - ya) - (yb - ya) * (xc - xa))
            g = k_area * 0.5 * (area - target)
            u[ia, 0, b] += g * (yc - yb)
            u[ia, 1, b] -= g * (xc - xb)
            u[ib, 0, b] += g * (ya - yc)
            u[ib, 1, b] -= g * (xa - xc)
            u[ic, 0, b] += g * (yb - ya)
            u[ic, 1, b] -= g * (xb - xa)


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _run_chunk(
    q0, start, stop, kind, pi, pj, pedge, pd, pa, gain_edge, gain_rep, eta, s0,
    ra, rb, rc, roff, vi, vj, vk, valpha, vpar, vw, theta, sa, sb, sc, starget, k_area,
    dt, n_steps, check_every, speed,
    q_out, u_out, steps_out, status_out, mc_out, ns_out,
):  # fmt: skip
    n = q0.shape[1]
    m = stop - start
    # double buffers: (q, u) at step k, (qp, up) at step k - 1
    q = np.empty((n, 2, m))
    u = np.empty((n, 2, m))
    qp = np.empty((n, 2, m))
    up = np.empty((n, 2, m))
    ids = np.arange(start, stop)
    mc = np.full(m, np.inf)  # least clearance over accepted states
    gap = np.empty(m)  # clearance of the current state
    cbuf = np.empty(m)  # c_abc of one triangle
    fin = np.zeros(m)  # 0 while the last Euler step was finite
    code = np.full(m, -1, dtype=np.int8)  # -1: still running
    qc = np.empty((n, 2, m))  # positions at the previous convergence check
    ns = np.full(m, np.nan)  # net speed over the last check interval (NaN: none yet)
    dbuf = np.empty(m)  # largest squared displacement since the previous check
    for b in range(m):
        for i in range(n):
            q[i, 0, b] = q0[start + b, i, 0]
            q[i, 1, b] = q0[start + b, i, 1]
    nact = m
    k = 0
    kc = -1  # step of the previous check (the same for every live trial)
    while nact > 0:
        _controls(
            q, u, gap, cbuf, nact, kind, pi, pj, pedge, pd, pa, gain_edge, gain_rep, eta, s0,
            ra, rb, rc, roff, vi, vj, vk, valpha, vpar, vw, theta, sa, sb, sc, starget, k_area,
        )  # fmt: skip
        stopping = 0
        if k > 0:  # reject the step that led here if it is not finite or reached contact
            for b in range(nact):
                if fin[b] != 0.0:
                    code[b] = STATUS_NON_FINITE
                    stopping += 1
                elif not gap[b] > 0.0:
                    code[b] = STATUS_COLLISION
                    stopping += 1
        for b in range(nact):
            mc[b] = min(mc[b], gap[b]) if code[b] < 0 else mc[b]
        if k % check_every == 0 or k == n_steps:
            # stopped: instantaneous speed max |u_i| or net speed since the previous
            # check, max |q_i(k) - q_i(kc)| / ((k - kc) dt), at most `speed`
            for b in range(nact):
                dbuf[b] = 0.0
            if kc >= 0:
                for i in range(n):
                    for b in range(nact):
                        dx = q[i, 0, b] - qc[i, 0, b]
                        dy = q[i, 1, b] - qc[i, 1, b]
                        dbuf[b] = max(dbuf[b], dx * dx + dy * dy)
            elapsed = (k - kc) * dt
            for b in range(nact):
                if code[b] >= 0:  # the step to this state was rejected
                    continue
                top = 0.0
                for i in range(n):
                    top = max(top, u[i, 0, b] * u[i, 0, b] + u[i, 1, b] * u[i, 1, b])
                net = math.sqrt(dbuf[b]) / elapsed if kc >= 0 else np.nan
                ns[b] = net
                if math.sqrt(top) <= speed or net <= speed:
                    code[b] = STATUS_CONVERGED
                    stopping += 1
            for i in range(n):
                for d in range(2):
                    for b in range(nact):
                        qc[i, d, b] = q[i, d, b]
            kc = k
        if k == n_steps:
            for b in range(nact):
                if code[b] < 0:
                    code[b] = STATUS_END
            stopping = nact
        if stopping:
            # write out the stopped trials, then compact the live range
            for b in range(nact - 1, -1, -1):
                if code[b] < 0:
                    continue
                g = ids[b]
                rejected = code[b] == STATUS_COLLISION or code[b] == STATUS_NON_FINITE
                for i in range(n):
                    for d in range(2):
                        # a rejected step ends the trial at the previous, accepted state
                        q_out[g, i, d] = qp[i, d, b] if rejected else q[i, d, b]
                        u_out[g, i, d] = up[i, d, b] if rejected else u[i, d, b]
                steps_out[g] = k - 1 if rejected else k
                status_out[g] = code[b]
                mc_out[g] = mc[b]
                ns_out[g] = ns[b]
                last = nact - 1
                if b != last:  # the trial at `last` is running (visited already)
                    for i in range(n):
                        for d in range(2):
                            q[i, d, b] = q[i, d, last]
                            u[i, d, b] = u[i, d, last]
                            qc[i, d, b] = qc[i, d, last]
                    ids[b] = ids[last]
                    mc[b] = mc[last]
                    ns[b] = ns[last]
                code[b] = -1
                code[last] = -1
                nact -= 1
        if nact == 0:
            break
        for b in range(nact):
            fin[b] = 0.0
        for i in range(n):
            for d in range(2):
                for b in range(nact):
                    x = q[i, d, b] + dt * u[i, d, b]  # explicit Euler
                    qp[i, d, b] = x  # the next state, written over the older one
                    fin[b] += x * 0.0  # NaN unless x is finite
        q, qp = qp, q
        u, up = up, u
        k += 1


@njit(cache=True, fastmath=False, error_model="numpy", parallel=True)
def run_chunks(
    q0, chunk, kind, pi, pj, pedge, pd, pa, gain_edge, gain_rep, eta, s0,
    ra, rb, rc, roff, vi, vj, vk, valpha, vpar, vw, theta, sa, sb, sc, starget, k_area,
    dt, n_steps, check_every, speed,
    q_out, u_out, steps_out, status_out, mc_out, ns_out,
):  # fmt: skip
    """Step every trial of ``q0`` ``(B, n, 2)``; chunks of ``chunk`` trials run in parallel.

    Fills ``q_out``, ``u_out`` ``(B, n, 2)``, ``steps_out`` (int64), ``status_out``
    (int8, the ``STATUS_*`` codes of :mod:`formationlab.studies.reference`),
    ``mc_out`` (least clearance) and ``ns_out`` (net speed over the last check
    interval), all of length ``B``.
    """
    n_trials = q0.shape[0]
    n_chunks = (n_trials + chunk - 1) // chunk
    for c in prange(n_chunks):
        start = c * chunk
        stop = min(n_trials, start + chunk)
        _run_chunk(
            q0, start, stop, kind, pi, pj, pedge, pd, pa, gain_edge, gain_rep, eta, s0,
            ra, rb, rc, roff, vi, vj, vk, valpha, vpar, vw, theta, sa, sb, sc, starget, k_area,
            dt, n_steps, check_every, speed,
            q_out, u_out, steps_out, status_out, mc_out, ns_out,
        )  # fmt: skip
