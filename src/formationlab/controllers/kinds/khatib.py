"""Khatib's repulsive potential ``gamma(s)`` of a clearance ``s`` and its slope.

The paper's ``gamma_ij`` of eq. (8) between non-neighbours cites O. Khatib, "Real-time
obstacle avoidance for manipulators and mobile robots", The International Journal of
Robotics Research 5(1):90-98, 1986, without writing it; this is its usual form,
``gamma = eta/2 (1/s - 1/s0)^2`` for ``0 < s < s0`` and 0 beyond. The same potential keeps
robots off obstacles (:mod:`formationlab.safety`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import formula

__all__ = ["dkhatib_ds", "khatib", "khatib_prime", "khatib_value", "repulsion_gain"]


@formula
def khatib_value(s, eta, s0):
    """``gamma = eta/2 (1/s - 1/s0)^2`` (for ``0 < s < s0``)."""
    return 0.5 * eta * (1.0 / s - 1.0 / s0) ** 2


@formula
def khatib_prime(s, eta, s0):
    """``gamma'(s) = -eta (1/s - 1/s0) / s^2`` (for ``s < s0``)."""
    return -eta * (1.0 / s - 1.0 / s0) / s**2


@formula
def repulsion_gain(r, s, gain, eta, s0):
    """``-gain grad_i gamma`` as a factor of ``r_ij``: ``gain gamma'(s) / r`` within ``s0``,
    else 0 (``s = r - a`` the clearance; the mask is arithmetic, so arrays take it too)."""
    return gain * khatib_prime(s, eta, s0) / r * (s < s0)


def khatib(s: ArrayLike, eta: float, s0: float) -> NDArray[np.float64]:
    """:func:`khatib_value` for arrays: 0 beyond ``s0``, ``+inf`` at ``s <= 0``."""
    s = np.asarray(s, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = khatib_value(s, eta, s0)
    return np.where(s <= 0, np.inf, np.where(s < s0, g, 0.0))


def dkhatib_ds(s: ArrayLike, eta: float, s0: float) -> NDArray[np.float64]:
    """:func:`khatib_prime` for arrays, 0 beyond ``s0``."""
    s = np.asarray(s, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = khatib_prime(s, eta, s0)
    return np.where(s < s0, g, 0.0)
