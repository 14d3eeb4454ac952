"""Generic rigidity in the plane for large graphs: rigid bodies, then the pebble game.

A graph is generically (infinitesimally) rigid in the plane when its rigidity
matrix at a generic realisation has rank ``2n - 3``. By Laman's theorem
(G. Laman, *J. Engineering Mathematics* 4, 1970) that rank is combinatorial,
and the (2, 3) pebble game of Jacobs and Hendrickson (*J. Computational
Physics* 137, 1997) computes it exactly, with integer arithmetic; Jacobs and
Thorpe (*Physical Review Letters* 75, 1995) used it on lattices of a million
sites. The numerical route, the rank of the sparse rigidity matrix at a random
realisation, is not used for large graphs: scipy has no rank-revealing sparse
factorisation (SuiteSparseQR), a sparse LU (``splu``) of ``R^T R`` has no
trustworthy zero pivot in floating point, the smallest singular values of a
100,000-robot lattice (order ``1/n``) are too close to round-off to separate
reliably, and an exact rank over a finite field needs sparse elimination
whose fill-in or black-box cost (Wiedemann: ``O(n m)``) is out of reach.

:func:`generic_rank_deficit` first removes vertices of degree at most two one
by one (each carries exactly its degree in rank; this undoes Henneberg type-I
steps in any order). On what is left it grows rigid bodies
(:func:`rigid_bodies`): from an unclaimed edge, it adds every vertex joined to
the body by two unclaimed edges (a type-I step, which keeps a body rigid) until
none is left. A body is then replaced by a minimally rigid fan on the vertices
it shares with the rest of the graph, and its other vertices are dropped (each
carried exactly two independent edges): the rank changes by a known amount and
rigidity is unchanged. Henneberg graphs vanish in the first step and
triangulated graphs (Delaunay, k-nearest on a lattice) collapse to one body,
both in ``O(m)``; what is left goes through the pebble game, compiled with
numba.

In space no counting condition decides rigidity. :func:`grows_rigid_in_space` decides
it for the graphs swarms are built with (tetrahedra joined face to face: Delaunay
tetrahedralisations, nearest neighbours on the face-centred cubic lattice) in ``O(m)``:
one rigid body grown by Henneberg steps in space (a vertex joined to three vertices of a
rigid body, which a generic realisation does not place on one line, is rigid with it;
Tay and Whiteley, *Structural Topology* 11, 1985). When it covers every vertex the graph
is generically rigid, exactly; otherwise :func:`moves_only_rigidly` counts the
infinitesimal motions of a random placement with a sparse eigensolver.

Robots are 0-based here; edges ``(m, 2)`` with ``i != j``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components

from .pebble import pebble_game

__all__ = [
    "generic_rank_deficit",
    "grows_rigid_in_space",
    "independent_edges",
    "is_generically_rigid",
    "moves_only_rigidly",
    "rigid_bodies",
    "rigidity_matrix",
]


def rigidity_matrix(q: NDArray[np.float64], edges: NDArray[np.int64]) -> csr_matrix:
    """The sparse rigidity matrix ``R`` of positions ``q`` (n, d): shape ``(m, d n)``.

    Row ``e = (i, j)`` holds ``q_i - q_j`` in columns ``d i .. d i + d - 1`` and
    ``q_j - q_i`` in those of ``j``: ``R qdot`` is half the rate of change of the
    squared edge lengths. ``d`` is 2 in the plane, 3 in space.
    """
    q = np.asarray(q, dtype=float)
    d = q.shape[-1]
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    diff = q[e[:, 0]] - q[e[:, 1]]
    rows = np.repeat(np.arange(len(e)), 2 * d)
    cols = np.concatenate([d * e[:, :1] + np.arange(d), d * e[:, 1:] + np.arange(d)], axis=1)
    vals = np.concatenate([diff, -diff], axis=1)
    return coo_matrix((vals.ravel(), (rows, cols.ravel())), shape=(len(e), d * len(q))).tocsr()


def _adjacency(edges: NDArray[np.int64], n: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """CSR of the graph: ``start (n + 1,)`` and, per half-edge, ``(neighbour, edge id)``."""
    m = len(edges)
    src = np.concatenate([edges[:, 0], edges[:, 1]])
    dst = np.concatenate([edges[:, 1], edges[:, 0]])
    eid = np.concatenate([np.arange(m), np.arange(m)])
    order = np.argsort(src, kind="stable")
    start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(src, minlength=n), out=start[1:])
    return start, np.stack([dst[order], eid[order]], axis=1)


def rigid_bodies(edges: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    """Assign every edge to a rigid body grown by Henneberg type-I steps.

    Bodies are grown one after another, each from the first edge no body has
    claimed yet: a vertex joined to the body by at least two unclaimed edges
    joins it, and those edges are claimed by it. A single edge is a body too.

    Returns
    -------
    ndarray of int, shape (m,)
        The body of each edge, numbered from 0 in the order grown.
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    m = len(edges)
    start, half = _adjacency(edges, n)
    nbr, eid = half[:, 0].tolist(), half[:, 1].tolist()
    st = start.tolist()
    body = [-1] * m
    member = [-1] * n  # the body a vertex was last added to
    count = [0] * n  # unclaimed edges into the current body
    seen = [-1] * n  # the body `count` refers to
    e0, e1 = edges[:, 0].tolist(), edges[:, 1].tolist()
    b = 0
    for seed in range(m):
        if body[seed] >= 0:
            continue
        body[seed] = b
        stack: list[int] = []

        def join(v: int, b: int = b, stack: list[int] = stack) -> None:
            member[v] = b
            for h in range(st[v], st[v + 1]):
                w, e = nbr[h], eid[h]
                if body[e] >= 0 or member[w] == b:
                    continue
                if seen[w] != b:
                    seen[w], count[w] = b, 0
                count[w] += 1
                if count[w] == 2:
                    stack.append(w)

        member[e0[seed]] = member[e1[seed]] = b
        join(e0[seed])
        join(e1[seed])
        while stack:
            v = stack.pop()
            if member[v] == b:
                continue
            for h in range(st[v], st[v + 1]):  # claim v's edges into the body
                w, e = nbr[h], eid[h]
                if body[e] < 0 and member[w] == b:
                    body[e] = b
            join(v)
        b += 1
    return np.asarray(body, dtype=np.int64)


def grows_rigid_in_space(edges: NDArray[np.int64], n: int) -> bool:
    """Whether one rigid body grown in space from the first edge takes in all ``n`` vertices.

    The body starts as the first edge's two ends; a vertex joined to both joins it (a
    triangle), and from three vertices on a vertex joins it when joined to three of its
    vertices (a Henneberg type-I step in space keeps a body generically rigid), until none
    is left. ``True`` proves the graph generically rigid in space; ``False`` proves
    nothing (the octahedron is rigid and no step of this kind starts it).
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if n < 2 or len(edges) == 0:
        return n < 2
    start, half = _adjacency(edges, n)
    nbr, st = half[:, 0].tolist(), start.tolist()
    member = [False] * n
    count = [0] * n  # edges into the body
    size = 0
    stack = [int(edges[0, 1]), int(edges[0, 0])]  # the seed edge joins unconditionally
    while stack:
        v = stack.pop()
        if member[v] or count[v] < min(size, 3):
            continue
        member[v] = True
        size += 1
        for h in range(st[v], st[v + 1]):
            w = nbr[h]
            if not member[w]:
                count[w] += 1
                if count[w] >= 2:  # (checked again when taken: from three on, three)
                    stack.append(w)
    return size == n


#: An eigenvalue of ``R^T R`` below this fraction of its largest diagonal entry is a motion.
MOTION_TOL = 1e-10

#: The shift of the inverse in :func:`moves_only_rigidly`, as a fraction of the same entry:
#: a hundredth of :data:`MOTION_TOL`, so an eigenvalue above the tolerance shrinks by 100 a
#: step.
MOTION_SHIFT = 1e-12


def moves_only_rigidly(edges: NDArray[np.int64], n: int, *, seed: int = 12345) -> bool:
    """Whether a random placement of the graph in space has only the six rigid motions.

    The infinitesimal motions of a placement ``q`` are the null space of its rigidity
    matrix ``R`` (:func:`rigidity_matrix`), the eigenvectors of ``K = R^T R`` with
    eigenvalue 0; a graph of ``n >= 4`` robots is generically rigid in space when there
    are exactly six (three translations, three rotations). The seven smallest eigenvalues
    come from subspace iteration with ``(K + s I)^-1`` (one sparse LU, scipy's ``splu``;
    ``s`` = :data:`MOTION_SHIFT` times ``K``'s largest diagonal entry) on eight random
    vectors, then Rayleigh-Ritz: rigid when the seventh is above :data:`MOTION_TOL` times
    that entry. Each step shrinks an eigenvector's share by ``s / (s + lambda)``, so the
    motions (``lambda = 0``) take over whatever the other eigenvalues are, and a cluster of
    zero eigenvalues of any size (a flexible graph) does not slow it, as it does ARPACK. A
    Ritz value is never below the eigenvalue it approximates, so a flexible graph cannot
    come out rigid unless an eigenvalue of ``K`` above ``MOTION_TOL`` is a rounded zero.
    A Gaussian placement is generic with probability one; the zero eigenvalues come out
    near 1e-18 of the scale, and the seventh of the lattices tried between 1e-7 and 5e-4
    (the fcc lattice, 1,000 robots: 3e-4; 10,000: 7e-5), far on either side of
    ``MOTION_TOL``. Tested against the dense rank (``tests/test_space_swarms.py``). Cost:
    the sparse LU, about a second for 1,000 robots and a minute for 10,000.
    """
    from scipy.sparse import identity  # (a large graph's fallback only: not at import)
    from scipy.sparse.linalg import splu

    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    rng = np.random.default_rng(seed)
    r = rigidity_matrix(rng.normal(size=(n, 3)), edges)
    k = (r.T @ r).tocsc()
    scale = float(k.diagonal().max())
    lu = splu((k + MOTION_SHIFT * scale * identity(3 * n, format="csc")).tocsc())
    x = np.linalg.qr(rng.normal(size=(3 * n, 8)))[0]
    for _ in range(_SUBSPACE_STEPS):
        x = np.linalg.qr(lu.solve(x))[0]
    ritz = np.linalg.eigvalsh(x.T @ (k @ x))
    return bool(ritz[6] > MOTION_TOL * scale)


#: Steps of subspace iteration in :func:`moves_only_rigidly`.
_SUBSPACE_STEPS = 6


def _reduce(edges: NDArray[np.int64], n: int) -> tuple[NDArray[np.int64], int, int] | None:
    """The graph with its rigid bodies collapsed: ``(edges, vertices, rank carried)``.

    Each body of :func:`rigid_bodies` keeps only its vertices shared with other
    bodies, joined by a minimally rigid fan (``v0 v1``, then ``v0 vk`` and
    ``v1 vk``); every vertex of a single body is dropped and carries rank 2
    (two independent edges into a rigid body). The generic rank of the graph
    is the reduced graph's plus the rank carried. One body: no reduced graph,
    and the rank carried is ``2k - 3`` for its ``k`` vertices. ``None`` when a
    body shares a single vertex with the rest (hinged there: not rigid).
    """
    body = rigid_bodies(edges, n)
    nb = int(body.max()) + 1
    ends = np.concatenate([edges[:, 0], edges[:, 1]])
    key = np.unique(ends * nb + np.tile(body, 2))
    vb = np.stack([key // nb, key % nb], axis=1)  # (vertex, body) incidences, sorted
    per_vertex = np.bincount(vb[:, 0], minlength=n)
    if nb == 1:
        return np.zeros((0, 2), dtype=np.int64), 0, 2 * int(np.count_nonzero(per_vertex)) - 3
    keep = vb[per_vertex[vb[:, 0]] >= 2]
    if np.any(np.bincount(keep[:, 1], minlength=nb) < 2):
        return None
    carried = 2 * int(np.count_nonzero(per_vertex == 1))
    keep = keep[np.lexsort((keep[:, 0], keep[:, 1]))]  # by body, then vertex
    starts = np.flatnonzero(np.r_[True, keep[1:, 1] != keep[:-1, 1]])
    sizes = np.diff(np.r_[starts, len(keep)])
    v = keep[:, 0]
    v0, v1 = np.repeat(v[starts], sizes), np.repeat(v[starts + 1], sizes)
    pos = np.arange(len(v)) - np.repeat(starts, sizes)
    later = pos >= 2
    red = np.concatenate(
        [
            np.stack([v0[pos == 1], v[pos == 1]], axis=1),
            np.stack([v0[later], v[later]], axis=1),
            np.stack([v1[later], v[later]], axis=1),
        ]
    )
    used, inverse = np.unique(red, return_inverse=True)
    red = inverse.reshape(-1, 2).astype(np.int64)
    lo, hi = np.minimum(red[:, 0], red[:, 1]), np.maximum(red[:, 0], red[:, 1])
    key = np.unique(lo * len(used) + hi)  # bodies sharing two vertices repeat an edge
    red = np.stack([key // len(used), key % len(used)], axis=1)
    return red, len(used), carried


def independent_edges(edges: NDArray[np.int64], n: int) -> int:
    """The generic rank of the rigidity matrix: independent edges by the (2, 3) pebble game.

    Exact (integer arithmetic). Edges are played in breadth-first order, so the
    pebbles a search needs are usually close; the game stops once ``2n - 3``
    edges are independent.
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if n < 2 or len(edges) == 0:
        return 0
    start, half = _adjacency(edges, n)
    order = _bfs_edge_order(edges, n, start, half)
    return int(pebble_game(edges[order], n, 2 * n - 3))


def _bfs_edge_order(
    edges: NDArray[np.int64], n: int, start: NDArray[np.int64], half: NDArray[np.int64]
) -> NDArray[np.int64]:
    """Edges sorted by the later breadth-first rank of their two ends."""
    from scipy.sparse.csgraph import breadth_first_order

    graph = csr_matrix((np.ones(len(half)), half[:, 0], start), shape=(n, n))
    rank = np.full(n, n, dtype=np.int64)
    pos = 0
    for root in range(n):  # every component
        if rank[root] < n:
            continue
        nodes = breadth_first_order(graph, root, directed=False, return_predecessors=False)
        rank[nodes] = np.arange(pos, pos + len(nodes))
        pos += len(nodes)
    hi = np.maximum(rank[edges[:, 0]], rank[edges[:, 1]])
    lo = np.minimum(rank[edges[:, 0]], rank[edges[:, 1]])
    return np.lexsort((lo, hi))


def _peel(edges: NDArray[np.int64], n: int) -> tuple[NDArray[np.int64], int, int, bool]:
    """Remove vertices of degree <= 2 one by one: ``(core edges, core size, rank, low)``.

    A vertex of degree ``d <= 2`` (with at least two other vertices left) carries
    exactly ``d`` independent edges at a generic realisation, so the rank of the
    graph is the rank removed plus the core's; this undoes Henneberg type-I steps
    in any order. ``low`` tells whether a removed vertex had degree < 2 (then the
    graph is not rigid). The core's vertices are renumbered from 0 in order.
    """
    m = len(edges)
    start, half = _adjacency(edges, n)
    nbr, eid, st = half[:, 0].tolist(), half[:, 1].tolist(), start.tolist()
    deg = np.diff(start).tolist()
    vertex_on, edge_on = [True] * n, [True] * m
    left, carried, low = n, 0, False
    queue = [v for v in range(n) if deg[v] <= 2]
    while queue and left > 2:
        v = queue.pop()
        if not vertex_on[v] or deg[v] > 2:
            continue
        low = low or deg[v] < 2
        carried += deg[v]
        vertex_on[v] = False
        left -= 1
        for h in range(st[v], st[v + 1]):
            e = eid[h]
            if edge_on[e]:
                edge_on[e] = False
                w = nbr[h]
                deg[w] -= 1
                if deg[w] <= 2:
                    queue.append(w)
    keep = np.asarray(vertex_on, dtype=bool)
    number = np.cumsum(keep) - 1
    core = number[edges[np.asarray(edge_on, dtype=bool)]].reshape(-1, 2).astype(np.int64)
    return core, int(left), carried, low


def _core_rank(core: NDArray[np.int64], n: int, *, exact: bool) -> int | None:
    """Generic rank of a graph with no vertex of degree <= 2 (see :func:`_reduce`).

    ``None`` when ``exact`` is false and a body is hinged at one vertex (not rigid).
    """
    if n <= 2 or len(core) == 0:
        return len(core)
    reduced = _reduce(core, n)
    if reduced is None:
        return independent_edges(core, n) if exact else None
    red, n_red, carried = reduced
    return carried + (independent_edges(red, n_red) if len(red) else 0)


def generic_rank_deficit(edges: NDArray[np.int64], n: int) -> int:
    """``2n - 3`` minus the generic rank of the rigidity matrix: 0 when rigid (n >= 2)."""
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if len(edges) == 0:
        return 2 * n - 3
    core, n_core, carried, _ = _peel(edges, n)
    rank = _core_rank(core, n_core, exact=True)
    assert rank is not None
    return 2 * n - 3 - carried - rank


def is_generically_rigid(edges: NDArray[np.integer], n: int) -> bool:
    """Whether the graph is generically rigid in the plane; for any size (see the module).

    Parameters
    ----------
    edges : ndarray of int, shape (m, 2)
        0-based pairs.
    n : int
        Number of vertices, >= 2.
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if n == 2:
        return len(edges) >= 1
    if len(edges) < 2 * n - 3:
        return False
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    if connected_components(graph, directed=False, return_labels=False) != 1:
        return False
    core, n_core, carried, low = _peel(edges, n)
    if low:
        return False
    rank = _core_rank(core, n_core, exact=False)
    return rank is not None and carried + rank == 2 * n - 3
