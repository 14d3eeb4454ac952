"""Equilibria: refinement, classification by eigenvalues, de-duplication, the command.

Reference values are derived by hand in docs/equilibria.md ("Two equilibria
by hand"): the desired triangle of the distance law and the collinear saddle
of the three-robot distance law.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import formationlab as fl
from formationlab.equilibria import (
    catalogue,
    classify_equilibrium,
    jacobian,
    random_starts,
    reduced_eigenvalues,
    refine,
    same_equilibrium,
    settle,
)

K_C = 2.0
A = 0.2  # contact distance a_ij = rho = 0.2
D = 1.0
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def dphi(r: float) -> float:
    return 1.0 / (D - A) - 1.0 / (r - A)  # eq. (7)


def ddphi(r: float) -> float:
    return 1.0 / (r - A) ** 2


@pytest.fixture(scope="module")
def triangle() -> fl.Formation:
    return fl.Formation.from_distances(3, distances=D, diameters=A)


@pytest.fixture(scope="module")
def sim2() -> fl.Formation:
    return fl.Formation.from_alpha_table(
        {(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}, n=3, distances=D, diameters=A
    )


def rotate(q: np.ndarray, ang: float) -> np.ndarray:
    c, s = np.cos(ang), np.sin(ang)
    return q @ np.array([[c, s], [-s, c]])


def test_desired_triangle_is_stable_with_hand_derived_eigenvalues(triangle):
    law = fl.DistanceLaw(k_c=K_C)
    rng = np.random.default_rng(3)
    eq_tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]])
    ref = refine(triangle, law, eq_tri + 0.05 * rng.standard_normal((3, 2)))
    assert ref.success
    eq = classify_equilibrium(triangle, law, ref)
    assert eq.desired and eq.stability == "stable" and eq.unstable_directions == 0
    np.testing.assert_allclose(eq.distances, D, atol=1e-10)
    # J = -k_c phi''(d) R^T R; R^T R of the unit equilateral triangle has 3/2, 3/2, 3
    expected = -K_C * ddphi(D) * np.array([1.5, 1.5, 3.0])
    np.testing.assert_allclose(eq.eigenvalues.real, expected, rtol=1e-6)
    np.testing.assert_allclose(eq.eigenvalues.imag, 0.0, atol=1e-8)


def test_collinear_equilibrium_is_a_saddle_with_hand_derived_eigenvalues(triangle):
    law = fl.DistanceLaw(k_c=K_C)
    # phi'(s) + phi'(2s) = 0  <=>  5 s^2 - 4.5 s + 0.5 = 0 for d = 1, a = 0.2
    s = (4.5 + np.sqrt(4.5**2 - 4 * 5 * 0.5)) / 10
    assert abs(dphi(s) + dphi(2 * s)) < 1e-12
    tau = dphi(2 * s)
    ref = refine(triangle, law, np.array([[-0.8, 0.01], [0.02, 0.0], [0.75, -0.01]]))
    assert ref.success
    eq = classify_equilibrium(triangle, law, ref)
    assert eq.stability == "saddle" and eq.unstable_directions == 1 and not eq.desired
    np.testing.assert_allclose(np.sort(eq.distances), [s, s, 2 * s], rtol=1e-9)
    expected = [
        3 * K_C * tau / s,  # bending: the middle robot leaves the line
        -K_C * (ddphi(s) + 2 * ddphi(2 * s)),  # antisymmetric stretch
        -3 * K_C * ddphi(s),  # symmetric stretch
    ]
    np.testing.assert_allclose(eq.eigenvalues.real, expected, rtol=1e-6)
    assert eq.growth_rate == pytest.approx(3 * K_C * tau / s, rel=1e-6)


def test_jacobian_has_the_rigid_modes_in_its_kernel(triangle):
    law = fl.DistanceLaw(k_c=K_C)
    ref = refine(triangle, law, np.array([[-0.8, 0.0], [0.0, 0.0], [0.8, 0.0]]))
    jac = jacobian(lambda x: law.control(triangle, x), ref.q)
    q = ref.q - ref.q.mean(0)
    for mode in (np.tile([1.0, 0.0], 3), np.tile([0.0, 1.0], 3), np.c_[-q[:, 1], q[:, 0]].ravel()):
        assert np.max(np.abs(jac @ mode)) < 1e-7
    # removing the modes leaves 2n - 3 eigenvalues, those of J that are not zero
    lam = reduced_eigenvalues(jac, ref.q)
    full = np.linalg.eigvals(jac)
    nonzero = np.sort(full.real[np.abs(full) > 1e-6])
    np.testing.assert_allclose(np.sort(lam.real), nonzero, rtol=1e-8)


def test_classification_is_invariant_to_translation_rotation_relabelling(sim2):
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    base = refine(sim2, law, np.array([[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]))
    assert base.success
    ref_eq = classify_equilibrium(sim2, law, base)
    q = base.q
    cyclic = q[[1, 2, 0]]  # an even relabelling keeps alpha
    mirror_swap = (q * np.array([-1.0, 1.0]))[[1, 0, 2]]  # odd one, with a reflection
    for moved in (
        q + np.array([5.0, -2.0]),
        rotate(q, 1.1),
        rotate(cyclic, -0.4) + 3.0,
        mirror_swap,
    ):
        # start off the equilibrium, so the root finder has work to do
        start = moved + 1e-3 * np.random.default_rng(0).standard_normal(q.shape)
        eq = classify_equilibrium(sim2, law, refine(sim2, law, start))
        assert eq.stability == ref_eq.stability
        assert eq.unstable_directions == ref_eq.unstable_directions
        np.testing.assert_allclose(eq.eigenvalues, ref_eq.eigenvalues, rtol=1e-5)
        np.testing.assert_allclose(np.sort(eq.distances), np.sort(ref_eq.distances), rtol=1e-9)
        assert same_equilibrium(sim2, q, eq.q)


def test_reflection_counts_only_where_the_formation_allows_it(sim2, triangle):
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]])
    mirror = tri * np.array([-1.0, 1.0])
    assert same_equilibrium(triangle, tri, mirror)  # free orientation
    assert not same_equilibrium(sim2, tri, mirror)  # alpha fixes the orientation
    assert same_equilibrium(sim2, tri, mirror[[1, 0, 2]])  # unless robots 1, 2 swap too
    other = np.array([[0.0, 0.0], [1.2, 0.0], [0.5, 0.9]])
    assert not same_equilibrium(triangle, tri, other)


def test_perturbation_decays_at_the_rate_of_the_largest_eigenvalue(sim2):
    """The equilibrium of simulation 2 (NOTES.md): eigenvalue checked against a simulation."""
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    run = fl.simulate(sim2, law, [[-3, -3], [3, -3], [0, 3]], duration=8.0, save_every=1000)
    eq = classify_equilibrium(sim2, law, refine(sim2, law, run.q[-1]))
    assert eq.stability == "stable" and not eq.desired
    assert eq.active == ("alpha_123",) and eq.surfaces == ()
    np.testing.assert_allclose(eq.distances, eq.distances[0], rtol=1e-9)  # equilateral
    # perturb by 1e-6 along a random direction and watch the shape error shrink
    rng = np.random.default_rng(1)
    start = eq.q + 1e-6 * rng.standard_normal(eq.q.shape)
    res = fl.simulate(sim2, law, start, duration=6.0, integrator=fl.RK4(dt=0.01))
    err = np.linalg.norm(fl.distance_errors(sim2, res.q) - (eq.distances - 1.0), axis=-1)
    late = res.t >= 2.0  # after the fast mode (-43/s) has died out
    slope = np.polyfit(res.t[late], np.log(err[late]), 1)[0]
    assert slope == pytest.approx(eq.growth_rate, rel=0.02)


def test_catalogue_merges_random_ends_of_the_distance_law(triangle):
    law = fl.DistanceLaw(k_c=K_C)
    rng = np.random.default_rng(7)
    starts = random_starts(triangle, 24, rng, collinear=0.25)
    ends = settle(triangle, law, starts, duration=30.0)
    cat = catalogue(triangle, law, ends.q_final, outcomes=ends.outcome)
    kinds = [(e.desired, e.stability) for e in cat.equilibria]
    assert kinds == [(True, "stable"), (False, "saddle")]  # desired first
    assert sum(cat.counts) + sum(cat.skipped.values()) == 24
    assert cat.counts[1] == np.sum(ends.outcome == "incorrect") > 0


def test_equilibria_command_writes_json_and_gallery(tmp_path):
    from formationlab.cli import main

    scenario = tmp_path / "tri.toml"
    scenario.write_text(
        "[robots]\npositions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]\n"
        '[formation]\ndistances = 1.0\n[controller]\nlaw = "distance"\n'
        '[simulation]\nintegrator = "rk4"\ndt = 0.01\nduration = 10.0\n'
        "[equilibria]\nstarts = 12\nduration = 30.0\n"
    )
    out = tmp_path / "eq"
    with pytest.raises(SystemExit) as exc:
        main(["equilibria", str(scenario), "--out", str(out), "--seed", "2", "-q"])
    assert exc.value.code == 0
    data = json.loads((out / "equilibria.json").read_text())
    assert (out / "gallery.png").stat().st_size > 0
    first = data["equilibria"][0]
    assert first["desired"] and first["stability"] == "stable"
    for key in (
        "positions",
        "distances",
        "residual",
        "unstable_directions",
        "eigenvalues",
        "count",
    ):
        assert key in first
    assert set(first["distances"]) == {"1-2", "1-3", "2-3"}
    assert sum(e["count"] for e in data["equilibria"]) == 13  # 12 starts + the scenario's run
    with pytest.raises(SystemExit) as exc:  # the folder now holds results
        main(["equilibria", str(scenario), "--out", str(out), "-q"])
    assert exc.value.code == 2


def test_study_end_states_are_read_by_law(tmp_path):
    pd = pytest.importorskip("pandas")
    from formationlab.errors import ScenarioError
    from formationlab.io.equilibria import read_study_end_states

    frame = pd.DataFrame(
        {
            "law": ["distance", "angle-restricted", "distance"],
            "outcome": ["incorrect", "desired", "desired"],
            "x1": [0.0, 1.0, 2.0],
            "y1": [0.5, 1.5, 2.5],
            "x2": [3.0, 4.0, 5.0],
            "y2": [3.5, 4.5, 5.5],
        }
    )
    frame.to_parquet(tmp_path / "trials.parquet")
    q, outcome = read_study_end_states(tmp_path, 2, "distance")
    np.testing.assert_array_equal(q, [[[0.0, 0.5], [3.0, 3.5]], [[2.0, 2.5], [5.0, 5.5]]])
    assert outcome.tolist() == ["incorrect", "desired"]
    with pytest.raises(ScenarioError, match="no trial of the law"):
        read_study_end_states(tmp_path, 2, "signed-area")
    with pytest.raises(ScenarioError, match="lacks the columns"):
        read_study_end_states(tmp_path, 3, "distance")


def test_study_end_states_keep_the_scenarios_point_of_a_sweep(tmp_path):
    pd = pytest.importorskip("pandas")
    from formationlab.errors import ScenarioError
    from formationlab.io.equilibria import read_study_end_states

    frame = pd.DataFrame(
        {
            "law": ["angle-restricted"] * 3 + ["distance"],
            "k_a": [1.0, 3.0, 3.0, np.nan],
            "outcome": ["desired", "incorrect", "desired", "mirror"],
            "x1": [0.0, 1.0, 2.0, 3.0],
            "y1": [0.0, 1.0, 2.0, 3.0],
            "x2": [5.0, 6.0, 7.0, 8.0],
            "y2": [5.0, 6.0, 7.0, 8.0],
        }
    )
    frame.to_parquet(tmp_path / "trials.parquet")
    q, outcome = read_study_end_states(tmp_path, 2, "angle-restricted", {"k_a": 3.0, "k_c": 2.0})
    assert outcome.tolist() == ["incorrect", "desired"]
    np.testing.assert_array_equal(q[:, 0, 0], [1.0, 2.0])
    q, outcome = read_study_end_states(tmp_path, 2, "distance", {"k_c": 2.0})
    assert outcome.tolist() == ["mirror"]
    with pytest.raises(ScenarioError, match="k_a = 1, 3"):
        read_study_end_states(tmp_path, 2, "angle-restricted", {"k_a": 5.0})


def test_filippov_equilibrium_of_the_square_attracts_at_its_sliding_rate():
    """The square with both diagonals under the angle-restricted law (docs/equilibria.md).

    The start is a rough guess of a flattened shape; what is checked is the
    definition of a Filippov equilibrium (on the surfaces, a convex combination
    of the one-sided fields vanishes, both sides point into the surfaces) and
    that a simulation returns to it at the rate of the sliding eigenvalue.
    """
    square = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], diameters=A)
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    guess = np.array([[-0.23, 0.12], [0.23, 0.12], [-1.02, -0.12], [1.02, -0.12]])
    ref = refine(square, law, guess)
    assert ref.success and ref.filippov
    eq = classify_equilibrium(square, law, ref)
    assert eq.stability == "filippov" and eq.attractive and not eq.desired
    assert set(eq.surfaces) == {"alpha_134", "alpha_234"}
    on = list(ref.surfaces)
    sigma = law.switching(square, ref.q)
    assert np.all(np.abs(sigma[on]) < 1e-10)
    assert np.all((ref.weights[on] > 0) & (ref.weights[on] < 1))
    assert np.max(np.abs(law.control_with(square, ref.q, ref.weights))) < 1e-9
    # the one-sided fields point into each surface (finite-difference gradient of sigma)
    h = 1e-6
    grad = np.zeros((len(on), 4, 2))
    for a in range(4):
        for b in range(2):
            e = np.zeros((4, 2))
            e[a, b] = h
            grad[:, a, b] = (law.switching(square, ref.q + e) - law.switching(square, ref.q - e))[
                on
            ] / (2 * h)
    for t, s in enumerate(on):
        w = ref.weights.copy()
        w[s] = 0.0
        assert np.sum(grad[t] * law.control_with(square, ref.q, w)) > 0
        w[s] = 1.0
        assert np.sum(grad[t] * law.control_with(square, ref.q, w)) < 0
    assert eq.unstable_directions == 0 and eq.growth_rate < 0
    start = ref.q + 1e-3 * np.random.default_rng(4).standard_normal(ref.q.shape)
    res = fl.simulate(
        square, law, start, duration=1.0, integrator=fl.get_integrator("implicit-euler", dt=4e-3)
    )
    err = np.linalg.norm(
        fl.distance_errors(square, res.q) - (eq.distances - square.distances), axis=-1
    )
    late = res.t >= 0.3
    slope = np.polyfit(res.t[late], np.log(err[late]), 1)[0]
    assert slope == pytest.approx(eq.growth_rate, rel=0.05)


def test_continuation_follows_the_hand_balance_of_the_equilateral_equilibrium(sim2):
    """Along k_a the shrunken triangle of simulation 2 keeps the balance of docs/paper.md.

    On the median of an equilateral triangle of side r the two pulls of phi and the
    push of psi (eq. 23, ordered pairs) balance when
    k_c sqrt(3) (1/(d - a) - 1/(r - a)) + 2 k_a r = 0, i.e.
    k_a = sqrt(3) k_c (1/(r - a) - 1/(d - a)) / (2 r).
    """
    from formationlab.equilibria import follow

    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    run = fl.simulate(sim2, law, [[-3, -3], [3, -3], [0, 3]], duration=8.0, save_every=1000)
    branch = follow(sim2, law, run.q[-1], "k_a", [3.0, 2.0, 1.0, 0.5])
    assert branch.end == "end of range"
    np.testing.assert_allclose(branch.values, [3.0, 2.0, 1.0, 0.5])
    for k_a, eq in zip(branch.values, branch.equilibria, strict=True):
        r = eq.distances[0]
        np.testing.assert_allclose(eq.distances, r, rtol=1e-9)
        balance = np.sqrt(3) * 2.0 * (1 / (r - A) - 1 / (D - A)) / (2 * r)
        assert balance == pytest.approx(k_a, rel=1e-8)
        assert eq.stability == "stable"  # below k_a* = 3.608 (docs/equilibria.md)
    sides = [eq.distances[0] for eq in branch.equilibria]
    assert np.all(np.diff(sides) > 0)  # the triangle grows back towards d as k_a falls


def test_relabelling_by_a_symmetry_of_the_square_is_the_same_equilibrium():
    square = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], diameters=A)
    law = fl.DistanceLaw(k_c=K_C)
    kite = refine(square, law, np.array([[-0.7, 0.0], [0.7, 0.1], [0.0, -0.5], [0.05, 0.45]]))
    assert kite.success
    eq = classify_equilibrium(square, law, kite)
    assert eq.outcome == "incorrect" and eq.stability == "stable"
    turned = kite.q[[3, 0, 1, 2]]  # robot k takes robot k-1's place: the 90-degree turn
    assert same_equilibrium(square, kite.q, rotate(turned, 0.3) + 1.0)
    again = classify_equilibrium(square, law, refine(square, law, turned + 1e-3))
    np.testing.assert_allclose(again.eigenvalues, eq.eigenvalues, rtol=1e-5)
    # swapping two adjacent robots is not a symmetry of the square's graph data
    assert not same_equilibrium(square, kite.q, kite.q[[1, 0, 2, 3]])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--follow", "k_a=3"], "--follow: expected PARAM=FROM:TO"),
        (["--law", "no-such-law"], "unknown law"),
        (["--follow", "eta=0.1:1", "--law", "distance"], "has no parameter"),
        (["--integrator", "filippov"], "cannot settle a batch"),
    ],
)
def test_equilibria_command_rejects_bad_options(tmp_path, capsys, args, message):
    from formationlab.cli import main

    with pytest.raises(SystemExit) as exc:
        main(
            [
                "equilibria",
                str(EXAMPLES / "paper-simulation-1.toml"),
                "--out",
                str(tmp_path / "o"),
                *args,
            ]
        )
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize(
    ("table", "key"),
    [
        ('law = "foo"', "equilibria.law"),  # was reported as controller.law, a valid line
        ('law = "distance"\nfollow = "eta=0.1:1"', "equilibria.follow"),
    ],
)
def test_a_bad_equilibria_table_is_reported_at_its_own_key_and_line(tmp_path, capsys, table, key):
    from formationlab.cli import main

    text = (EXAMPLES / "paper-simulation-1.toml").read_text() + f"\n[equilibria]\n{table}\n"
    path = tmp_path / "bad.toml"
    path.write_text(text)
    line = text.splitlines().index(table.splitlines()[-1]) + 1
    with pytest.raises(SystemExit) as exc:
        main(["validate", str(path)])
    assert exc.value.code == 2
    err = " ".join(capsys.readouterr().err.split())
    assert f"{key} (line {line})" in err, err


@pytest.mark.parametrize(
    ("value", "said"),
    [
        ("-3", "must be >= 0, got -3"),
        ('"x"', "expected a whole number, got 'x'"),
        ("2.5", "expected a whole number, got 2.5"),
        ("5000000", "must be <= 1e+06, got 5000000"),
    ],
)
def test_bad_starts_are_refused_in_the_packages_words_at_key_and_line(tmp_path, capsys, value,
                                                                       said):  # fmt: skip
    """``[equilibria] starts`` out of range or of the wrong type: one line naming the key, its
    line, what it must be and what was given (not pydantic's "Input should be ...")."""
    from formationlab.cli import main

    table = f"\n[equilibria]\nstarts = {value}\n"
    text = (EXAMPLES / "paper-simulation-1.toml").read_text() + table
    path = tmp_path / "bad.toml"
    path.write_text(text)
    line = len(text.splitlines())
    with pytest.raises(SystemExit) as exc:
        main(["validate", str(path)])
    assert exc.value.code == 2
    err = " ".join(capsys.readouterr().err.split())
    assert f"equilibria.starts (line {line}): {said}" in err, err
    assert "Input should" not in err and "input should" not in err
