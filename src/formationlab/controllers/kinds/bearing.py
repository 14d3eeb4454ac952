"""The bearing-only term of an edge: the projection of the desired bearing onto the measured one.

Reference: S. Zhao and D. Zelazo, "Bearing Rigidity and Almost Global Bearing-Only Formation
Stabilization", IEEE Transactions on Automatic Control 61(5):1255-1268, 2016. Their notation:
``e_ij = p_j - p_i`` (our ``r_ij``), the bearing ``g_ij = e_ij / ||e_ij||``, the desired
bearing ``g*_ij``, and the orthogonal projection ``P_x = I_d - x x^T / ||x||^2`` onto the
orthogonal complement of ``x``. Robot ``i`` moves by ``p_i' = -sum_{j in N_i} P_{g_ij} g*_ij``
(their eq. 11); ``g_ji = -g_ij`` and ``g*_ji = -g*_ij``, so robot ``j`` of an edge gets the
opposite of robot ``i``'s term, as the other edge kinds do.

The term uses the bearing alone: it is the same for ``r_ij`` and ``c r_ij`` with ``c > 0``,
so the law needs no distance and keeps the formation's centroid and scale (their Lemma 2).
"""

from __future__ import annotations

import numpy as np

from . import formula

__all__ = [
    "bearing_error",
    "bearing_force",
    "bearing_force_in_space",
    "bearing_misalignment",
    "bearing_misalignment_in_space",
]


@formula
def bearing_force_in_space(rx, ry, rz, bx, by, bz, gain):
    """Robot ``i``'s term ``-gain P_{g_ij} g*_ij`` of an edge seen at ``r_ij = (rx, ry, rz)``
    with desired bearing ``g*_ij = (bx, by, bz)`` (a unit vector), as ``(x, y, z)`` (Zhao and
    Zelazo 2016, eq. 11: ``P_g g* = g* - g (g . g*)``, in any dimension)."""
    r = np.sqrt(rx * rx + ry * ry + rz * rz)
    gx = rx / r  # g_ij = e_ij / ||e_ij||
    gy = ry / r
    gz = rz / r
    dot = gx * bx + gy * by + gz * bz
    return -gain * (bx - gx * dot), -gain * (by - gy * dot), -gain * (bz - gz * dot)  # eq. (11)


@formula
def bearing_force(rx, ry, bx, by, gain):
    """:func:`bearing_force_in_space` in the plane (``z = 0``: the same numbers), as ``(x, y)``."""
    fx, fy, _ = bearing_force_in_space(rx, ry, 0.0, bx, by, 0.0, gain)
    return fx, fy


@formula
def bearing_error(rx, ry, bx, by):
    """``||g_ij - g*_ij||^2 = 2 (1 - g_ij . g*_ij)``: 0 at the desired bearing, 4 at the
    reversed one (Zhao and Zelazo 2016, the bearing error of their section V)."""
    r = np.sqrt(rx * rx + ry * ry)
    return 2.0 * (1.0 - (rx * bx + ry * by) / r)


@formula
def bearing_misalignment_in_space(rx, ry, rz, bx, by, bz):
    """``g*_ij^T P_{g_ij} g*_ij = 1 - (g_ij . g*_ij)^2``: the rate term of the Lyapunov function
    ``V = 1/2 ||p - p*||^2``, ``V' = -sum_E ||e*_ij|| g*_ij^T P_{g_ij} g*_ij`` (Zhao and Zelazo
    2016, proof of Theorem 5); 0 where the bearing is the desired or the reversed one."""
    r = np.sqrt(rx * rx + ry * ry + rz * rz)
    c = (rx * bx + ry * by + rz * bz) / r
    return 1.0 - c * c


@formula
def bearing_misalignment(rx, ry, bx, by):
    """:func:`bearing_misalignment_in_space` in the plane (``z = 0``: the same numbers)."""
    return bearing_misalignment_in_space(rx, ry, 0.0, bx, by, 0.0)
