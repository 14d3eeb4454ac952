"""Scenario files: parsing, the formation/law/integrator they build, and every bad input.

The reference values are the paper's section 4 (q0, d_ij = 1, k_c = 2, k_a = 3,
theta = 0.5, the alpha tables of simulations 1 and 2) and hand-made formations.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import formationlab as fl
from formationlab.controllers import LAWS, Law, register
from formationlab.errors import ScenarioError
from formationlab.formation.graph import edges_connected
from formationlab.io.scenario import load_scenario
from formationlab.scenario import Scenario, parse_scenario

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

PAPER_Q0 = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]  # section 4
SIM1 = {(1, 2, 3): -1, (3, 1, 2): -1, (2, 1, 3): 1}  # alpha_123 = alpha_312 = -alpha_213 = -1
SIM2 = {key: -value for key, value in SIM1.items()}

BASE = """\
name = "triangle"
[robots]
positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]
diameters = 0.2
[formation]
edges = "complete"
distances = 1.0
[controller]
law = "distance"
k_c = 2.0
[simulation]
integrator = "euler"
dt = 1e-3
duration = 1.0
"""


def parse(text: str) -> Scenario:
    return parse_scenario(text, source="test.toml")


# ---------------------------------------------------------------- what a file builds


def test_paper_simulation_files_build_the_papers_formation_and_law() -> None:
    for name, table in (("paper-simulation-1", SIM1), ("paper-simulation-2", SIM2)):
        sc = load_scenario(EXAMPLES / f"{name}.toml")
        ref = fl.Formation.from_alpha_table(table, n=3, distances=1.0, diameters=0.2)
        assert sc.name == name
        np.testing.assert_array_equal(sc.formation.alpha, ref.alpha)
        np.testing.assert_array_equal(sc.formation.edges, ref.edges)
        np.testing.assert_array_equal(sc.formation.distances, [1.0, 1.0, 1.0])
        np.testing.assert_array_equal(sc.q0, PAPER_Q0)
        assert sc.law == fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
        assert sc.integrator == fl.Euler(dt=1e-3)
        assert sc.duration == 15.0
        assert sc.formation.orientation == "table"
        # alpha_ikj = -alpha_ijk completes the printed table (eq. 3)
        assert sc.formation.alpha is not None
        assert sc.formation.alpha[0, 2, 1] == -table[(1, 2, 3)]


def test_euler_trajectory_of_paper_simulation_1_equals_simulate_with_papers_parameters() -> None:
    sc = load_scenario(EXAMPLES / "paper-simulation-1.toml")
    duration = 4.0  # long enough to converge (the distance law, restrictions inactive)
    got = fl.simulate(sc.formation, sc.law, sc.q0, duration=duration, integrator=sc.integrator)
    f = fl.Formation.from_alpha_table(SIM1, n=3, distances=1.0, diameters=0.2)
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    ref = fl.simulate(f, law, PAPER_Q0, duration=duration, integrator=fl.Euler(dt=1e-3))
    np.testing.assert_array_equal(got.t, ref.t)
    np.testing.assert_array_equal(got.q, ref.q)
    # simulation 1 ends at the equilateral triangle of side 1 (section 4)
    assert got.outcome() == "desired"


@pytest.mark.parametrize("simulation", [1, 2])
def test_example_trajectories_agree_with_the_paper_command(simulation: int) -> None:
    from formationlab.studies.paper import PaperSetup

    sc = load_scenario(EXAMPLES / f"paper-simulation-{simulation}.toml")
    setup = PaperSetup(duration=2.0, dt=1e-3, integrator="euler", diameter=0.2)
    ref = setup.run(simulation, perturbation=0.0)  # type: ignore[arg-type]
    got = fl.simulate(sc.formation, sc.law, sc.q0, duration=2.0, integrator=sc.integrator)
    np.testing.assert_array_equal(got.q, ref.q)


def test_every_example_validates() -> None:
    files = sorted(EXAMPLES.glob("*.toml"))
    names = {p.stem for p in files}
    assert {
        "paper-simulation-1",
        "paper-simulation-2",
        "square-with-diagonals",
        "hexagon",
        "ten-robots",
    } <= names
    for p in files:
        sc = load_scenario(p)
        assert edges_connected(sc.formation.edges, sc.n)
        assert sc.q0.shape == (sc.n, 2)
        assert not sc.q0.flags.writeable


def test_examples_have_the_graphs_the_readme_promises() -> None:
    square = load_scenario(EXAMPLES / "square-with-diagonals.toml").formation
    assert square.n == 4 and len(square.edges) == 6  # sides and both diagonals
    hexagon = load_scenario(EXAMPLES / "hexagon.toml").formation
    assert hexagon.n == 6 and len(hexagon.edges) == 2 * 6 - 3 and hexagon.is_rigid  # minimal
    ten = load_scenario(EXAMPLES / "ten-robots.toml").formation
    assert ten.n == 10 and len(ten.edges) < 10 * 9 // 2 and ten.is_rigid  # incomplete


def test_template_gives_distances_and_mirror_flips_every_sign() -> None:
    tpl = [[0.0, 0.0], [3.0, 0.0], [0.0, 4.0]]  # a 3-4-5 right triangle
    text = BASE.replace("distances = 1.0", f"template = {tpl}\norientation = 'template'")
    text = text.replace('law = "distance"', 'law = "angle-restricted"')
    f = parse(text).formation
    assert f.alpha is not None
    # edges (1,2), (1,3), (2,3) have lengths 3, 4, 5
    np.testing.assert_allclose(f.distances, [3.0, 4.0, 5.0])
    # template turns counter-clockwise (c_123 = 12 > 0): the paper's alpha_123 is negative
    assert f.alpha[0, 1, 2] == -1.0
    g = parse(text.replace("'template'", "'mirror'")).formation
    assert g.alpha is not None
    np.testing.assert_array_equal(g.alpha, -f.alpha)
    free = parse(text.replace("'template'", "'free'")).formation
    assert free.alpha is None


def test_alpha_values_angle_gives_the_templates_angles() -> None:
    tpl = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
    text = BASE.replace("distances = 1.0", f"template = {tpl}")
    text = text.replace('law = "distance"', 'law = "angle-restricted"\nalpha_values = "angle"')
    f = parse(text).formation
    assert f.alpha is not None
    # angle at robot 1 from r_12 to r_13 is +pi/2 (ccw); the paper's sign is opposite
    assert f.alpha[0, 1, 2] == pytest.approx(-np.pi / 2)
    assert f.kappa == pytest.approx(np.pi)


def test_orientation_defaults_to_template_when_a_template_is_given() -> None:
    text = BASE.replace("distances = 1.0", "template = [[0, 0], [1, 0], [0.5, 0.9]]")
    assert parse(text).formation.orientation == "template"


def test_distances_per_edge_follow_the_users_edge_order() -> None:
    text = BASE.replace('edges = "complete"', "edges = [[2, 3], [1, 2], [1, 3]]")
    text = text.replace("distances = 1.0", "distances = [1.0, 1.5, 2.0]")
    d = parse(text).formation.distance_matrix
    assert (d[1, 2], d[0, 1], d[0, 2]) == (1.0, 1.5, 2.0)


def test_diameters_one_per_robot() -> None:
    text = BASE.replace("diameters = 0.2", "diameters = [0.1, 0.2, 0.4]")
    f = parse(text).formation
    np.testing.assert_array_equal(f.diameters, [0.1, 0.2, 0.4])
    assert f.contact_matrix[0, 2] == pytest.approx(0.25)  # a_13 = (0.1 + 0.4) / 2 (eq. 5)


def test_controller_parameters_and_repulsion_reach_the_law() -> None:
    text = BASE.replace("k_c = 2.0", "k_c = 4\nrepulsion = { eta = 2.5, influence = 0.3 }")
    law = parse(text).law
    assert law == fl.DistanceLaw(k_c=4.0, repulsion=fl.Repulsion(eta=2.5, influence=0.3))
    assert isinstance(law.k_c, float)


def test_dict_input_equals_text_input_and_study_tables_pass_through() -> None:
    import tomllib

    text = BASE + "[study]\ntrials = 10\n[equilibria]\nseeds = [1, 2]\n"
    a = parse(text)
    b = parse_scenario(tomllib.loads(text))
    assert a.study == b.study == {"trials": 10}
    assert a.equilibria == {"seeds": [1, 2]}
    assert a.law == b.law and a.integrator == b.integrator
    np.testing.assert_array_equal(a.formation.distances, b.formation.distances)
    assert tomllib.loads(b.text) == tomllib.loads(text)  # dict input gets TOML text too


def test_name_defaults_to_the_file_stem(tmp_path: Path) -> None:
    p = tmp_path / "my-formation.toml"
    p.write_text(BASE.replace('name = "triangle"\n', ""))
    assert load_scenario(p).name == "my-formation"


def test_laws_registered_later_are_accepted_with_their_own_parameters() -> None:
    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Damped(Law):
        name = "test-damped"
        k_c: float = 1.0
        damping: float = 0.5

    register(Damped)
    try:
        text = BASE.replace('law = "distance"', 'law = "test-damped"\ndamping = 0.25')
        assert parse(text).law == Damped(k_c=2.0, damping=0.25)
        with pytest.raises(ScenarioError, match=r"takes no key 'dampnig'.*'damping'"):
            parse(text.replace("damping = 0.25", "dampnig = 0.25"))
    finally:
        del LAWS["test-damped"]


def test_non_rigid_graph_is_a_warning_not_an_error() -> None:
    text = BASE.replace(
        "positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]",
        "positions = [[0, 0], [2, 0], [2, 2], [0, 2]]",
    ).replace('edges = "complete"', "edges = [[1, 2], [2, 3], [3, 4], [4, 1]]")
    sc = parse(text)  # a 4-cycle: connected, flexible
    assert any("not rigid" in w for w in sc.warnings)


# ---------------------------------------------------------------- bad input

BAD = {
    # case: (edit of BASE, fragments the message must contain)
    "toml syntax": (("k_c = 2.0", "k_c = = 2.0"), ["TOML syntax error", "line 10"]),
    "unknown top key": (
        ('name = "triangle"', 'nmae = "triangle"'),
        ["'nmae'", "did you mean 'name'"],
    ),
    "unknown table key": (
        ("distances = 1.0", "distnces = 1.0"),
        ["line 7", "did you mean 'distances'"],
    ),
    "unknown law key": (("k_c = 2.0", "kc = 2.0"), ["controller.kc", "Did you mean 'k_c'"]),
    "key of another table": (("k_c = 2.0", "dt = 3.0"), ["'dt' belongs to the integrator"]),
    "unknown law": (('law = "distance"', 'law = "distanse"'), ["did you mean 'distance'"]),
    "unknown integrator": (('"euler"', '"eulr"'), ["unknown integrator", "did you mean 'euler'"]),
    "wrong type": (("k_c = 2.0", 'k_c = "two"'), ["controller.k_c", "expected a number", "'two'"]),
    "wrong type in schema": (("duration = 1.0", 'duration = "1"'), ["duration", "'1'"]),
    "position shape": (("[0.0, 3.0]]", "[0.0, 3.0, 1.0]]"), ["row 3", "pair [x, y]"]),
    "diameters length": (("diameters = 0.2", "diameters = [0.2, 0.2]"), ["3 positions but 2"]),
    "nan": (("[0.0, 3.0]]", "[nan, 3.0]]"), ["robots.positions", "finite", "nan"]),
    "inf": (("distances = 1.0", "distances = inf"), ["formation.distances", "finite", "inf"]),
    "d <= a": (("diameters = 0.2", "diameters = 1.0"), ["d_12 = 1", "a_12", "exceed"]),
    "overlap": (("[0.0, 3.0]]", "[-3.0, -2.85]]"), ["robots 1 and 3 overlap"]),
    "edge to missing robot": (('"complete"', "[[1, 2], [2, 4]]"), ["robot 4", "1..3"]),
    "edge to itself": (('"complete"', "[[1, 2], [2, 2]]"), ["joins robot 2 to itself"]),
    "duplicate edge": (('"complete"', "[[1, 2], [2, 3], [2, 1]]"), ["(2, 1) is given twice"]),
    "orientation without template": (
        ("distances = 1.0", "distances = 1.0\norientation = 'template'"),
        ["needs a template"],
    ),
    "table without alpha": (
        ("distances = 1.0", "distances = 1.0\norientation = 'table'"),
        ["needs formation.alpha"],
    ),
    "collinear template": (
        ("distances = 1.0", "template = [[0, 0], [1, 0], [2, 0]]"),
        ["collinear", "formation.template"],
    ),
    "disconnected": (
        ('"complete"', "[[1, 2]]"),
        ["not connected"],
    ),
    "dt zero": (("dt = 1e-3", "dt = 0.0"), ["simulation.dt", "> 0"]),
    "dt negative": (("dt = 1e-3", "dt = -1e-3"), ["simulation.dt", "> 0"]),
    "duration zero": (("duration = 1.0", "duration = 0.0"), ["duration", "must be > 0, got 0.0"]),
    "duration missing": (("duration = 1.0", ""), ["simulation.duration", "required"]),
    "gain not positive": (("k_c = 2.0", "k_c = -1.0"), ["controller.k_c", "> 0"]),
    "repulsion bad key": (
        ("k_c = 2.0", "repulsion = { eta = 1.0, s0 = 0.5 }"),
        ["controller.repulsion.s0", "eta, influence"],
    ),
    "alpha with a template": (
        ("distances = 1.0", "template = [[0, 0], [1, 0], [0, 1]]\nalpha = [[1, 2, 3, 1.0]]"),
        ["not both"],
    ),
    "distances and template": (
        ("distances = 1.0", "distances = 1.0\ntemplate = [[0, 0], [1, 0], [0, 1]]"),
        ["distances or a template, not both"],
    ),
    "bad alpha row": (
        ("distances = 1.0", "distances = 1.0\nalpha = [[1, 2, 1.0]]"),
        ["[i, j, k, value]"],
    ),
    "bool as number": (("k_c = 2.0", "k_c = true"), ["expected a number"]),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_gives_a_scenario_error_naming_the_problem(case: str) -> None:
    (old, new), fragments = BAD[case]
    assert old in BASE, "the test's edit must apply"
    text = BASE.replace(old, new, 1)
    with pytest.raises(ScenarioError) as info:
        parse(text)
    msg = str(info.value)
    assert msg.startswith("test.toml")
    assert "\n" not in msg
    for frag in fragments:
        assert frag in msg, f"{frag!r} not in {msg!r}"


def test_line_numbers_point_at_the_offending_key() -> None:
    text = BASE.replace("dt = 1e-3", "dt = -1.0")
    line = 1 + text.splitlines().index("dt = -1.0")
    with pytest.raises(ScenarioError, match=rf"simulation\.dt \(line {line}\)"):
        parse(text)


def test_misspelt_table_is_named_with_its_line_and_the_missing_one() -> None:
    text = BASE.replace("[robots]", "[robot]")
    with pytest.raises(ScenarioError) as info:
        parse(text)
    msg = str(info.value)
    assert "robot (line 2): unknown key 'robot'" in msg and "did you mean 'robots'" in msg
    assert "the table [robots] is required" in msg
    assert msg.index("unknown key") < msg.index("is required")  # the cause first


def test_missing_file_and_folder(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="does not exist"):
        load_scenario(tmp_path / "nope.toml")
    with pytest.raises(ScenarioError, match="is a folder"):
        load_scenario(tmp_path)


def test_not_utf8(tmp_path: Path) -> None:
    p = tmp_path / "bin.toml"
    p.write_bytes(b"\xff\xfe\x00name")
    with pytest.raises(ScenarioError, match="UTF-8"):
        load_scenario(p)
