"""Pairs of robots that are close, without ``n x n`` arrays: a k-d tree query.

Khatib's repulsion acts only within clearance ``s0`` of contact, and contact
only at clearance 0, so for a formation of many robots only the pairs closer
than ``max a_ij + reach`` matter. :func:`close_pairs` finds exactly those
(``scipy.spatial.cKDTree.query_pairs``, tested against brute force), for one
state or each state of a batch; :func:`non_edges` drops the graph's edges.
Small formations (at most ``DENSE_LIMIT`` robots) keep the plain all-pairs
arithmetic of the paper's figures.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

__all__ = ["close_pairs", "non_edges", "pairs_within"]


def pairs_within(state: NDArray[np.float64], radius: float) -> NDArray[np.int64]:
    """Pairs ``i < j`` of one state ``(n, d)`` at most ``radius`` apart, sorted; ``(p, 2)``."""
    ij = cKDTree(state).query_pairs(r=float(radius), output_type="ndarray")
    ij = np.sort(ij.astype(np.int64).reshape(-1, 2), axis=1)
    return ij[np.lexsort((ij[:, 1], ij[:, 0]))]


def close_pairs(q: NDArray[np.float64], cutoff: float) -> NDArray[np.int64]:
    """Pairs ``i < j`` closer than ``cutoff`` in any state of ``q`` ``(..., n, d)``; ``(p, 2)``.

    Sorted and unique (the union over the batch).
    """
    q = np.asarray(q, dtype=float)
    n = q.shape[-2]
    found = []
    for state in q.reshape(-1, n, q.shape[-1]):
        ok = np.all(np.isfinite(state), axis=-1)
        idx = np.flatnonzero(ok)
        found.append(idx[pairs_within(state[idx], cutoff)].reshape(-1, 2))
    p = np.sort(np.concatenate(found), axis=1) if found else np.zeros((0, 2), np.int64)
    return np.unique(p, axis=0).astype(np.int64).reshape(-1, 2)


def non_edges(pairs: NDArray[np.integer], edges: NDArray[np.integer], n: int) -> NDArray[np.int64]:
    """The ``pairs`` ``(p, 2)``, ``i < j``, that are not ``edges`` ``(m, 2)``, ``i < j``.

    Each pair is the key ``i n + j``, looked up in the sorted keys of the edges
    (``O((p + m) log m)``; ``np.isin`` sorted both lists together).
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if len(e) == 0 or len(pairs) == 0:
        return pairs
    key = pairs[:, 0] * n + pairs[:, 1]
    edge_key = np.sort(e[:, 0] * n + e[:, 1])
    at = np.minimum(np.searchsorted(edge_key, key), len(edge_key) - 1)
    return pairs[edge_key[at] != key]
