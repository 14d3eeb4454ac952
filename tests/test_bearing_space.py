"""The bearing-only law of Zhao and Zelazo (IEEE TAC 61(5), 2016) in space.

Their setting is ``R^d``: the same properties hold for formations in space, and the tests
of tests/test_bearing.py are repeated here on a tetrahedron and a triangular bipyramid:
the centroid and the scale invariant (Lemma 2), the Lyapunov rate of Theorem 5, almost
global convergence, the reversed equilibrium unstable. In space the reversed formation
``-p*`` is the mirror image of the target (a point reflection has determinant -1): the
bearing law has no chirality problem.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import formationlab as fl
from formationlab.controllers.bearing import (
    bearing_controls,
    bearing_lyapunov,
    bearing_lyapunov_rate,
    leader_target,
    target,
)
from formationlab.controllers.kinds.bearing import bearing_force, bearing_force_in_space
from formationlab.errors import FormationError, ParameterError
from formationlab.formation.bearing_rigidity import bearing_realisation
from formationlab.formation.chirality import signed_volumes
from formationlab.outcomes.analysis import bearing_errors
from formationlab.sensing import Sensing

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "space"

TETRA = np.array(
    [[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0], [0.5, np.sqrt(3) / 6, np.sqrt(2 / 3)]]
)
BIPYRAMID = np.vstack([TETRA, TETRA[3] * np.array([1, 1, -1])])
BIPYRAMID_EDGES = [(1, 2), (1, 3), (2, 3), (1, 4), (2, 4), (3, 4), (1, 5), (2, 5), (3, 5)]

FORMATIONS = {
    "tetrahedron": fl.Formation.from_template(TETRA, diameters=0.1),
    "bipyramid": fl.Formation.from_template(BIPYRAMID, edges=BIPYRAMID_EDGES, diameters=0.1),
}


@pytest.fixture(params=list(FORMATIONS))
def formation(request) -> fl.Formation:
    return FORMATIONS[request.param].with_bearings()


#: Runge-Kutta at a step the law's rates (about 1/s) resolve: the runs here take seconds
RK4 = fl.get_integrator("rk4", dt=0.02)


def _starts(formation: fl.Formation, count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        q = rng.uniform(-3.0, 3.0, size=(formation.n, 3))
        d = np.linalg.norm(q[:, None] - q[None], axis=-1) + 10 * np.eye(formation.n)
        if d.min() > 0.5:
            out.append(q)
    return np.array(out)


def test_the_term_is_minus_the_projection_of_the_desired_bearing_in_space() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        r, b = rng.normal(size=3), rng.normal(size=3)
        b /= np.linalg.norm(b)
        g = r / np.linalg.norm(r)
        want = -2.5 * (np.eye(3) - np.outer(g, g)) @ b  # -k P_g g*, eq. (11)
        np.testing.assert_allclose(bearing_force_in_space(*r, *b, 2.5), want, atol=1e-15)
        # in the plane the formula is the same one with z = 0
        np.testing.assert_array_equal(bearing_force(r[0], r[1], b[0], b[1], 2.5),
                                      bearing_force_in_space(r[0], r[1], 0.0, b[0], b[1], 0.0,
                                                             2.5)[:2])  # fmt: skip


def test_the_centroid_and_the_scale_are_invariant_in_space(formation) -> None:
    law = fl.BearingLaw(k=1.3)
    dt = 1e-2
    for q in _starts(formation, 3, 2):
        c0 = q.mean(axis=0)
        for _ in range(200):
            u = law.control(formation, q)
            assert u.shape == (formation.n, 3)
            assert np.abs(u.sum(axis=0)).max() < 1e-13  # the commands sum to zero
            s2 = np.sum((q - q.mean(axis=0)) ** 2)
            q_next = q + dt * u
            grown = np.sum((q_next - q_next.mean(axis=0)) ** 2) - s2
            np.testing.assert_allclose(grown, dt * dt * np.sum(u * u), rtol=1e-6, atol=1e-14)
            q = q_next
        np.testing.assert_allclose(q.mean(axis=0), c0, rtol=0, atol=1e-12)


def test_the_lyapunov_rate_is_the_derivative_and_never_positive_in_space(formation) -> None:
    for q in _starts(formation, 10, 4):
        u = bearing_controls(formation, q)
        rate = bearing_lyapunov_rate(formation, q)
        assert rate <= 0
        h = 1e-6
        fd = (bearing_lyapunov(formation, q + h * u) - bearing_lyapunov(formation, q - h * u)) / (
            2 * h
        )
        np.testing.assert_allclose(fd, rate, rtol=1e-6)


def test_almost_every_start_reaches_the_template_and_its_chirality(formation) -> None:
    law = fl.BearingLaw()
    template = FORMATIONS["tetrahedron"].template if formation.n == 4 else BIPYRAMID
    quad = np.array([[0, 1, 2, 3]])
    for q0 in _starts(formation, 6, 5):
        res = fl.simulate(formation, law, q0, duration=30.0, integrator=RK4)
        assert res.outcome() == "desired"
        q = res.q[-1]
        np.testing.assert_allclose(q, target(formation, q), atol=1e-4)
        # bearings fix the chirality: the signed volume has the template's sign
        assert np.sign(signed_volumes(q, quad)) == np.sign(signed_volumes(template, quad))


def test_the_reversed_formation_is_the_mirror_and_an_unstable_equilibrium() -> None:
    f = FORMATIONS["tetrahedron"].with_bearings()
    p = bearing_realisation(f)
    q = -p  # every bearing reversed: the point reflection, the other chirality
    quad = np.array([[0, 1, 2, 3]])
    assert np.sign(signed_volumes(q, quad)) == -np.sign(signed_volumes(p, quad))
    np.testing.assert_allclose(bearing_controls(f, q), 0.0, atol=1e-15)
    np.testing.assert_allclose(bearing_errors(f, q), 2.0, atol=1e-12)
    law = fl.BearingLaw()
    still = fl.simulate(f, law, q, duration=2.0, integrator=RK4)
    assert still.outcome() == "incorrect"
    # a nudge leaves it and the formation turns inside out to the template's chirality
    nudge = 0.01 * np.random.default_rng(0).normal(size=(4, 3))
    nudged = fl.simulate(f, law, q + nudge, duration=60.0, integrator=RK4)
    assert nudged.outcome() == "desired"
    assert np.sign(signed_volumes(nudged.q[-1], quad)) == np.sign(signed_volumes(p, quad))


def test_leaders_in_space_fix_the_followers() -> None:
    f = FORMATIONS["bipyramid"].with_bearings()
    lead = [1, 2]
    place = 2.0 * BIPYRAMID + np.array([1.0, -1.0, 0.5])
    got = leader_target(f, lead, place[[0, 1]])
    np.testing.assert_allclose(got, place, atol=1e-12)


def test_bearings_in_space_are_checked() -> None:
    f = FORMATIONS["tetrahedron"]
    with pytest.raises(FormationError, match=r"one \[x, y, z\] per edge"):
        f.with_bearings(np.ones((6, 2)))
    with pytest.raises(FormationError, match="not zero"):
        f.with_bearings(np.zeros((6, 3)))


def test_bearing_robots_that_sense_in_space_are_refused_by_name() -> None:
    f = FORMATIONS["tetrahedron"]
    q0 = _starts(f, 1, 6)[0]
    with pytest.raises(ParameterError, match="the law 'bearing'"):
        fl.simulate(f, fl.BearingLaw(), q0, duration=1.0, sensing=Sensing(noise=0.01))


def test_a_bearing_scenario_in_space_runs(tmp_path) -> None:
    text = (EXAMPLES / "tetrahedron-mirror.toml").read_text()
    text = text.replace('law = "chirality-restricted"', 'law = "bearing"')
    text = "\n".join(line for line in text.splitlines() if not line.startswith("theta"))
    path = tmp_path / "bearing.toml"
    path.write_text(text)
    from typer.testing import CliRunner  # (the command line: loaded when a test needs it)

    from formationlab.cli import _load_commands, app

    _load_commands()
    res = CliRunner().invoke(app, ["run", str(path), "--out", str(tmp_path / "out"), "--quiet"])
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["outcome"] == "desired" and s["max_bearing_error"] < 0.01
