"""The paper's edge potential: ``phi_ij`` of eq. (5), its slope (eq. 7) and force (eq. 8).

Reference: "Formation Control of Multiple Robots Avoiding Local Minima", section 2.2
(eqs. 5-7) and section 3.1 (eq. 8): ``u_i = -k_c grad_i phi_i``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import formula

__all__ = ["dphi_dr", "phi", "phi_gain", "phi_prime", "phi_value", "slope_over"]


@formula
def phi_value(r, d, a):
    """``phi = (r - d)/(d - a) - log((r - a)/(d - a))`` for ``r > a`` (eq. 5)."""
    return (r - d) / (d - a) - np.log((r - a) / (d - a))  # eq. (5)


@formula
def phi_prime(r, d, a):
    """``d phi / d r = 1/(d - a) - 1/(r - a)`` (eq. 7)."""
    return slope_over(r, d, a, 1.0)  # eq. (7)


@formula
def slope_over(r, d, a, s):
    """``phi'(r) / s``, eq. (7) over one denominator: ``(r - d) / ((d - a) (r - a) s)``.

    The same number as ``1/(d - a) - 1/(r - a)`` without its cancellation near ``r = d``,
    and with one division per call where ``d`` and ``a`` are fixed (a compiled loop over
    trials computes ``1/(d - a)`` once); ``(r - a) s`` overflows only where ``r^2`` would.
    """
    return (1.0 / (d - a)) * (r - d) / ((r - a) * s)  # eq. (7)


@formula
def phi_gain(r, d, a, k_c):
    """``k_c phi'(r) / r``: robot ``i`` of an edge gets this times ``r_ij = q_j - q_i`` (eq. 8)."""
    return k_c * slope_over(r, d, a, r)  # eq. (8): -k_c grad_i phi_ij = k_c phi' r_ij / r


def phi(r: ArrayLike, d: ArrayLike, a: ArrayLike) -> NDArray[np.float64]:
    """Combined attractive-repulsive potential ``phi_ij`` of eq. (5), for arrays.

    ``+inf`` at and below contact. Zero only at ``r = d`` (eq. 6).
    """
    r, d, a = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (r, d, a)))
    out = np.full(r.shape, np.inf)
    ok = r > a
    out[ok] = phi_value(r[ok], d[ok], a[ok])  # eq. (5)
    return out


def dphi_dr(r: ArrayLike, d: ArrayLike, a: ArrayLike) -> NDArray[np.float64]:
    """Derivative of eq. (5): ``d phi / d r = 1/(d - a) - 1/(r - a)`` (eq. 7), for arrays."""
    r, d, a = (np.asarray(x, dtype=float) for x in (r, d, a))
    return phi_prime(r, d, a)  # eq. (7)
