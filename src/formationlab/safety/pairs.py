"""Which robots sense each other: pairs within a sensing radius.

A barrier constraint is only posed between robots closer than the sensing
radius ``R`` (Wang, Ames and Egerstedt, IEEE T-RO 2017, section IV: each robot
only needs its neighbours within range). Small formations use a dense distance
matrix; large ones a k-d tree (:func:`formationlab.neighbours.kdtree.pairs_within`), which is
``O(n log n + m)`` instead of ``O(n^2)``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..neighbours.kdtree import pairs_within

__all__ = ["neighbour_lists", "sensed_pairs"]

#: Below this many robots the dense ``n x n`` search is faster than building a tree.
DENSE_BELOW = 48


def _dense_pairs(q: NDArray[np.float64], radius: float) -> NDArray[np.int64]:
    """``(trial, i, j)`` with ``|q_i - q_j| <= radius``, ``i < j``, from ``(B, n, d)``."""
    n = q.shape[-2]
    iu, ju = np.triu_indices(n, k=1)
    diff = q[:, ju, :] - q[:, iu, :]
    d2 = np.einsum("bpk,bpk->bp", diff, diff)
    b, p = np.nonzero(d2 <= radius * radius)
    return np.stack([b, iu[p], ju[p]], axis=-1).astype(np.int64)


def sensed_pairs(q: NDArray[np.float64], radius: float) -> NDArray[np.int64]:
    """All pairs of robots within ``radius`` of each other, per trial.

    Parameters
    ----------
    q : ndarray, shape (..., n, d)
        Positions; the batch axes are flattened.
    radius : float
        Sensing radius ``R`` (``inf``: every pair).

    Returns
    -------
    pairs : ndarray of int64, shape (m, 3)
        Rows ``(trial, i, j)`` with ``i < j`` and ``|q_i - q_j| <= R``, sorted by trial,
        then ``i``, then ``j``; ``trial`` indexes the flattened batch.
    """
    q = np.asarray(q, dtype=float)
    n = q.shape[-2]
    flat = q.reshape(-1, n, q.shape[-1])
    if n < 2:
        return np.zeros((0, 3), np.int64)
    if n < DENSE_BELOW or not math.isfinite(radius):
        return _dense_pairs(flat, radius)
    out = []
    for b in range(flat.shape[0]):
        ij = pairs_within(flat[b], radius)
        out.append(np.column_stack([np.full(len(ij), b, np.int64), ij]))
    return np.concatenate(out) if out else np.zeros((0, 3), np.int64)


def neighbour_lists(
    pairs: NDArray[np.int64], trials: int, n: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Compressed neighbour lists of the flattened robots ``r = trial * n + i``.

    Parameters
    ----------
    pairs : ndarray of int, shape (m, 3)
        ``(trial, i, j)`` from :func:`sensed_pairs`.
    trials, n : int
        Number of trials and of robots per trial.

    Returns
    -------
    ptr : ndarray of int64, shape (trials * n + 1,)
        Robot ``r``'s neighbours are ``nbr[ptr[r]:ptr[r + 1]]``.
    nbr : ndarray of int64, shape (2 m,)
        Flattened neighbour indices ``trial * n + j``, ascending within each robot.
    """
    base = pairs[:, 0] * n
    src = np.concatenate([base + pairs[:, 1], base + pairs[:, 2]])
    dst = np.concatenate([base + pairs[:, 2], base + pairs[:, 1]])
    order = np.lexsort((dst, src))
    counts = np.bincount(src, minlength=trials * n)
    ptr = np.zeros(trials * n + 1, np.int64)
    np.cumsum(counts, out=ptr[1:])
    return ptr, dst[order].astype(np.int64)
