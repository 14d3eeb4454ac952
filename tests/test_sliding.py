"""Sliding along the switching surfaces of the angle-restricted law (eqs. 14, 26).

The sliding-mode integrators are checked on a scalar textbook case with a
known exact solution, on three-robot starts that slide (the mechanism of the
paper's figure 3), on the paper's simulation 2, and on a four-robot start with
two surfaces active at once. The event-driven Filippov solver is the yardstick.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from scipy.optimize import brentq

import formationlab as fl
from formationlab.integrators import Filippov, ImplicitEuler

# ---------------------------------------------------------------- scalar textbook case


@dataclass(frozen=True)
class Relay:
    """``x' = 1 - 2 Upsilon(x) + a sin t`` (= ``-sign(x) + a sin t``), time as a state.

    A "System-like" object: the state is ``q = [[x, t]]`` (shape (1, 2)), one
    switching function ``sigma = x``. For ``|a| < 1`` every trajectory reaches
    ``x = 0`` and slides there for ever (Filippov weight ``(1 + a sin t) / 2``);
    for ``|a| > 1`` sliding ends when ``|a sin t| = 1``.
    """

    a: float

    def rhs_with(self, q, weights, t=0.0):  # the time is a state here: t is not used
        q = np.asarray(q, dtype=float)
        w = np.asarray(weights, dtype=float)[..., 0]
        x_dot = 1.0 - 2.0 * w + self.a * np.sin(q[..., 0, 1])
        return np.stack([x_dot, np.ones_like(x_dot)], axis=-1)[..., None, :]

    def rhs(self, q, t=0.0):
        return self.rhs_with(q, np.heaviside(self.sigma(q), 1.0))

    time_dependent = False

    def speed(self, q, v):
        return np.max(np.abs(np.asarray(v)[..., 0]), axis=-1)

    def sigma(self, q):
        return np.asarray(q, dtype=float)[..., 0, :1]

    def clearance(self, q):
        return np.full(np.shape(q)[:-2], np.inf)

    def clearances(self, q):
        """Robot-robot and robot-obstacle clearances: none to have (infinite)."""
        return self.clearance(q), self.clearance(q)

    def step_verdict(self, q, q_new):
        """Every step is acceptable (no robots to collide); the clearance is infinite."""
        shape = np.shape(q)[:-2]
        return np.zeros(shape, np.int8), np.full(shape, np.inf)

    def judge(self, q, q_new):
        """:meth:`step_verdict` with the clearance in its two parts (both infinite)."""
        verdict, clear = self.step_verdict(q, q_new)
        return verdict, clear, clear


def relay_hitting_time(x0: float, a: float) -> float:
    """First ``t`` with ``x(t) = 0`` from ``x0 > 0``: ``x0 - t + a (1 - cos t) = 0``."""
    return brentq(lambda t: x0 - t + a * (1.0 - np.cos(t)), 0.0, 10.0)


def test_implicit_euler_lands_on_the_surface_and_stays():
    relay, dt, duration = Relay(a=0.5), 1e-2, 4.0
    sol = ImplicitEuler(dt=dt).run(relay, np.array([[1.0, 0.0]]), duration)
    x = sol.q[:, 0, 0]
    t_hit = relay_hitting_time(1.0, 0.5)
    after = sol.t > t_hit + dt
    assert np.max(np.abs(x[after])) <= 1e-14  # on x = 0 to round-off, every step
    assert np.all(x[sol.t < t_hit - dt] > 0)
    # reaches the surface once and never leaves: one change of state (on -> on the surface)
    assert sol.stats["switch_count"] == 1
    assert sol.stats["sliding_time"] == pytest.approx(duration - t_hit, abs=2 * dt)
    assert sol.stats["max_excursion"] <= 1e-14


def test_explicit_euler_chatters_on_the_same_case():
    relay, dt, duration = Relay(a=0.5), 1e-2, 4.0
    sol = fl.Euler(dt=dt).run(relay, np.array([[1.0, 0.0]]), duration)
    t_hit = relay_hitting_time(1.0, 0.5)
    steps_sliding = (duration - t_hit) / dt
    # after a crossing |x| <= 1.5 dt (|x'| <= 1.5) and the other side brings it back at
    # |x'| >= 0.5: at least one crossing every 3 steps, for ever
    assert sol.stats["switch_count"] > steps_sliding / 3
    assert sol.stats["max_excursion"] >= 0.5 * dt  # chattering amplitude of order dt
    assert sol.stats["sliding_time"] == pytest.approx(duration - t_hit, abs=3 * dt)


def test_filippov_sliding_time_matches_the_exact_one():
    relay, duration = Relay(a=0.5), 4.0
    sol = Filippov().run(relay, np.array([[1.0, 0.0]]), duration)
    t_hit = relay_hitting_time(1.0, 0.5)
    assert sol.stats["sliding_start"] == pytest.approx(t_hit, abs=1e-9)
    assert sol.stats["sliding_time"] == pytest.approx(duration - t_hit, abs=1e-9)
    assert sol.stats["switch_count"] == 1
    assert np.max(np.abs(sol.q[sol.t > t_hit + 1e-6, 0, 0])) <= 1e-9


def test_sliding_ends_where_the_filippov_weight_leaves_the_interval():
    # a = 1.5 from x = 0: the weight (1 + 1.5 sin t) / 2 reaches 1 at sin t = 2/3,
    # then x' = -1 + 1.5 sin t > 0 and x leaves the surface upwards
    relay, t_exit = Relay(a=1.5), float(np.arcsin(2.0 / 3.0))
    ref = Filippov().run(relay, np.array([[0.0, 0.0]]), 1.5)
    assert ref.stats["sliding_end"] == pytest.approx(t_exit, abs=1e-8)
    assert ref.q[-1, 0, 0] > 0
    dt = 1e-3
    sol = ImplicitEuler(dt=dt).run(relay, np.array([[0.0, 0.0]]), 1.5)
    assert sol.stats["sliding_end"] == pytest.approx(t_exit, abs=3 * dt)
    assert sol.stats["switch_count"] == 1  # on the surface -> on
    # after the exit the exact solution is x = -(t - t_e) + 1.5 (cos t_e - cos t)
    x_end = -(1.5 - t_exit) + 1.5 * (np.cos(t_exit) - np.cos(1.5))
    assert ref.q[-1, 0, 0] == pytest.approx(x_end, abs=1e-8)
    assert sol.q[-1, 0, 0] == pytest.approx(x_end, abs=5 * dt)


# ---------------------------------------------------------------- three robots that slide

LAW = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)  # section 4
SIM1_TABLE = {(1, 2, 3): -1, (3, 1, 2): -1, (2, 1, 3): 1}  # desired: c_123 > 0
SIM2_TABLE = {(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}
PAPER_Q0 = np.array([[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]])
#: figure 3's mechanism: robot 1 far from robots 2 and 3 and on the wrong side of their
#: line (c_123 = -6 < 0, so the restriction is on, sigma = 6.5); phi pulls robot 1 back
#: towards the line while psi pushes it over: it slides along s (eq. 26)
SLIDING_Q0 = np.array([[5.0, -2.0], [-1.5, 0.0], [1.5, 0.0]])


def triangle(table):
    return fl.Formation.from_alpha_table(table, n=3, distances=1.0, diameters=0.2)


@pytest.fixture(scope="module")
def sliding_runs():
    f = triangle(SIM1_TABLE)
    dt, duration = 1e-3, 3.0
    return {
        "filippov": fl.simulate(f, LAW, SLIDING_Q0, duration=duration, integrator=Filippov()),
        "implicit": fl.simulate(
            f, LAW, SLIDING_Q0, duration=duration, integrator=ImplicitEuler(dt=dt)
        ),
        "euler": fl.simulate(f, LAW, SLIDING_Q0, duration=duration, integrator=fl.Euler(dt=dt)),
    }


def test_the_start_slides(sliding_runs):
    ref = sliding_runs["filippov"]
    assert ref.stats["unresolved_events"] == 0
    assert ref.stats["sliding_time"] > 0.5  # a real sliding phase, not a crossing
    assert ref.stats["switch_count"] == 2  # onto the surface, off it
    assert ref.outcome() == "desired"


def test_implicit_euler_and_filippov_agree_on_formation_and_sliding_end(sliding_runs):
    ref, imp = sliding_runs["filippov"], sliding_runs["implicit"]
    dt = imp.integrator.dt
    assert imp.outcome() == ref.outcome() == "desired"
    # first order: the error at dt = 1e-3 is a few dt times the speeds (measured 5e-4)
    np.testing.assert_allclose(imp.final, ref.final, atol=3e-3)
    assert imp.stats["sliding_start"] == pytest.approx(ref.stats["sliding_start"], abs=3 * dt)
    assert imp.stats["sliding_end"] == pytest.approx(ref.stats["sliding_end"], abs=5 * dt)
    assert imp.stats["switch_count"] == ref.stats["switch_count"]
    # while sliding the implicit steps sit on the surface to round-off
    inside = (imp.t > imp.stats["sliding_start"] + dt) & (imp.t < imp.stats["sliding_end"] - dt)
    assert inside.sum() > 400
    assert np.max(np.abs(imp.sigma[inside, 0])) <= 1e-12


def test_implicit_euler_switches_ten_times_less_than_explicit_euler(sliding_runs):
    imp, eul = sliding_runs["implicit"], sliding_runs["euler"]
    assert eul.stats["switch_count"] >= 10 * imp.stats["switch_count"]
    # explicit Euler crosses back and forth, by far more than round-off
    assert eul.stats["max_excursion"] > 1e-2
    assert imp.stats["max_excursion"] <= 1e-12


# ---------------------------------------------------------------- the paper's simulation 2


def shrunken_side() -> float:
    """Side of the equilateral equilibrium of simulation 2 with the restriction on.

    On robot i, -k_c grad phi_i is radial with size sqrt(3) k_c |dphi/dr(L)|
    (two edges at 60 degrees, eq. 6); -k_a grad psi_i = -k_a (2 k x r_jk) has size
    2 k_a L and points inwards (the ordered pairs (j, k) and (k, j) add, eqs. 13,
    23). Balance: sqrt(3) k_c (1/(L - a) - 1/(d - a)) = 2 k_a L, a = 0.2, d = 1.
    """
    k_c, k_a, a, d = 2.0, 3.0, 0.2, 1.0
    return brentq(
        lambda L: np.sqrt(3) * k_c * (1 / (L - a) - 1 / (d - a)) - 2 * k_a * L, a + 1e-6, d
    )


SIM2_INTEGRATORS = {
    "euler": fl.Euler(dt=1e-2),
    "rk4": fl.RK4(dt=1e-2),
    "implicit-euler": ImplicitEuler(dt=1e-2),
    "filippov": Filippov(save_dt=0.05),
}


@pytest.mark.parametrize("name", SIM2_INTEGRATORS)
def test_simulation_2_exact_start_ends_at_the_shrunken_triangle(name):
    # the start is mirror-symmetric (x -> -x with robots 1, 2 swapped) and so is the
    # law: the run stays symmetric and ends at the equilateral equilibrium where the
    # restriction, still on, balances phi's repulsion -- not the desired formation
    res = fl.simulate(
        triangle(SIM2_TABLE), LAW, PAPER_Q0, duration=20.0, integrator=SIM2_INTEGRATORS[name]
    )
    assert res.outcome() == "incorrect"
    r = np.linalg.norm(res.final[[1, 2, 0]] - res.final, axis=-1)
    np.testing.assert_allclose(r, shrunken_side(), atol=1e-4)
    assert res.sigma[-1, 0] > 0  # the restriction is on at the end
    assert res.stats["switch_count"] == 0


@pytest.mark.parametrize("name", SIM2_INTEGRATORS)
def test_simulation_2_perturbed_start_reaches_the_desired_formation_without_sliding(name):
    # x_1(0) = -3 + 1e-6 breaks the symmetry; the run escapes the shrunken triangle,
    # crosses the surface once, transversally, and reaches the desired formation.
    # The paper's "smaller sliding region over s" is not reproduced: no sliding phase.
    q0 = PAPER_Q0.copy()
    q0[0, 0] += 1e-6
    res = fl.simulate(
        triangle(SIM2_TABLE), LAW, q0, duration=20.0, integrator=SIM2_INTEGRATORS[name]
    )
    assert res.outcome() == "desired"
    assert res.sigma[-1, 0] < 0
    if name == "filippov":
        assert res.stats["switch_count"] == 1
        assert res.stats["sliding_time"] == 0.0
    else:  # implicit Euler may land on the surface for one step of the crossing
        assert res.stats["switch_count"] in (1, 2)
        assert res.stats["sliding_time"] <= 2 * SIM2_INTEGRATORS[name].dt


# ---------------------------------------------------------------- two surfaces at once


def test_two_robots_slide_on_two_surfaces_at_once():
    # a rhombus of two unit triangles: robot 3 wanted above line 1-2 (c_123 > 0), robot 4
    # below (c_124 < 0); both start far away on the wrong side, so each slides along its
    # own line s, for a while both at the same time
    table = dict(SIM1_TABLE) | {(1, 2, 4): 1, (4, 1, 2): 1, (2, 1, 4): -1}
    f = fl.Formation.from_alpha_table(
        table, n=4, edges=[[1, 2], [1, 3], [2, 3], [1, 4], [2, 4]], distances=1.0, diameters=0.2
    )
    assert len(f.surfaces[0]) == 2
    q0 = np.array([[-1.5, 0.0], [1.5, 0.0], [5.0, -2.0], [-4.5, 2.3]])
    duration = 1.5
    ref = fl.simulate(f, LAW, q0, duration=duration, integrator=Filippov(save_dt=1e-3))
    assert ref.stats["unresolved_events"] == 0
    both_ref = np.all(np.abs(ref.sigma) < 1e-8, axis=1)
    assert both_ref.sum() * 1e-3 > 0.1  # both surfaces held together for > 0.1 s
    errors = []
    for dt in (2e-3, 1e-3):
        imp = fl.simulate(f, LAW, q0, duration=duration, integrator=ImplicitEuler(dt=dt))
        assert imp.stats.get("unresolved_steps", 0) == 0
        errors.append(np.max(np.abs(imp.final - ref.final)))
    both_imp = np.all(np.abs(imp.sigma) < 1e-12, axis=1)
    assert both_imp.sum() * dt > 0.1
    # surface 1 is re-entered almost tangentially, so its time is sensitive: compare at dt = 1e-3
    t_ref, t_imp = ref.t[both_ref], imp.t[both_imp]
    assert t_imp.min() == pytest.approx(t_ref.min(), abs=5 * dt)
    assert t_imp.max() == pytest.approx(t_ref.max(), abs=5 * dt)
    # first order through the two-surface sliding: halving dt halves the error
    assert errors[1] < 2e-3
    assert np.log2(errors[0] / errors[1]) == pytest.approx(1.0, abs=0.25)


def test_two_sliding_weights_reaching_zero_together_both_exit():
    # a start symmetric under the half-turn (1 <-> 2, 3 <-> 4): both weights reach 0 at
    # the same instant; the solver reports one event, the other must be released too
    table = dict(SIM1_TABLE) | {(1, 2, 4): 1, (4, 1, 2): 1, (2, 1, 4): -1}
    f = fl.Formation.from_alpha_table(
        table, n=4, edges=[[1, 2], [1, 3], [2, 3], [1, 4], [2, 4]], distances=1.0, diameters=0.2
    )
    q0 = np.array([[-1.5, 0.0], [1.5, 0.0], [5.0, -2.0], [-5.0, 2.0]])
    dt, duration = 2e-3, 1.5
    ref = fl.simulate(f, LAW, q0, duration=duration, integrator=Filippov())
    imp = fl.simulate(f, LAW, q0, duration=duration, integrator=ImplicitEuler(dt=dt))
    assert ref.stats["sliding_end"] < duration - 0.2  # sliding ends, on both surfaces
    assert np.all(ref.sigma[-1] < -1e-3)
    assert imp.stats["sliding_end"] == pytest.approx(ref.stats["sliding_end"], abs=5 * dt)
    np.testing.assert_allclose(imp.final, ref.final, atol=5e-3)


def test_nearly_coincident_surfaces_are_separate_sliding_motions():
    # angle-valued alpha from a template whose angles differ a little (0.866 != sqrt(3)/2):
    # robots 1 and 2 switch with beta_A, robot 3 with beta_B, |beta_B| > |beta_A| by 4e-5.
    # The exact motion slides on surface A with B already off, sigma_B = theta (1 -
    # beta_B / beta_A) ~ -1.8e-5: a different motion from the merged surface, which a
    # scheme that jumps by ~0.5 in sigma per step (explicit Euler) cannot resolve.
    f = fl.Formation.from_template(
        [[0.0, 0.0], [1.0, 0.0], [0.5, 0.866]], diameters=0.2, alpha_values="angle"
    )
    _, beta, _ = f.surfaces
    assert len(beta) == 2
    ref = fl.simulate(f, LAW, SLIDING_Q0, duration=1.5, integrator=Filippov(save_dt=0.01))
    sliding = (ref.t > 0.1) & (ref.t < 0.8)
    a, b = (0, 1) if abs(beta[0]) < abs(beta[1]) else (1, 0)
    assert np.max(np.abs(ref.sigma[sliding, a])) < 1e-9
    np.testing.assert_allclose(ref.sigma[sliding, b], 0.5 * (1 - beta[b] / beta[a]), atol=1e-9)
    imp = fl.simulate(f, LAW, SLIDING_Q0, duration=1.5, integrator=ImplicitEuler(dt=1e-3))
    np.testing.assert_allclose(imp.final, ref.final, atol=5e-3)
    eul = fl.simulate(f, LAW, SLIDING_Q0, duration=1.5, integrator=fl.Euler(dt=1e-3))
    assert np.max(np.abs(eul.final - ref.final)) > 0.05


def test_equilateral_angle_template_has_one_surface():
    """The three angles of an equilateral template differ in their last bits; one surface."""
    f = fl.Formation.from_template(
        [[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]], diameters=0.2, alpha_values="angle"
    )
    assert len(f.surfaces[1]) == 1


def test_rk4_is_first_order_through_a_sliding_phase():
    # its stages straddle the surface: fourth order is lost where the field switches
    f = triangle(SIM1_TABLE)
    ref = fl.simulate(f, LAW, SLIDING_Q0, duration=1.5, integrator=Filippov()).final
    errors = [
        np.max(
            np.abs(
                fl.simulate(f, LAW, SLIDING_Q0, duration=1.5, integrator=fl.RK4(dt=dt)).final - ref
            )
        )
        for dt in (2e-3, 1e-3)
    ]
    assert np.log2(errors[0] / errors[1]) == pytest.approx(1.0, abs=0.3)
    assert errors[1] > 1e-4  # far above what fourth order would leave at dt = 1e-3
