"""The (2, 3) pebble game, compiled (private to :mod:`formationlab.formation.rigidity`).

Jacobs and Hendrickson, "An algorithm for two-dimensional rigidity
percolation: the pebble game", J. Computational Physics 137 (1997). Every
vertex starts with two pebbles; an edge is independent when four pebbles can
be gathered on its two ends, and is then covered by a pebble of one end
(directed away from it). Pebbles move by reversing directed paths.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _find(root, avoid, pebbles, out, seen, stamp, parent, stack):  # type: ignore[no-untyped-def]
    """Bring one free pebble to ``root`` along a directed path avoiding ``avoid``."""
    seen[root] = stamp
    seen[avoid] = stamp
    top = 0
    stack[top] = root
    top += 1
    while top > 0:
        top -= 1
        w = stack[top]
        for s in range(2):
            x = out[w, s]
            if x < 0 or seen[x] == stamp:
                continue
            seen[x] = stamp
            parent[x] = w
            if pebbles[x] > 0:
                y = x
                while y != root:  # reverse the path root -> ... -> x
                    p = parent[y]
                    if out[p, 0] == y:
                        out[p, 0] = -1
                    else:
                        out[p, 1] = -1
                    if out[y, 0] < 0:
                        out[y, 0] = p
                    else:
                        out[y, 1] = p
                    pebbles[y] -= 1
                    pebbles[p] += 1
                    y = p
                return True
            stack[top] = x
            top += 1
    return False


@njit(cache=True)
def pebble_game(edges, n, target):  # type: ignore[no-untyped-def]
    """Number of independent edges of ``edges`` (m, 2) on ``n`` vertices, up to ``target``."""
    pebbles = np.full(n, 2, dtype=np.int64)
    out = np.full((n, 2), -1, dtype=np.int64)
    seen = np.zeros(n, dtype=np.int64)
    parent = np.zeros(n, dtype=np.int64)
    stack = np.zeros(n, dtype=np.int64)
    stamp = 0
    independent = 0
    for e in range(edges.shape[0]):
        u = edges[e, 0]
        v = edges[e, 1]
        if u == v:
            continue
        while pebbles[u] < 2:
            stamp += 1
            if not _find(u, v, pebbles, out, seen, stamp, parent, stack):
                break
        while pebbles[v] < 2:
            stamp += 1
            if not _find(v, u, pebbles, out, seen, stamp, parent, stack):
                break
        if pebbles[u] + pebbles[v] == 4:
            if out[u, 0] < 0:
                out[u, 0] = v
            else:
                out[u, 1] = v
            pebbles[u] -= 1
            independent += 1
            if independent >= target:
                break
    return independent
