"""Orientation data of a formation: alpha from a shape, and the switching surfaces.

See ``docs/conventions.md`` for the sign of alpha (the paper's eq. 14 drives a
triangle to ``sign(c_ijk) = -sign(alpha_ijk)``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import FormationError
from .geometry import cross

__all__ = [
    "BETA_RTOL",
    "COLLINEAR_SIN",
    "alpha_from_shape",
    "both_orders",
    "neighbour_lists",
    "neighbour_triples",
    "signed_angle",
    "switching_surfaces",
]

#: A template triple whose |sin| of the angle at i is below this counts as collinear.
COLLINEAR_SIN = 1e-6

#: Two triples of one triangle share a switching surface when their ``beta`` agree to this.
BETA_RTOL = 1e-9


def signed_angle(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Counter-clockwise angle from ``u`` to ``v`` in ``(-pi, pi]``."""
    dot = u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1]
    return np.arctan2(cross(u, v), dot)


def neighbour_lists(
    edges: NDArray[np.integer], n: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Every half-edge ``(i, j)`` of the graph, sorted by ``i`` then ``j``, and where each
    robot's row starts: ``dst[ptr[i]:ptr[i + 1]]`` are the neighbours of ``i``, sorted."""
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    src = np.concatenate([e[:, 0], e[:, 1]])
    dst = np.concatenate([e[:, 1], e[:, 0]])
    order = np.lexsort((dst, src))
    src, dst = src[order], dst[order]
    ptr = np.concatenate([[0], np.cumsum(np.bincount(src, minlength=n))])
    return src, dst, ptr


def neighbour_triples(edges: NDArray[np.integer], n: int) -> NDArray[np.int64]:
    """Every ordered ``(i, j, k)`` with ``j != k`` both neighbours of ``i`` (the sum of eq. 13).

    Shape ``(t, 3)``, sorted lexicographically; ``t = sum_i deg_i (deg_i - 1)``, so
    the cost grows with the edges, not with ``n^3``.
    """
    src, dst, ptr = neighbour_lists(edges, n)
    deg = np.diff(ptr)
    reps = deg[src]  # each half-edge (i, j) pairs with every neighbour k of i
    first = np.repeat(np.arange(src.size), reps)
    offset = np.arange(first.size) - np.repeat(np.cumsum(reps) - reps, reps)
    k = dst[ptr[src[first]] + offset]
    t = np.stack([src[first], dst[first], k], axis=1)
    return t[t[:, 1] != t[:, 2]]


def alpha_from_shape(
    shape: NDArray[np.float64], edges: NDArray[np.int64], alpha_values: str
) -> tuple[NDArray[np.int64], NDArray[np.float64], int]:
    """``alpha_ijk`` that drive towards ``shape`` (paper's sign convention, eq. 2).

    ``alpha_ijk = -angle(r_ij -> r_ik)`` (angles) or its sign, for every ordered
    pair ``j != k`` of neighbours of ``i``. A collinear triple (a lattice has
    neighbours on opposite sides) has no orientation and is skipped; the
    formation is refused only when a connected component of three or more
    robots is left with no triple to fix its orientation.

    Returns
    -------
    triples : ndarray of int, shape (t, 3)
        The restricted triples, sorted.
    alpha : ndarray, shape (t,)
        Their ``alpha_ijk``.
    skipped : int
        Ordered triples skipped as collinear.
    """
    t = neighbour_triples(edges, shape.shape[0])
    r_ij = shape[t[:, 1]] - shape[t[:, 0]]
    r_ik = shape[t[:, 2]] - shape[t[:, 0]]
    ang = signed_angle(r_ij, r_ik)  # ccw angle r_ij -> r_ik
    coincident = (np.hypot(*r_ij.T) == 0) | (np.hypot(*r_ik.T) == 0)
    collinear = (np.abs(np.sin(ang)) < COLLINEAR_SIN) | coincident
    keep = ~collinear
    _check_oriented(t, keep, edges, shape.shape[0])
    alpha = -ang[keep]  # paper's sign: opposite to the ccw angle
    return t[keep], (np.sign(alpha) if alpha_values == "sign" else alpha), int(collinear.sum())


def _check_oriented(
    t: NDArray[np.int64], keep: NDArray[np.bool_], edges: NDArray[np.int64], n: int
) -> None:
    """Refuse a component of >= 3 robots whose triples are all collinear."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    size = np.bincount(label)
    oriented = np.zeros(size.size, bool)
    oriented[label[t[keep, 0]]] = True
    bad = np.flatnonzero((size >= 3) & ~oriented & np.isin(np.arange(size.size), label[t[:, 0]]))
    if bad.size:
        i, j, k = t[label[t[:, 0]] == bad[0]][0] + 1
        raise FormationError(
            f"robots {i}, {j} and {k} are collinear in the template, and so is every other "
            "triple of their component: nothing fixes its orientation; move a robot off the "
            'line or use orientation = "free"',
            key="template",
        )


def switching_surfaces(
    triples: NDArray[np.integer], alpha: NDArray[np.float64]
) -> tuple[NDArray[np.integer], NDArray[np.float64], NDArray[np.int32]]:
    """Distinct switching surfaces ``beta c_abc + theta = 0`` (see ``Formation.surfaces``).

    ``triples`` ``(t, 3)`` sorted lexicographically and their ``alpha`` ``(t,)``.
    Triples of one sorted triangle whose ``beta`` agree to ``BETA_RTOL`` share a
    surface, whose ``beta`` is that of its first triple; surfaces are numbered in
    the order of their first triple. Returns the triangles ``(s, 3)`` (of the triples'
    integer type), ``beta`` ``(s,)`` (float64; ``alpha`` may be float64 or int8 signs) and
    the surface of each triple ``(t,)`` (int32).

    Each triangle is one int64 key and sign-valued ``beta`` one bit of it, so that the
    scratch stays near 40 bytes a triple (a formation of 100,000 robots derives its
    surfaces inside a run: docs/swarms.md).
    """
    t = np.asarray(triples).reshape(-1, 3)
    if len(t) == 0:
        none = t[:0].copy()
        beta, surface = np.zeros(0), np.zeros(0, np.int32)
        for arr in (none, beta, surface):
            arr.setflags(write=False)
        return none, beta, surface
    i, j, k = t.T
    held = np.asarray(alpha)
    # alpha_ijk parity(i, j, k): c_ijk = parity c_abc; int8 signs stay int8 (a byte a triple)
    beta = np.array(held, dtype=np.int8 if held.dtype == np.int8 else float).reshape(-1)
    beta[(i > j) ^ (i > k) ^ (j > k)] *= -1
    lo, hi = np.minimum(np.minimum(i, j), k), np.maximum(np.maximum(i, j), k)
    top = int(hi.max()) + 1
    if top**3 < 2**62:  # the sorted triangle (a, b, c) as one key, sign-valued beta a bit of it
        key = lo.astype(np.int64)
        key *= top * top
        mid = i.astype(np.int64)
        for x in (j, k):
            mid += x
        for x in (lo, hi):
            mid -= x
        del lo
        mid *= top
        key += mid
        del mid
        key += hi
        del hi
        if np.all(np.abs(beta) == 1):
            key *= 2
            key += beta > 0
            order = np.argsort(key, kind="stable")
            key = key[order]
            new = key[1:] != key[:-1]
        else:
            order = np.lexsort((beta, key))
            key = key[order]
            sb = beta[order]
            new = (key[1:] != key[:-1]) | (
                np.abs(sb[1:] - sb[:-1]) > BETA_RTOL * np.maximum(1.0, np.abs(sb[:-1]))
            )
            del sb
        del key
    else:  # beyond 1.6 million robots: the three columns
        srt = np.sort(t, axis=1)
        order = np.lexsort((beta, srt[:, 2], srt[:, 1], srt[:, 0]))
        st, sb = srt[order], beta[order]
        new = np.any(st[1:] != st[:-1], axis=1) | (
            np.abs(sb[1:] - sb[:-1]) > BETA_RTOL * np.maximum(1.0, np.abs(sb[:-1]))
        )
        del srt, st, sb
    new = np.concatenate([[True], new])
    starts = np.flatnonzero(new)
    first = np.minimum.reduceat(order, starts)  # each surface's first triple
    del starts
    group = np.cumsum(new, dtype=np.int32)
    group -= 1
    del new
    rank = np.empty(first.size, dtype=np.int32)
    rank[np.argsort(first, kind="stable")] = np.arange(first.size, dtype=np.int32)
    surface = np.empty(len(t), dtype=np.int32)
    surface[order] = rank[group]
    del order, group, rank
    first.sort()
    tri_arr = t[first]
    tri_arr.sort(axis=1)
    beta_arr = beta[first].astype(float)
    for arr in (tri_arr, beta_arr, surface):
        arr.setflags(write=False)
    return tri_arr, beta_arr, surface


def both_orders(
    halves: NDArray[np.integer], alpha: NDArray
) -> tuple[NDArray[np.int64], NDArray, NDArray[np.int64]]:
    """Every restricted triple in both orders, from one of each pair.

    ``halves`` ``(h, 3)``: the triples ``(i, j, k)`` with ``j < k``, and their
    ``alpha`` ``(h,)``; ``alpha_ikj = -alpha_ijk`` (eq. 3) gives the others. Returns the
    ``2 h`` triples sorted lexicographically, their alpha (of ``alpha``'s type) and the
    half each one comes from.
    """
    t = np.asarray(halves, dtype=np.int64).reshape(-1, 3)
    h = len(t)
    full = np.concatenate([t, t[:, [0, 2, 1]]])
    order = np.lexsort((full[:, 2], full[:, 1], full[:, 0]))
    values = np.concatenate([alpha, -alpha])[order]  # eq. (3)
    half = np.concatenate([np.arange(h), np.arange(h)])[order]
    out = (full[order], values, half)
    for arr in out:
        arr.setflags(write=False)
    return out
