"""Whether a formation's desired distances can be met by any configuration in the plane.

A set of desired distances ``d_ij`` on the edges of a graph is *realisable*
when some positions ``q`` have ``|q_j - q_i| = d_ij`` on every edge. The laws
drive the distance errors towards zero only if it is; otherwise every run ends
``incorrect`` or ``not-converged`` and the scenario, not the law, is at fault.
:func:`realisability_problems` finds the two ways a scenario gets this wrong:

1. a triangle of the graph violates the triangle inequality
   (``d_ij + d_jk < d_ik``), the certain and explainable case;
2. the distances admit no planar realisation although every triangle passes
   (e.g. four robots whose six distances fit only in 3-D): for the complete
   graph by classical multidimensional scaling (Young and Householder,
   Psychometrika 1938: the distances are Euclidean in the plane iff the
   double-centred matrix ``-J D^2 J / 2`` is positive semi-definite of rank
   <= 2), for other graphs by least squares from several starts, which may
   only miss a realisation of a large, awkward graph.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
from numpy.typing import NDArray

from .spec import Formation

__all__ = ["best_realisation", "realisability_problems"]

#: relative error of a distance that counts as met (3-digit rounding in the user's numbers)
_RTOL = 1e-3
#: least squares: random starts, and the largest formation it is tried on
_STARTS = 8
_MAX_ROBOTS = 200


#: most pairs of neighbours the triangle check looks at (``sum_i C(deg_i, 2)``: about a
#: minute of Python beyond it); a denser graph is not checked by triangles
_TRIANGLE_WORK = 2_000_000
#: most robots of a complete graph checked by multidimensional scaling (an ``n x n`` matrix
#: and its eigenvalues: 32 MB and a few seconds at this size)
_MDS_ROBOTS = 2000


def _triangle_work(edges: NDArray[np.integer], n: int) -> float:
    """Pairs of neighbours :func:`_triangles` looks at: ``sum_i C(deg_i, 2)``."""
    deg = np.bincount(np.asarray(edges, np.int64).ravel(), minlength=n).astype(float)
    return float(np.sum(deg * (deg - 1) / 2))


def _triangles(edges: NDArray[np.integer], n: int) -> list[tuple[int, int, int]]:
    """Triples ``i < j < k`` whose three pairs are all edges."""
    nbrs: list[set[int]] = [set() for _ in range(n)]
    for i, j in edges:
        nbrs[i].add(int(j))
        nbrs[j].add(int(i))
    out = []
    for i in range(n):
        for j, k in combinations(sorted(v for v in nbrs[i] if v > i), 2):
            if k in nbrs[j]:
                out.append((i, j, k))
    return out


def _triangle_problems(f: Formation) -> list[str]:
    d = {(int(i), int(j)): float(x) for (i, j), x in zip(f.edges, f.distances, strict=True)}
    out = []
    for i, j, k in _triangles(f.edges, f.n):
        sides = {(i, j): d[i, j], (j, k): d[j, k], (i, k): d[i, k]}
        (a, b), longest = max(sides.items(), key=lambda kv: kv[1])
        rest = sum(sides.values()) - longest
        if longest - rest > _RTOL * longest:
            others = " + ".join(f"d_{p + 1}{q + 1}" for p, q in sides if (p, q) != (a, b))
            out.append(
                f"robots {i + 1}, {j + 1} and {k + 1}: d_{a + 1}{b + 1} = {longest:g} is longer "
                f"than {others} = {rest:g}, so no triangle has these sides"
            )
    return out


def best_realisation(f: Formation, *, seed: int = 0) -> tuple[NDArray[np.float64], float]:
    """Positions that meet the desired distances best, and their largest distance error.

    Least squares on ``r_ij - d_ij`` over the edges (scipy's trust-region
    reflective method) from the template, when there is one, and from
    ``_STARTS`` random starts (a seeded generator, so the answer is repeatable).

    Returns
    -------
    q : ndarray, shape (n, dim)
    error : float
        ``max |r_ij - d_ij|`` at ``q``.
    """
    from scipy.optimize import least_squares

    e, d = f.edges, f.distances

    def residual(x: NDArray[np.float64]) -> NDArray[np.float64]:
        q = x.reshape(-1, f.dim)
        return np.linalg.norm(q[e[:, 1]] - q[e[:, 0]], axis=-1) - d

    rng = np.random.default_rng(seed)
    scale = float(np.max(d))
    starts = [rng.normal(scale=scale, size=(f.n, f.dim)) for _ in range(_STARTS)]
    if f.template is not None:
        starts.insert(0, np.asarray(f.template, float))
    best_q, best = starts[0], np.inf
    for q0 in starts:
        sol = least_squares(residual, q0.ravel(), xtol=1e-14, ftol=1e-14, gtol=1e-14)
        err = float(np.max(np.abs(residual(sol.x))))
        if err < best:
            best_q, best = sol.x.reshape(-1, f.dim), err
        if best <= 1e-9 * scale:
            break
    return best_q, best


def _mds_error(f: Formation) -> float:
    """How far the complete graph's distances are from the formation's space: relative size
    of what the double-centred squared-distance matrix has beyond ``dim`` non-negative
    eigenvalues (two in the plane, three in space)."""
    n = f.n
    D2 = np.zeros((n, n))
    D2[f.edges[:, 0], f.edges[:, 1]] = D2[f.edges[:, 1], f.edges[:, 0]] = f.distances**2
    J = np.eye(n) - 1.0 / n
    w = np.linalg.eigvalsh(-0.5 * J @ D2 @ J)[::-1]  # Gram matrix of centred points
    extra = np.concatenate([np.abs(w[f.dim :]), np.maximum(-w[: f.dim], 0.0)])
    return float(np.max(extra, initial=0.0) / max(float(w[0]), 1e-300))


def realisability_problems(f: Formation) -> list[str]:
    """Why no configuration in ``f``'s space (the plane, or space for ``dim = 3``) meets its
    desired distances; empty if one does.

    Each entry is a sentence for a warning: a violated triangle inequality
    (naming the robots), or, when every triangle passes, the best
    configuration's largest distance error. See the module docstring. Its work is bounded:
    a graph with more than :data:`_TRIANGLE_WORK` pairs of neighbours is not checked by
    triangles, and a complete graph of more than :data:`_MDS_ROBOTS` robots not at all.
    """
    out = _triangle_problems(f) if _triangle_work(f.edges, f.n) <= _TRIANGLE_WORK else []
    if out:
        return out
    complete = len(f.edges) == f.n * (f.n - 1) // 2
    if complete and f.n > _MDS_ROBOTS:
        return []  # a dense check of this size would take minutes and gigabytes
    space = "space" if f.dim == 3 else "the plane"
    if complete:
        mds = _mds_error(f)
        if mds <= 1e-9:
            return []
        if f.n > _MAX_ROBOTS:  # least squares on this many pairs would take gigabytes
            return [
                f"no configuration in {space} has these distances (they are not those of "
                f"points in {space}: multidimensional scaling leaves {mds:.3g} of their "
                "spread outside it)"
            ]
    if f.n > _MAX_ROBOTS:
        return []  # least squares would be slow; the triangles are checked
    _, err = best_realisation(f)
    if err <= _RTOL * float(np.max(f.distances)):
        return []
    return [f"no configuration in {space} has these distances (the closest one found misses "
            f"one by {err:.3g})"]  # fmt: skip
