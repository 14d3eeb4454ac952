"""The centralized barrier QP in closed form for one or two active rows (safety/closed_form.py).

Checked against the KKT conditions of the QP (stationarity ``u - u_hat + G' lambda = 0``,
``lambda >= 0``, feasibility, complementary slackness), against Clarabel's solution of
the same QP, and for completeness: whenever it declines, the QP's solution has more than
two active rows.
"""

import numpy as np
import pytest

from formationlab.safety import (
    Circle,
    Polygon,
    SafetyFilter,
    barrier_constraints,
    barrier_filter,
    solve_barrier_qp,
)
from formationlab.safety.barrier import PAIR
from formationlab.safety.closed_form import closed_form

OBSTACLES = (
    Circle(center=[0.0, 0.0], radius=0.25),
    Polygon(vertices=[[0.6, 0.5], [1.1, 0.6], [0.8, 1.0]]),
)


def _rows(c):
    ri = np.ascontiguousarray(c.index[:, 0])
    rj = np.where(c.kind == PAIR, c.index[:, 1], -1).astype(np.int64)
    return ri, rj, np.ascontiguousarray(c.coef), np.ascontiguousarray(c.bound)


def _case(seed):
    rng = np.random.default_rng(seed)
    cfg = SafetyFilter(
        filter="barrier", distance=0.3, gamma=float(rng.choice([0.5, 5.0, 100.0])),
        max_speed=None if seed % 3 else 1.5,
    )  # fmt: skip
    while True:
        q = rng.uniform(-1.2, 1.2, (6, 2))
        d = np.linalg.norm(q[:, None] - q[None], axis=-1) + 9 * np.eye(6)
        clear = min(ob.signed_distance(q)[0].min() for ob in OBSTACLES)
        if d.min() > 0.32 and clear > 0.17:
            break
    u_hat = rng.normal(0.0, float(rng.choice([0.1, 0.5, 2.0])), (6, 2))
    return cfg, q, u_hat


def test_hand_derived_single_row():
    # robots 0.5 apart on the x-axis driving into each other at 1 m/s each:
    # h = 0.25 - 0.09 = 0.16, row -2 (q1 - q2) . (u1 - u2) <= gamma h^3 with q1 - q2 = (-0.5, 0)
    # reads (u1 - u2)_x <= gamma h^3; lambda = (2 - gamma h^3) / |g|^2, |g|^2 = 2 * 1^2
    cfg = SafetyFilter(filter="barrier", distance=0.3, gamma=1.0)
    q = np.array([[-0.25, 0.0], [0.25, 0.0]])
    u_hat = np.array([[1.0, 0.0], [-1.0, 0.0]])
    c = barrier_constraints(cfg, q)
    out, lam = np.empty((2, 2)), np.empty(len(c.bound))
    assert closed_form(*_rows(c), u_hat, out, lam) == 1
    bound = 0.16**3
    np.testing.assert_allclose(out, [[bound / 2, 0.0], [-bound / 2, 0.0]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(lam, [(2.0 - bound) / 2.0], rtol=1e-14)


def test_feasible_command_is_returned_bit_for_bit():
    _, q, _ = _case(1)
    c = barrier_constraints(SafetyFilter(filter="barrier", distance=0.3), q, OBSTACLES)
    u_hat = 1e-6 * np.arange(12.0).reshape(6, 2)  # slow: every row holds (h >= 0.002 here)
    assert c.barrier.min() > 0.002
    out, lam = np.empty((6, 2)), np.empty(len(c.bound))
    assert closed_form(*_rows(c), u_hat, out, lam) == 0
    assert out.tobytes() == u_hat.tobytes()


def test_closed_form_is_the_qp_solution_and_complete():
    solved = declined = 0
    for seed in range(120):
        cfg, q, u_hat = _case(seed)
        c = barrier_constraints(cfg, q, OBSTACLES)
        ri, rj, ra, rb = _rows(c)
        out, lam = np.empty_like(u_hat), np.empty(len(rb))
        code = closed_form(ri, rj, ra, rb, u_hat, out, lam)
        qp = solve_barrier_qp(c, u_hat)
        if code == 0:
            assert qp.status == 0
            continue
        x = out.reshape(-1)
        scale = np.abs(c.bound) + abs(c.G) @ (np.abs(x) + np.abs(u_hat).reshape(-1))
        if code == 1:
            solved += 1
            # KKT: stationarity, dual feasibility, primal feasibility, complementary slackness
            np.testing.assert_allclose(x - u_hat.reshape(-1) + c.G.T @ lam, 0.0, atol=1e-12)
            assert np.all(lam >= 0) and 1 <= np.count_nonzero(lam) <= 2
            slack = c.bound - c.G @ x
            assert np.all(slack >= -1e-10 * scale)
            assert np.all(np.abs(slack[lam > 0]) <= 1e-10 * scale[lam > 0])
            np.testing.assert_allclose(out, qp.u, rtol=0, atol=1e-7)  # Clarabel to 1e-10
        else:
            declined += 1
            # the QP's solution needs more than two active rows with positive multipliers
            assert qp.status == 1
            assert np.count_nonzero(qp.multipliers > 1e-6 * qp.multipliers.max()) >= 3
    assert solved >= 30 and declined >= 5, (solved, declined)


@pytest.mark.parametrize("seed", range(4))
def test_barrier_filter_skips_the_solver_for_one_or_two_rows(seed, monkeypatch):
    """barrier_filter's answer with the closed form equals Clarabel's on the same rows."""
    import formationlab.safety.barrier as barrier

    cfg, q, u_hat = _case(seed)
    rng = np.random.default_rng(seed)
    qs = q[None] + rng.normal(0.0, 0.05, (30, 6, 2))
    us = u_hat[None] * rng.uniform(0.05, 1.0, (30, 1, 1))
    qs = qs[[np.linalg.norm(x[:, None] - x[None], axis=-1)[np.triu_indices(6, 1)].min() > 0.3
             and min(ob.signed_distance(x)[0].min() for ob in OBSTACLES) > 0.15
             for x in qs]]  # fmt: skip
    us = us[: len(qs)]
    calls = []
    real = barrier._solve
    monkeypatch.setattr(barrier, "_solve", lambda *a: calls.append(1) or real(*a))
    fast = barrier_filter(cfg, qs, us, OBSTACLES)
    fast_calls = len(calls)
    monkeypatch.setattr(barrier, "closed_form", lambda *a: -1)  # always the solver
    slow = barrier_filter(cfg, qs, us, OBSTACLES)
    # Clarabel (tolerances 1e-10) is accurate to about 1e-7 on these commands (measured
    # 1.4e-7); the closed form is exact (test_closed_form_is_the_qp_solution_and_complete)
    np.testing.assert_allclose(fast.u, slow.u, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(fast.status, slow.status)
    assert fast_calls < len(calls) - fast_calls  # the closed form took some trials
