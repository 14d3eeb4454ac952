"""Distances that no planar configuration meets: found, explained, and warned about."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import formationlab as fl
from formationlab.cli import _load_commands, app
from formationlab.formation.realisability import best_realisation, realisability_problems

_load_commands()


def complete(n: int, distances: object) -> fl.Formation:
    return fl.Formation.from_distances(n, distances=distances, diameters=0.1)


def test_a_triangle_with_sides_1_1_5_violates_the_triangle_inequality() -> None:
    # edges in order 1-2, 1-3, 2-3
    problems = realisability_problems(complete(3, [1.0, 1.0, 5.0]))
    assert problems == [
        "robots 1, 2 and 3: d_23 = 5 is longer than d_12 + d_13 = 2, so no triangle has these sides"
    ]


@pytest.mark.parametrize(
    "distances",
    [
        [1.0, 1.0, 1.0],  # equilateral
        [3.0, 4.0, 5.0],  # right angle
        [1.0, 1.0, 2.0],  # collinear: degenerate, but met
    ],
)
def test_triangles_that_exist_pass(distances: list[float]) -> None:
    assert realisability_problems(complete(3, distances)) == []


def test_four_robots_all_at_distance_1_fit_only_in_space() -> None:
    # a regular tetrahedron: every triangle is equilateral, no planar placement exists
    f = complete(4, 1.0)
    problems = realisability_problems(f)
    assert len(problems) == 1
    assert problems[0].startswith("no configuration in the plane has these distances")
    # the least-squares optimum, by hand: a square of side s (diagonals s sqrt 2)
    # minimises 4 (s - 1)^2 + 2 (s sqrt 2 - 1)^2 at s = 1/2 + sqrt(2)/4 (sum of squares
    # 0.172, against 0.402 for the best triangle with its centre); the largest error is
    # the diagonal's, s sqrt 2 - 1 = sqrt(2)/2 - 1/2
    q, err = best_realisation(f)
    assert err == pytest.approx(math.sqrt(2) / 2 - 0.5, abs=1e-7)
    r = np.sort(np.linalg.norm(q[:, None] - q[None], axis=-1)[np.triu_indices(4, 1)])
    s = 0.5 + math.sqrt(2) / 4
    np.testing.assert_allclose(r, [s] * 4 + [s * math.sqrt(2)] * 2, atol=1e-7)


def test_a_square_with_diagonals_rounded_to_three_digits_passes() -> None:
    # edges 1-2, 1-3, 1-4, 2-3, 2-4, 3-4 of the square 1-2-3-4; diagonals 1-3 and 2-4
    d = [1.0, 1.414, 1.0, 1.0, 1.414, 1.0]
    assert realisability_problems(complete(4, d)) == []


def test_a_non_complete_graph_is_checked_by_least_squares() -> None:
    # the tetrahedron (robots 1-4) plus robot 5 tied to robots 1 and 2: not complete,
    # every triangle passes, no planar realisation
    edges = [[1, 2], [1, 3], [1, 4], [2, 3], [2, 4], [3, 4], [1, 5], [2, 5]]
    f = fl.Formation.from_distances(5, edges=edges, distances=1.0, diameters=0.1)
    problems = realisability_problems(f)
    assert len(problems) == 1 and problems[0].startswith("no configuration in the plane")
    ok = fl.Formation.from_distances(
        5, edges=[e for e in edges if e != [3, 4]], distances=1.0, diameters=0.1
    )
    assert realisability_problems(ok) == []


def test_a_template_formation_is_realisable_by_construction(rng: np.random.Generator) -> None:
    q = rng.normal(size=(7, 2)) * 3
    f = fl.Formation.from_template(q, diameters=0.01)
    assert realisability_problems(f) == []
    best, err = best_realisation(f)
    assert err < 1e-9
    np.testing.assert_allclose(fl.outcomes.analysis.distance_errors(f, best), 0.0, atol=1e-9)


BAD_TRIANGLE = """\
name = "bad-triangle"
[robots]
positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]
diameters = 0.2
[formation]
edges = "complete"
distances = [1.0, 1.0, 5.0]
[controller]
law = "distance"
k_c = 2.0
[simulation]
integrator = "euler"
dt = 1e-3
duration = 0.1
"""


def test_validate_and_run_warn_before_the_run(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(BAD_TRIANGLE)
    cli = CliRunner()
    warning = (
        "formation.distances cannot all be met: robots 1, 2 and 3: d_23 = 5 is longer than "
        "d_12 + d_13 = 2, so no triangle has these sides; runs will not reach the desired "
        "shape, check the distances"
    )
    res = cli.invoke(app, ["validate", str(path)], catch_exceptions=False)
    assert res.exit_code == 0
    assert f"warning: {path}: {warning}" in res.stderr.replace("\n", " ")
    res = cli.invoke(app, ["run", str(path), "--out", str(tmp_path / "o")], catch_exceptions=False)
    assert res.exit_code == 0
    assert f"warning: {warning}" in res.stderr.replace("\n", " ")
    assert res.stderr.index("warning:") < res.stderr.index("100 steps")  # before the run
