"""The graph-family scenarios of docs/swarms.md have the graphs they are named after."""

from __future__ import annotations

from pathlib import Path

import pytest

from formationlab.formation.graph import edges_connected, is_rigid
from formationlab.io.scenario import load_scenario

FOLDER = Path(__file__).resolve().parents[1] / "examples" / "graph-families"


def expected(family: str, n: int) -> tuple[int, bool]:
    """Edges and rigidity of a family on ``n`` robots."""
    return {
        "complete": (n * (n - 1) // 2, True),
        "triangulated": (6 if n == 4 else 2 * n, True),
        "henneberg": (2 * n - 3, True),
        "tree": (n - 1, False),
        "cycle-chord": (n + 1, n == 4),
    }[family]


@pytest.mark.parametrize("kind", ["polygon", "lattice"])
def test_graph_family_scenarios(kind: str) -> None:
    files = sorted((FOLDER / kind).glob("*.toml"))
    assert len(files) == 25
    for path in files:
        n_text, family = path.stem.split("-", 1)
        n = int(n_text.removeprefix("n"))
        sc = load_scenario(path)
        f = sc.formation
        assert sc.n == n and edges_connected(f.edges, n)
        assert sc.study is not None and sc.study["laws"] == ["distance", "angle-restricted"]
        if family == "delaunay":
            assert len(f.edges) >= 2 * n - 3 and is_rigid(f.edges, n)
            continue
        m, rigid = expected(family, n)
        assert (len(f.edges), is_rigid(f.edges, n)) == (m, rigid), path.name
        thin = [w for w in sc.warnings if "restrictions" in w]
        if kind == "polygon":
            assert not thin  # every triangle of a regular polygon is thicker than theta
