"""Relative equilibria: shapes that the closed loop moves as a rigid body.

The finder (``refine(..., moving=True)``) is held against simulations: implicit
Euler keeps a translating Filippov relative equilibrium exactly (a translate of
it solves the implicit step, the field being translation invariant), so a
drifting hexagon settled by implicit Euler must be the finder's shape and
velocity to 1e-6; explicit Euler's chattering drift converges to the finder's
velocity at first order in dt. A static equilibrium is the case v = 0, omega = 0.
"""

import numpy as np
import pytest

import formationlab as fl
from formationlab.equilibria.catalogue import catalogue
from formationlab.equilibria.classify import classify_equilibrium
from formationlab.equilibria.dedup import canonical_pose, same_equilibrium
from formationlab.equilibria.refine import refine
from formationlab.equilibria.search import settle
from formationlab.integrators import ImplicitEuler
from formationlab.io.scenario import load_scenario
from formationlab.studies.batch import run_batch
from formationlab.studies.config import BoxInitial
from formationlab.studies.sampling import trial_initial_states


def _body(q, v):
    """``v`` in the frame of ``q`` turned so that robot 1 -> robot 2 points along +x."""
    d = q[1] - q[0]
    c, s = d / np.hypot(*d)
    return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1]])


@pytest.fixture(scope="module")
def hexagon_drift():
    """The first drifting trial of the hexagon study (box 3, seed 3), after 20 s of Euler."""
    sc = load_scenario("examples/hexagon.toml")
    q0 = trial_initial_states(sc.formation, BoxInitial(half_width=3.0), 3, np.arange(12))
    res = run_batch(sc.formation, sc.law, q0, dt=1e-3, duration=20.0)
    k = int(np.flatnonzero(res.outcome == "drifting")[0])
    return sc, res.q_final[k], res.motion[k]


@pytest.mark.slow
def test_finder_recovers_the_drifting_hexagon_of_a_simulation(hexagon_drift):
    sc, q_end, _ = hexagon_drift
    f, law = sc.formation, sc.law
    found = refine(f, law, q_end, moving=True)
    assert found.success and found.filippov and found.residual < 1e-12
    # the simulation: implicit Euler slides on the surfaces and keeps the drift exactly
    settled = settle(f, law, q_end[None], duration=20.0, integrator=ImplicitEuler(dt=0.01))
    assert settled.outcome[0] == "drifting"
    q_sim, m = settled.q_final[0], settled.motion[0]
    assert m.shape_rate < 1e-9
    assert same_equilibrium(f, found.q, q_sim, tol=1e-6)
    np.testing.assert_allclose(canonical_pose(found.q), canonical_pose(q_sim), atol=1e-6)
    np.testing.assert_allclose(_body(found.q, found.velocity), _body(q_sim, m.velocity), atol=1e-6)
    assert abs(found.omega) < 1e-9 and abs(m.omega) < 1e-9
    # the field at the found shape is the rigid motion, robot by robot
    u = law.control_with(f, found.q, found.weights)
    np.testing.assert_allclose(u, np.broadcast_to(found.velocity, u.shape), atol=1e-12)
    eq = classify_equilibrium(f, law, found)
    assert eq.outcome == "drifting" and eq.moving and eq.unstable_directions == 0
    assert eq.speed == pytest.approx(float(np.hypot(*found.velocity)))


def test_explicit_euler_drift_converges_to_the_finder_at_first_order(hexagon_drift):
    sc, q_end, _ = hexagon_drift
    found = refine(sc.formation, sc.law, q_end, moving=True)
    target = float(np.hypot(*found.velocity))
    errors = []
    for dt in (1e-3, 5e-4, 2.5e-4):
        r = run_batch(sc.formation, sc.law, q_end[None], dt=dt, duration=6.0)
        assert r.outcome[0] == "drifting"
        errors.append(abs(float(r.motion.speed[0]) - target))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 1.6) & (ratios < 2.6)), (errors, ratios)


def test_a_static_equilibrium_is_the_case_of_no_motion(rng):
    f = fl.Formation.from_template(
        [[1.0, 0.0], [0.5, 0.866], [-0.5, 0.866], [-1.0, 0.0], [-0.5, -0.866], [0.5, -0.866]],
        edges=[[1, 2], [2, 3], [3, 4], [4, 5], [5, 6], [6, 1], [1, 3], [1, 4], [1, 5]],
        orientation="template",
    )
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    start = f.template + 0.02 * rng.standard_normal((6, 2))
    static = refine(f, law, start)
    moving = refine(f, law, start, moving=True)
    assert static.success and moving.success
    assert np.abs(moving.velocity).max() < 1e-10 and abs(moving.omega) < 1e-10
    np.testing.assert_allclose(moving.q, static.q, atol=1e-9)
    eq = classify_equilibrium(f, law, moving)
    assert eq.outcome == "desired" and eq.stability == "stable" and not eq.moving
    # the distance law's collinear saddle of three robots, found as a moving shape
    tri = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
    line = np.array([[-0.8, 0.01], [0.02, 0.0], [0.75, -0.01]])
    a = refine(tri, fl.DistanceLaw(k_c=2.0), line)
    b = refine(tri, fl.DistanceLaw(k_c=2.0), line, moving=True)
    assert a.success and b.success and np.abs(b.velocity).max() < 1e-10 and abs(b.omega) < 1e-10
    np.testing.assert_allclose(b.q, a.q, atol=1e-9)


def test_catalogue_lists_moving_shapes_with_their_velocity(hexagon_drift):
    sc, q_end, motion = hexagon_drift
    f, law = sc.formation, sc.law
    # the raw end state and a copy of it turned and shifted:
    # one relative equilibrium, its velocity turned with its pose
    turn = np.array([[0.0, -1.0], [1.0, 0.0]])
    other = q_end @ turn.T + [5.0, -2.0]
    cat = catalogue(f, law, np.stack([q_end, other]), outcomes=np.array(["drifting"] * 2))
    assert len(cat.equilibria) == 1 and cat.counts == [2]
    eq = cat.equilibria[0]
    assert eq.outcome == "drifting"
    np.testing.assert_allclose(canonical_pose(eq.q), eq.q, atol=1e-12)  # posed
    found = refine(f, law, q_end, moving=True)
    np.testing.assert_allclose(eq.velocity, _body(found.q, found.velocity), atol=1e-9)
    row = cat.to_dict()["equilibria"][0]
    assert row["outcome"] == "drifting" and row["centre"] is None
    assert row["speed"] == pytest.approx(float(np.hypot(*found.velocity)), rel=1e-9)
    # the simulation's measured drift is the finder's to explicit Euler's O(dt) error
    assert float(motion.speed) == pytest.approx(row["speed"], rel=5e-2)


class _Spinning(fl.DistanceLaw):
    """The distance law plus a rigid rotation ``omega0 k x (q_i - q_bar)`` of every shape."""

    name = "spinning-for-test"
    omega0 = 0.7

    def control(self, formation, q):
        q = np.asarray(q, dtype=float)
        p = q - q.mean(axis=-2, keepdims=True)
        return super().control(formation, q) + self.omega0 * np.stack([-p[..., 1], p[..., 0]], -1)


def test_rotating_equilibrium_is_classified_in_the_co_moving_frame(rng):
    """The spinning law turns the distance law's triangle at omega0; in the co-moving frame
    its eigenvalues are the distance law's at rest (the added rotation's Jacobian is omega0 k x
    minus a map into translations), not shifted by +-i omega0."""
    f = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
    start = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.87]]) + 0.03 * rng.standard_normal((3, 2))
    spin = refine(f, _Spinning(k_c=2.0), start, moving=True)
    rest = refine(f, fl.DistanceLaw(k_c=2.0), start)
    assert spin.success and rest.success
    assert spin.omega == pytest.approx(0.7, abs=1e-10) and np.abs(spin.velocity).max() < 1e-10
    np.testing.assert_allclose(spin.q, rest.q, atol=1e-9)
    a = classify_equilibrium(f, _Spinning(k_c=2.0), spin)
    b = classify_equilibrium(f, fl.DistanceLaw(k_c=2.0), rest)
    np.testing.assert_allclose(a.eigenvalues, b.eigenvalues, atol=1e-6)
    assert np.all(a.eigenvalues.imag == 0) and a.stability == b.stability == "stable"
    assert a.centre is None and a.outcome == "desired"  # distances met: desired, turning or not
    # the collinear saddle of the distance law, turning: outcome rotating about its centroid
    line = np.array([[-0.8, 0.01], [0.02, 0.0], [0.75, -0.01]])
    turning = refine(f, _Spinning(k_c=2.0), line, moving=True)
    still = refine(f, fl.DistanceLaw(k_c=2.0), line)
    c = classify_equilibrium(f, _Spinning(k_c=2.0), turning)
    d = classify_equilibrium(f, fl.DistanceLaw(k_c=2.0), still)
    assert c.outcome == "rotating" and c.moving and d.outcome == "incorrect"
    np.testing.assert_allclose(c.centre, turning.q.mean(axis=0), atol=1e-9)
    np.testing.assert_allclose(c.eigenvalues, d.eigenvalues, atol=1e-6)
    assert c.stability == d.stability == "saddle" and c.unstable_directions == 1


def test_a_drifting_shape_is_followed_in_k_a(hexagon_drift):
    from formationlab.equilibria.continuation import follow

    sc, q_end, _ = hexagon_drift
    start = refine(sc.formation, sc.law, q_end, moving=True)
    branch = follow(sc.formation, sc.law, start.q, "k_a", [3.0, 3.2, 3.4], moving=True)
    assert branch.end == "end of range" and len(branch.equilibria) == 3
    assert all(e.outcome == "drifting" and e.residual < 1e-10 for e in branch.equilibria)
    assert branch.equilibria[0].speed == pytest.approx(float(np.hypot(*start.velocity)))
    # at each value the field is the drift: checked against the law built at that value
    for v, e in zip(branch.values, branch.equilibria, strict=True):
        lw = sc.law.with_params(k_a=float(v))
        u = lw.control_with(sc.formation, e.q, e.weights)
        np.testing.assert_allclose(u, np.broadcast_to(e.velocity, u.shape), atol=1e-9)
    speeds = [e.speed for e in branch.equilibria]
    assert speeds[0] != speeds[1] != speeds[2]
