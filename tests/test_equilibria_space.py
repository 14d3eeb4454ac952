"""Equilibria of formations in space: refinement, classification modulo SO(3), chirality.

docs/three-d.md ("Equilibria in space") reports what these tests check on the regular
tetrahedron: the refined equilibria have a vanishing field; the Jacobian has six trivial
zero eigenvalues (three translations, three rotations); the desired shape and its mirror
image are both stable under the distance law and distinct (a reflection is not a rigid
motion: it flips the chirality), and every undesired equilibrium is unstable (Pham, Trinh
and Ahn, "Formation control of rigid graphs with a flex node addition", IEEE CDC 2017);
the chirality-restricted law pushes at the mirror image, which is no equilibrium of it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import formationlab as fl
from formationlab.equilibria import (
    catalogue,
    classify_equilibrium,
    jacobian,
    random_starts,
    refine,
    rigid_modes,
    same_equilibrium,
    settle,
)
from formationlab.outcomes.analysis import chirality_agreement

#: a regular tetrahedron of edge 1
TETRA = np.array(
    [[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0], [0.5, np.sqrt(3) / 6, np.sqrt(2 / 3)]]
)
MIRROR = TETRA * np.array([1.0, 1.0, -1.0])
EXAMPLES = Path(__file__).parents[1] / "examples" / "space"
#: a field below this is zero: refine's tolerance (1e-9 of the field's scale, here < 10)
FIELD_TOL = 1e-8


@pytest.fixture(scope="module")
def tetra() -> fl.Formation:
    return fl.Formation.from_template(TETRA)


def distance_law() -> fl.controllers.Law:
    return fl.controllers.LAWS["distance"]()


def chirality_law() -> fl.controllers.Law:
    return fl.controllers.LAWS["chirality-restricted"]()


def largest_field(formation: fl.Formation, law: fl.controllers.Law, q: np.ndarray) -> float:
    return float(np.max(np.linalg.norm(law.control(formation, q), axis=-1)))


def test_the_tetrahedron_under_distances_has_two_attractors_and_only_saddles_else(tetra) -> None:
    law = distance_law()
    starts = random_starts(tetra, 20, np.random.default_rng(0))  # 4 on lines, 4 on planes
    ends = settle(tetra, law, starts, duration=20.0)
    cat = catalogue(tetra, law, ends.q_final, outcomes=ends.outcome)
    assert sum(cat.counts) + sum(cat.skipped.values()) == 20
    for eq in cat.equilibria:
        assert eq.q.shape == (4, 3)
        assert eq.residual <= FIELD_TOL and largest_field(tetra, law, eq.q) <= FIELD_TOL
    by_outcome = {eq.outcome: eq for eq in cat.equilibria if eq.outcome != "incorrect"}
    assert set(by_outcome) == {"desired", "mirror"}
    assert by_outcome["desired"].stability == by_outcome["mirror"].stability == "stable"
    undesired = [eq for eq in cat.equilibria if eq.outcome == "incorrect"]
    assert undesired, "the collinear and coplanar starts end at saddles"
    # Pham, Trinh and Ahn (CDC 2017): every undesired equilibrium of K4 is unstable
    assert all(eq.stability == "saddle" and eq.unstable_directions >= 1 for eq in undesired)
    # no two listed equilibria are one up to rotation, translation and allowed relabelling
    for a in range(len(cat.equilibria)):
        for b in range(a):
            assert not same_equilibrium(tetra, cat.equilibria[a].q, cat.equilibria[b].q)


def test_the_desired_eigenvalues_are_those_of_the_rigidity_matrix(tetra) -> None:
    """At the desired shape ``phi' = 0``, so ``J = -k_c phi''(d) R^T R`` with ``R`` the
    rigidity matrix of unit edge directions (docs/equilibria.md, "Two equilibria by hand")
    and ``phi''(d) = 1 / (d - a)^2`` (eq. 7): computed here from the template, not the law."""
    law = distance_law()
    eq = classify_equilibrium(tetra, law, refine(tetra, law, TETRA + 1e-4))
    a = float(tetra.contact_matrix[0, 1])
    rows = []
    for i, j in tetra.edges:
        row = np.zeros((4, 3))
        e = (TETRA[j] - TETRA[i]) / np.linalg.norm(TETRA[j] - TETRA[i])
        row[i], row[j] = -e, e
        rows.append(row.ravel())
    rr = np.linalg.eigvalsh(np.array(rows) @ np.array(rows).T)  # the non-zero ones of R^T R
    expected = np.sort(-law.k_c / (1.0 - a) ** 2 * rr)[::-1]
    assert eq.eigenvalues.shape == (3 * 4 - 6,)
    # central differences of step 1e-6 size: error ~1e-9 relative; 1e-6 is ample
    np.testing.assert_allclose(eq.eigenvalues.real, expected, rtol=1e-6)
    assert eq.stability == "stable" and eq.outcome == "desired" and eq.zero_directions == 0


def test_six_trivial_zero_eigenvalues_in_space_five_on_a_line(tetra) -> None:
    law = distance_law()
    rng = np.random.default_rng(3)
    turn = Rotation.random(random_state=rng).as_matrix()
    q = TETRA @ turn.T + rng.normal(size=3)  # the desired shape, turned and moved
    jac = jacobian(lambda x: law.control(tetra, x), q)
    lam = np.linalg.eigvals(jac)
    zero = 1e-6 * np.max(np.abs(lam))  # classify's tolerance
    assert int(np.sum(np.abs(lam) <= zero)) == 6
    modes = rigid_modes(q)
    assert modes.shape == (12, 6)
    np.testing.assert_allclose(modes.T @ modes, np.eye(6), atol=1e-12)
    assert np.max(np.abs(jac @ modes)) <= zero
    line = np.outer([0.0, 0.7, 1.9, 3.1], [1.0, 2.0, 2.0]) / 3.0
    assert rigid_modes(line).shape == (12, 5)  # the turn about the line moves nothing


def test_the_mirror_is_the_other_chirality_stable_under_distances_and_distinct(tetra) -> None:
    law = distance_law()
    rng = np.random.default_rng(5)
    mirror = classify_equilibrium(
        tetra, law, refine(tetra, law, MIRROR + 1e-3 * rng.normal(size=(4, 3)))
    )
    desired = classify_equilibrium(tetra, law, refine(tetra, law, TETRA))
    assert mirror.outcome == "mirror" and mirror.stability == "stable"
    np.testing.assert_allclose(mirror.distances, 1.0, atol=1e-9)
    np.testing.assert_allclose(mirror.eigenvalues.real, desired.eigenvalues.real, rtol=1e-6)
    # distances alike, chirality not: never the same equilibrium, by any rotation
    assert not same_equilibrium(tetra, desired.q, mirror.q)
    turn = Rotation.random(random_state=rng).as_matrix()
    assert same_equilibrium(tetra, desired.q, TETRA @ turn.T + 2.0)
    assert same_equilibrium(tetra, mirror.q, MIRROR @ turn.T - 1.0)
    # a relabelling the chirality allows (an even one: 1 2 3 -> 2 3 1, a turn about 4)
    assert same_equilibrium(tetra, desired.q, (TETRA @ turn.T)[[1, 2, 0, 3]])
    # an odd one is a reflection paired with a relabelling: the mirror relabelled is desired
    assert same_equilibrium(tetra, desired.q, (MIRROR @ turn.T)[[1, 0, 2, 3]])


def test_the_chirality_law_pushes_at_the_mirror_which_is_no_equilibrium(tetra) -> None:
    """At the mirror image ``beta v = |v| > -theta``: the restriction is on for every theta,
    the distance term vanishes, and robot ``i`` is pushed by ``k_a |r_jl x r_jk|``, ``k_a``
    times twice the area of the opposite face (docs/three-d.md): ``3 sqrt(3) / 2``."""
    law = chirality_law()
    assert np.all(law.switching(tetra, MIRROR) > 0)
    speeds = np.linalg.norm(law.control(tetra, MIRROR), axis=-1)
    np.testing.assert_allclose(speeds, law.k_a * np.sqrt(3) / 2, rtol=1e-12)
    # the desired shape is one (theta = 0.5 below its |v| = 0.707: the restriction is off)
    assert np.all(law.switching(tetra, TETRA) < 0)
    assert largest_field(tetra, law, TETRA) <= FIELD_TOL
    # from near the mirror, runs end at the desired shape, never at the mirror
    rng = np.random.default_rng(7)
    near = MIRROR + 1e-2 * rng.normal(size=(3, 4, 3))
    ends = settle(tetra, law, near, duration=10.0)
    cat = catalogue(tetra, law, ends.q_final, outcomes=ends.outcome, extra=[MIRROR])
    assert [eq.outcome for eq in cat.equilibria] == ["desired", "incorrect"]
    assert cat.counts == [3, 0] and cat.equilibria[0].stability == "stable"
    # refined from the mirror itself: the mirror shrunk until the barrier of phi balances
    # the push (the plane's equilateral equilibrium of simulation 2, docs/equilibria.md),
    # a saddle at the paper's gains whose two unstable directions lead out of the symmetry
    shrunk = cat.equilibria[1]
    assert shrunk.residual <= FIELD_TOL and shrunk.active == ("v_1234",)
    assert np.ptp(shrunk.distances) <= 1e-9 and 0.5 < shrunk.distances[0] < 1.0
    assert chirality_agreement(tetra, shrunk.q) == (0, 4)
    assert shrunk.stability == "saddle" and shrunk.unstable_directions == 2


def test_random_starts_in_space_lie_on_lines_planes_and_in_the_cube(tetra) -> None:
    q = random_starts(tetra, 10, np.random.default_rng(1), collinear=0.2, coplanar=0.3)
    assert q.shape == (10, 4, 3)
    centred = q - q.mean(axis=1, keepdims=True)
    ranks = [int(np.sum(np.linalg.svd(c, compute_uv=False) > 1e-9)) for c in centred]
    assert ranks == [1, 1, 2, 2, 2, 3, 3, 3, 3, 3]
    assert np.all(np.abs(q) <= 3.0 * 1.0 + 1e-12)  # in [-3 max d, 3 max d]^3


def test_the_plane_ignores_the_coplanar_fraction() -> None:
    f = fl.Formation.from_template([[0, 0], [1, 0], [0.5, 0.8]])
    a = random_starts(f, 12, np.random.default_rng(2), coplanar=0.0)
    b = random_starts(f, 12, np.random.default_rng(2), coplanar=0.9)
    np.testing.assert_array_equal(a, b)


def test_the_rigid_guess_in_space_recovers_a_hand_built_screw() -> None:
    """``(v, w)`` of an exact screw field ``v + w x (q_i - q_bar)``, from the field alone."""
    from formationlab.equilibria.relative import rigid_field, rigid_guess

    q = np.random.default_rng(4).normal(size=(6, 3))
    motion = np.array([0.3, -0.2, 0.1, 0.5, -1.5, 0.25])
    np.testing.assert_allclose(rigid_guess(rigid_field(q, motion), q), motion, atol=1e-12)
    np.testing.assert_allclose(rigid_field(q, motion)[0], motion[:3] + np.cross(
        motion[3:], q[0] - q.mean(axis=0)), atol=1e-15)  # fmt: skip


#: each robot's own desired distances of the tetrahedron: a 1 % mismatch (seed 0)
def _mismatched(tetra):
    from formationlab.agents.mismatch import own_distances
    from formationlab.sensing import Sensing, local_controls, measured

    law = distance_law()
    own = own_distances(tetra, law, 0.01, [0])[0]

    class Mismatched(type(law)):  # the field the robots of a mismatched run follow
        def control(self, formation, q):
            terms = law.sensed_terms(formation)
            return local_controls(terms, measured(np.asarray(q, float), None), own_distance=own)

    return Mismatched(), Sensing(mismatch=0.01, seed=0)


def test_the_helix_of_mismatched_distances_is_a_relative_equilibrium_in_space(tetra) -> None:
    """Sun, Mou, Anderson and Morse (IEEE TAC 2017): a mismatched tetrahedron ends in a
    screw motion. Refined as a relative equilibrium (shape and screw solved for together,
    from the run's end state and from a state of its transient), it is the screw that a
    simulated run settles into, fitted from the run's positions (two independent paths),
    and it is stable in the co-moving frame (3n - 6 = 6 eigenvalues, all negative)."""
    from formationlab.outcomes.rigid_motion import rigid_motion

    law, sensing = _mismatched(tetra)
    start = TETRA * 1.3 + np.random.default_rng(1).normal(scale=0.1, size=(4, 3))
    run = fl.simulate(tetra, distance_law(), start, duration=40.0,
                      integrator=fl.get_integrator("rk4", dt=0.01), sensing=sensing)  # fmt: skip
    fit = rigid_motion(run.q[-501], run.q[-1], run.t[-1] - run.t[-501])
    assert fit.shape_rate < 1e-9 and fit.omega > 1e-2
    for q0 in (run.q[-1], run.q[np.searchsorted(run.t, 12.0)]):
        found = refine(tetra, law, q0, moving=True)
        assert found.success and found.residual < 1e-12
        assert found.omega == pytest.approx(float(fit.omega), rel=1e-9)
        np.testing.assert_allclose(found.axis, fit.axis, atol=1e-9)
        # the same shape as the run's, up to a rigid motion
        assert same_equilibrium(tetra, found.q, run.q[-1], tol=1e-9)
    eq = classify_equilibrium(tetra, law, refine(tetra, law, run.q[-1], moving=True))
    assert eq.outcome == "rotating" and eq.stability == "stable"
    assert eq.motion.axial_velocity == pytest.approx(float(fit.axial_velocity), rel=1e-8)
    assert eq.eigenvalues.size == 6 and np.all(eq.eigenvalues.real < -1.0)
    # the catalogue refines a rotating end state in space (no longer skipped) and poses it
    # with its velocity and axis turned along: the posed screw is still the law's field
    cat = catalogue(tetra, law, run.q[-1:], outcomes=np.array(["rotating"]))
    (posed,) = cat.equilibria
    assert cat.counts == [1] and not cat.skipped
    screw = posed.velocity + posed.omega * np.cross(posed.axis, posed.q - posed.q.mean(axis=0))
    np.testing.assert_allclose(law.control(tetra, posed.q), screw, atol=1e-12)
    item = cat.to_dict()["equilibria"][0]
    assert item["outcome"] == "rotating" and len(item["axis"]) == 3


def test_the_command_finds_the_tetrahedrons_equilibria(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from formationlab.cli import _load_commands, app

    _load_commands()
    out = tmp_path / "eq"
    args = ["equilibria", EXAMPLES / "study-tetrahedron.toml", "--law", "distance"]
    args += ["--starts", "10", "--out", out]
    res = CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    data = json.loads((out / "equilibria.json").read_text())
    assert data["source"]["random_starts"]["coplanar"] == 0.2
    outcomes = {e["outcome"] for e in data["equilibria"]}
    assert {"desired", "mirror"} <= outcomes
    for e in data["equilibria"]:
        assert len(e["positions"]) == 4 and all(len(p) == 3 for p in e["positions"])
        assert e["residual"] <= FIELD_TOL
        line = np.linalg.matrix_rank(np.array(e["positions"]) - np.mean(e["positions"], 0)) == 1
        assert len(e["eigenvalues"]) == (7 if line else 6)  # 12 less 5 or 6 rigid modes
    assert (out / "gallery.png").stat().st_size > 10_000
