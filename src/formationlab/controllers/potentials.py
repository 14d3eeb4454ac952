"""The paper's potentials as pure functions of distances and positions (numpy arrays).

Arrays follow the package layout: positions ``q`` have shape ``(..., n, 2)``
with any batch axes leading; pairwise quantities ``(..., n, n)`` are indexed
``[i, j]`` and triple quantities ``(..., n, n, n)`` are indexed ``[i, j, k]``.

Each formula is written once, in the module of its kind of term
(:mod:`formationlab.controllers.kinds`); this module gathers the array forms under the
paper's names, and the collinear minimiser of eq. (18).

Reference: "Formation Control of Multiple Robots Avoiding Local Minima",
section 2.2 (eqs. 5-7) and section 3 (eqs. 8, 12-14, 18, 23).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..formation.geometry import cross, pair_vectors, parity, perp, scatter_rows, triple_products
from .kinds.khatib import dkhatib_ds, khatib
from .kinds.log_barrier import dphi_dr, phi
from .kinds.restriction import psi, triangle_products, upsilon

__all__ = [
    "collinear_minimizer",
    "cross",
    "dkhatib_ds",
    "dphi_dr",
    "khatib",
    "pair_vectors",
    "parity",
    "perp",
    "phi",
    "psi",
    "scatter_rows",
    "triangle_products",
    "triple_products",
    "upsilon",
]


def _outer_root(total: float, c: float) -> float:
    """Positive root ``w`` of ``total = 1/w + 1/(w + c)`` (a minimum beyond an end robot)."""
    b = total * c - 2.0
    return (-b + np.sqrt(b * b + 4.0 * total * c)) / (2.0 * total)


def collinear_minimizer(
    q_j: ArrayLike,
    q_k: ArrayLike,
    d_ij: float,
    d_ik: float,
    a_ij: float,
    a_ik: float,
) -> tuple[NDArray[np.float64], float]:
    """Point ``q_i`` on the line through ``q_j, q_k`` minimising ``phi_ij + phi_ik`` (eq. 18).

    Our derivation (the printed eq. 19 does not give it, see ``docs/paper.md``):
    with ``x`` the coordinate of ``q_i`` along the line (``q_j`` at 0, ``q_k`` at
    ``L = r_jk``), ``phi_ij + phi_ik`` is convex on each of the three open
    intervals it is defined on, so each holds one stationary point, found in
    closed form from eq. (7) with ``A = 1/(d_ij - a_ij)``, ``B = 1/(d_ik - a_ik)``:

    * between the robots, ``u = x - a_ij`` and ``S = L - a_ij - a_ik``:
      ``A - 1/u = B - 1/(S - u)``, i.e. ``D u^2 - (D S + 2) u + S = 0`` with
      ``D = A - B``, root ``u = (D S + 2 - sqrt(D^2 S^2 + 4)) / (2 D)`` (``S/2`` if ``D = 0``);
    * beyond ``q_k`` (beyond ``q_j``): ``A + B = 1/w + 1/(w + c)`` with ``w`` the
      clearance to the nearer robot and ``c = L + a_ik - a_ij`` (``L + a_ij - a_ik``).

    The smallest of the (up to) three values is the minimum.

    Returns
    -------
    point : ndarray, shape (2,)
        The minimiser.
    value : float
        ``phi_ij + phi_ik`` there (> 0 unless the distances allow a collinear
        configuration, eq. 17).
    """
    qj, qk = np.asarray(q_j, dtype=float), np.asarray(q_k, dtype=float)
    L = float(np.linalg.norm(qk - qj))
    A, B = 1.0 / (d_ij - a_ij), 1.0 / (d_ik - a_ik)
    xs = []
    S = L - a_ij - a_ik
    if S > 0:
        D = A - B
        u = S / 2 if abs(D * S) < 1e-12 else (D * S + 2 - np.sqrt(D * D * S * S + 4)) / (2 * D)
        xs.append(a_ij + u)
    xs.append(L + a_ik + _outer_root(A + B, L + a_ik - a_ij))  # beyond q_k
    xs.append(-(a_ij + _outer_root(A + B, L + a_ij - a_ik)))  # beyond q_j
    values = [float(phi(abs(x), d_ij, a_ij) + phi(abs(L - x), d_ik, a_ik)) for x in xs]
    best = int(np.argmin(values))
    return qj + xs[best] * (qk - qj) / L, values[best]
