"""Chirality in three dimensions: signed volumes, their gradients, and the sign table.

In the plane, distances fix a rigid shape only up to a reflection, and the paper restricts
the orientation of triangles through the sign of ``c_ijk = (r_ij x r_ik) . k`` (eq. 14).
In space the same ambiguity is a reflection through a plane, and what it flips is the
*chirality* of every tetrahedron: the sign of its signed volume

``v_ijkl = r_ij . (r_ik x r_il) = det[r_ij, r_ik, r_il]``  (six times the volume),

with ``r_ij = q_j - q_i`` as in the paper. The idea of a signed measure next to the
distances is Anderson, Sun, Sugie, Azuma and Sakurama's, "Formation shape control with
distance and area constraints" (IFAC Journal of Systems and Control 1, 2017), lifted to
signed volumes by Liu and de Queiroz, "An orthogonal basis approach to formation shape
control" (Automatica 137, 2022). The restriction built on it here is the paper's eq. (14)
with ``v_ijkl`` in place of ``c_ijk``; docs/three-d.md derives it.

``v`` is alternating: exchanging two of ``i, j, k, l`` flips its sign, so ``beta v`` with
``beta`` the sign table below is the same number for every ordering of a quadruple. Its
gradients (the analogue of eq. 23) are

``grad_j v = r_ik x r_il``, ``grad_k v = r_il x r_ij``, ``grad_l v = r_ij x r_ik``,
``grad_i v = r_jl x r_jk`` (minus their sum: ``v`` does not change when every robot moves
by the same vector).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import FormationError
from .orientation import neighbour_lists, neighbour_triples

__all__ = [
    "COPLANAR_SINE",
    "chirality_from_shape",
    "chirality_surfaces",
    "neighbour_quadruples",
    "signed_volumes",
    "volume_gradients",
]

#: A template quadruple whose signed volume, divided by the product of its three edge
#: lengths from ``i``, is below this counts as coplanar (no chirality to keep).
COPLANAR_SINE = 1e-6


def _rows(q: NDArray[np.float64], quads: NDArray[np.integer]) -> tuple[NDArray, ...]:
    """``r_ij, r_ik, r_il`` of every quadruple; each ``(..., Q, 3)``."""
    i, j, k, m = np.asarray(quads, dtype=np.int64).reshape(-1, 4).T  # (i, j, k, l)
    qi = q[..., i, :]
    return q[..., j, :] - qi, q[..., k, :] - qi, q[..., m, :] - qi


def signed_volumes(q: ArrayLike, quads: ArrayLike) -> NDArray[np.float64]:
    """``v_ijkl = r_ij . (r_ik x r_il)`` of each quadruple; ``(..., n, 3) -> (..., Q)``."""
    q = np.asarray(q, dtype=float)
    a, b, c = _rows(q, np.asarray(quads))
    return np.einsum("...d,...d->...", a, np.cross(b, c))  # six times the signed volume


def volume_gradients(q: ArrayLike, quads: ArrayLike) -> NDArray[np.float64]:
    """``grad_i v, grad_j v, grad_k v, grad_l v`` of each quadruple; ``(..., Q, 4, 3)``.

    The 3-D analogue of the paper's eq. (23) (docs/three-d.md): the gradient at ``j`` is
    ``r_ik x r_il`` (the area vector of the face opposite ``j``, twice), and so on
    cyclically; the gradient at ``i`` is ``r_jl x r_jk``, minus the sum of the other three.
    """
    q = np.asarray(q, dtype=float)
    a, b, c = _rows(q, np.asarray(quads))
    gj = np.cross(b, c)  # r_ik x r_il
    gk = np.cross(c, a)  # r_il x r_ij
    gl = np.cross(a, b)  # r_ij x r_ik
    gi = np.cross(c - a, b - a)  # r_jl x r_jk = -(gj + gk + gl)
    return np.stack([gi, gj, gk, gl], axis=-2)


def neighbour_quadruples(edges: NDArray[np.integer], n: int) -> NDArray[np.int64]:
    """Every ``(i, j, k, l)`` with ``j < k < l`` all neighbours of ``i``; shape ``(Q, 4)``.

    Each robot holds one restriction per set of three of its neighbours (the orderings of
    a set give the same ``beta v``, so each set counts once), sorted lexicographically.
    """
    t = neighbour_triples(edges, n)  # (i, j, k), j != k neighbours of i
    t = t[t[:, 1] < t[:, 2]]
    if len(t) == 0:
        return np.zeros((0, 4), dtype=np.int64)
    _, dst, ptr = neighbour_lists(edges, n)
    reps = np.diff(ptr)[t[:, 0]]  # each (i, j, k) with every neighbour l of i
    first = np.repeat(np.arange(len(t)), reps)
    offset = np.arange(first.size) - np.repeat(np.cumsum(reps) - reps, reps)
    fourth = dst[ptr[t[first, 0]] + offset]  # l
    quads = np.concatenate([t[first], fourth[:, None]], axis=1)
    quads = quads[quads[:, 2] < quads[:, 3]]
    return quads[np.lexsort(quads.T[::-1])]


def chirality_from_shape(
    shape: ArrayLike, edges: NDArray[np.integer]
) -> tuple[NDArray[np.int64], NDArray[np.int8], int]:
    """The sign table that drives towards ``shape``'s chirality, in the paper's convention.

    ``beta_ijkl = -sign(v_ijkl)`` of the shape for every quadruple of
    :func:`neighbour_quadruples`: as with ``alpha`` in eq. (14) (docs/conventions.md), the
    restriction ``psi = beta v Upsilon(beta v + theta)`` lowers ``beta v``, so it drives
    towards ``sign(v) = -beta``. A coplanar quadruple (a cubic lattice has neighbours in
    one plane) has no chirality and is skipped; a connected set of four or more robots
    left with none is refused.

    Returns
    -------
    quads : ndarray of int, shape (Q, 4)
        The restricted quadruples, sorted.
    beta : ndarray of int8, shape (Q,)
        Their signs.
    skipped : int
        Quadruples skipped as coplanar.
    """
    pts = np.asarray(shape, dtype=float)
    n = pts.shape[0]
    quads = neighbour_quadruples(edges, n)
    a, b, c = _rows(pts, quads)
    v = np.einsum("...d,...d->...", a, np.cross(b, c))
    scale = np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1) * np.linalg.norm(c, axis=-1)
    flat = np.abs(v) <= COPLANAR_SINE * scale
    skipped = int(np.count_nonzero(flat))
    if n >= 4 and len(quads) and skipped == len(quads):
        raise FormationError(
            "every quadruple of neighbours in the template is coplanar, so no chirality is "
            'left to keep; use orientation = "free" or a graph whose neighbours span space',
            key="orientation",
        )
    keep = ~flat
    return quads[keep], (-np.sign(v[keep])).astype(np.int8), skipped


def _parity(rows: NDArray[np.int64]) -> NDArray[np.int64]:
    """+1 or -1: the sign of the permutation that sorts each row (its inversions' parity)."""
    inv = np.zeros(len(rows), dtype=np.int64)
    for a in range(rows.shape[1]):
        for b in range(a + 1, rows.shape[1]):
            inv += rows[:, a] > rows[:, b]
    return 1 - 2 * (inv % 2)


def chirality_surfaces(
    quads: NDArray[np.integer], signs: NDArray[np.integer]
) -> tuple[NDArray[np.int64], NDArray[np.int8], NDArray[np.int64]]:
    """The distinct switching surfaces ``beta_s v_abcd + theta = 0`` of the quadruples.

    ``beta_ijkl v_ijkl = beta_s v_abcd`` for the sorted tetrahedron ``a < b < c < d`` with
    ``beta_s = beta_ijkl * parity(i, j, k, l)`` (``v`` is alternating): the robots of a
    tetrahedron that each hold its restriction switch together, on one surface.

    Returns
    -------
    tetrahedra : ndarray of int, shape (s, 4)
        Sorted robots of each surface.
    beta : ndarray of int8, shape (s,)
        Coefficient of ``v_abcd`` in the switching function.
    surface : ndarray of int, shape (Q,)
        Surface of each quadruple.
    """
    q = np.asarray(quads, dtype=np.int64).reshape(-1, 4)
    beta = np.asarray(signs, dtype=np.int64).reshape(-1) * _parity(q)
    key = np.concatenate([np.sort(q, axis=1), beta[:, None]], axis=1)
    unique, surface = np.unique(key, axis=0, return_inverse=True)
    return unique[:, :4], unique[:, 4].astype(np.int8), surface.reshape(-1)
