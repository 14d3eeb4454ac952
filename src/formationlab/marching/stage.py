"""Marching as a stage of the compiled loop (:mod:`formationlab.engine.loop`).

The compiled twin of :meth:`formationlab.marching.Marching.command` and
:meth:`~formationlab.marching.MotionParameters.command`: after the law's field and before
the obstacles and the filter (``System.command``), the command ``u`` ``(n, 2, C)`` at the
law's points ``p`` of step ``k`` gets ``gain v_ref(k dt)`` (every robot), has the leaders'
replaced by it (or each by its own row), or gets ``gain sum_k a_ik z_k`` (motion
parameters, Garcia de Marina, Jayawardhana and Cao, IEEE Transactions on Robotics 32(3),
2016).
"""

from __future__ import annotations

from numba import njit

from .config import marched
from .terms import EVERY, MOTION, STILL

__all__ = ["march"]


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def march(p, u, nact, k, mt, acc):
    """Add the marching term of step ``k`` to ``u`` of the first ``nact`` trials (none for
    kind STILL); ``acc`` ``(n, 2)`` room for one trial's motion-parameter sums."""
    n = u.shape[0]
    if mt.kind == STILL:
        return
    if mt.kind == MOTION:
        for b in range(nact):
            acc[:] = 0.0
            for e in range(mt.edge_i.shape[0]):
                i = mt.edge_i[e]
                j = mt.edge_j[e]
                zx = p[i, 0, b] - p[j, 0, b]  # z_k = p_i - p_j
                zy = p[i, 1, b] - p[j, 1, b]
                acc[i, 0] += mt.mu[e] * zx
                acc[i, 1] += mt.mu[e] * zy
                acc[j, 0] += mt.mu_tilde[e] * zx
                acc[j, 1] += mt.mu_tilde[e] * zy
            for i in range(n):
                u[i, 0, b] = marched(u[i, 0, b], mt.gain, acc[i, 0])
                u[i, 1, b] = marched(u[i, 1, b], mt.gain, acc[i, 1])
        return
    row = k - mt.k0 if mt.v.shape[0] > 1 else 0
    if mt.kind == EVERY:
        vx = mt.v[row, 0, 0]
        vy = mt.v[row, 0, 1]
        for i in range(n):
            for b in range(nact):
                u[i, 0, b] = marched(u[i, 0, b], mt.gain, vx)
                u[i, 1, b] = marched(u[i, 1, b], mt.gain, vy)
    else:  # the leaders move with v_ref alone (one, or each its own)
        for m in range(mt.leaders.shape[0]):
            leader = mt.leaders[m]
            each = m if mt.v.shape[1] > 1 else 0
            vx = mt.v[row, each, 0]
            vy = mt.v[row, each, 1]
            for b in range(nact):
                u[leader, 0, b] = mt.gain * vx
                u[leader, 1, b] = mt.gain * vy
