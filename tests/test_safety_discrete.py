"""The barrier's bound written once, and the discrete-time condition's promise at every step.

``h_dot >= -min(gamma h^3, h / dt)`` for ``h > 0`` keeps every pair and obstacle clearance of
single integrators at every explicit Euler step and along it (docs/safety.md, "Discrete-time
safety of an Euler step"); the paper's ``h_dot >= -gamma h^3`` lets a far pair jump past.
"""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from formationlab.errors import ParameterError
from formationlab.safety import (
    Circle,
    Polygon,
    SafetyFilter,
    barrier_bound,
    barrier_bounds,
    obstacle_barrier_rows,
    swept_clearances,
)

OBSTACLES = (
    Circle(center=[0.0, 0.0], radius=0.4),
    Polygon(vertices=[[1.0, 1.0], [2.0, 1.0], [2.0, 2.0], [1.6, 1.3]]),
)
D_S, D_O = 0.3, 0.15


def test_the_bound_against_hand_derived_values():
    # dt gamma h^2 = 1e-3 * 100 * 4 = 0.4 <= 1: the paper's gamma h^3 = 800
    assert barrier_bound(2.0, 100.0, 1e-3) == 800.0
    # dt gamma h^2 = 2.5 > 1: capped at h / dt = 5000 (gamma h^3 would be 12,500)
    assert barrier_bound(5.0, 100.0, 1e-3) == 5000.0
    assert barrier_bound(5.0, 100.0, 0.0) == 12500.0  # the continuous condition
    # h <= 0 keeps gamma h^3 (rows of a pair inside the distance ask h to grow)
    assert barrier_bound(-0.5, 1e6, 0.02) == -125000.0
    assert barrier_bound(0.0, 100.0, 1e-3) == 0.0
    h = np.array([2.0, 5.0, -0.5, 0.0, 4.0])
    np.testing.assert_array_equal(barrier_bounds(h, 100.0, 1e-3), [800, 5000, -12.5, 0, 4000])
    np.testing.assert_array_equal(barrier_bounds(h, 100.0, 0.0), [800, 12500, -12.5, 0, 6400])


def test_condition_is_validated_and_takes_the_step():
    with pytest.raises(ParameterError, match=r"safety\.condition must be one of") as err:
        SafetyFilter(filter="barrier", condition="exact")  # type: ignore[arg-type]
    assert err.value.key == "condition"
    with pytest.raises(ParameterError, match="step"):
        SafetyFilter(filter="barrier", step=-1.0)
    f = SafetyFilter(filter="barrier")
    assert f.condition == "discrete" and f.rows_step == 0.0  # no step known: continuous rows
    assert f.at_step(1e-3).rows_step == 1e-3
    assert f.at_step(1e-3).at_step(None).rows_step == 0.0
    assert SafetyFilter(filter="barrier", condition="continuous").at_step(1e-3).rows_step == 0.0


def _pairs_clear_along(q0, q1):
    """Least pair distance along the straight step ``q0 -> q1`` (every pair moves linearly)."""
    i, j = np.triu_indices(len(q0), 1)
    w0, dw = q0[i] - q0[j], (q1[i] - q1[j]) - (q0[i] - q0[j])
    s = np.clip(-np.sum(w0 * dw, -1) / np.maximum(np.sum(dw * dw, -1), 1e-300), 0.0, 1.0)
    return float(np.min(np.linalg.norm(w0 + s[:, None] * dw, axis=-1)))


@pytest.mark.parametrize("kind", ["barrier", "barrier-decentralized"])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(
    data=st.data(),
    n=st.integers(2, 5),
    log_gamma=st.floats(0.0, 7.0),
    dt=st.sampled_from([1e-4, 1e-3, 1e-2, 0.1]),
    log_speed=st.floats(-1.0, 5.0),
)
def test_a_filtered_euler_step_from_a_clear_state_stays_clear(kind, data, n, log_gamma, dt,
                                                              log_speed):  # fmt: skip
    """From any state with every pair >= D_s and every robot >= D_o from the obstacles, one
    explicit Euler step of the filtered command keeps both, at its end and along it."""
    flat = data.draw(st.lists(st.floats(-4.0, 4.0), min_size=2 * n, max_size=2 * n))
    q = np.array(flat).reshape(n, 2)
    dirs = np.array(data.draw(st.lists(st.floats(-1.0, 1.0), min_size=2 * n, max_size=2 * n)))
    u_hat = 10.0**log_speed * dirs.reshape(n, 2)
    assume(_pairs_clear_along(q, q) >= D_S)
    assume(np.all(obstacle_barrier_rows(q, OBSTACLES, distance=D_O, gamma=1.0).h >= 0))
    cfg = SafetyFilter(filter=kind, distance=D_S, gamma=10.0**log_gamma).at_step(dt)
    u = cfg.command(q, u_hat, obstacles=OBSTACLES)
    q1 = q + dt * u
    tol = 1e-6 * (1.0 + dt * np.abs(u_hat).max())  # rounding of the rows held with equality
    assert _pairs_clear_along(q, q1) >= D_S - tol
    swept = swept_clearances(q, q1, np.full(n, D_O), OBSTACLES)
    assert swept.min() >= -tol


@pytest.mark.parametrize("kind", ["barrier", "barrier-decentralized"])
def test_the_continuous_condition_lets_a_far_pair_jump_past(kind):
    """Two robots 5 m apart, commanded at each other at 1e4 m/s, dt = 1e-3, gamma = 100:
    ``dt gamma h^2 = 62 > 1``. The paper's row allows the command (``gamma h^3 = 1.5e6``
    against the approach rate ``2 r |u_i - u_j| = 2e5``), and the step carries each robot
    10 m, through the other; the discrete row caps the approach at ``h / dt``: robot 1's
    speed becomes ``(25 - 0.09) / (dt 2 r 2) = 1245.5`` m/s, and the pair ends 2.509 m apart."""
    q = np.array([[0.0, 0.0], [5.0, 0.0]])
    u_hat = np.array([[1e4, 0.0], [-1e4, 0.0]])
    dt = 1e-3
    old = SafetyFilter(filter=kind, distance=D_S, condition="continuous").at_step(dt)
    u = old.command(q, u_hat)
    np.testing.assert_array_equal(u, u_hat)
    assert _pairs_clear_along(q, q + dt * u) == 0.0  # they pass through each other
    new = SafetyFilter(filter=kind, distance=D_S).at_step(dt)
    u = new.command(q, u_hat)
    np.testing.assert_allclose(u, [[1245.5, 0.0], [-1245.5, 0.0]], rtol=1e-12)
    assert _pairs_clear_along(q, q + dt * u) == pytest.approx(2.509, abs=1e-12)
    # and where dt gamma h^2 <= 1 both conditions build the same rows, bit for bit
    near = np.array([[0.0, 0.0], [0.5, 0.0]])
    slow = np.array([[3.0, 0.0], [-3.0, 0.0]])
    np.testing.assert_array_equal(old.command(near, slow), new.command(near, slow))


def test_triangle_with_obstacles_has_no_first_step_collision_from_a_clear_start():
    """docs/safety.md's study of the triangle with a disc and a triangle, 300 starts per law
    (seed 1) for its first 10 steps: under the continuous condition some trials that start
    with every pair >= D_s and every robot >= D_o from the obstacles collide in the first
    steps (Khatib's repulsion throws a robot through something); under the discrete one none
    does (the trials that still collide started inside D_o or D_s)."""
    import dataclasses
    import warnings

    from formationlab.io.scenario import load_scenario
    from formationlab.safety import clearances
    from formationlab.studies.config import parse_study
    from formationlab.studies.runner import StudySetup, run_study

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = load_scenario("examples/triangle-obstacle.toml")
    clear_collisions = {}
    for condition in ("continuous", "discrete"):
        safety = dataclasses.replace(sc.safety, condition=condition)
        s2 = dataclasses.replace(sc, safety=safety)
        config = parse_study(s2.study, trials=300, duration=0.01, chunk_size=300)
        df = run_study(StudySetup.from_scenario(s2, config), seed=1).trials
        count = 0
        for _, r in df[df.outcome == "collision"].iterrows():
            q0 = np.array([[r[f"x{i}_init"], r[f"y{i}_init"]] for i in (1, 2, 3)])
            radii = np.asarray(sc.formation.diameters, dtype=float) / 2
            inside_o = clearances(q0, radii, sc.obstacles)[0].min() < safety.d_obstacle - radii[0]
            inside_s = _pairs_clear_along(q0, q0) < safety.distance
            count += not (inside_o or inside_s)
        clear_collisions[condition] = count
    assert clear_collisions["continuous"] > 0
    assert clear_collisions["discrete"] == 0
