"""Graphs of formations: edge lists, connectivity, rigidity.

Edges are pairs ``(i, j)`` with ``i < j``, 0-based, shape ``(m, 2)``; users give
them 1-based (``one_based=True``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import FormationError

__all__ = ["as_edges", "complete_edges", "is_connected", "is_rigid"]


def complete_edges(n: int) -> NDArray[np.int64]:
    """Edges ``(i, j)``, ``i < j``, of the complete graph on ``n`` robots, shape ``(m, 2)``."""
    if n < 2:
        raise FormationError(f"a formation needs at least 2 robots, got {n}", key="positions")
    i, j = np.triu_indices(n, k=1)
    return np.stack([i, j], axis=1).astype(np.int64)


def as_edges(edges: str | ArrayLike, n: int, *, one_based: bool) -> NDArray[np.int64]:
    if isinstance(edges, str):
        if edges != "complete":
            raise FormationError(
                f'edges must be "complete" or a list of robot pairs, got the string {edges!r}',
                key="edges",
            )
        return complete_edges(n)
    arr = np.asarray(edges)
    if arr.size == 0:
        raise FormationError(
            "the edge list is empty: give at least one pair of robots", key="edges"
        )
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise FormationError(
            f"edges must be pairs [i, j], got an array of shape {arr.shape}", key="edges"
        )
    if not np.all(np.isfinite(arr.astype(float))) or not np.all(arr == np.round(arr)):
        raise FormationError("edges must hold whole robot numbers", key="edges")
    arr = arr.astype(np.int64)
    base = 1 if one_based else 0
    seen: set[tuple[int, int]] = set()
    out = []
    for i, j in arr:
        for x in (i, j):
            if not base <= x < n + base:
                raise FormationError(
                    f"edge ({i}, {j}) names robot {x}, but robots are numbered "
                    f"{base}..{n - 1 + base}",
                    key="edges",
                )
        if i == j:
            raise FormationError(f"edge ({i}, {j}) joins robot {i} to itself", key="edges")
        key = (min(i, j) - base, max(i, j) - base)
        if key in seen:
            raise FormationError(f"edge ({i}, {j}) is given twice", key="edges")
        seen.add(key)
        out.append(key)
    return np.asarray(sorted(out), dtype=np.int64)


def is_connected(adjacency: NDArray[np.bool_]) -> bool:
    """Whether the graph with adjacency matrix ``(n, n)`` is connected."""
    n = adjacency.shape[0]
    seen = {0}
    frontier = [0]
    while frontier:
        i = frontier.pop()
        for j in np.flatnonzero(adjacency[i]):
            if int(j) not in seen:
                seen.add(int(j))
                frontier.append(int(j))
    return len(seen) == n


def is_rigid(edges: NDArray[np.int64], n: int) -> bool:
    """Generic infinitesimal rigidity in the plane: the rigidity matrix has rank ``2n - 3``.

    The rank is evaluated at a generic (seeded random) placement, so the answer
    is the graph's, not a particular shape's.
    """
    if n == 2:
        return len(edges) == 1
    q = np.random.default_rng(12345).normal(size=(n, 2))
    rows = np.zeros((len(edges), 2 * n))
    for e, (i, j) in enumerate(edges):
        diff = q[i] - q[j]
        rows[e, 2 * i : 2 * i + 2] = diff
        rows[e, 2 * j : 2 * j + 2] = -diff
    return bool(np.linalg.matrix_rank(rows) == 2 * n - 3)
