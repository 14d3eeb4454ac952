"""Graph builders (Delaunay, knn, within, Henneberg) and the scalable rigidity check."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial import Delaunay

from formationlab.errors import FormationError
from formationlab.formation.graph import as_edges, edges_connected, is_rigid
from formationlab.formation.graphs import (
    build_edges,
    delaunay_edges,
    henneberg_edges,
    knn_edges,
    nearest_gap,
    overlapping_pairs,
    within_edges,
)
from formationlab.formation.rigidity import (
    generic_rank_deficit,
    independent_edges,
    rigid_bodies,
    rigidity_matrix,
)
from formationlab.formation.templates import lattice


def _check_layout(e: np.ndarray, n: int) -> None:
    assert e.dtype == np.int64 and e.ndim == 2 and e.shape[1] == 2
    assert np.all(e[:, 0] < e[:, 1]) and e.min() >= 0 and e.max() < n
    assert np.all(np.diff(e[:, 0] * n + e[:, 1]) > 0)  # sorted, no repeats


def _random_points(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-5.0, 5.0, size=(n, 2))


# ---------------------------------------------------------------- builders


def test_delaunay_of_a_triangular_lattice_is_its_nearest_neighbour_graph() -> None:
    # the flat slivers along the hull are peeled: no edge longer than the spacing is left
    for count in (7, 30, 500):
        pts = lattice("triangular", count, 0.5)
        e = delaunay_edges(pts)
        _check_layout(e, count)
        np.testing.assert_array_equal(e, within_edges(pts, 0.5))
        assert is_rigid(e, count)


def test_delaunay_without_peeling_is_scipys_triangulation() -> None:
    pts = _random_points(60, 1)
    simp = Delaunay(pts).simplices
    pairs = {tuple(sorted(p)) for s in simp for p in itertools.combinations(s.tolist(), 2)}
    got = delaunay_edges(pts, peel_angle=4.0)
    assert {tuple(p) for p in got.tolist()} == pairs
    peeled = delaunay_edges(pts)
    assert {tuple(p) for p in peeled.tolist()} <= pairs  # peeling only removes
    assert is_rigid(peeled, 60, method="dense")  # and keeps a triangulated, rigid disc


def test_delaunay_square_lattice_has_one_diagonal_per_cell() -> None:
    pts = lattice("square", 100, 1.0)
    e = delaunay_edges(pts)
    length = np.linalg.norm(pts[e[:, 1]] - pts[e[:, 0]], axis=1)
    sides = np.isclose(length, 1.0)
    assert np.all(sides | np.isclose(length, np.sqrt(2.0)))
    np.testing.assert_array_equal(e[sides], within_edges(pts, 1.0))
    # each full cell has exactly one of its two diagonals (the others are right-angled
    # triangles in the notches of the boundary's staircase)
    index = {p: t for t, p in enumerate(map(tuple, np.round(pts).astype(int).tolist()))}
    have = set(map(tuple, e[~sides].tolist()))
    for x, y in _square_cells(pts):
        d1 = tuple(sorted((index[x, y], index[x + 1, y + 1])))
        d2 = tuple(sorted((index[x + 1, y], index[x, y + 1])))
        assert (d1 in have) != (d2 in have)


def _square_cells(pts: np.ndarray) -> list[tuple[int, int]]:
    cells = set(map(tuple, np.round(pts).astype(int).tolist()))
    return [(x, y) for x, y in cells if {(x + 1, y), (x, y + 1), (x + 1, y + 1)} <= cells]


def test_delaunay_small_and_degenerate_inputs() -> None:
    np.testing.assert_array_equal(delaunay_edges([[0.0, 0.0], [1.0, 0.0]]), [[0, 1]])
    with pytest.raises(FormationError, match="on one line") as info:
        delaunay_edges([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    assert info.value.key == "edges"


def test_knn_is_the_symmetric_union_of_the_k_nearest() -> None:
    pts = _random_points(150, 2)
    k = 4
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    near = np.argsort(d, axis=1)[:, :k]
    want = {(min(i, j), max(i, j)) for i in range(150) for j in near[i].tolist()}
    e = knn_edges(pts, k)
    _check_layout(e, 150)
    assert {tuple(p) for p in e.tolist()} == want
    assert np.all(np.bincount(e.ravel(), minlength=150) >= k)


def test_knn_on_a_triangular_lattice_with_six_is_the_triangulation() -> None:
    pts = lattice("triangular", 91, 1.0)
    e = knn_edges(pts, 6)
    unit = within_edges(pts, 1.0)
    inner = np.bincount(unit.ravel(), minlength=91) == 6  # points with their whole hexagon
    both = inner[e[:, 0]] & inner[e[:, 1]]
    np.testing.assert_array_equal(e[both], unit[inner[unit[:, 0]] & inner[unit[:, 1]]])
    assert set(map(tuple, unit.tolist())) <= set(map(tuple, e.tolist()))


@pytest.mark.parametrize("k", [0, 5, 2.0, True])
def test_knn_rejects_bad_k(k: object) -> None:
    with pytest.raises(FormationError, match=r"1 <= k < 5"):
        knn_edges(_random_points(5, 0), k)  # type: ignore[arg-type]


def test_within_matches_brute_force_and_counts_pairs_at_exactly_r() -> None:
    pts = _random_points(120, 3)
    r = 1.3
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    i, j = np.nonzero(np.triu(d <= r, k=1))
    np.testing.assert_array_equal(within_edges(pts, r), np.stack([i, j], axis=1))
    sq = lattice("square", 49, 0.1)  # 0.1 is not exact in binary; neighbours still count
    assert len(within_edges(sq, 0.1)) == len(within_edges(sq, 0.1 * 1.01))
    with pytest.raises(FormationError, match="r > 0"):
        within_edges(pts, -1.0)


@pytest.mark.parametrize("kind", ["triangular", "square", "hexagonal"])
def test_henneberg_is_minimally_rigid_and_deterministic(kind: str) -> None:
    pts = lattice(kind, 40, 1.0)
    e = henneberg_edges(pts)
    _check_layout(e, 40)
    assert len(e) == 2 * 40 - 3
    assert is_rigid(e, 40, method="dense")
    for drop in range(len(e)):  # minimal: every edge is needed
        assert not is_rigid(np.delete(e, drop, axis=0), 40, method="dense")
    np.testing.assert_array_equal(e, henneberg_edges(pts.copy()))


def test_henneberg_on_random_points_and_collinear_prefixes() -> None:
    pts = _random_points(30, 4)
    e = henneberg_edges(pts, neighbours=2)  # forces the fallback search for some points
    assert len(e) == 57 and is_rigid(e, 30, method="dense")
    line = np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [2.0, 0.0], [0.5, 1.0]])
    e = henneberg_edges(line)
    assert len(e) == 7 and is_rigid(e, 5, method="dense")


def test_build_edges_by_name() -> None:
    pts = lattice("triangular", 19, 1.0)
    np.testing.assert_array_equal(build_edges("delaunay", pts), delaunay_edges(pts))
    np.testing.assert_array_equal(build_edges("henneberg", pts), henneberg_edges(pts))
    np.testing.assert_array_equal(build_edges({"knn": 3}, pts), knn_edges(pts, 3))
    np.testing.assert_array_equal(build_edges({"within": 1.0}, pts), within_edges(pts, 1.0))
    assert len(build_edges("complete", pts)) == 19 * 18 // 2
    with pytest.raises(FormationError, match="did you mean 'delaunay'"):
        build_edges("delauny", pts)
    with pytest.raises(FormationError, match="did you mean 'knn'"):
        build_edges({"kn": 3}, pts)


def test_overlapping_pairs_and_gap_agree_with_brute_force() -> None:
    q = _random_points(300, 5)
    diam = np.random.default_rng(6).uniform(0.0, 0.6, size=300)
    d = np.linalg.norm(q[:, None] - q[None], axis=-1)
    a = 0.5 * (diam[:, None] + diam[None])
    i, j = np.nonzero(np.triu(d <= a, k=1))
    np.testing.assert_array_equal(overlapping_pairs(q, diam), np.stack([i, j], axis=1))
    np.fill_diagonal(d, np.inf)
    nn = np.argmin(d, axis=1)
    want = np.min(d[np.arange(300), nn] - a[np.arange(300), nn])
    assert nearest_gap(q, diam) == pytest.approx(want, rel=1e-12)


def test_as_edges_errors_keep_their_wording() -> None:
    with pytest.raises(FormationError, match=r"edge \(1, 5\) names robot 5"):
        as_edges([[1, 2], [1, 5]], 4, one_based=True)
    with pytest.raises(FormationError, match=r"edge \(3, 3\) joins robot 3 to itself"):
        as_edges([[1, 2], [3, 3]], 4, one_based=True)
    with pytest.raises(FormationError, match=r"edge \(2, 1\) is given twice"):
        as_edges([[1, 2], [3, 4], [2, 1], [4, 3]], 4, one_based=True)
    np.testing.assert_array_equal(as_edges([[3, 1], [2, 1]], 3, one_based=True), [[0, 1], [0, 2]])


# ---------------------------------------------------------------- rigidity


def _random_graph(rng: np.random.Generator) -> tuple[np.ndarray, int]:
    n = int(rng.integers(3, 11))
    pairs = np.array(list(itertools.combinations(range(n), 2)))
    m = int(np.clip(rng.normal(2 * n - 3, 2.0), 1, len(pairs)))  # around the Laman count
    return pairs[np.sort(rng.choice(len(pairs), m, replace=False))], n


def test_pebble_game_agrees_with_the_dense_rank_on_random_graphs() -> None:
    rng = np.random.default_rng(7)
    rigid = 0
    for _ in range(400):
        e, n = _random_graph(rng)
        q = rng.normal(size=(n, 2))
        rank = int(np.linalg.matrix_rank(rigidity_matrix(q, e).toarray()))
        assert independent_edges(e, n) == rank
        assert generic_rank_deficit(e, n) == 2 * n - 3 - rank
        dense = is_rigid(e, n, method="dense")
        assert is_rigid(e, n, method="pebble") == dense == (rank == 2 * n - 3)
        rigid += dense
    assert 50 < rigid < 350  # both answers are exercised


_K4 = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
_K4b = [(i + 4, j + 4) for i, j in _K4]

KNOWN = {
    "triangle": ([(0, 1), (1, 2), (0, 2)], 3, True),
    "square with one diagonal": ([(0, 1), (1, 2), (2, 3), (0, 3), (0, 2)], 4, True),
    "square": ([(0, 1), (1, 2), (2, 3), (0, 3)], 4, False),
    "path": ([(0, 1), (1, 2), (2, 3)], 4, False),
    "star": ([(0, 1), (0, 2), (0, 3), (0, 4)], 5, False),
    "two triangles sharing a vertex": ([(0, 1), (1, 2), (0, 2), (2, 3), (3, 4), (2, 4)], 5, False),
    "two triangles sharing an edge": ([(0, 1), (1, 2), (0, 2), (1, 3), (2, 3)], 4, True),
    "K33": ([(i, j) for i in range(3) for j in range(3, 6)], 6, True),
    # two K4 joined by two bars: 14 >= 2n - 3 = 13 edges, yet they turn about a point
    "two K4 and two bars": (_K4 + _K4b + [(0, 4), (2, 6)], 8, False),
    "two K4 and three bars": (_K4 + _K4b + [(0, 4), (2, 6), (3, 7)], 8, True),
}


@pytest.mark.parametrize("name", sorted(KNOWN))
@pytest.mark.parametrize("method", ["dense", "pebble"])
def test_known_cases(name: str, method: str) -> None:
    edges, n, rigid = KNOWN[name]
    assert is_rigid(np.array(edges), n, method=method) is rigid


def test_known_deficits() -> None:
    tri2 = np.array(KNOWN["two triangles sharing a vertex"][0])
    assert generic_rank_deficit(tri2, 5) == 1  # one hinge
    n = 50
    path = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    assert generic_rank_deficit(path, n) == (2 * n - 3) - (n - 1)


def test_rigid_bodies_of_a_triangulation_is_one_body() -> None:
    pts = lattice("triangular", 200, 1.0)
    e = delaunay_edges(pts)
    assert np.all(rigid_bodies(e, 200) == 0)
    tri2 = np.array(KNOWN["two triangles sharing a vertex"][0])
    np.testing.assert_array_equal(rigid_bodies(tri2, 5), [0, 0, 0, 1, 1, 1])


def test_rigidity_matrix_values_and_trivial_motions() -> None:
    q = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]])
    e = np.array([[0, 1], [0, 2], [1, 2]])
    r = rigidity_matrix(q, e).toarray()
    np.testing.assert_array_equal(
        r, [[-2, 0, 2, 0, 0, 0], [0, -1, 0, 0, 0, 1], [0, 0, 2, -1, -2, 1]]
    )
    rng = np.random.default_rng(8)
    q = rng.normal(size=(20, 2))
    e = delaunay_edges(q)
    rot = np.stack([-q[:, 1], q[:, 0]], axis=1).ravel()
    for motion in (np.tile([1.0, 0.0], 20), np.tile([0.0, 1.0], 20), rot):
        np.testing.assert_allclose(rigidity_matrix(q, e) @ motion, 0.0, atol=1e-12)


def test_rigidity_at_ten_thousand_robots() -> None:
    pts = lattice("triangular", 10_000, 1.0)
    e = delaunay_edges(pts)
    assert edges_connected(e, 10_000) and is_rigid(e, 10_000)
    h = henneberg_edges(pts)
    assert len(h) == 2 * 10_000 - 3 and is_rigid(h, 10_000)
    assert not is_rigid(h[1:], 10_000)  # minimally rigid: one edge less is a mechanism
    tree = np.stack([np.arange(1, 10_000) // 2, np.arange(1, 10_000)], axis=1)
    assert edges_connected(tree, 10_000) and not is_rigid(tree, 10_000)
    assert not edges_connected(e[np.all(e != 0, axis=1)], 10_000)  # robot 1 cut off


def _hinged(pts: np.ndarray) -> np.ndarray:
    """Two minimally rigid halves joined by two bars plus one redundant edge in a half."""
    e = delaunay_edges(pts)
    left = pts[:, 0] < 0
    parts = []
    for side in (left, ~left):
        idx = np.flatnonzero(side)
        parts.append(idx[henneberg_edges(pts[idx])])
    across = e[left[e[:, 0]] != left[e[:, 1]]][:2]
    have = {tuple(x) for x in parts[0].tolist()}
    extra = next(x for x in e[left[e[:, 0]] & left[e[:, 1]]].tolist() if tuple(x) not in have)
    return np.unique(np.sort(np.concatenate([*parts, across, [extra]]), axis=1), axis=0)


@pytest.mark.parametrize("n", [40, 10_000])
def test_enough_edges_yet_hinged(n: int) -> None:
    # 2n - 3 edges, so counting does not decide; the halves turn about a point
    pts = lattice("triangular", n, 1.0)
    g = _hinged(pts)
    assert len(g) == 2 * n - 3
    assert not is_rigid(g, n, method="pebble") and generic_rank_deficit(g, n) == 1
    more = np.unique(np.concatenate([g, delaunay_edges(pts)]), axis=0)  # the triangulation
    assert is_rigid(more, n, method="pebble") and generic_rank_deficit(more, n) == 0
    if n <= 50:
        assert not is_rigid(g, n, method="dense") and is_rigid(more, n, method="dense")
