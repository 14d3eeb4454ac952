"""Swarms in space: cubic lattices, the Delaunay tetrahedralisation without slivers, and
rigidity of large graphs in space (docs/three-d.md, "Swarms in space")."""

from __future__ import annotations

import json
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import Delaunay

import formationlab as fl
from formationlab.errors import FormationError
from formationlab.formation.graph import complete_edges, is_rigid
from formationlab.formation.graphs import (
    SLIVER_QUALITY,
    delaunay_edges,
    knn_edges,
    tetrahedron_quality,
    within_edges,
)
from formationlab.formation.rigidity import (
    grows_rigid_in_space,
    moves_only_rigidly,
    rigidity_matrix,
)
from formationlab.formation.templates import lattice
from formationlab.io.scenario import load_scenario

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "space"

_PAIRS = list(combinations(range(4), 2))

#: neighbours of an interior point, and the grid the points come from
CUBIC = {"cubic": 6, "fcc": 12, "bcc": 8}


def _dense_rigid(edges: np.ndarray, n: int) -> bool:
    """The rank of the dense rigidity matrix at a Gaussian placement: the reference."""
    q = np.random.default_rng(7).normal(size=(n, 3))
    return bool(np.linalg.matrix_rank(rigidity_matrix(q, edges).toarray()) == 3 * n - 6)


# ------------------------------------------------------------ Delaunay in space


def test_tetrahedron_quality_is_one_for_the_regular_and_zero_for_the_flat() -> None:
    regular = np.array(
        [[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0], [0.5, np.sqrt(3) / 6, np.sqrt(2 / 3)]]
    )
    assert tetrahedron_quality(regular) == pytest.approx(1.0, rel=1e-12)
    assert tetrahedron_quality(regular * 17.0 + 3.0) == pytest.approx(1.0, rel=1e-12)
    flat = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    assert tetrahedron_quality(flat) == 0.0
    sliver = flat + np.array([0, 0, 0, 0.01])[:, None] * np.array([0, 0, 1])
    assert 0 < tetrahedron_quality(sliver) < SLIVER_QUALITY


@pytest.mark.parametrize("kind", [*CUBIC, "random"])
def test_delaunay_in_space_keeps_the_edges_of_good_tetrahedra_and_is_rigid(kind) -> None:
    pts = (
        np.random.default_rng(3).uniform(size=(150, 3)) if kind == "random" else lattice(kind, 150)
    )
    edges = delaunay_edges(pts)
    tri = Delaunay(pts)
    simp = tri.simplices

    def sides(tets):
        return {tuple(sorted((int(t[a]), int(t[b])))) for t in tets for a, b in _PAIRS}

    want = sides(simp[tetrahedron_quality(pts[simp]) >= SLIVER_QUALITY])
    assert {tuple(e) for e in edges.tolist()} == want
    dropped = sides(simp) - want
    if kind == "cubic":
        assert dropped  # the flat tetrahedra of cospherical cubes gave edges that are gone
    assert _dense_rigid(edges, len(pts))
    assert is_rigid(edges, len(pts), dim=3)


def test_delaunay_in_space_refuses_points_in_one_plane() -> None:
    pts = np.c_[np.random.default_rng(0).uniform(size=(10, 2)), np.zeros(10)]
    with pytest.raises(FormationError, match="all in one plane"):
        delaunay_edges(pts)


# ------------------------------------------------------------ rigidity of large graphs


def _graphs(n: int):
    for kind in CUBIC:
        pts = lattice(kind, n)
        yield f"{kind}-nn", within_edges(pts, 1.0)
        for k in (4, 5, 6):
            yield f"{kind}-knn{k}", knn_edges(pts, k)
        e = delaunay_edges(pts)
        yield f"{kind}-delaunay", e
        yield f"{kind}-delaunay-less", e[np.random.default_rng(1).permutation(len(e))[:-200]]


def test_the_sparse_motion_count_agrees_with_the_dense_rank() -> None:
    verdicts = []
    for name, edges in _graphs(120):
        dense = _dense_rigid(edges, 120)
        assert moves_only_rigidly(edges, 120) == dense, name
        verdicts.append(dense)
        if grows_rigid_in_space(edges, 120):
            assert dense, name  # growth proves rigidity
    assert any(verdicts) and not all(verdicts)  # both answers were tried


def test_growth_recognises_tetrahedra_but_not_the_octahedron() -> None:
    octa = [e for e in combinations(range(6), 2) if abs(e[0] - e[1]) != 3]
    assert len(octa) == 12
    edges = np.array(octa)
    assert not grows_rigid_in_space(edges, 6)  # no tetrahedron to start from
    assert is_rigid(edges, 6, dim=3)  # yet rigid (Cauchy): the rank says so
    assert grows_rigid_in_space(complete_edges(5), 5)


def test_large_graphs_in_space_are_decided_both_ways() -> None:
    pts = lattice("fcc", 1000)
    nn = within_edges(pts, 1.0)  # octahedra and tetrahedra: not grown, counted
    assert not grows_rigid_in_space(nn, 1000)
    assert is_rigid(nn, 1000, dim=3)
    weak = knn_edges(lattice("cubic", 1000), 6)[::2]
    assert not is_rigid(weak, 1000, dim=3)
    cubic_nn = within_edges(lattice("cubic", 1000), 1.0)  # the cubes hinge: flexible
    assert not moves_only_rigidly(cubic_nn, 1000)
    assert is_rigid(delaunay_edges(lattice("bcc", 3000)), 3000, dim=3)


# ------------------------------------------------------------ scenario and run


def test_a_lattice_scenario_in_space_runs_to_its_lattice(tmp_path) -> None:
    text = (EXAMPLES / "drones-1000.toml").read_text()
    text = text.replace("count = 1000", "count = 60").replace("duration = 8.0", "duration = 6.0")
    path = tmp_path / "drones.toml"
    path.write_text(text)
    sc = load_scenario(path)
    f = sc.formation
    assert f.dim == 3 and f.n == 60 and f.is_rigid
    np.testing.assert_array_equal(f.edges, delaunay_edges(lattice("fcc", 60)))
    from typer.testing import CliRunner  # (the command line: loaded when a test needs it)

    from formationlab.cli import _load_commands, app

    _load_commands()
    res = CliRunner().invoke(app, ["run", str(path), "--out", str(tmp_path / "out"), "--quiet"])
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["outcome"] == "desired"
    assert s["max_distance_error"] < 0.01


def test_the_drone_lattice_example_is_what_it_says() -> None:
    sc = load_scenario(EXAMPLES / "drones-1000.toml")
    f = sc.formation
    assert f.n == 1000 and f.dim == 3 and f.is_rigid
    assert sc.model.name == "quadrotor" and sc.x0.shape == (1000, 6)
    assert sc.law.name == fl.DistanceLaw.name
    assert not sc.warnings
