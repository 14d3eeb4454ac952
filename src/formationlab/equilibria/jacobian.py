"""Linearisation of the closed loop ``q_dot = u(q)`` at an equilibrium.

Every law in the package uses relative positions only and turns with the
robots: ``u(q + t) = u(q)`` and ``u(R q) = R u(q)`` for a rotation ``R``. The
equilibria therefore come in three-dimensional orbits (two translations and
one rotation), and the Jacobian ``J = du/dq`` at an equilibrium has these
three directions in its kernel. They carry no information about stability,
so they are projected out before the eigenvalues are taken: with ``T`` the
span of the rigid-motion modes, ``J T = 0`` makes ``T`` invariant, and the
remaining eigenvalues are those of ``P^T J P`` for an orthonormal basis ``P``
of the orthogonal complement of ``T``.

In space the orbits are six-dimensional: three translations and three rotations (about
the axes through the centroid), so ``J`` has six trivial zero eigenvalues; the scale is not
among them for the laws of distances (a scaled formation has other distances). At a
collinear state the rotation about its own line moves no robot, and the orbit has five
dimensions: the modes are orthonormalised by their rank.

Arrays: positions ``(n, d)``, ``d = 2`` or ``3``; the flat state is ``q.ravel()`` of length
``dn`` (``x_1, y_1, (z_1,) x_2, ...``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "jacobian",
    "reduced_eigenvalues",
    "rigid_modes",
    "rigid_modes_in_space",
]

Field = Callable[[NDArray[np.float64]], NDArray[np.float64]]


def jacobian(field: Field, q: NDArray[np.float64], *, step: float | None = None) -> NDArray:
    """``J = du/dq`` of ``field`` at ``q`` by central differences, shape ``(dn, dn)``.

    ``field`` maps positions ``(..., n, d)`` to velocities ``(..., n, d)``; all
    ``2dn`` perturbed states are evaluated in one batched call. The default step
    is ``1e-6`` times the size of the configuration (RMS distance to the
    centroid), which balances the ``O(h^2)`` truncation against rounding.
    """
    q = np.asarray(q, dtype=float)
    n2 = q.size
    if step is None:
        size = float(np.sqrt(np.mean(np.sum((q - q.mean(axis=0)) ** 2, axis=-1))))
        step = 1e-6 * max(size, 1e-3)
    e = np.eye(n2).reshape(n2, *q.shape) * step
    batch = np.concatenate([q + e, q - e])  # (2 * dn, n, d)
    u = np.asarray(field(batch)).reshape(2, n2, n2)
    return ((u[0] - u[1]) / (2.0 * step)).T  # column c is du / dq_c


def rigid_modes(q: NDArray[np.float64], invariance: str = "rotation") -> NDArray[np.float64]:
    """Orthonormal basis of the directions that leave the field unchanged at ``q``; ``(2n, 3)``.

    Translations ``(1, 0)`` and ``(0, 1)`` for every robot; the rotation about the centroid
    ``k x (q_i - c)`` (``invariance = "rotation"``, the laws of distances), or the scaling
    about it, ``q_i - c`` (``"scale"``, the bearing law: ``u(s q) = u(q)``). In space
    (``q`` of shape ``(n, 3)``) :func:`rigid_modes_in_space`, ``(3n, 6)`` at a generic state.
    """
    q = np.asarray(q, dtype=float)
    n = q.shape[0]
    if q.shape[-1] == 3:
        return rigid_modes_in_space(q, invariance)
    tx = np.tile([1.0, 0.0], n)
    ty = np.tile([0.0, 1.0], n)
    p = q - q.mean(axis=0)
    if invariance == "scale":
        third = p.ravel()
    elif invariance == "rotation":
        third = np.stack([-p[:, 1], p[:, 0]], axis=-1).ravel()
    else:
        raise ValueError(f'invariance is "rotation" or "scale", got {invariance!r}')
    basis, _ = np.linalg.qr(np.stack([tx, ty, third], axis=1))
    return basis


def rigid_modes_in_space(
    q: NDArray[np.float64], invariance: str = "rotation"
) -> NDArray[np.float64]:
    """Orthonormal basis ``(3n, r)`` of the rigid motions of ``q`` ``(n, 3)`` in space.

    The three translations ``e_a`` of every robot and the three rotations about the axes
    through the centroid, ``e_a x (q_i - c)`` (``invariance = "rotation"``), or the scaling
    ``q_i - c`` (``"scale"``). ``r`` is their rank: 6 at a generic state (7 with scaling
    alone: 4), 5 when the robots are on one line (the turn about it moves nothing).
    Reflections are not among them: a reflection is not a motion, and it flips the
    chirality of every tetrahedron (docs/three-d.md).
    """
    n = q.shape[0]
    p = q - q.mean(axis=0)
    eye = np.eye(3)
    cols = [np.tile(e, n) for e in eye]
    if invariance == "scale":
        cols.append(p.ravel())
    elif invariance == "rotation":
        cols += [np.cross(e, p).ravel() for e in eye]
    else:
        raise ValueError(f'invariance is "rotation" or "scale", got {invariance!r}')
    u, s, _ = np.linalg.svd(np.stack(cols, axis=1), full_matrices=False)
    return u[:, s > 1e-9 * s[0]]


def complement(vectors: NDArray[np.float64]) -> NDArray[np.float64]:
    """Orthonormal basis ``(N, N - r)`` of the orthogonal complement of the columns ``(N, r)``."""
    full, _, _ = np.linalg.svd(vectors, full_matrices=True)
    rank = int(np.linalg.matrix_rank(vectors))
    return full[:, rank:]


def reduced_eigenvalues(
    jac: NDArray[np.float64],
    q: NDArray[np.float64],
    *,
    extra: NDArray[np.float64] | None = None,
    invariance: str = "rotation",
) -> NDArray[np.complex128]:
    """Eigenvalues of ``jac`` with the rigid-motion modes (and ``extra`` directions) removed.

    Parameters
    ----------
    jac : ndarray, shape (dn, dn)
        Jacobian of the closed loop at the equilibrium ``q``.
    q : ndarray, shape (n, d)
        The equilibrium.
    extra : ndarray, shape (dn, r), optional
        Further directions to remove, e.g. the normal of a switching surface
        for the sliding dynamics on it (its left null vector).

    Returns
    -------
    ndarray of complex, shape (2n - 3 - r,); in space (3n - 6 - r,)
        Sorted by decreasing real part.
    """
    modes = rigid_modes(q, invariance)
    if extra is not None:
        modes = np.concatenate([modes, np.asarray(extra, dtype=float)], axis=1)
    basis = complement(modes)
    lam = np.linalg.eigvals(basis.T @ jac @ basis).astype(np.complex128)
    return lam[np.argsort(-lam.real, kind="stable")]
