"""Scenario keys of large formations: lattice templates, graph builders, perturbed starts."""

from __future__ import annotations

import numpy as np
import pytest

from formationlab.errors import ScenarioError
from formationlab.formation.graphs import delaunay_edges, henneberg_edges, knn_edges, within_edges
from formationlab.formation.templates import lattice
from formationlab.scenario import parse_scenario

TAIL = """
[controller]
law = "distance"
[simulation]
dt = 1e-3
duration = 1.0
"""


def lattice_text(
    *,
    template: str = '{ lattice = "triangular", count = 61, spacing = 1.0 }',
    edges: str = '"delaunay"',
    positions: str = '{ around = "template", sigma = 0.05, seed = 1 }',
    orientation: str = '"free"',
    diameters: str = "0.2",
) -> str:
    return (
        f"[robots]\npositions = {positions}\ndiameters = {diameters}\n"
        f"[formation]\ntemplate = {template}\nedges = {edges}\norientation = {orientation}\n" + TAIL
    )


def test_lattice_template_delaunay_and_start_around_it() -> None:
    sc = parse_scenario(lattice_text())
    pts = lattice("triangular", 61, 1.0)
    np.testing.assert_array_equal(sc.formation.template, pts)
    np.testing.assert_array_equal(sc.formation.edges, delaunay_edges(pts))
    np.testing.assert_allclose(sc.formation.distances, 1.0, rtol=1e-12)  # all unit sides
    noise = np.random.default_rng(1).normal(scale=0.05, size=(61, 2))
    np.testing.assert_array_equal(sc.q0, pts + noise)
    assert sc.formation.is_rigid and sc.n == 61


@pytest.mark.parametrize(
    ("edges", "build"),
    [
        ('"henneberg"', henneberg_edges),
        ("{ knn = 4 }", lambda p: knn_edges(p, 4)),
        ("{ within = 1.8 }", lambda p: within_edges(p, 1.8)),
    ],
)
@pytest.mark.parametrize("kind", ["square", "hexagonal"])
def test_every_builder_and_kind(edges: str, build, kind: str) -> None:  # type: ignore[no-untyped-def]
    tpl = f'{{ lattice = "{kind}", count = 40, spacing = 0.8 }}'
    sc = parse_scenario(lattice_text(template=tpl, edges=edges))
    pts = lattice(kind, 40, 0.8)
    e = build(pts)
    np.testing.assert_array_equal(sc.formation.edges, e)
    np.testing.assert_allclose(
        sc.formation.distances, np.linalg.norm(pts[e[:, 1]] - pts[e[:, 0]], axis=1)
    )


def test_a_list_of_points_with_a_builder_and_a_list_of_positions() -> None:
    tpl = "[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]"
    pos = "[[0.0, 0.0], [3.0, 0.0], [0.0, 3.0], [3.0, 3.0]]"
    sc = parse_scenario(lattice_text(template=tpl, edges='"henneberg"', positions=pos))
    assert len(sc.formation.edges) == 5 and sc.formation.is_rigid
    np.testing.assert_array_equal(sc.q0, [[0, 0], [3, 0], [0, 3], [3, 3]])


def test_sigma_zero_starts_on_the_template() -> None:
    sc = parse_scenario(lattice_text(positions='{ around = "template", sigma = 0.0 }'))
    np.testing.assert_array_equal(sc.q0, lattice("triangular", 61, 1.0))


def test_orientation_from_a_lattice_without_collinear_neighbours() -> None:
    # a triangular patch of 3 robots has no collinear neighbour triple
    tpl = '{ lattice = "triangular", count = 3, spacing = 1.0 }'
    sc = parse_scenario(lattice_text(template=tpl, orientation='"template"'))
    assert sc.formation.alpha is not None and sc.formation.orientation == "template"


def test_perturbed_start_that_overlaps_names_robots_and_suggests_a_sigma() -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario(lattice_text(positions='{ around = "template", sigma = 0.5, seed = 3 }'))
    msg = str(info.value)
    assert info.value.key == "robots.positions" and "(line 2)" in msg
    assert "overlap in the start drawn around the template (sigma = 0.5, seed = 3)" in msg
    assert "use a smaller sigma (e.g. sigma = 0.07)" in msg
    # the suggested sigma indeed gives a start without contact
    parse_scenario(lattice_text(positions='{ around = "template", sigma = 0.07, seed = 3 }'))


def test_large_lists_of_positions_are_checked_without_all_pairs() -> None:
    pts = lattice("square", 2500, 1.0)  # above the dense check's limit
    pts[1700] = pts[1699] + [0.1, 0.0]
    text = lattice_text(
        template='{ lattice = "square", count = 2500 }',
        positions=str(pts.tolist()),
        edges="{ within = 1.5 }",
    )
    with pytest.raises(ScenarioError, match=r"robots 1700 and 1701 overlap in the initial") as e:
        parse_scenario(text)
    assert e.value.key == "robots.positions"


BAD = {
    "unknown lattice": (
        {"template": '{ lattice = "triangle", count = 10 }'},
        "formation.template",
        "unknown lattice 'triangle'; did you mean 'triangular'?",
    ),
    "count < 2": (
        {"template": '{ lattice = "square", count = 1 }'},
        "formation.template",
        "template.count must be a whole number >= 2, got 1",
    ),
    "spacing <= 0": (
        {"template": '{ lattice = "square", count = 9, spacing = -1.0 }'},
        "formation.template",
        "template.spacing must be > 0",
    ),
    "misspelt lattice key": (
        {"template": '{ lattice = "square", cont = 9 }'},
        "formation.template",
        "template has no key 'cont'; did you mean 'count'?",
    ),
    "knn >= count": (
        {"edges": "{ knn = 61 }"},
        "formation.edges",
        "knn needs a whole k with 1 <= k < 61",
    ),
    "unknown graph": (
        {"edges": '"delauney"'},
        "formation.edges",
        "did you mean 'delaunay'?",
    ),
    "bad graph table": ({"edges": "{ nearest = 3 }"}, "formation.edges", "{ knn = k }"),
    "within <= 0": ({"edges": "{ within = 0 }"}, "formation.edges", "edges.within must be > 0"),
    "around without template": (
        {"template": "none"},
        "robots.positions",
        'positions = { around = "template", ... } needs formation.template',
    ),
    "sigma < 0": (
        {"positions": '{ around = "template", sigma = -0.1 }'},
        "robots.positions",
        "positions.sigma must be >= 0",
    ),
    "around what": (
        {"positions": '{ around = "centre", sigma = 0.1 }'},
        "robots.positions",
        'takes "template"',
    ),
    "misspelt sigma": (
        {"positions": '{ around = "template", sigm = 0.1 }'},
        "robots.positions",
        "did you mean 'sigma'?",
    ),
    "wrong count of positions": (
        {"positions": "[[0.0, 0.0], [2.0, 0.0]]"},
        "formation.template",
        "the template has 61 points but there are 2 robots",
    ),
    "diameters per robot": (
        {"diameters": "[0.2, 0.2]"},
        "robots.diameters",
        "there are 61 positions but 2 diameters",
    ),
    "builder without template": (
        {"template": "none", "positions": "[[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]]"},
        "formation.edges",
        'edges = "delaunay" builds the graph from the template',
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input(case: str) -> None:
    changes, key, message = BAD[case]
    kwargs = dict(changes)
    if kwargs.get("template") == "none":
        del kwargs["template"]
        text = lattice_text(**kwargs).replace("template = none\n", "")
        text = "\n".join(x for x in text.splitlines() if not x.startswith("template ="))
    else:
        text = lattice_text(**kwargs)
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text)
    assert info.value.key == key, str(info.value)
    assert message in str(info.value)


THIN = """
[robots]
positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]
[formation]
template = [[0.0, 0.0], [1.0, 0.0], [0.5, {h}]]
orientation = "{orientation}"
[controller]
law = "angle-restricted"
theta = {theta}
[simulation]
duration = 1.0
"""


@pytest.mark.parametrize("orientation", ["template", "mirror"])
def test_a_template_triangle_thinner_than_theta_is_a_warning(orientation: str) -> None:
    # c_123 = 1 * 0.2 = 0.2 (twice the area) <= theta = 0.5: the restriction stays on at the
    # desired shape, so the angular term pushes there and it is not an equilibrium
    sc = parse_scenario(THIN.format(h=0.2, theta=0.5, orientation=orientation))
    (msg,) = [w for w in sc.warnings if "restrictions" in w]
    assert "1 of the 1 restrictions of law 'angle-restricted' are on at the desired shape" in msg
    assert "|c_123| = 0.2 <= theta = 0.5" in msg and "use theta below 0.2" in msg
    target = sc.formation.template * ([-1.0, 1.0] if orientation == "mirror" else [1.0, 1.0])
    u = sc.law.control(sc.formation, target)
    assert np.max(np.abs(u)) > 0.1  # the desired shape is not an equilibrium
    # below the bound the warning goes and the desired shape is an equilibrium
    ok = parse_scenario(THIN.format(h=0.2, theta=0.19, orientation=orientation))
    assert not [w for w in ok.warnings if "restrictions" in w]
    np.testing.assert_allclose(ok.law.control(ok.formation, target), 0.0, atol=1e-12)
