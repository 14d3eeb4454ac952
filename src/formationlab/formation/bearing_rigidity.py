"""Bearing rigidity: when do the bearings of the edges fix a formation's shape?

Reference: S. Zhao and D. Zelazo, "Bearing Rigidity and Almost Global Bearing-Only Formation
Stabilization", IEEE Transactions on Automatic Control 61(5):1255-1268, 2016.

For positions ``p`` ``(n, d)`` and edges ``(i, j)`` with ``e_ij = p_j - p_i``, the bearing
rigidity matrix (their eq. 5) is ``R_B = diag(P_{g_ij} / ||e_ij||) H_bar``, one block of ``d``
rows per edge holding ``P_{g_ij} / ||e_ij||`` in robot ``j``'s columns and its negative in
robot ``i``'s (``H_bar = H kron I_d``, ``H`` the incidence matrix). Its null space always holds
the translations and the scaling ``p`` itself, so ``rank R_B <= dn - d - 1``; the framework is
*infinitesimally bearing rigid* when equality holds (their Theorem 4), and then the bearings
fix the shape up to translation and scale. In the plane this coincides with infinitesimal
distance rigidity (their Theorem 8), which the tests check on random frameworks and lattices.

The *bearing Laplacian* of desired bearings ``g*`` (their eq. 12), ``L_B`` with blocks
``-P_{g*_ij}`` off the diagonal and ``sum_j P_{g*_ij}`` on it, has the same null space for
``R_B`` taken at any realisation of ``g*``: :func:`bearing_realisation` reads the target shape
from it when the bearings were given per edge.

Ranks: dense (numpy's SVD with its default tolerance) up to :data:`DENSE_BEARING_LIMIT`
robots; beyond, the nullity of the sparse ``R_B^T R_B`` from its ``d + 2`` smallest
eigenvalues (scipy's ARPACK, shift-invert about a small negative shift, so the factorised
matrix is positive definite), a zero being an eigenvalue below ``1e-9`` of the largest
(:data:`NULL_RELATIVE`). The smallest non-zero eigenvalue of a lattice falls like ``1/n^2``;
at 10,000 robots it is still about five orders above that threshold.
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.linalg import eigsh

from ..errors import FormationError

if TYPE_CHECKING:
    from .spec import Formation

__all__ = [
    "DENSE_BEARING_LIMIT",
    "bearing_laplacian",
    "bearing_nullity",
    "bearing_realisation",
    "bearing_rigidity_matrix",
    "bearings_of",
    "is_infinitesimally_bearing_rigid",
]

#: robots up to which ranks are computed densely (SVD)
DENSE_BEARING_LIMIT = 400
#: an eigenvalue of ``R_B^T R_B`` below this fraction of the largest counts as zero (sparse)
NULL_RELATIVE = 1e-9


def bearings_of(q: ArrayLike, edges: ArrayLike) -> NDArray[np.float64]:
    """The bearings ``g_ij = (p_j - p_i) / ||p_j - p_i||`` of the edges; ``(..., m, d)``."""
    q = np.asarray(q, dtype=float)
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    r = q[..., e[:, 1], :] - q[..., e[:, 0], :]
    return r / np.linalg.norm(r, axis=-1, keepdims=True)


def _blocks(g: NDArray[np.float64], scale: NDArray[np.float64]) -> NDArray[np.float64]:
    """``P_g * scale`` per row of ``g`` ``(m, d)``: ``(m, d, d)``."""
    d = g.shape[-1]
    return (np.eye(d) - g[:, :, None] * g[:, None, :]) * scale[:, None, None]


def bearing_rigidity_matrix(q: ArrayLike, edges: ArrayLike) -> csr_matrix:
    """``R_B`` of positions ``q`` ``(n, d)``: sparse, shape ``(m d, n d)`` (eq. 5)."""
    q = np.asarray(q, dtype=float)
    n, d = q.shape
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    r = q[e[:, 1]] - q[e[:, 0]]
    length = np.linalg.norm(r, axis=-1)
    if np.any(length == 0):
        raise FormationError("two robots of an edge coincide: their bearing is undefined")
    block = _blocks(r / length[:, None], 1.0 / length)  # P_{g_ij} / ||e_ij||
    m = len(e)
    rows = (np.arange(m)[:, None] * d + np.arange(d))[:, :, None]  # (m, d, 1)
    rows = np.broadcast_to(rows, (m, d, d))
    cj = (e[:, 1, None] * d + np.arange(d))[:, None, :]
    ci = (e[:, 0, None] * d + np.arange(d))[:, None, :]
    cols = np.concatenate([np.broadcast_to(cj, (m, d, d)), np.broadcast_to(ci, (m, d, d))])
    vals = np.concatenate([block, -block])
    return coo_matrix(
        (vals.ravel(), (np.concatenate([rows, rows]).ravel(), cols.ravel())), shape=(m * d, n * d)
    ).tocsr()


def bearing_laplacian(bearings: ArrayLike, edges: ArrayLike, n: int) -> csr_matrix:
    """``L_B`` of desired bearings ``(m, d)`` on ``n`` robots (eq. 12): sparse ``(n d, n d)``."""
    g = np.asarray(bearings, dtype=float)
    g = g / np.linalg.norm(g, axis=-1, keepdims=True)
    m, d = g.shape
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    block = _blocks(g, np.ones(m))
    r = np.arange(d)
    out = []
    for a, b, sign in ((0, 0, 1.0), (1, 1, 1.0), (0, 1, -1.0), (1, 0, -1.0)):
        rows = np.broadcast_to((e[:, a, None] * d + r)[:, :, None], (m, d, d))
        cols = np.broadcast_to((e[:, b, None] * d + r)[:, None, :], (m, d, d))
        out.append((rows.ravel(), cols.ravel(), (sign * block).ravel()))
    rows, cols, vals = (np.concatenate(x) for x in zip(*out, strict=True))
    return coo_matrix((vals, (rows, cols)), shape=(n * d, n * d)).tocsr()


def _nullity(gram: csr_matrix, dense: bool) -> tuple[int, NDArray[np.float64], NDArray]:
    """Nullity of a symmetric positive semi-definite matrix, its smallest eigenvalues and
    their vectors (columns)."""
    size = gram.shape[0]
    if dense:
        w, v = np.linalg.eigh(gram.toarray())
        top = max(float(w[-1]), 1e-300)
        tol = top * size * np.finfo(float).eps * 10  # numpy's rank rule, on eigenvalues
        return int(np.sum(w <= tol)), w, v
    top = float(eigsh(gram, k=1, which="LA", return_eigenvectors=False)[0])
    want = min(size - 1, 8)
    w, v = eigsh(gram, k=want, sigma=-1e-6 * top, which="LM")
    order = np.argsort(w)
    w, v = w[order], v[:, order]
    return int(np.sum(w <= NULL_RELATIVE * top)), w, v


def bearing_nullity(q: ArrayLike, edges: ArrayLike) -> int:
    """``dim null R_B`` at positions ``q`` ``(n, d)``: ``d + 1`` for an infinitesimally
    bearing-rigid framework, more otherwise."""
    q = np.asarray(q, dtype=float)
    rb = bearing_rigidity_matrix(q, edges)
    return _nullity((rb.T @ rb).tocsr(), len(q) <= DENSE_BEARING_LIMIT)[0]


def is_infinitesimally_bearing_rigid(q: ArrayLike, edges: ArrayLike) -> bool:
    """Whether ``rank R_B = d n - d - 1`` at ``q`` ``(n, d)`` (Zhao and Zelazo 2016, Theorem 4)."""
    q = np.asarray(q, dtype=float)
    return bearing_nullity(q, edges) == q.shape[1] + 1


_REALISED: weakref.WeakKeyDictionary[Formation, NDArray[np.float64]] = weakref.WeakKeyDictionary()


def bearing_realisation(formation: Formation) -> NDArray[np.float64]:
    """The shape the formation's desired bearings fix: positions ``(n, d)`` with centroid 0
    and scale ``sqrt(1/n sum_i ||p_i||^2) = 1`` whose bearings are ``g*``.

    The template's, when its bearings are the formation's; else the null vector of the
    bearing Laplacian orthogonal to the translations (its sign chosen so that the bearings
    are ``g*``, not ``-g*``). Refused when the bearings do not fix the shape (the formation
    is not infinitesimally bearing rigid at the bearings given).
    """
    if formation in _REALISED:
        return _REALISED[formation]
    g = formation.bearings
    if g is None:
        raise FormationError("the formation has no desired bearings", key="bearings")
    e = formation.edges
    t = formation.template
    if t is not None and np.allclose(bearings_of(t, e), g, rtol=0.0, atol=1e-12):
        p = t - t.mean(axis=0)
    else:
        p = _from_laplacian(g, e, formation.n)
    p = p / np.sqrt(np.mean(np.sum(p * p, axis=-1)))
    p.setflags(write=False)
    _REALISED[formation] = p
    return p


def _from_laplacian(g: NDArray[np.float64], e: NDArray, n: int) -> NDArray[np.float64]:
    d = g.shape[1]
    lap = bearing_laplacian(g, e, n)
    # the translations are known null vectors: lift them so the shape's vector is the only
    # zero left (L + T T^T, T the orthonormal translations, is L on their complement)
    tr = np.kron(np.ones((n, 1)), np.eye(d)) / np.sqrt(n)
    if n <= DENSE_BEARING_LIMIT:
        full = lap.toarray() + tr @ tr.T
        w, v = np.linalg.eigh(full)
        tol = max(float(w[-1]), 1e-300) * full.shape[0] * np.finfo(float).eps * 10
        zero = int(np.sum(w <= tol))
    else:
        count, w, v = _nullity(lap, dense=False)
        zero = count - d
        keep = np.abs(tr.T @ v).max(axis=0) < 1e-6  # drop the translations' vectors
        w, v = w[keep], v[:, keep]
    if zero != 1:
        raise FormationError(
            f"the desired bearings do not fix the shape: {zero} independent shapes meet them "
            "(the formation is not infinitesimally bearing rigid); add edges, or give the "
            "bearings of a template",
            key="bearings",
        )
    p = v[:, 0].reshape(n, d)
    p = p - p.mean(axis=0)
    if np.sum(bearings_of(p, e) * g) < 0:  # -p has the reversed bearings
        p = -p
    return p
