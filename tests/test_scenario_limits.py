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

import formationlab as fl
from formationlab import resources
from formationlab.cli import _load_commands, app
from formationlab.errors import ScenarioError
from formationlab.formation.spec import check_alpha_signs
from formationlab.integrators.base import steps_for
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


# ------------------------------------------------------------ accepted nonsense


def test_a_step_longer_than_the_duration_is_refused() -> None:
    text = triangle("long-step", "10.0").replace("dt = 1e-3", "dt = 20.0")
    assert refusal(text) == (
        "s.toml: simulation.dt (line 17): dt = 20 s is longer than the duration, 10 s: its one "
        "step would end past the duration; use dt <= duration (e.g. dt = 0.01)"
    )


def test_a_duration_that_is_not_whole_steps_is_rounded_with_a_warning() -> None:
    text = triangle("odd", "10.0").replace("dt = 1e-3", "dt = 0.3")
    sc = parse_scenario(text, source="s.toml")
    assert sc.duration == pytest.approx(9.9, rel=1e-12)  # 33 steps (it ran 34, to 10.2 s)
    assert (
        "s.toml: simulation.duration (line 18): 10 s is not a whole number of steps of "
        "dt = 0.3 s; running 33 steps, to t = 9.9 s (set the duration to a multiple of dt to "
        "choose)"
    ) in sc.warnings
    assert steps_for(sc.duration, 0.3) == 33  # what the run takes
    exact = parse_scenario(triangle("whole", "1.5"))  # 1500 steps of 1e-3: no warning
    assert exact.duration == 1.5 and not [w for w in exact.warnings if "whole number" in w]


def test_an_alpha_table_no_triangle_realises_is_refused() -> None:
    # alpha_123 = alpha_312 = alpha_213 = +1: (2, 1, 3) is a swap of (1, 2, 3), so its alpha
    # must have the opposite sign (eq. (3)); the paper's tables (+, +, -) pass
    text = triangle("bad-alpha", "1.0").replace("[2, 1, 3, -1.0]]", "[2, 1, 3, 1.0]]")
    assert refusal(text) == (
        "s.toml: formation.alpha (line 9): alpha_123 = +1 and alpha_213 = +1 contradict: "
        "(2, 1, 3) is a swap of (1, 2, 3), so no triangle realises both signs (eq. (3) of the "
        "paper); give alpha_213 the sign -1"
    )
    parse_scenario(triangle("paper", "1.0"))  # simulation 2's table
    with pytest.raises(fl.FormationError, match="alpha_123 = -1 and alpha_231 = \\+1"):
        check_alpha_signs([[1, 2, 3, -1.0], [2, 3, 1, 1.0]])  # a cyclic permutation keeps it
