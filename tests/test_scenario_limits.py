"""Scenarios that used to end in a traceback: each is one line naming the key and its line.

A noise so large that the start overflows (scipy's k-d tree), arrays nested thousands
deep (the TOML reader's recursion), a lattice or a complete graph too large for memory
(refused by an estimate before anything is allocated), a NUL in the name (which the
results' files cannot hold).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from _scenarios import triangle
from typer.testing import CliRunner

from formationlab import resources
from formationlab.cli import _load_commands, app
from formationlab.errors import ScenarioError
from formationlab.scenario import parse_scenario

_load_commands()

LATTICE = """\
name = "lattice"
[robots]
positions = { around = "template", sigma = SIGMA, seed = 1 }
diameters = 0.2
[formation]
template = { lattice = "triangular", count = COUNT, spacing = 1.0 }
edges = "EDGES"
orientation = "free"
[controller]
law = "distance"
[simulation]
integrator = "euler"
dt = 1e-3
duration = 1.0
"""


def lattice(sigma: str = "0.05", count: str = "100", edges: str = "delaunay") -> str:
    return LATTICE.replace("SIGMA", sigma).replace("COUNT", count).replace("EDGES", edges)


def refusal(text: str) -> str:
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, source="s.toml")
    return str(info.value)


def test_a_start_drawn_with_a_huge_sigma_is_refused() -> None:
    message = refusal(lattice(sigma="1e200"))
    assert message.startswith(
        "s.toml: robots.positions (line 3): the start drawn around the template "
        "(sigma = 1e+200) has coordinates up to "
    )
    assert "beyond 1e+150" in message


def test_arrays_nested_thousands_deep_are_refused() -> None:
    deep = "[" * 5000 + "]" * 5000
    text = triangle("deep", "1.0").replace("[[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]", deep)
    assert refusal(text) == (
        "s.toml: robots.positions (line 3): arrays or tables nested more than 32 deep, too "
        "deep to read; positions are a list of pairs, [[x, y], ...]"
    )


def test_a_lattice_too_large_for_memory_is_refused_before_it_is_built(monkeypatch) -> None:
    monkeypatch.setattr(resources, "available_memory", lambda: 16e9)
    assert refusal(lattice(count="1000000000")) == (
        "s.toml: formation.template (line 6): a triangular lattice of 1,000,000,000 points "
        "needs about 282 GB of memory to build, 16 GB available (at most half of it: a run "
        "needs as much again); use fewer points"
    )


def test_a_complete_graph_too_large_for_memory_is_refused_before_it_is_built(
    monkeypatch,
) -> None:
    monkeypatch.setattr(resources, "available_memory", lambda: 16e9)
    message = refusal(lattice(count="10000", edges="complete"))
    assert message == (
        "s.toml: formation.edges (line 7): the complete graph of 10,000 robots (49,995,000 "
        "edges) needs about 17 GB of memory to build, 16 GB available (at most half of it: a "
        'run needs as much again); use a sparser graph (edges = "delaunay", { knn = k } or '
        "{ within = r })"
    )
    # the same graph of fewer robots is built
    assert len(parse_scenario(lattice(count="60", edges="complete")).formation.edges) == 1770


@pytest.mark.parametrize("name", ["a\\u0000b", "tab\\u0007bell"])
def test_a_control_character_in_the_name_is_refused(name: str) -> None:
    message = refusal(triangle(name, "1.0"))
    assert message.startswith("s.toml: name (line 1): must be printable text, got the control")


def test_validate_prints_one_line_and_exits_2(tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(lattice(sigma="1e200"))
    res = CliRunner().invoke(app, ["validate", str(scenario)], catch_exceptions=False)
    assert res.exit_code == 2 and "Traceback" not in res.output
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "robots.positions (line 3)" in errors[0]
