"""The integrators away from the switching surfaces, their diagnostics, and their contract.

Sliding behaviour is in ``test_sliding.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

import formationlab as fl
from formationlab.errors import ParameterError
from formationlab.integrators import (
    INTEGRATORS,
    Filippov,
    ImplicitEuler,
    get_integrator,
    switching_diagnostics,
)

LAW = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)  # section 4
SIM1 = fl.Formation.from_alpha_table(
    {(1, 2, 3): -1, (3, 1, 2): -1, (2, 1, 3): 1}, n=3, distances=1.0, diameters=0.2
)
PAPER_Q0 = np.array([[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]])


def test_registry_names():
    assert {"euler", "rk4", "implicit-euler", "filippov"} <= set(INTEGRATORS)
    assert isinstance(get_integrator("implicit-euler", dt=0.01), ImplicitEuler)
    assert isinstance(get_integrator("filippov", rtol=1e-8), Filippov)


@pytest.mark.parametrize(
    ("cls", "params"),
    [
        (ImplicitEuler, {"dt": -1.0}),
        (ImplicitEuler, {"dt": 0.01, "tol": 0.0}),
        (ImplicitEuler, {"dt": 0.01, "max_surfaces": 0}),
        (Filippov, {"rtol": 0.0}),
        (Filippov, {"save_dt": float("nan")}),
        (Filippov, {"max_events": 0}),
        (Filippov, {"method": "euler"}),
    ],
)
def test_bad_parameters_are_refused(cls, params):
    with pytest.raises(ParameterError):
        cls(**params)


def test_implicit_euler_is_explicit_euler_away_from_the_surfaces():
    # simulation 1: sigma = -c_123 + 0.5 starts at -35.5 and stays far below 0
    system = fl.System(formation=SIM1, law=LAW)
    a = fl.Euler(dt=1e-2).run(system, PAPER_Q0, 2.0)
    b = ImplicitEuler(dt=1e-2).run(system, PAPER_Q0, 2.0)
    assert np.all(system.sigma(a.q) < -0.1)
    np.testing.assert_array_equal(a.q, b.q)  # bit for bit
    assert b.stats.get("corrected_steps", 0) == 0


def test_implicit_euler_batch_step_equals_one_by_one(rng):
    system = fl.System(formation=SIM1, law=LAW)
    # states around the surface sigma = 0 and far from it
    q = PAPER_Q0 * rng.uniform(0.05, 0.3, size=(6, 1, 1)) + rng.normal(0, 0.2, (6, 3, 2))
    integ = ImplicitEuler(dt=0.05)
    batch = integ.step(system, q, 0.05)
    for b in range(len(q)):
        np.testing.assert_array_equal(batch[b], integ.step(system, q[b], 0.05))


def smooth_reference(q0, duration):
    system = fl.System(formation=SIM1, law=LAW)
    return Filippov(rtol=1e-13, atol=1e-14).run(system, q0, duration).q[-1]


@pytest.mark.parametrize(("name", "order"), [("euler", 1), ("implicit-euler", 1), ("rk4", 4)])
def test_convergence_order_away_from_the_surfaces(name, order):
    # simulation 1 never meets its surface: the field is smooth along the run
    system = fl.System(formation=SIM1, law=LAW)
    duration = 0.4
    ref = smooth_reference(PAPER_Q0, duration)
    dts = np.array([0.04, 0.02, 0.01, 0.005])
    errors = [
        np.max(np.abs(get_integrator(name, dt=dt).run(system, PAPER_Q0, duration).q[-1] - ref))
        for dt in dts
    ]
    slope = np.polyfit(np.log(dts), np.log(errors), 1)[0]
    assert slope == pytest.approx(order, abs=0.15)


def test_filippov_error_within_its_tolerance():
    # adaptive (DOP853, order 8): the error is controlled by rtol, not by a step; on
    # this smooth stretch it stays below the requested tolerance (RK4 at dt = 2.5e-3
    # has error ~ 4e-13 by the fourth-order test above)
    system = fl.System(formation=SIM1, law=LAW)
    duration = 0.4
    ref = fl.RK4(dt=2.5e-3).run(system, PAPER_Q0, duration).q[-1]
    for rtol in (1e-5, 1e-7, 1e-9):
        sol = Filippov(rtol=rtol, atol=rtol * 1e-2).run(system, PAPER_Q0, duration)
        assert np.max(np.abs(sol.q[-1] - ref)) < rtol * np.max(np.abs(PAPER_Q0))


def test_smooth_law_has_no_switching_diagnostics():
    f = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
    law = fl.DistanceLaw(k_c=2.0)
    for integ in (fl.Euler(dt=0.01), fl.RK4(dt=0.01), ImplicitEuler(dt=0.01), Filippov()):
        res = fl.simulate(f, law, PAPER_Q0, duration=1.0, integrator=integ)
        d = res.summary()["diagnostics"]
        assert d["switch_count"] == 0
        assert d["sliding_time"] == 0
        assert d["max_excursion"] == 0
        assert d["step_cost_s"] > 0


def test_implicit_euler_equals_euler_for_a_smooth_law():
    f = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
    system = fl.System(formation=f, law=fl.DistanceLaw(k_c=2.0))
    a = fl.Euler(dt=0.01).run(system, PAPER_Q0, 1.0)
    b = ImplicitEuler(dt=0.01).run(system, PAPER_Q0, 1.0)
    np.testing.assert_array_equal(a.q, b.q)


# ------------------------------------------------------------------ diagnostics by hand


def test_diagnostics_of_one_transversal_crossing():
    t = np.arange(6) * 0.1
    sigma = np.array([-0.3, -0.2, -0.1, 0.05, 0.15, 0.25])[:, None]
    d = switching_diagnostics(t, sigma)
    assert d["switch_count"] == 1
    assert d["sliding_time"] == 0
    assert np.isnan(d["sliding_end"])


def test_diagnostics_of_chattering():
    # crosses at steps 3, 4, 6, 7: each time back before |sigma| exceeds twice the jump
    t = np.arange(9) * 0.1
    sigma = np.array([-0.3, -0.2, -0.1, 0.02, -0.01, -0.005, 0.02, -0.01, -0.2])[:, None]
    d = switching_diagnostics(t, sigma)
    assert d["switch_count"] == 4
    # chattering from the step before the first crossing (t = 0.2) to the last (t = 0.7)
    assert d["sliding_start"] == pytest.approx(0.2)
    assert d["sliding_end"] == pytest.approx(0.7)
    assert d["sliding_time"] == pytest.approx(0.5)
    assert d["max_excursion"] == pytest.approx(0.02)


def test_diagnostics_of_resting_on_two_surfaces():
    t = np.arange(5) * 0.5
    sigma = np.array(
        [[0.4, -1.0], [0.0, -1.0], [1e-13, 0.0], [-1e-13, 0.0], [-0.2, 0.0]]
    )  # surface 1 rests on [0.5, 1.5], surface 2 on [1.0, 2.0]
    d = switching_diagnostics(t, sigma)
    assert d["switch_count"] == 3  # 1: on -> surface -> off; 2: off -> surface
    assert d["sliding_time"] == pytest.approx(1.5)  # union of [0.5, 1.5] and [1.0, 2.0]
    assert d["max_excursion"] == pytest.approx(1e-13)


def test_sliding_figure_has_one_panel_per_run_with_its_diagnostics():
    from formationlab.plotting.integrators import sliding_figure

    q0 = np.array([[5.0, -2.0], [-1.5, 0.0], [1.5, 0.0]])  # slides (test_sliding.py)
    runs = {
        "explicit": fl.simulate(SIM1, LAW, q0, duration=0.3, integrator=fl.Euler(dt=1e-2)),
        "implicit": fl.simulate(SIM1, LAW, q0, duration=0.3, integrator=ImplicitEuler(dt=1e-2)),
    }
    fig = sliding_figure(runs, window=(0.0, 0.3), ylim=(-2.0, 0.6))
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 2
    for ax, res in zip(visible, runs.values(), strict=True):
        assert f"switches {res.stats['switch_count']:.0f}" in ax.get_title()
        assert ax.get_ylim() == (-2.0, 0.6)
        # the curve is sigma(t) itself
        np.testing.assert_allclose(ax.lines[0].get_ydata(), res.sigma[:, 0])


@pytest.mark.parametrize("max_surfaces", [6, 1])
def test_implicit_euler_vectorised_batch_equals_one_by_one_at_two_surfaces(max_surfaces):
    """The batched step == the step of each member alone (a batch of one).

    The square with both diagonals near its sliding equilibrium on two surfaces
    (docs/equilibria.md), perturbed from 1e-3 to 0.3, plus states far from any
    surface: walked 25 steps, every batch step is compared with the step of each
    member alone (the scalar solver). The walk must meet every case: no surface
    crossed, one and two inconsistent surfaces, and steps ending on two surfaces.
    With ``max_surfaces = 1`` the widening to a second surface is not allowed,
    which leaves those members to the least-violation fallback.
    """
    square = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], diameters=0.2)
    system = fl.System(formation=square, law=LAW)
    rng = np.random.default_rng(7)
    sliding = np.array([[-0.23, 0.12], [0.23, 0.12], [-1.02, -0.12], [1.02, -0.12]])
    scale = np.geomspace(1e-3, 0.3, 32)[:, None, None]
    far = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]) * 1.5
    q = np.concatenate(
        [sliding + scale * rng.standard_normal((32, 4, 2)), far + 0.05 * rng.normal(size=(4, 4, 2))]
    )
    dt = 0.01
    integ = ImplicitEuler(dt=dt, max_surfaces=max_surfaces)
    seen = np.zeros(3, int)
    on_two = 0
    for _ in range(25):
        sigma = system.sigma(q)
        end = q + dt * system.rhs_with(q, (sigma >= 0).astype(float))
        sig_end = system.sigma(end)
        bad = np.where(sigma >= 0, sig_end < -integ.tol, sig_end > integ.tol)
        seen += np.bincount(np.minimum(bad.sum(axis=-1), 2), minlength=3)
        batch = integ.step(system, q, dt)
        alone = np.array([integ.step(system, member, dt) for member in q])
        np.testing.assert_allclose(batch, alone, rtol=0, atol=1e-13)
        on_two += int(np.sum(np.sum(np.abs(system.sigma(alone)) < 1e-11, axis=-1) == 2))
        q = alone
    assert np.all(seen > 10) and on_two > 10
