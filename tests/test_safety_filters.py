"""Barrier-certificate filters: KKT conditions, exactness, the decentralized kernel against
Clarabel, hand-derived values, batching, statuses and configuration errors."""

import re

import numpy as np
import pytest
import scipy.sparse as sp

from formationlab.errors import ParameterError
from formationlab.formation.spec import Formation
from formationlab.safety import (
    Circle,
    FilterStatus,
    Polygon,
    SafetyFilter,
    barrier_constraints,
    decentralized_reference,
    project_onto_halfplanes,
    sensed_pairs,
    solve_barrier_qp,
)
from formationlab.safety.pairs import _dense_pairs

OBSTACLES = (
    Circle(center=[0.0, 0.0], radius=0.3),
    Polygon(vertices=[[1.0, 1.0], [2.0, 1.0], [2.0, 2.0], [1.6, 1.3]]),
)


def _random_case(rng, n=8, width=2.0, obstacles=OBSTACLES, d_o=0.1):
    """Positions outside every obstacle's safety distance, and pushy commands."""
    from formationlab.safety import obstacle_barrier_rows

    while True:
        q = rng.uniform(-width, width, (n, 2))
        rows = obstacle_barrier_rows(q, obstacles, distance=d_o, gamma=1.0)
        d = np.linalg.norm(q[:, None] - q[None], axis=-1) + 10 * np.eye(n)
        if np.all(rows.h > 0) and d.min() > 0.5:
            return q, 3.0 * rng.normal(size=(n, 2))


def test_hand_derived_two_robot_value():
    """Two robots 1 apart pushed together: u_1x = -u_2x = gamma h^3 / 4 with h = 1 - D_s^2."""
    q = np.array([[0.0, 0.0], [1.0, 0.0]])
    u_hat = np.array([[1.0, 0.0], [-1.0, 0.0]])
    h = 1.0 - 0.5**2
    expected = np.array([[h**3 / 4, 0.0], [-(h**3) / 4, 0.0]])  # 0.10546875
    for kind in ("barrier", "barrier-decentralized"):
        res = SafetyFilter(filter=kind, distance=0.5, gamma=1.0).apply(q, u_hat)
        np.testing.assert_allclose(res.u, expected, atol=1e-9)
        assert res.status == FilterStatus.SOLVED
        assert res.active.tolist() == [True, True]
        assert res.active_pairs.tolist() == [[0, 0, 1]]


@pytest.mark.parametrize("seed", range(6))
def test_centralized_solution_satisfies_kkt(seed):
    rng = np.random.default_rng(seed)
    cfg = SafetyFilter(filter="barrier", distance=0.5, gamma=0.5, max_speed=2.5)
    q, u_hat = _random_case(rng, obstacles=OBSTACLES, d_o=cfg.d_obstacle)
    c = barrier_constraints(cfg, q, OBSTACLES)
    sol = solve_barrier_qp(c, u_hat)
    assert sol.status == FilterStatus.SOLVED
    x, z = sol.u.reshape(-1), sol.multipliers
    slack = c.bound - c.G @ x
    scale = 1.0 + np.abs(u_hat).max()
    # stationarity of 1/2 |x - u_hat|^2 + z'(G x - bound)
    np.testing.assert_allclose(x - u_hat.reshape(-1) + c.G.T @ z, 0.0, atol=1e-7 * scale)
    assert np.all(slack >= -1e-8 * (1 + np.abs(c.bound)))  # primal feasibility
    assert np.all(z >= 0)  # dual feasibility
    np.testing.assert_allclose(z * slack, 0.0, atol=1e-7 * scale)  # complementarity
    assert np.count_nonzero(z > 1e-6) >= 2  # the case is not trivial


@pytest.mark.parametrize("seed", range(4))
def test_decentralized_kernel_equals_clarabel_reference(seed):
    rng = np.random.default_rng(100 + seed)
    cfg = SafetyFilter(
        filter="barrier-decentralized", distance=0.5, gamma=0.5, max_speed=2.5, sensing_radius=1.5
    )
    cases = [_random_case(rng, obstacles=OBSTACLES, d_o=cfg.d_obstacle) for _ in range(12)]
    q = np.stack([c[0] for c in cases])
    u_hat = np.stack([c[1] for c in cases])
    res = cfg.apply(q, u_hat, obstacles=OBSTACLES)
    ref, codes = decentralized_reference(cfg, q, u_hat, OBSTACLES)
    np.testing.assert_allclose(res.u, ref, atol=1e-8)
    np.testing.assert_array_equal(res.status, codes.max(axis=-1))
    assert np.count_nonzero(codes == 1) > 10


def test_decentralized_relaxation_equals_reference():
    """Robots already inside D_s with a speed limit: infeasible, relaxed to h_dot >= 0."""
    cfg = SafetyFilter(filter="barrier-decentralized", distance=0.5, gamma=100.0, max_speed=1.0)
    q = np.array([[0.0, 0.0], [0.1, 0.0], [3.0, 3.0]])
    u_hat = np.array([[1.0, 0.2], [-1.0, 0.0], [0.5, 0.5]])
    res = cfg.apply(q, u_hat)
    ref, codes = decentralized_reference(cfg, q, u_hat)
    assert codes.tolist() == [2, 2, 0]
    assert res.status == FilterStatus.RELAXED
    np.testing.assert_allclose(res.u, ref, atol=1e-8)
    # relaxed rows "get no closer": the x components no longer approach
    assert res.u[0, 0] <= 1e-12 and res.u[1, 0] >= -1e-12
    assert res.u[2].tobytes() == u_hat[2].tobytes()


def test_centralized_relaxes_when_infeasible():
    cfg = SafetyFilter(filter="barrier", distance=0.5, gamma=100.0, max_speed=1.0)
    q = np.array([[0.0, 0.0], [0.1, 0.0]])
    u_hat = np.array([[1.0, 0.2], [-1.0, 0.0]])
    res = cfg.apply(q, u_hat)
    assert res.status == FilterStatus.RELAXED and not res.ok
    assert "relaxed" in res.message
    assert res.u[1, 0] - res.u[0, 0] >= -1e-9  # h_dot = 2 (q_1 - q_2).(u_1 - u_2) >= 0
    assert np.all(np.linalg.norm(res.u, axis=-1) <= 1.0 + 1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_projection_by_enumeration_equals_clarabel(seed):
    import qpsolvers

    rng = np.random.default_rng(seed)
    for _ in range(60):
        m = int(rng.integers(1, 12))
        A = rng.normal(size=(m, 2))
        b = rng.uniform(0.0, 1.0, m)  # the origin is feasible
        if rng.random() < 0.3:  # degenerate: three lines through one point
            p = rng.normal(size=2)
            A = np.vstack([A, rng.normal(size=(3, 2))])
            b = np.concatenate([b, A[-3:] @ p + [0.0, 0.0, 0.0]])
            b = np.maximum(b, A @ np.zeros(2))
        u_hat = 4.0 * rng.normal(size=2)
        u, code = project_onto_halfplanes(u_hat, A, b)
        x = qpsolvers.solve_qp(
            sp.identity(2, format="csc"), -u_hat, sp.csc_matrix(A), b, solver="clarabel",
            tol_feas=1e-11, tol_gap_abs=1e-11, tol_gap_rel=1e-11,
        )  # fmt: skip
        np.testing.assert_allclose(u, x, atol=1e-7)
        assert code == (0 if np.all(A @ u_hat <= b) else 1)


def test_inactive_filter_returns_command_bit_for_bit(rng):
    q = 10.0 * np.arange(12, dtype=float).reshape(6, 2)  # far apart
    u_hat = rng.normal(size=(3, 6, 2)) * np.pi
    qb = np.broadcast_to(q, u_hat.shape)
    for kind in ("none", "barrier", "barrier-decentralized"):
        res = SafetyFilter(filter=kind, distance=0.5, max_speed=100.0).apply(qb, u_hat)
        assert res.u.tobytes() == u_hat.tobytes(), kind
        assert np.all(res.status == FilterStatus.UNCHANGED) and not res.active.any()


def test_robots_away_from_the_action_keep_their_command_bit_for_bit(rng):
    """Centralized: components of the sensing graph without a violation are not touched."""
    q = np.array([[0.0, 0.0], [1.0, 0.0], [20.0, 0.0], [21.0, 0.0], [40.0, 0.0]])
    u_hat = np.array([[1.0, 0.3], [-1.0, 0.1], [-0.7, 0.0], [0.0, 0.2], [5.0, 5.0]]) * np.e
    for kind in ("barrier", "barrier-decentralized"):
        cfg = SafetyFilter(filter=kind, distance=0.5, gamma=1.0, sensing_radius=3.0)
        res = cfg.apply(q, u_hat)
        assert not np.allclose(res.u[:2], u_hat[:2])
        assert res.u[2:].tobytes() == u_hat[2:].tobytes(), kind


def test_decentralized_command_is_feasible_for_the_centralized_qp(rng):
    cfg = SafetyFilter(filter="barrier-decentralized", distance=0.5, gamma=0.5, max_speed=2.5)
    for _ in range(10):
        q, u_hat = _random_case(rng, obstacles=OBSTACLES, d_o=cfg.d_obstacle)
        u = cfg.apply(q, u_hat, obstacles=OBSTACLES).u
        c = barrier_constraints(cfg, q, OBSTACLES)
        assert np.all(c.G @ u.reshape(-1) <= c.bound + 1e-9 * (1 + np.abs(c.bound)))


def test_batched_call_equals_one_by_one(rng):
    cases = [_random_case(rng) for _ in range(5)]
    q = np.stack([c[0] for c in cases])
    u_hat = np.stack([c[1] for c in cases])
    for kind in ("barrier", "barrier-decentralized"):
        cfg = SafetyFilter(filter=kind, distance=0.5, gamma=0.5, max_speed=2.5)
        batch = cfg.apply(q, u_hat, obstacles=OBSTACLES)
        for t in range(len(q)):
            one = cfg.apply(q[t], u_hat[t], obstacles=OBSTACLES)
            np.testing.assert_allclose(batch.u[t], one.u, atol=1e-12, rtol=0)
            assert batch.status[t] == one.status


def test_speed_limit_is_the_inscribed_polygon(rng):
    cfg = SafetyFilter(filter="barrier-decentralized", distance=0.5, max_speed=0.7)
    normals, bound = cfg.speed_polygon()
    assert normals.shape == (8, 2) and bound == pytest.approx(0.7 * np.cos(np.pi / 8))
    q = 10.0 * rng.normal(size=(50, 2))
    u_hat = 5.0 * rng.normal(size=(50, 2))
    for kind in ("barrier", "barrier-decentralized"):
        u = SafetyFilter(filter=kind, distance=0.5, max_speed=0.7).apply(q, u_hat).u
        assert np.all(np.linalg.norm(u, axis=-1) <= 0.7 + 1e-9)
        # the polygon's vertices lie on the disc: some commands reach the full speed
        assert np.linalg.norm(u, axis=-1).max() > 0.7 * np.cos(np.pi / 8)


def test_kd_tree_pairs_equal_dense_pairs(rng):
    q = rng.uniform(0, 10, (2, 300, 2))
    kd = sensed_pairs(q, 0.9)
    dense = _dense_pairs(q, 0.9)
    np.testing.assert_array_equal(kd, dense)
    assert len(kd) > 100


def test_configuration_errors():
    with pytest.raises(ParameterError, match="gamma must be >= 0 \\(the barrier gain"):
        SafetyFilter(filter="barrier", gamma=-1.0)
    with pytest.raises(ParameterError, match='one of "none", "barrier"'):
        SafetyFilter(filter="cbf")  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="distance must be a finite number > 0"):
        SafetyFilter(distance=0.0)
    with pytest.raises(ParameterError, match="sensing_radius"):
        SafetyFilter(distance=0.5, sensing_radius=0.4)
    with pytest.raises(ParameterError, match="max_speed"):
        SafetyFilter(max_speed=float("nan"))
    f = Formation.from_distances(3, diameters=[0.2, 0.2, 0.4])
    with pytest.raises(ParameterError, match=r"a_13 = 0.3 of robots 1 and 3; use distance >= 0.3"):
        SafetyFilter(filter="barrier", distance=0.25).check_contact(f.contact_matrix)
    with pytest.raises(ParameterError, match=r"radius 0.2 of robot 3"):
        SafetyFilter(distance=0.35).check_contact(f.contact_matrix)
    SafetyFilter(distance=0.4).check_contact(f.contact_matrix)
    with pytest.raises(ParameterError, match="below the contact distance"):
        SafetyFilter(filter="barrier", distance=0.25).apply(
            np.zeros((3, 2)), np.zeros((3, 2)), contact=f.contact_matrix
        )
    with pytest.raises(ParameterError, match=r"shape \(\.\.\., n, d\) with d = 2 or 3"):
        SafetyFilter(filter="barrier").apply(np.zeros((3, 2)), np.zeros((2, 2)))


@pytest.mark.parametrize("seed", range(6))
def test_the_diameters_check_names_the_pair_of_the_largest_contact_distance(seed):
    """``check_diameters`` (O(n): no n x n contact matrix for a swarm) refuses exactly when
    the largest ``a_ij`` exceeds ``D_s`` and names the first such pair of the matrix."""
    rng = np.random.default_rng(seed)
    rho = rng.choice([0.1, 0.2, 0.3], size=7)  # ties on purpose
    a = 0.5 * (rho[:, None] + rho[None, :]) - np.diag(np.full(7, np.inf))
    i, j = np.unravel_index(np.argmax(a), a.shape)  # the first largest, row by row
    words = f"a_{i + 1}{j + 1} = {a[i, j]:g} of robots {i + 1} and {j + 1}"
    cfg = SafetyFilter(filter="barrier", distance=a[i, j] - 1e-3, obstacle_distance=1.0)
    for check in (cfg.check_diameters, lambda d: cfg.check_contact(0.5 * (d[:, None] + d))):
        with pytest.raises(ParameterError, match=re.escape(words)):
            check(rho)
    SafetyFilter(filter="barrier", distance=a[i, j], obstacle_distance=1.0).check_diameters(rho)
