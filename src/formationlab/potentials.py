"""The paper's potentials as pure functions of distances and positions.

Arrays follow the package layout: positions ``q`` have shape ``(..., n, 2)``
with any batch axes leading; pairwise quantities ``(..., n, n)`` are indexed
``[i, j]`` and triple quantities ``(..., n, n, n)`` are indexed ``[i, j, k]``.

Reference: "Formation Control of Multiple Robots Avoiding Local Minima",
section 2.2 (eqs. 5-7) and section 3 (eqs. 8, 12-14, 23).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .geometry import cross, parity, perp

__all__ = [
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


def phi(r: ArrayLike, d: ArrayLike, a: ArrayLike) -> NDArray[np.float64]:
    """Combined attractive-repulsive potential ``phi_ij`` of eq. (5).

    ``phi = (r - d)/(d - a) - log((r - a)/(d - a))``, defined for ``r > a``;
    ``+inf`` at and below contact. Zero only at ``r = d`` (eq. 6).
    """
    r, d, a = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (r, d, a)))
    out = np.full(r.shape, np.inf)
    ok = r > a
    ra, da = r[ok] - a[ok], d[ok] - a[ok]
    out[ok] = (r[ok] - d[ok]) / da - np.log(ra / da)  # eq. (5)
    return out


def dphi_dr(r: ArrayLike, d: ArrayLike, a: ArrayLike) -> NDArray[np.float64]:
    """Derivative of eq. (5): ``d phi / d r = 1/(d - a) - 1/(r - a)`` (eq. 7)."""
    r, d, a = (np.asarray(x, dtype=float) for x in (r, d, a))
    return 1.0 / (d - a) - 1.0 / (r - a)  # eq. (7)


def khatib(s: ArrayLike, eta: float, s0: float) -> NDArray[np.float64]:
    """Khatib's repulsive potential ``gamma = eta/2 (1/s - 1/s0)^2`` for ``s < s0``, else 0.

    ``s`` is the clearance ``r_ij - a_ij`` between non-neighbours (the paper's
    ``gamma_ij`` of eq. 8 cites Khatib 1986 without writing it; this is its
    usual form). ``+inf`` at ``s <= 0``.
    """
    s = np.asarray(s, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = 0.5 * eta * (1.0 / s - 1.0 / s0) ** 2
    return np.where(s <= 0, np.inf, np.where(s < s0, g, 0.0))


def dkhatib_ds(s: ArrayLike, eta: float, s0: float) -> NDArray[np.float64]:
    """Derivative of :func:`khatib` in the clearance: ``-eta (1/s - 1/s0) / s^2`` for ``s < s0``."""
    s = np.asarray(s, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = -eta * (1.0 / s - 1.0 / s0) / s**2
    return np.where(s < s0, g, 0.0)


def pair_vectors(q: ArrayLike) -> NDArray[np.float64]:
    """Relative positions ``r_ij = q_j - q_i``; ``(..., n, 2) -> (..., n, n, 2)``."""
    q = np.asarray(q, dtype=float)
    return q[..., None, :, :] - q[..., :, None, :]


def triple_products(q: ArrayLike) -> NDArray[np.float64]:
    """``c_ijk = (r_ij x r_ik) . k`` for all triples; ``(..., n, 2) -> (..., n, n, n)``.

    Twice the signed area of triangle ``(i, j, k)``; invariant under cyclic
    permutation, odd under a swap of ``j`` and ``k`` (term of eq. 14).
    """
    r = pair_vectors(q)
    return cross(r[..., :, :, None, :], r[..., :, None, :, :])


def triangle_products(q: ArrayLike, triangles: ArrayLike) -> NDArray[np.float64]:
    """``c_abc = (r_ab x r_ac) . k`` of listed triangles; ``(..., n, 2), (t, 3) -> (..., t)``.

    The one place the switching functions of eq. (14) take their triple products
    from (``Formation.surfaces`` lists the triangles), so every path that decides
    whether a restriction is on computes the same number, bit for bit.
    """
    q = np.asarray(q, dtype=float)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    a, b, c = (q[..., t[:, m], :] for m in range(3))
    return cross(b - a, c - a)


def scatter_rows(values: ArrayLike, rows: ArrayLike, n: int) -> NDArray[np.float64]:
    """Sum ``values`` ``(..., m, 2)`` into ``n`` rows by ``rows`` ``(m,)``: ``(..., n, 2)``.

    ``out[..., rows[p], :] += values[..., p, :]``: the sum of per-edge or per-triple
    terms into per-robot controls, without dense pair arrays.
    """
    v = np.asarray(values, dtype=float)
    idx = np.asarray(rows, dtype=np.int64)
    batch = int(np.prod(v.shape[:-2], dtype=np.int64))
    flat = v.reshape(batch, -1, 2)
    where = (np.arange(batch)[:, None] * n + idx[None, :]).ravel()
    out = np.empty((batch * n, 2))
    for d in range(2):
        out[:, d] = np.bincount(where, weights=flat[..., d].ravel(), minlength=batch * n)
    return out.reshape(*v.shape[:-2], n, 2)


def upsilon(x: ArrayLike) -> NDArray[np.float64]:
    """Unit step ``Upsilon(x)`` of eq. (14), taking ``Upsilon(0) = 1``.

    The value at 0 only matters on the switching surface, a set of measure
    zero that the Filippov integrator treats as set-valued ``[0, 1]``.
    """
    return np.heaviside(np.asarray(x, dtype=float), 1.0)


def psi(alpha: ArrayLike, c: ArrayLike, theta: float) -> NDArray[np.float64]:
    """Angular potential ``psi_ijk = alpha c Upsilon(alpha c + theta)`` of eq. (14)."""
    ac = np.asarray(alpha, dtype=float) * np.asarray(c, dtype=float)
    return ac * upsilon(ac + theta)  # eq. (14)


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
