"""Planar geometry used by every layer: the cross product, the quarter turn, permutation parity,
relative positions and the sum of per-item terms into per-robot rows.

The lowest module of the package (it imports nothing of it), so that the
formation specification, the potentials and the kernels' data take these
from one place.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._jit import formula

__all__ = [
    "cross",
    "cross2",
    "pair_vectors",
    "parity",
    "perp",
    "row_norms",
    "scatter_rows",
    "triple_products",
]


@formula
def cross2(ux, uy, vx, vy):
    """``(u x v) . k`` of planar vectors given by their components (numbers or arrays)."""
    return ux * vy - uy * vx


def row_norms(d: NDArray[np.float64]) -> NDArray[np.float64]:
    """``|d|`` of vectors ``(..., 2)`` in the plane or ``(..., 3)`` in space, as the sum of
    the squared components in order (elementwise: faster than a reduction over so short an
    axis, and in the plane the same numbers as ``sqrt(dx dx + dy dy)``)."""
    square = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]
    if d.shape[-1] == 3:
        square = square + d[..., 2] * d[..., 2]
    return np.sqrt(square)


def cross(u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """Scalar triple product ``(u x v) . k`` of planar vectors ``(..., 2)``."""
    u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
    return cross2(u[..., 0], u[..., 1], v[..., 0], v[..., 1])


def perp(v: ArrayLike) -> NDArray[np.float64]:
    """``k x v``: planar vectors ``(..., 2)`` turned by +90 degrees."""
    v = np.asarray(v, dtype=float)
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def parity(i: ArrayLike, j: ArrayLike, k: ArrayLike) -> NDArray[np.float64]:
    """Sign of the permutation taking the sorted ``(a, b, c)`` to ``(i, j, k)``; elementwise.

    ``c_ijk = parity(i, j, k) c_abc``: the triple product is invariant under
    cyclic permutations and odd under a swap. Distinct indices give +-1.
    """
    i, j, k = (np.asarray(x, dtype=np.int64) for x in (i, j, k))
    return np.sign((j - i) * (k - i) * (k - j)).astype(float)


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


def scatter_rows(values: ArrayLike, rows: ArrayLike, n: int) -> NDArray[np.float64]:
    """Sum ``values`` ``(..., m, d)`` into ``n`` rows by ``rows`` ``(m,)``: ``(..., n, d)``.

    ``out[..., rows[p], :] += values[..., p, :]``: the sum of per-edge or per-triple
    terms into per-robot controls, without dense pair arrays.
    """
    v = np.asarray(values, dtype=float)
    idx = np.asarray(rows, dtype=np.int64)
    batch = int(np.prod(v.shape[:-2], dtype=np.int64))
    dim = v.shape[-1]
    flat = v.reshape(batch, -1, dim)
    where = (np.arange(batch)[:, None] * n + idx[None, :]).ravel()
    out = np.empty((batch * n, dim))
    for d in range(dim):
        out[:, d] = np.bincount(where, weights=flat[..., d].ravel(), minlength=batch * n)
    return out.reshape(*v.shape[:-2], n, dim)
