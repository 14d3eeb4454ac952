"""The paper's angular restriction: the triple product, the switching decision and the force.

Reference: "Formation Control of Multiple Robots Avoiding Local Minima", section 3.2:
``psi_ijk = alpha_ijk c_ijk Upsilon(alpha_ijk c_ijk + theta)`` (eq. 14) with
``c_ijk = (r_ij x r_ik) . k``, added to the distance law as ``-k_a grad_i psi_i``
(eqs. 11, 13) with ``grad_i psi_ijk = alpha_ijk Upsilon(.) k x r_jk`` (eq. 23).

Restricted triples that share a triangle share a switching surface
``sigma_s = beta_s c_abc + theta`` (``Formation.surfaces``): the decision is made once per
surface, by :func:`switching` and :func:`switched_on`, wherever it is made (the numpy law,
the compiled loops, the robots' own-frame commands, the diagnostics).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...formation.geometry import cross2
from . import formula

__all__ = [
    "psi",
    "restriction_force",
    "switched_on",
    "switching",
    "triangle_product",
    "triangle_products",
    "upsilon",
]


@formula
def triangle_product(ax, ay, bx, by, cx, cy):
    """``c_abc = (r_ab x r_ac) . k``, twice the signed area of ``(a, b, c)`` (eq. 14's term)."""
    return cross2(bx - ax, by - ay, cx - ax, cy - ay)


@formula
def switching(beta, c, theta):
    """``sigma_s = beta_s c_abc + theta``: ``alpha_ijk c_ijk + theta`` of the surface (eq. 14)."""
    return beta * c + theta  # eq. (14)


@formula
def switched_on(sigma):
    """``Upsilon(sigma)`` as 1.0 or 0.0, with ``Upsilon(0) = 1`` (eq. 14)."""
    return 1.0 * (sigma >= 0.0)


@formula
def restriction_force(w, rx, ry):
    """``-w k x r_jk`` as ``(x, y)``: robot ``i``'s term of a restricted triple ``(i, j, k)``
    with weight ``w = k_a alpha_ijk Upsilon(.)`` per ordered pair, ``r_jk = (rx, ry)``
    (eqs. 13, 23)."""
    return w * ry, -(w * rx)


def triangle_products(q: ArrayLike, triangles: ArrayLike) -> NDArray[np.float64]:
    """``c_abc`` of listed triangles; ``(..., n, 2), (t, 3) -> (..., t)``.

    The one place the switching functions of eq. (14) take their triple products
    from on the numpy path (``Formation.surfaces`` lists the triangles).
    """
    q = np.asarray(q, dtype=float)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    a, b, c = (q[..., t[:, m], :] for m in range(3))
    return triangle_product(a[..., 0], a[..., 1], b[..., 0], b[..., 1], c[..., 0], c[..., 1])


def upsilon(x: ArrayLike) -> NDArray[np.float64]:
    """Unit step ``Upsilon(x)`` of eq. (14) for arrays, ``Upsilon(0) = 1`` (NaN stays NaN).

    The value at 0 only matters on the switching surface, a set of measure
    zero that the Filippov integrator treats as set-valued ``[0, 1]``.
    """
    return np.heaviside(np.asarray(x, dtype=float), 1.0)


def psi(alpha: ArrayLike, c: ArrayLike, theta: float) -> NDArray[np.float64]:
    """Angular potential ``psi_ijk = alpha c Upsilon(alpha c + theta)`` of eq. (14)."""
    ac = np.asarray(alpha, dtype=float) * np.asarray(c, dtype=float)
    return ac * upsilon(switching(1.0, ac, theta))  # eq. (14)
