"""Formations in space: signed volumes, the chirality restriction and its Lyapunov function.

docs/three-d.md derives what these tests check: the gradient of the signed volume (the 3-D
eq. 23), the law's field as the gradient of each robot's own potential, and eq. (25)'s
condition with kappa = 4, the robots of a tetrahedron.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import formationlab as fl
from formationlab.controllers.chirality_restricted import chi_sum
from formationlab.controllers.distance import grad_phi, phi_sum
from formationlab.errors import FormationError, ParameterError
from formationlab.formation.chirality import (
    chirality_surfaces,
    neighbour_quadruples,
    signed_volumes,
    volume_gradients,
)
from formationlab.io.scenario import load_scenario
from formationlab.models import Unicycle
from formationlab.outcomes.analysis import chirality_agreement
from formationlab.safety.obstacles import Circle
from formationlab.scenario.build import restrictions_on_at_target

#: a regular tetrahedron of edge 1
TETRA = np.array(
    [[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0], [0.5, np.sqrt(3) / 6, np.sqrt(2 / 3)]]
)
#: a triangular bipyramid: the equator 1-2-3 and the apexes 4 (above) and 5 (below)
BIPYRAMID = np.vstack([TETRA, TETRA[3] * np.array([1, 1, -1])])
BIPYRAMID_EDGES = [(1, 2), (1, 3), (2, 3), (1, 4), (2, 4), (3, 4), (1, 5), (2, 5), (3, 5)]


def test_the_signed_volume_is_six_times_the_volume_and_alternates(rng) -> None:
    v = signed_volumes(TETRA, [[0, 1, 2, 3]])
    assert v[0] == pytest.approx(np.sqrt(2) / 2, rel=1e-14)  # 6 x (edge^3 / (6 sqrt 2))
    q = rng.normal(size=(5, 4, 3))
    base = signed_volumes(q, [[0, 1, 2, 3]])
    for odd in ([1, 0, 2, 3], [0, 2, 1, 3], [0, 1, 3, 2], [3, 1, 2, 0]):
        np.testing.assert_allclose(signed_volumes(q, [odd]), -base, rtol=1e-12)
    for even in ([1, 2, 0, 3], [2, 3, 0, 1]):
        np.testing.assert_allclose(signed_volumes(q, [even]), base, rtol=1e-12)
    mirror = q * np.array([-1.0, 1.0, 1.0])
    np.testing.assert_allclose(signed_volumes(mirror, [[0, 1, 2, 3]]), -base, rtol=1e-12)


def test_the_volume_gradients_match_finite_differences(rng) -> None:
    q = rng.normal(size=(6, 3))
    quads = np.array([[0, 1, 2, 3], [4, 0, 2, 5], [3, 1, 4, 5]])
    grads = volume_gradients(q, quads)  # (Q, 4, 3)
    h = 1e-6
    for m, quad in enumerate(quads):
        for slot, robot in enumerate(quad):
            for d in range(3):
                up, down = q.copy(), q.copy()
                up[robot, d] += h
                down[robot, d] -= h
                fd = (signed_volumes(up, [quad]) - signed_volumes(down, [quad]))[0] / (2 * h)
                assert grads[m, slot, d] == pytest.approx(fd, abs=1e-8)
    np.testing.assert_allclose(grads.sum(axis=1), 0.0, atol=1e-12)  # translation invariance


def test_the_template_fixes_each_robots_quadruples_and_one_surface_per_tetrahedron() -> None:
    f = fl.Formation.from_template(TETRA)
    assert f.dim == 3 and f.kappa == 4.0
    np.testing.assert_array_equal(f.chiral_quads, [[0, 1, 2, 3], [1, 0, 2, 3], [2, 0, 1, 3],
                                                   [3, 0, 1, 2]])  # fmt: skip
    # the template has the chirality the restriction drives towards: sign(v) = -beta
    np.testing.assert_array_equal(np.sign(signed_volumes(TETRA, f.chiral_quads)), f.chiral_sign)
    tets, _, surface = chirality_surfaces(f.chiral_quads, f.chiral_signs)
    np.testing.assert_array_equal(tets, [[0, 1, 2, 3]])  # the four holders switch together
    np.testing.assert_array_equal(surface, [0, 0, 0, 0])
    assert f.surface_labels == ["v_1234"]
    mirror = f.with_orientation("mirror")
    np.testing.assert_array_equal(mirror.chiral_signs, -f.chiral_signs)
    assert chirality_agreement(f, TETRA) == (4, 0)
    assert chirality_agreement(f, TETRA * np.array([1, -1, 1])) == (0, 4)


def test_neighbour_quadruples_are_every_three_neighbours_of_a_robot() -> None:
    edges = np.array(BIPYRAMID_EDGES) - 1
    quads = neighbour_quadruples(edges, 5)
    degree = np.bincount(edges.ravel(), minlength=5)
    from math import comb

    assert len(quads) == sum(comb(int(d), 3) for d in degree)  # 4 + 4 + 4 + 1 + 1
    adj = {(i, j) for i, j in edges} | {(j, i) for i, j in edges}
    assert all((q[0], o) in adj for q in quads for o in q[1:])
    assert np.all((quads[:, 1] < quads[:, 2]) & (quads[:, 2] < quads[:, 3]))


def _k4(rng, scale: float = 1.5) -> tuple[fl.Formation, np.ndarray]:
    f = fl.Formation.from_template(TETRA, diameters=0.2)
    q = TETRA * scale + rng.normal(scale=0.15, size=(4, 3))
    return f, q


def test_the_field_is_each_robots_own_gradient(rng) -> None:
    law = fl.ChiralityRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    f, q = _k4(rng)
    q = q * np.array([1, 1, -1])  # the mirror: every restriction on
    assert np.all(law.switching(f, q) > 0)
    u = law.control(f, q)

    def own(i: int, x: np.ndarray) -> float:  # phi_i + k_a / k_c psi_i, robot i's own terms
        mine = f.chiral_quads[:, 0] == i
        bv = f.chiral_signs[mine] * signed_volumes(x, f.chiral_quads[mine])
        return float(np.sum(bv * (bv + law.theta >= 0)))

    h = 1e-6
    for i in range(4):
        for d in range(3):
            up, down = q.copy(), q.copy()
            up[i, d] += h
            down[i, d] -= h
            fd_psi = (own(i, up) - own(i, down)) / (2 * h)
            want = -law.k_c * grad_phi(f, q, law.repulsion)[i, d] - law.k_a * fd_psi
            assert u[i, d] == pytest.approx(want, rel=1e-6, abs=1e-8)


@pytest.mark.parametrize("kappa, holds", [(4.0, True), (3.0, False)])
def test_eq25_with_kappa_4_makes_V_a_lyapunov_function(rng, kappa, holds) -> None:
    """Between switches ``dV/dt = grad V . u = -(2/k_c) sum |u_i|^2`` when ``lambda kappa k_c
    = 2 k_a`` with kappa = 4 (each of the tetrahedron's four robots holds its restriction);
    the plane's kappa = 3 leaves a remainder."""
    law = fl.ChiralityRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    lam = 2 * law.k_a / (kappa * law.k_c)
    for _ in range(5):
        f, q = _k4(rng)
        q = q * np.array([1, 1, -1])  # restrictions on, away from their surface
        assert np.all(np.abs(law.switching(f, q)) > 1e-3)
        u = law.control(f, q)
        h = 1e-7

        def V(x: np.ndarray, f: fl.Formation = f) -> float:
            return float(phi_sum(f, x, law.repulsion) + lam * chi_sum(f, x, law.theta))

        rate = (V(q + h * u) - V(q - h * u)) / (2 * h)
        want = -(2.0 / law.k_c) * np.sum(u * u)
        if holds:
            assert rate == pytest.approx(want, rel=1e-5)
            assert law.potential(f, q) == pytest.approx(V(q), rel=1e-12)  # the law's own V
        else:
            assert abs(rate - want) > 1e-3 * abs(want)


def test_from_the_mirror_the_distance_law_keeps_it_and_the_chirality_law_turns_it() -> None:
    """The paper's question in space: from a start near the template's mirror image the
    distance law ends at the mirror, the chirality-restricted law at the template."""
    f = fl.Formation.from_template(TETRA, diameters=0.2)
    rng = np.random.default_rng(3)
    q0 = TETRA * 3 * np.array([-1, 1, 1]) + rng.normal(scale=0.3, size=(4, 3))
    assert chirality_agreement(f, q0) == (0, 4)
    euler = fl.get_integrator("euler", dt=5e-3)
    plain = fl.simulate(f, fl.DistanceLaw(), q0, duration=10.0, integrator=euler)
    assert plain.summary()["outcome"] == "mirror"
    turned = fl.simulate(f, fl.ChiralityRestrictedLaw(), q0, duration=10.0, integrator=euler)
    s = turned.summary()
    assert s["outcome"] == "desired", s
    assert chirality_agreement(f, turned.q[-1]) == (4, 0)
    assert turned.q.shape[-1] == 3
    assert np.all(np.diff(turned.V) <= 1e-9 + 3.0 * 0.5)  # falls, but for the switches' jumps


def test_a_formation_in_space_from_distances_and_its_positions() -> None:
    f = fl.Formation.from_distances(4, dim=3)
    assert f.dim == 3 and not f.has_orientation
    f.check_positions(TETRA * 2)
    with pytest.raises(FormationError, match=r"shape \(\.\.\., 4, 3\)"):
        f.check_positions(TETRA[:, :2])
    with pytest.raises(FormationError, match="dim must be 2 or 3"):
        fl.Formation.from_distances(4, dim=4)
    with pytest.raises(FormationError, match="chirality, which has signs only"):
        fl.Formation.from_template(TETRA, alpha_values="angle")


def test_what_cannot_work_in_space_is_refused_by_name() -> None:
    f = fl.Formation.from_template(TETRA)
    q0 = TETRA * 2
    with pytest.raises(ParameterError, match="chirality-restricted"):
        fl.simulate(f, fl.AngleRestrictedLaw(), q0, duration=0.1)
    with pytest.raises(ParameterError, match="angle-restricted"):
        fl.simulate(fl.Formation.from_template(TETRA[:3, :2]), fl.ChiralityRestrictedLaw(),
                    TETRA[:3, :2] * 2, duration=0.1)  # fmt: skip
    with pytest.raises(ParameterError, match="unicycle"):
        fl.simulate(f, fl.DistanceLaw(), q0, duration=0.1, model=Unicycle())
    with pytest.raises(ParameterError, match=r"circle at .* is an obstacle in the plane") as err:
        fl.simulate(f, fl.DistanceLaw(), q0, duration=0.1,
                    obstacles=[Circle(center=(9.0, 9.0), radius=0.5)])  # fmt: skip
    assert err.value.key == "obstacles"
    for law in (fl.ChiralityRestrictedLaw(), fl.BearingLaw()):  # (the compiled loop in space
        with pytest.raises(ParameterError, match="numpy path"):  # steps the laws of distances)
            law.compiled_terms(f)
    assert fl.DistanceLaw().compiled_terms(f).pair_i.size == 6


def test_the_switching_plane_is_parallel_to_the_face() -> None:
    """Eq. (26) in space: with j, k, l held, sigma = 0 is the plane parallel to the face jkl
    at distance theta / |r_jk x r_jl| from it, on the side of the desired chirality."""
    f = fl.Formation.from_template(TETRA)
    law = fl.ChiralityRestrictedLaw(theta=0.5)
    q = TETRA.copy()
    normal = np.cross(q[2] - q[1], q[3] - q[1])  # of the face 2-3-4 (robot 1 opposite)
    unit = normal / np.linalg.norm(normal)
    side = np.sign(np.dot(q[0] - q[1], unit))  # the template's side: the desired chirality
    for offset in (0.0, 0.3):  # anywhere in the plane
        along = np.cross(unit, [1.0, 0.0, 0.0]) * offset
        q[0] = q[1] + side * unit * law.theta / np.linalg.norm(normal) + along
        assert law.switching(f, q)[0] == pytest.approx(0.0, abs=1e-12)
    q[0] = q[1] + side * unit * 2 * law.theta / np.linalg.norm(normal)  # farther: off
    assert law.switching(f, q)[0] == pytest.approx(-law.theta, rel=1e-12)
    q[0] = q[1]  # in the face: on, by theta
    assert law.switching(f, q)[0] == pytest.approx(law.theta, rel=1e-12)


def test_a_tetrahedron_flatter_than_theta_is_named() -> None:
    f = fl.Formation.from_template(BIPYRAMID, edges=BIPYRAMID_EDGES)
    say = restrictions_on_at_target(f, fl.ChiralityRestrictedLaw(theta=0.5))
    assert say is not None and say.startswith("3 of the 5 restrictions"), say
    assert re.search(r"\|v_[12]345\| = 0.471 <= theta = 0.5", say), say  # (a tie of three)
    assert "use theta below 0.471" in say
    assert restrictions_on_at_target(f, fl.ChiralityRestrictedLaw(theta=0.3)) is None


@pytest.mark.parametrize("integrator", ["euler", "rk4", "implicit-euler", "filippov"])
@pytest.mark.parametrize("law", ["distance", "squared-distance", "chirality-restricted"])
def test_every_law_and_integrator_of_space_reaches_the_distances(law, integrator) -> None:
    f = fl.Formation.from_template(BIPYRAMID, edges=BIPYRAMID_EDGES, diameters=0.2)
    rng = np.random.default_rng(11)
    q0 = BIPYRAMID * 2.0 + rng.normal(scale=0.2, size=(5, 3))
    step = {} if integrator == "filippov" else {"dt": 0.01}
    gains = {"theta": 0.3} if law == "chirality-restricted" else {}  # below |v| = 0.47
    r = fl.simulate(f, fl.get_law(law, **gains), q0, duration=6.0,
                    integrator=fl.get_integrator(integrator, **step))  # fmt: skip
    s = r.summary()
    assert s["outcome"] in ("desired", "mirror"), s
    assert r.q.shape == (len(r.t), 5, 3)
    assert s["state_names"] == ["x", "y", "z"]
    assert np.max(np.abs(fl.distance_errors(f, r.q[-1]))) < 1e-2
    if law == "chirality-restricted":
        assert s["outcome"] == "desired"


# ------------------------------------------------------------------ scenario files and commands

EXAMPLES = Path(__file__).parents[1] / "examples" / "space"


def invoke(*args: object):
    from typer.testing import CliRunner

    from formationlab.cli import _load_commands, app

    _load_commands()
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def tetra_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("space") / "out"
    res = invoke("run", EXAMPLES / "tetrahedron-mirror.toml", "--out", out, "--quiet")
    assert res.exit_code == 0, res.output
    return out


def test_run_writes_a_run_in_space(tetra_run: Path) -> None:
    import xarray as xr

    s = json.loads((tetra_run / "summary.json").read_text())
    assert s["outcome"] == "desired" and s["state_names"] == ["x", "y", "z"]
    assert s["max_distance_error"] < 1e-3
    with xr.open_dataset(tetra_run / "trajectory.nc") as ds:
        assert list(ds["axis"].values) == ["x", "y", "z"]
        assert ds["q"].shape[1:] == (4, 3)
        q_end = ds["q"].values[-1]
        assert list(ds["surface"].values) == ["v_1234"]
    f = fl.Formation.from_template(TETRA)
    assert chirality_agreement(f, q_end) == (4, 0)
    for name in ("trajectories", "controls_x", "controls_y", "controls_z", "lyapunov"):
        assert (tetra_run / f"{name}.png").stat().st_size > 10_000


def test_the_distance_law_from_the_same_file_ends_at_the_mirror(tmp_path: Path) -> None:
    text = (EXAMPLES / "tetrahedron-mirror.toml").read_text()
    path = tmp_path / "plain.toml"
    path.write_text(text.replace('law = "chirality-restricted"', 'law = "distance"'))
    res = invoke("run", path, "--out", tmp_path / "out", "--quiet")
    assert res.exit_code == 1 or res.exit_code == 0, res.output
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["outcome"] == "mirror"


@pytest.mark.parametrize(
    "change, key, words",
    [
        (("[0.2, 0.1, 0.3], [-3.1", "[0.2, 0.1], [-3.1"), "robots.positions",
         "positions, row 2, must be a pair [x, y], as row 1, got [-3.1, -0.2, 0.1]"),
        (("[[0.2, 0.1, 0.3], [-3.1, -0.2, 0.1], [-1.4, 2.7, -0.2], [-1.6, 0.8, 2.6]]",
          "[[0.2, 0.1], [-3.1, -0.2], [-1.4, 2.7], [-1.6, 0.8]]"), "robots.positions",
         "the positions are [x, y] pairs (the plane) and the template is [x, y, z] triples"),
        (('edges = "complete"', 'edges = "henneberg"'), "formation.edges",
         "the henneberg graph is built from points in the plane"),
        (('law = "chirality-restricted"', 'law = "angle-restricted"'), "",
         'use law = "chirality-restricted"'),
        (('[robots]', '[robots]\nmodel = "unicycle"'), "", "moves in the plane"),
    ],
)  # fmt: skip
def test_scenario_mistakes_in_space_are_named(tmp_path, change, key, words) -> None:
    text = (EXAMPLES / "tetrahedron-mirror.toml").read_text()
    assert change[0] in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(*change, 1))
    res = invoke("run", path, "--out", tmp_path / "out")
    assert res.exit_code == 2, res.output
    assert key in res.output and words in res.output, res.output
    assert "Traceback" not in res.output


def test_an_alpha_table_with_points_in_space_is_refused(tmp_path) -> None:
    text = """
[robots]
positions = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
[formation]
edges = "complete"
alpha = [[1, 2, 3, 1.0], [2, 3, 1, 1.0], [3, 1, 2, 1.0]]
[controller]
law = "distance"
[simulation]
integrator = "euler"
dt = 0.01
duration = 1.0
"""
    path = tmp_path / "alpha.toml"
    path.write_text(text)
    res = invoke("validate", path)
    assert res.exit_code == 2 and "formation.alpha" in res.output, res.output
    assert "an alpha table restricts triangles in the plane" in res.output


def test_rigidity_and_realisability_in_space() -> None:
    from formationlab.formation.graph import is_rigid
    from formationlab.formation.realisability import realisability_problems

    k4 = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
    assert is_rigid(k4, 4, dim=3) and is_rigid(k4, 4)
    assert not is_rigid(k4[:5], 4, dim=3)  # a hinge: two triangles on a common edge
    bip = np.array(BIPYRAMID_EDGES) - 1
    assert is_rigid(bip, 5, dim=3)  # 3n - 6 = 9 edges, rigid
    assert not is_rigid(bip[:-1], 5, dim=3)
    octa = [
        (i, j) for i in range(6) for j in range(i + 1, 6) if (i, j) not in ((0, 1), (2, 3), (4, 5))
    ]
    assert is_rigid(np.array(octa), 6, dim=3)  # 12 edges: the octahedron
    # a regular tetrahedron's distances need space: the plane cannot realise them
    assert realisability_problems(fl.Formation.from_distances(4, dim=3)) == []
    assert realisability_problems(fl.Formation.from_distances(4))  # in the plane: a warning
    assert fl.Formation.from_template(BIPYRAMID, edges=BIPYRAMID_EDGES).is_rigid


def test_knn_and_within_graphs_take_points_in_space(rng) -> None:
    from formationlab.formation.graphs import build_edges

    pts = rng.normal(size=(30, 3))
    knn = build_edges({"knn": 4}, pts)
    assert np.all(np.bincount(knn.ravel(), minlength=30) >= 4)
    within = build_edges({"within": 1.0}, pts)
    r = np.linalg.norm(pts[within[:, 1]] - pts[within[:, 0]], axis=-1)
    assert np.all(r <= 1.0 + 1e-9) and len(within) > 0


def test_a_study_in_space_measures_both_chiralities(tmp_path: Path) -> None:
    """The tetrahedron from random starts: the distance law ends at the template or its
    mirror image (both occur), the chirality-restricted law at the template; each trial is
    the single run of the same start (the numpy path, as the study says)."""
    import pandas as pd

    text = (EXAMPLES / "study-tetrahedron.toml").read_text()
    text = text.replace("trials = 10000", "trials = 60")
    path = tmp_path / "study.toml"
    path.write_text(text)
    res = invoke("study", path, "--out", tmp_path / "out", "--quiet")
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["backend_used"] == "numpy" and "in space" in s["backend_note"]
    trials = pd.read_parquet(tmp_path / "out" / "trials.parquet")
    assert {"z1_init", "z4", "drift_vz"} <= set(trials.columns)
    by_law = trials.groupby("law")["outcome"].value_counts().unstack(fill_value=0)
    assert by_law.loc["distance", "desired"] >= 15 and by_law.loc["distance", "mirror"] >= 15
    assert by_law.loc["chirality-restricted", "desired"] >= 57
    assert by_law.loc["chirality-restricted"].get("mirror", 0) == 0
    # a trial of the table is the single run of its start
    sc = load_scenario(path)
    row = trials[trials["law"] == "distance"].iloc[3]
    q0 = np.array([[row[f"{a}{i}_init"] for a in "xyz"] for i in range(1, 5)])
    one = fl.simulate(sc.formation, fl.DistanceLaw(), q0, duration=20.0,
                      integrator=fl.get_integrator("euler", dt=0.01))  # fmt: skip
    assert one.summary()["outcome"] == row["outcome"]
    q_end = np.array([[row[f"{a}{i}"] for a in "xyz"] for i in range(1, 5)])
    np.testing.assert_allclose(one.q[int(row["steps"])], q_end, atol=1e-9)  # where it stopped
