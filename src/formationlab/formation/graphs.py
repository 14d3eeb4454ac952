"""Graph builders: the edges of a formation from its template points.

Every builder returns 0-based edges ``(i, j)`` with ``i < j``, sorted, as an
array of shape ``(m, 2)``; none builds an ``n x n`` matrix, so they work for
100,000 points (``benchmarks/bench_graphs.py``).

* :func:`delaunay_edges`: the Delaunay triangulation (scipy, Qhull), with the
  flat triangles of the boundary peeled off (see the function); in space the
  Delaunay tetrahedralisation without its slivers.
* :func:`knn_edges`: the symmetric ``k``-nearest-neighbour graph.
* :func:`within_edges`: every pair closer than a distance.
* :func:`henneberg_edges`: a minimally rigid graph (``2n - 3`` edges) by
  Henneberg type-I vertex additions (Henneberg, *Die graphische Statik der
  starren Systeme*, 1911; Tay and Whiteley, *Structural Topology* 11, 1985).
* :func:`build_edges`: one of these, or the complete graph, by name (the
  scenario key ``formation.edges``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import Delaunay, QhullError, cKDTree

from ..errors import FormationError
from ..validation import suggest
from .graph import complete_edges

__all__ = [
    "BUILDERS",
    "PEEL_ANGLE",
    "SLIVER_QUALITY",
    "build_edges",
    "delaunay_edges",
    "henneberg_edges",
    "knn_edges",
    "nearest_gap",
    "overlapping_pairs",
    "tetrahedron_quality",
    "within_edges",
]

#: Boundary triangles of a Delaunay triangulation whose angle opposite the boundary is at
#: least this (radians) are peeled off: flat slivers along the convex hull.
PEEL_ANGLE = 2.0 * math.pi / 3.0

#: Tetrahedra of a Delaunay tetrahedralisation whose quality ``6 sqrt(2) V / l^3`` (``l`` the
#: root mean square of the six edges; 1 for a regular tetrahedron, 0 for four points in a
#: plane) is below this are slivers, and give no edges.
SLIVER_QUALITY = 0.1

#: Relative tolerance of :func:`within_edges` (lattice neighbours at exactly ``r`` count).
WITHIN_RTOL = 1e-9

#: Three points whose |sin| of the angle at the new point is below this are collinear
#: (:func:`henneberg_edges` avoids such pairs of anchors when it can).
COLLINEAR_SIN = 1e-6

#: Graph names of ``formation.edges``; ``{knn = k}`` and ``{within = r}`` are tables.
BUILDERS = ("complete", "delaunay", "henneberg", "knn", "within")


def _sorted_unique(i: NDArray[np.int64], j: NDArray[np.int64]) -> NDArray[np.int64]:
    """Pairs ``(min, max)``, without repeats or loops, sorted; shape ``(m, 2)``."""
    lo, hi = np.minimum(i, j).astype(np.int64), np.maximum(i, j).astype(np.int64)
    keep = lo != hi
    lo, hi = lo[keep], hi[keep]
    if lo.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    base = int(hi.max()) + 1
    key = np.unique(lo * base + hi)  # one integer per pair: sorts as (lo, hi)
    return np.stack([key // base, key % base], axis=1)


def _points(points: ArrayLike, what: str = "", dims: tuple[int, ...] = (2,)) -> NDArray[np.float64]:
    """The builder's points, checked: ``(n, 2)``, or ``(n, 3)`` for the builders of ``dims``
    that work in space (``what`` names the builder for the message)."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim == 2 and pts.shape[1] == 3 and 3 not in dims and pts.shape[0] >= 2:
        raise FormationError(
            f"the {what} graph is built from points in the plane, and this template is in "
            'space: use edges = { knn = k }, { within = r }, "complete" or a list of pairs',
            key="edges",
        )
    if pts.ndim != 2 or pts.shape[1] not in dims or pts.shape[0] < 2:
        shapes = " or ".join(f"(n, {d})" for d in dims)
        raise FormationError(
            f"graph builders need points of shape {shapes} with n >= 2, got {pts.shape}",
            key="template",
        )
    if not np.all(np.isfinite(pts)):
        raise FormationError("the template holds NaN or infinite numbers", key="template")
    return pts


def delaunay_edges(points: ArrayLike, *, peel_angle: float = PEEL_ANGLE) -> NDArray[np.int64]:
    """Edges of the Delaunay triangulation of ``points``, boundary slivers peeled.

    The triangulation of a convex hull has flat triangles along the hull where
    boundary points are (nearly) collinear, as on every side of a lattice
    patch: exactly flat ones (three collinear points, an edge as long as the
    other two together) and thin caps whose long edge spans a shallow dent of
    the boundary. A boundary triangle (one side on the boundary) whose angle
    opposite that side is at least ``peel_angle`` (120 degrees) is removed,
    together with that side, provided its apex is not on the boundary yet
    (otherwise the triangulation would pinch into two parts hinged at one
    point); this is repeated on the triangles it exposes. The result is still
    a triangulated disc, hence rigid, and has no edge across a flat sliver.
    Interior triangles are never removed: a Delaunay triangulation has no flat
    interior triangle.

    In space (points ``(n, 3)``) the Delaunay tetrahedralisation fills the convex hull
    with tetrahedra, some of them slivers: four (nearly) coplanar points, as on every face
    of a cube of the simple cubic lattice (Qhull splits the cospherical cube into
    tetrahedra, some flat) and along the hull. A sliver's edges fix its four points only
    to first order in its height, so its edges are left out: the graph is the edges of the
    tetrahedra whose quality (:func:`tetrahedron_quality`) is at least
    :data:`SLIVER_QUALITY`. The tetrahedra that remain are joined face to face on the
    lattices and on random points tried (``tests/test_space_swarms.py``), which makes the
    graph rigid (each tetrahedron added over a face is a Henneberg step in space);
    :attr:`Formation.is_rigid` checks it for any points.

    Parameters
    ----------
    points : array_like, shape (n, 2) or, in space, (n, 3)
    peel_angle : float
        Radians; ``pi`` keeps only the exactly flat slivers out, anything above ``pi``
        keeps every triangle (the plane only).

    Returns
    -------
    ndarray of int, shape (m, 2)

    Raises
    ------
    FormationError
        The points are all on one line (no triangulation; use ``{ knn = 2 }``), or in
        space all in one plane.
    """
    pts = _points(points, "delaunay", (2, 3))
    n = pts.shape[0]
    if n == 2:
        return np.array([[0, 1]], dtype=np.int64)
    space = pts.shape[1] == 3
    try:
        tri = Delaunay(pts)
    except QhullError:
        where = "in one plane" if space else "on one line"
        raise FormationError(
            f"the template's points are all {where}, so they have no Delaunay "
            "triangulation; use edges = { knn = k } or a list of pairs",
            key="edges",
        ) from None
    simp = tri.simplices.astype(np.int64)
    if space:
        s = simp[tetrahedron_quality(pts[simp]) >= SLIVER_QUALITY]
        i = np.concatenate([s[:, a] for a, _ in _TET_EDGES])
        j = np.concatenate([s[:, b] for _, b in _TET_EDGES])
        return _sorted_unique(i, j)
    alive = _peel(pts, simp, tri.neighbors.astype(np.int64), peel_angle)
    s = simp[alive]
    i = np.concatenate([s[:, 0], s[:, 1], s[:, 2]])
    j = np.concatenate([s[:, 1], s[:, 2], s[:, 0]])
    return _sorted_unique(i, j)


#: The six edges of a tetrahedron, as pairs of its corners.
_TET_EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))


def tetrahedron_quality(corners: NDArray[np.float64]) -> NDArray[np.float64]:
    """The quality ``6 sqrt(2) V / l^3`` of tetrahedra ``corners (..., 4, 3)``: ``V`` the
    volume, ``l`` the root mean square of the six edges; 1 for the regular tetrahedron, 0
    for four points in a plane (a scale-free measure of flatness; Parthasarathy, Graichen
    and Hathaway, "A comparison of tetrahedron quality measures", Finite Elements in
    Analysis and Design 15, 1994)."""
    c = np.asarray(corners, dtype=float)
    e = c[..., 1:, :] - c[..., :1, :]  # the three edges from the first corner
    volume = (
        np.abs(np.einsum("...k,...k->...", e[..., 0, :], np.cross(e[..., 1, :], e[..., 2, :])))
        / 6.0
    )
    l2 = sum(np.sum((c[..., a, :] - c[..., b, :]) ** 2, axis=-1) for a, b in _TET_EDGES) / 6.0
    return 6.0 * math.sqrt(2.0) * volume / l2**1.5


def _peel(
    pts: NDArray[np.float64],
    simp: NDArray[np.int64],
    nbr: NDArray[np.int64],
    peel_angle: float,
) -> NDArray[np.bool_]:
    """Which triangles survive peeling (see :func:`delaunay_edges`); shape ``(T,)``."""
    alive = np.ones(len(simp), dtype=bool)
    boundary = np.zeros(len(pts), dtype=bool)
    open_side = nbr < 0  # side k (opposite vertex k) lies on the boundary
    for t, k in np.argwhere(open_side):
        boundary[simp[t, (k + 1) % 3]] = boundary[simp[t, (k + 2) % 3]] = True
    queue: list[int] = np.flatnonzero(open_side.any(axis=1)).tolist()
    while queue:
        t = int(queue.pop())
        if not alive[t]:
            continue
        sides = [k for k in range(3) if nbr[t, k] < 0 or not alive[nbr[t, k]]]
        if len(sides) != 1:
            continue
        k = sides[0]
        apex = simp[t, k]
        if boundary[apex]:
            continue
        u = pts[simp[t, (k + 1) % 3]] - pts[apex]
        v = pts[simp[t, (k + 2) % 3]] - pts[apex]
        angle = math.atan2(abs(u[0] * v[1] - u[1] * v[0]), u[0] * v[0] + u[1] * v[1])
        if angle < peel_angle * (1.0 - 1e-12):
            continue
        alive[t] = False
        boundary[apex] = True
        queue.extend(int(nbr[t, s]) for s in range(3) if s != k and nbr[t, s] >= 0)
    return alive


def knn_edges(points: ArrayLike, k: int) -> NDArray[np.int64]:
    """The symmetric ``k``-nearest-neighbour graph: ``i ~ j`` when either is among the other's.

    Ties (equal distances, as on a lattice) are broken by the k-d tree, in the
    same way on every run; every point gets at least ``k`` neighbours.

    Parameters
    ----------
    points : array_like, shape (n, 2) or, in space, (n, 3)
    k : int
        ``1 <= k < n``.
    """
    pts = _points(points, "knn", (2, 3))
    n = pts.shape[0]
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 1 <= k < n:
        raise FormationError(
            f"knn needs a whole k with 1 <= k < {n} (the number of robots), got {k!r}",
            key="edges",
        )
    _, idx = cKDTree(pts).query(pts, k=int(k) + 1)
    own = np.arange(n)[:, None]
    keep = idx != own
    full = keep.all(axis=1)  # a duplicate point took the place of the point itself
    keep[full, -1] = False
    rows = np.broadcast_to(own, idx.shape)
    return _sorted_unique(rows[keep], idx[keep])


def within_edges(points: ArrayLike, r: float) -> NDArray[np.int64]:
    """Every pair at distance ``<= r`` (to a relative 1e-9, so lattice neighbours at ``r`` count).

    Parameters
    ----------
    points : array_like, shape (n, 2) or, in space, (n, 3)
    r : float
        The largest distance of a pair (positive).

    Returns
    -------
    ndarray of int64, shape (m, 2)
        The pairs ``(i, j)``, ``i < j`` (0-based), sorted.
    """
    pts = _points(points, "within", (2, 3))
    if (
        isinstance(r, bool)
        or not isinstance(r, int | float | np.floating)
        or not (math.isfinite(r) and r > 0)
    ):
        raise FormationError(f"within needs a distance r > 0, got {r!r}", key="edges")
    pairs = cKDTree(pts).query_pairs(float(r) * (1.0 + WITHIN_RTOL), output_type="ndarray")
    return _sorted_unique(pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64))


def henneberg_edges(points: ArrayLike, *, neighbours: int = 12) -> NDArray[np.int64]:
    """A minimally rigid graph on ``points`` by Henneberg type-I vertex additions.

    Points are taken in order of distance from their centroid (ties by index).
    The first two are joined; each further point is joined to two earlier
    points: the nearest earlier one, and the nearest earlier one not collinear
    with those two (if all earlier points are on that line, the nearest one).
    A type-I addition keeps a graph minimally rigid in the plane, so the result
    has ``2n - 3`` edges and is generically minimally rigid (Laman's theorem;
    Tay and Whiteley 1985). Deterministic for given points.

    Parameters
    ----------
    points : array_like, shape (n, 2)
    neighbours : int
        How many nearest points to look among first (more only when needed).
    """
    pts = _points(points, "henneberg")
    n = pts.shape[0]
    d2 = np.sum((pts - pts.mean(axis=0)) ** 2, axis=1)
    order = np.argsort(d2, kind="stable")
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(n)
    tree = cKDTree(pts)
    kq = min(n, neighbours + 1)
    _, idx = tree.query(pts, k=kq)
    idx = idx.reshape(n, kq)
    earlier = rank[idx] < rank[:, None]
    has = earlier.any(axis=1)
    first = np.where(has, idx[np.arange(n), np.argmax(earlier, axis=1)], -1)
    u = pts[first] - pts
    v = pts[idx] - pts[:, None, :]
    cross = u[:, None, 0] * v[..., 1] - u[:, None, 1] * v[..., 0]
    scale = np.linalg.norm(u, axis=1)[:, None] * np.linalg.norm(v, axis=-1)
    ok = earlier & (idx != first[:, None]) & (np.abs(cross) > COLLINEAR_SIN * scale)
    has2 = ok.any(axis=1)
    second = np.where(has2, idx[np.arange(n), np.argmax(ok, axis=1)], -1)
    anchors = np.stack([first, second], axis=1)
    for p in order[2:][~(has & has2)[order[2:]]]:  # rare: look further than `neighbours`
        anchors[p] = _anchors(pts, order[: rank[p]], p)
    new = order[2:]
    i = np.concatenate([[order[0]], new, new])
    j = np.concatenate([[order[1]], anchors[new, 0], anchors[new, 1]])
    edges = _sorted_unique(i.astype(np.int64), j.astype(np.int64))
    return edges


def _anchors(pts: NDArray[np.float64], prior: NDArray[np.int64], p: int) -> tuple[int, int]:
    """The two anchors of point ``p`` among the ``prior`` points (see :func:`henneberg_edges`)."""
    dist = np.linalg.norm(pts[prior] - pts[p], axis=1)
    by = prior[np.argsort(dist, kind="stable")]
    a = int(by[0])
    u = pts[a] - pts[p]
    for b in by[1:]:
        v = pts[b] - pts[p]
        cross = u[0] * v[1] - u[1] * v[0]
        if abs(cross) > COLLINEAR_SIN * np.linalg.norm(u) * np.linalg.norm(v):
            return a, int(b)
    return a, int(by[1])


def build_edges(spec: str | Mapping[str, Any] | ArrayLike, points: ArrayLike) -> NDArray[np.int64]:
    """The edges named by ``spec`` on ``points`` (0-based, sorted; shape ``(m, 2)``).

    Parameters
    ----------
    spec : str or mapping
        ``"complete"``, ``"delaunay"``, ``"henneberg"``, ``{"knn": k}`` or
        ``{"within": r}`` (the scenario key ``formation.edges``).
    points : array_like, shape (n, 2)

    Raises
    ------
    FormationError
        An unknown name (with a suggestion) or a bad parameter; ``key`` is ``"edges"``.
    """
    if isinstance(spec, str):
        if spec == "complete":
            return complete_edges(_points(points, "complete", (2, 3)).shape[0])
        if spec == "delaunay":
            return delaunay_edges(points)
        if spec == "henneberg":
            return henneberg_edges(points)
        raise FormationError(
            f'unknown graph {spec!r}{suggest(spec, BUILDERS) or "."} Known: "complete", '
            '"delaunay", "henneberg", { knn = k }, { within = r }, or a list of pairs',
            key="edges",
        )
    if isinstance(spec, Mapping):
        if len(spec) != 1 or next(iter(spec)) not in ("knn", "within"):
            keys = ", ".join(map(str, spec)) or "none"
            hint = suggest(next(iter(spec), ""), ("knn", "within")) if len(spec) == 1 else ""
            raise FormationError(
                f"a graph table is {{ knn = k }} or {{ within = r }}, got the keys {keys}{hint}",
                key="edges",
            )
        if "knn" in spec:
            return knn_edges(points, spec["knn"])
        return within_edges(points, spec["within"])
    raise FormationError(f"not a graph name or table: {spec!r}", key="edges")


def overlapping_pairs(q: ArrayLike, diameters: ArrayLike) -> NDArray[np.int64]:
    """Pairs of robots that touch or overlap: ``|q_i - q_j| <= a_ij = (rho_i + rho_j) / 2``.

    A k-d tree search, so it works for 100,000 robots (``Formation.check_positions``
    compares all pairs).

    Parameters
    ----------
    q : array_like, shape (n, 2)
    diameters : array_like, shape (n,)

    Returns
    -------
    ndarray of int, shape (p, 2)
        0-based pairs ``i < j``, sorted.
    """
    pts = np.asarray(q, dtype=float)
    d = np.asarray(diameters, dtype=float)
    pairs = cKDTree(pts).query_pairs(float(np.max(d)), output_type="ndarray").astype(np.int64)
    pairs = _sorted_unique(pairs[:, 0], pairs[:, 1]) if len(pairs) else pairs.reshape(0, 2)
    r = np.linalg.norm(pts[pairs[:, 1]] - pts[pairs[:, 0]], axis=-1)
    return pairs[r <= 0.5 * (d[pairs[:, 0]] + d[pairs[:, 1]])]


def nearest_gap(q: ArrayLike, diameters: ArrayLike) -> float:
    """The smallest clearance ``|q_i - q_j| - a_ij`` over each robot's nearest neighbour.

    Parameters
    ----------
    q : array_like, shape (n, 2)
    diameters : array_like, shape (n,)
    """
    pts = np.asarray(q, dtype=float)
    d = np.asarray(diameters, dtype=float)
    dist, idx = cKDTree(pts).query(pts, k=2)
    return float(np.min(dist[:, 1] - 0.5 * (d + d[idx[:, 1]])))
