"""The contact rule of the compiled loop: the twin of ``System.step_verdict``.

A step is rejected when it is not finite (a coordinate NaN or infinite, or a position
whose square overflows: :func:`.euler.euler`), when it ends with a pair in contact
(``Status.COLLISION``) or when the straight path of the step passes through contact
(``Status.STEP_TOO_LARGE``). The swept test is computed only for pairs whose end
clearance is below twice the largest displacement of the step (farther pairs cannot have
met during it).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..status import Status

__all__ = [
    "COLLISION",
    "CONVERGED",
    "END",
    "NON_FINITE",
    "SWEPT_MARGIN",
    "TOO_LARGE",
    "contact",
    "segment_clearance",
    "segment_clearance_in_space",
    "verdict",
]

END = Status.SUCCESS.code
CONVERGED = Status.CONVERGED.code
COLLISION = Status.COLLISION.code
TOO_LARGE = Status.STEP_TOO_LARGE.code
NON_FINITE = Status.NON_FINITE.code
#: pairs closer than this many times the largest displacement of a step get the swept test
SWEPT_MARGIN = 2.01


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def segment_clearance(x0, y0, ex, ey, a):
    """Least ``|(x0, y0) + s (ex, ey)| - a`` over ``s`` in ``[0, 1]``.

    A pair's clearance along a straight step: ``(x0, y0) = q_j - q_i`` at its start,
    ``(ex, ey)`` the change of ``q_j - q_i`` over the step, ``a = a_ij``. The plane's case
    of :func:`segment_clearance_in_space` (``z = 0`` adds exact zeros: the same numbers).
    """
    return segment_clearance_in_space(x0, y0, 0.0, ex, ey, 0.0, a)


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def segment_clearance_in_space(x0, y0, z0, ex, ey, ez, a):
    """Least ``|(x0, y0, z0) + s (ex, ey, ez)| - a`` over ``s`` in ``[0, 1]``
    (:func:`segment_clearance` in space)."""
    dd = ex * ex + ey * ey + ez * ez
    s = min(max(-(x0 * ex + y0 * ey + z0 * ez) / (dd if dd > 0 else 1.0), 0.0), 1.0)
    mx = x0 + s * ex
    my = y0 + s * ey
    mz = z0 + s * ez
    return math.sqrt(mx * mx + my * my + mz * mz) - a


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _swept(q, qp, i, j, b, a, axes):
    """Least ``r_ij - a_ij`` along the straight step ``qp -> q`` (``System.swept_clearance``),
    in the plane or in space (``axes.ndim``: 2 or 3)."""
    x0 = qp[j, 0, b] - qp[i, 0, b]
    y0 = qp[j, 1, b] - qp[i, 1, b]
    ex = (q[j, 0, b] - q[i, 0, b]) - x0
    ey = (q[j, 1, b] - q[i, 1, b]) - y0
    if axes.ndim == 2:
        return segment_clearance(x0, y0, ex, ey, a)
    z0 = qp[j, 2, b] - qp[i, 2, b]
    ez = (q[j, 2, b] - q[i, 2, b]) - z0
    return segment_clearance_in_space(x0, y0, z0, ex, ey, ez, a)


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def contact(x, xp, disp, gap, swept, near, nact, terms, rr, axes):
    """Clearances of the centres ``x`` for the step rule (``System.step_verdict``), the
    positions ``x[:, :axes.ndim]`` (2 or 3 axes, the plane or space).

    ``rr[p, b]`` becomes pair ``p``'s length in trial ``b`` at ``x``, which the law's field
    at ``x`` reads at the next step (:func:`formationlab.controllers.stage.law_field`).

    ``gap``: least ``r_ij - a_ij`` at ``x``; ``swept``: least clearance along the
    straight step from ``xp`` to ``x`` of the pairs within ``SWEPT_MARGIN disp``
    (``disp`` is each trial's largest displacement, 0 before the first step). Two
    passes: every trial's least clearance, and ``near`` flags the trials with such a
    pair, those whose least clearance is within the margin (plain arithmetic,
    vectorised); then the swept test of those pairs of the flagged trials (rare: a pair
    about to touch). A call in the first loop would keep it, and the law's loops if they
    held it, from being vectorised.
    """
    for b in range(nact):
        gap[b] = np.inf
        swept[b] = np.inf
    for p in range(terms.pair_i.shape[0]):
        i = terms.pair_i[p]
        j = terms.pair_j[p]
        a = terms.pair_contact[p]
        for b in range(nact):
            dx = x[j, 0, b] - x[i, 0, b]
            dy = x[j, 1, b] - x[i, 1, b]
            if axes.ndim == 3:  # (a constant: compiled for one dimension)
                dz = x[j, 2, b] - x[i, 2, b]
                r = math.sqrt(dx * dx + dy * dy + dz * dz)
            else:
                r = math.sqrt(dx * dx + dy * dy)
            rr[p, b] = r
            gap[b] = min(gap[b], r - a)
    for b in range(nact):  # (a pair within the margin: the least clearance is within it)
        near[b] = 1.0 if gap[b] <= SWEPT_MARGIN * disp[b] else 0.0
    for b in range(nact):
        if near[b] == 0.0:
            continue
        for p in range(terms.pair_i.shape[0]):
            i = terms.pair_i[p]
            j = terms.pair_j[p]
            a = terms.pair_contact[p]
            if rr[p, b] - a <= SWEPT_MARGIN * disp[b]:
                swept[b] = min(swept[b], _swept(x, xp, i, j, b, a, axes))


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def verdict(fin, gap, swept):
    """A step's verdict (``System.step_verdict``): 0 when accepted, else ``Status.code``.

    ``fin`` is 0 while the new state is finite (:func:`.euler.euler`), ``gap`` its least
    clearance and ``swept`` the least along the step (:func:`contact`, with the obstacles'
    joined in by :func:`.loop.step_chunk`); the order of the checks is the driver's. The
    compiled loop and the commanded step (:mod:`.commanded`) both decide by it.
    """
    if fin != 0.0:
        return NON_FINITE
    if not gap > 0.0:
        return COLLISION
    if not swept > 0.0:
        return TOO_LARGE
    return 0
