"""Graphs of formations: edge lists, connectivity, rigidity.

Edges are pairs ``(i, j)`` with ``i < j``, 0-based, shape ``(m, 2)``; users give
them 1-based (``one_based=True``). Builders of graphs from points (Delaunay,
k-nearest, ...) are in :mod:`formationlab.formation.graphs`; the rigidity check for large
graphs in :mod:`formationlab.formation.rigidity`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import FormationError
from ..resources import check_memory
from .rigidity import (
    grows_rigid_in_space,
    is_generically_rigid,
    moves_only_rigidly,
    rigidity_matrix,
)

__all__ = [
    "DENSE_RIGIDITY_MAX",
    "as_edges",
    "complete_edges",
    "edges_connected",
    "is_connected",
    "is_rigid",
]

#: Up to this many robots :func:`is_rigid` computes the dense rank; above, the pebble game in
#: the plane, and growth by Henneberg steps or the count of motions in space.
DENSE_RIGIDITY_MAX = 50


#: bytes per edge of building and checking a formation (measured: 671 MB at the peak for
#: the 1,999,000 edges of 2,000 robots from a scenario); the complete graph's refusal
FORMATION_BYTES_PER_EDGE = 340


def complete_edges(n: int) -> NDArray[np.int64]:
    """Edges ``(i, j)``, ``i < j``, of the complete graph on ``n`` robots, shape ``(m, 2)``."""
    if n < 2:
        raise FormationError(f"a formation needs at least 2 robots, got {n}", key="positions")
    m = n * (n - 1) // 2
    check_memory(
        FORMATION_BYTES_PER_EDGE * m, f"the complete graph of {n:,} robots ({m:,} edges)",
        key="edges", fix='use a sparser graph (edges = "delaunay", { knn = k } or { within = r })',
    )  # fmt: skip
    i, j = np.triu_indices(n, k=1)
    return np.stack([i, j], axis=1).astype(np.int64)


def as_edges(edges: str | ArrayLike, n: int, *, one_based: bool) -> NDArray[np.int64]:
    """Validated edges ``(m, 2)``, 0-based, ``i < j``, sorted, from ``"complete"`` or pairs."""
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
    outside = np.flatnonzero(((arr < base) | (arr >= n + base)).any(axis=1))
    if outside.size:
        i, j = arr[outside[0]]
        x = i if not base <= i < n + base else j
        raise FormationError(
            f"edge ({i}, {j}) names robot {x}, but robots are numbered {base}..{n - 1 + base}",
            key="edges",
        )
    loops = np.flatnonzero(arr[:, 0] == arr[:, 1])
    if loops.size:
        i, j = arr[loops[0]]
        raise FormationError(f"edge ({i}, {j}) joins robot {i} to itself", key="edges")
    pairs = np.sort(arr, axis=1) - base
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    pairs = pairs[order]
    repeat = np.flatnonzero((pairs[1:] == pairs[:-1]).all(axis=1))
    if repeat.size:
        first = np.min(order[repeat + 1])  # the later of the two, in the order given
        i, j = arr[first]
        raise FormationError(f"edge ({i}, {j}) is given twice", key="edges")
    return np.ascontiguousarray(pairs, dtype=np.int64)


def is_connected(adjacency: NDArray[np.bool_]) -> bool:
    """Whether the graph with adjacency matrix ``(n, n)`` is connected (:func:`edges_connected`)."""
    a = np.asarray(adjacency, dtype=bool)
    return edges_connected(np.argwhere(np.triu(a | a.T, k=1)), a.shape[0])


def edges_connected(edges: NDArray[np.integer], n: int) -> bool:
    """Whether the graph of ``edges`` (m, 2) on ``n`` robots is connected (sparse, any size)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return bool(connected_components(graph, directed=False, return_labels=False) == 1)


def is_rigid(edges: NDArray[np.integer], n: int, *, method: str = "auto", dim: int = 2) -> bool:
    """Generic infinitesimal rigidity: the rigidity matrix has rank ``2n - 3`` in the plane,
    ``3n - 6`` in space (``dim = 3``, ``n >= 3``; ``2n - 3`` for three robots, one for two).

    Parameters
    ----------
    edges : ndarray of int, shape (m, 2)
        0-based pairs.
    n : int
        Number of robots.
    method : {"auto", "dense", "pebble"}
        ``"dense"``: the rank of the dense rigidity matrix at a generic (seeded
        random) placement, so the answer is the graph's, not a particular
        shape's; ``"pebble"``: rigid bodies and the pebble game
        (:func:`formationlab.formation.rigidity.is_generically_rigid`, exact, for any
        size; the plane only); ``"auto"``: dense up to :data:`DENSE_RIGIDITY_MAX` robots,
        then the pebble game in the plane and the tests for large graphs in space (below).
    dim : {2, 3}
        The space. In space no counting condition decides rigidity (Laman's theorem has no
        analogue), so the rank at a random placement is the test: a placement drawn from a
        Gaussian is generic with probability one, and a rank that rounding lowers would say
        "not rigid" for a rigid graph, never the reverse (``numpy.linalg.matrix_rank``'s
        tolerance, far above the rounding of these entries). A graph of tetrahedra joined
        face to face (a Delaunay tetrahedralisation, the 12 nearest on the cubic lattices)
        is recognised first above :data:`DENSE_RIGIDITY_MAX` robots, exactly and in
        ``O(m)`` (:func:`~formationlab.formation.rigidity.grows_rigid_in_space`); other large
        graphs get the sparse test of
        :func:`~formationlab.formation.rigidity.moves_only_rigidly`.
    """
    if method not in ("auto", "dense", "pebble"):
        raise ValueError(f'method must be "auto", "dense" or "pebble", got {method!r}')
    if dim == 3:
        if method == "pebble":
            raise ValueError("the pebble game decides rigidity in the plane only")
        want = 1 if n == 2 else 3 if n == 3 else 3 * n - 6
        edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        if len(edges) < want:
            return False
        if n >= 4 and np.bincount(edges.ravel(), minlength=n).min() < 3:
            return False  # a robot with fewer than three neighbours turns about them
        if method == "auto" and n > DENSE_RIGIDITY_MAX:  # grown: exact, O(m)
            return grows_rigid_in_space(edges, n) or moves_only_rigidly(edges, n)
        q = np.random.default_rng(12345).normal(size=(n, 3))
        return bool(np.linalg.matrix_rank(rigidity_matrix(q, edges).toarray()) == want)
    if method == "pebble" or (method == "auto" and n > DENSE_RIGIDITY_MAX):
        return is_generically_rigid(edges, n)
    if n == 2:
        return len(edges) == 1
    q = np.random.default_rng(12345).normal(size=(n, 2))
    rows = np.zeros((len(edges), 2 * n))
    for e, (i, j) in enumerate(edges):
        diff = q[i] - q[j]
        rows[e, 2 * i : 2 * i + 2] = diff
        rows[e, 2 * j : 2 * j + 2] = -diff
    return bool(np.linalg.matrix_rank(rows) == 2 * n - 3)
