"""Batches with obstacles and a safety filter on the compiled loop (safety/stage.py, engine/).

Held trial by trial against the numpy driver path (``run_batch(..., backend="numpy")``,
the stepping driver with ``System.rhs``): the same outcomes, statuses and step counts,
final states and least clearances to 1e-9.
"""

from pathlib import Path

import numpy as np
import pytest
from _exact_qp import exact_solve

import formationlab.safety as safety_pkg
from formationlab.controllers import AngleRestrictedLaw, DistanceLaw, SquaredDistanceLaw
from formationlab.dynamics import System
from formationlab.io.scenario import load_scenario
from formationlab.models import Unicycle
from formationlab.safety import Polygon, SafetyFilter, point_safety_distance
from formationlab.status import Status
from formationlab.studies.batch import batch_backend, run_batch
from formationlab.studies.config import BoxInitial
from formationlab.studies.sampling import trial_initial_states

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: the paper's triangle with its orientation table, a disc and a triangle
TRI = load_scenario(EXAMPLES / "triangle-obstacle.toml")
TRIANGLE, OBSTACLES = TRI.formation, TRI.obstacles


def _same(a, b):
    """Trial by trial equal batch results (outcomes, statuses, steps; numbers to 1e-9)."""
    assert list(a.outcome) == list(b.outcome)
    np.testing.assert_array_equal(a.status, b.status)
    np.testing.assert_array_equal(a.steps, b.steps)
    np.testing.assert_allclose(a.q_final, b.q_final, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.u_final, b.u_final, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.min_clearance, b.min_clearance, rtol=0, atol=1e-9)
    # its two parts, and the least distance of the filter's pairs with its verdict
    np.testing.assert_allclose(a.min_robot_clearance, b.min_robot_clearance, rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        a.min_obstacle_clearance, b.min_obstacle_clearance, rtol=0, atol=1e-9
    )
    np.testing.assert_allclose(a.min_pair_distance, b.min_pair_distance, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(a.below_safety_distance, b.below_safety_distance)
    np.testing.assert_array_equal(
        a.min_clearance, np.minimum(a.min_robot_clearance, a.min_obstacle_clearance)
    )


def _both(formation, law, q0, **kw):
    kw.setdefault("dt", 1e-3)
    a = run_batch(formation, law, q0, backend="numba", **kw)
    b = run_batch(formation, law, q0, backend="numpy", **kw)
    return a, b


@pytest.fixture(scope="module")
def starts():
    """16 random starts at least 0.1 off the obstacles (closer, Khatib's repulsion throws
    a robot metres away in one Euler step: docs/safety.md)."""
    q0 = trial_initial_states(
        TRIANGLE, BoxInitial(half_width=3.0), 3, np.arange(40), obstacles=OBSTACLES
    )
    clear = System(formation=TRIANGLE, law=DistanceLaw(), obstacles=OBSTACLES)
    far = clear.obstacle_clearances(q0).min(axis=(-2, -1)) > 0.1
    return q0[far][:16]


@pytest.mark.parametrize("kind", ["none", "barrier-decentralized", "barrier"])
@pytest.mark.parametrize("law", [SquaredDistanceLaw(), AngleRestrictedLaw(k_a=3.0, theta=0.5)])
def test_kernel_equals_driver_with_obstacles_and_filter(kind, law, starts):
    cfg = SafetyFilter(filter=kind, distance=0.3, gamma=100.0)
    a, b = _both(TRIANGLE, law, starts, duration=2.0, obstacles=OBSTACLES, safety=cfg)
    _same(a, b)
    assert len(set(a.outcome)) >= 2  # the starts end in several ways


def test_kernel_equals_driver_with_speed_limit_and_sensing_radius(starts, monkeypatch):
    cfg = SafetyFilter(filter="barrier-decentralized", distance=0.3, gamma=5.0, max_speed=0.6,
                       sensing_radius=1.5)  # fmt: skip
    a, b = _both(TRIANGLE, SquaredDistanceLaw(), starts, duration=1.0, obstacles=OBSTACLES,
                 safety=cfg)  # fmt: skip
    _same(a, b)
    cfg = SafetyFilter(filter="barrier", distance=0.3, gamma=5.0, max_speed=0.6)
    # a robot at the speed limit holds two sides of the polygon and often a pair row: the
    # kernel solves those QPs exactly, and so does the driver here (its Clarabel is 1e-7 off)
    monkeypatch.setattr(safety_pkg.barrier, "_solve", exact_solve)
    a, b = _both(TRIANGLE, SquaredDistanceLaw(), starts[:4], duration=1.0, safety=cfg)
    _same(a, b)


def test_contact_with_an_obstacle_ends_the_trial_as_in_the_driver():
    # robot 1 driven at a thin polygon by a strong squared-distance law: without a
    # filter the repulsion (influence 0.5) cannot stop a 1 ms Euler step of it
    wall = (Polygon(vertices=[[0.0, -3.0], [0.02, -3.0], [0.02, 3.0], [0.0, 3.0]]),)
    q0 = np.array([[[-0.6, 0.0], [2.5, 0.0], [2.5, 1.0]], [[-0.4, 0.5], [2.5, 0.0], [2.5, 1.0]]])
    law = SquaredDistanceLaw(k=60.0)
    a, b = _both(TRIANGLE, law, q0, duration=1.0, obstacles=wall)
    _same(a, b)
    assert {Status.from_code(c) for c in a.status} & {Status.COLLISION, Status.STEP_TOO_LARGE}


def test_three_active_rows_are_solved_in_the_kernel(monkeypatch):
    """The head-on deadlock holds three pair rows active: solved in the kernel, no pause."""
    sc = load_scenario(EXAMPLES / "head-on-deadlock.toml")
    rng = np.random.default_rng(2)
    q0 = sc.q0[None] + rng.normal(0.0, 1e-3, (2, *sc.q0.shape)) * [1.0, 0.0]
    calls = []
    real = safety_pkg.barrier_filter

    def counted(*args, **kw):
        calls.append(len(args[1]))
        return real(*args, **kw)

    monkeypatch.setattr(safety_pkg, "barrier_filter", counted)
    a = run_batch(sc.formation, sc.law, q0, dt=1e-3, duration=2.0, backend="numba",
                  obstacles=sc.obstacles, safety=sc.safety)  # fmt: skip
    assert calls == []  # no step left the kernel
    monkeypatch.setattr(safety_pkg, "barrier_filter", real)
    solves = []
    real_solve = safety_pkg.barrier._solve
    monkeypatch.setattr(safety_pkg.barrier, "_solve", lambda *x: solves.append(1) or real_solve(*x))
    b = run_batch(sc.formation, sc.law, q0, dt=1e-3, duration=2.0, backend="numpy",
                  obstacles=sc.obstacles, safety=sc.safety)  # fmt: skip
    assert len(solves) > 10  # the driver's Clarabel met three active rows that often
    _same(a, b)


@pytest.mark.parametrize("kind", ["barrier-decentralized", "barrier"])
def test_unicycles_on_the_compiled_path_equal_the_driver(kind, starts):
    model = Unicycle(offset=0.05)
    cfg = SafetyFilter(filter=kind, distance=point_safety_distance(0.3, 0.05), gamma=100.0)
    rng = np.random.default_rng(5)
    x0 = np.concatenate([starts[:10], rng.uniform(-np.pi, np.pi, (10, 3, 1))], axis=-1)
    a, b = _both(TRIANGLE, DistanceLaw(), x0, duration=2.0, obstacles=OBSTACLES, safety=cfg,
                 model=model)  # fmt: skip
    _same(a, b)


def test_backend_stays_compiled_with_obstacles_and_filter():
    cfg = SafetyFilter(filter="barrier", distance=0.3)
    assert batch_backend("numba", OBSTACLES, cfg) == ("numba", "")
    assert batch_backend("numba", OBSTACLES, cfg, sensed=True) == ("numba", "")
