"""The viewer from Python: the widget run for a while and read back (V and the errors),
a state that is not finite pausing the stream, the speed reached, large formations on the
compiled loop, and the numbers behind the error plot's legend and switching marks."""

from __future__ import annotations

import numpy as np
import pytest
from _scenarios import lattice
from _viewer import SIM2, sim2_session

import formationlab as fl
from formationlab.io.scenario import load_scenario
from formationlab.outcomes.analysis import distance_errors
from formationlab.scenario import closed_loop, parse_scenario
from formationlab.viewer import Controller, SessionError
from formationlab.viewer.frames import error_fields, switch_times, worst_edges
from formationlab.viewer.stepping import COMPILED_FROM


def test_widget_runs_for_a_while_and_reads_back_V_and_the_errors():
    """``run(seconds)`` is ``round(seconds / dt)`` steps of the run ``simulate`` steps; the
    history's V and errors are the system's own of the states stepped (eq. 15 and
    ``r_ij - d_ij``), also across a change of law (each state by the law in force)."""
    v = fl.Viewer(load_scenario(SIM2), seed=3)
    assert v.run(0.04) == 40 and v.t == pytest.approx(0.04, abs=1e-12)
    sc = v.session.scenario
    ref = fl.simulate(sc.formation, sc.law, sc.q0, duration=0.04, integrator=sc.integrator,
                      backend="numpy")  # fmt: skip
    h = v.history
    assert h.V.shape == (41,) and h.errors.shape == (41, 3)
    system = closed_loop(sc)
    np.testing.assert_allclose(h.V, system.potential(ref.x), rtol=1e-12, atol=0)
    np.testing.assert_allclose(h.errors, distance_errors(sc.formation, ref.q), rtol=0, atol=1e-12)
    assert h.V[-1] < h.V[0]  # the law descends V from the start
    v.law = "distance"
    v.run(0.01)
    h = v.history
    distance = v.session.system
    assert distance.law.name == "distance"
    np.testing.assert_allclose(h.V[-10:], distance.potential(h.positions[-10:]), rtol=1e-12)
    assert not np.allclose(h.V[:41], distance.potential(ref.x))  # another V before the switch
    np.testing.assert_allclose(h.V[:41], system.potential(ref.x), rtol=1e-12)
    for bad in (0.0, -1.0, float("inf"), "1"):
        with pytest.raises(SessionError, match="duration"):
            v.run(bad)


@pytest.mark.parametrize("bad", [np.inf, -np.inf, np.nan])
def test_a_state_that_is_not_finite_pauses_the_stream_with_a_message(bad):
    """A robot at +-inf or NaN: the next tick pauses the run as ``non-finite`` with a
    message naming the robot; no inf or NaN goes to the page; Run keeps it paused; a reset
    runs again."""
    s = sim2_session()
    ctl = Controller(s, clock=iter(np.arange(0, 100, 0.02)).__next__)
    ctl.hello()
    s.state[0] = [bad, 0.0]
    header = ctl.handle('{"type": "tick"}')[0].header
    assert header["paused"] and header["status"] == "non-finite"
    assert "robot 1 at inf or NaN" in header["message"] and "paused" in header["message"]
    assert s.steps == 0 and header["V"] is None
    assert np.all(np.isfinite(s.frame().positions))
    s.set_paused(False)  # Run: still not finite, still paused with the message
    assert s.paused and s.status == "non-finite" and s.step(3) == 0
    s.reset()
    s.set_paused(False)
    assert s.step(3) == 3 and s.status == "running"


def test_speed_reached_is_simulated_time_over_wall_time():
    """The header's ``reached`` is the simulated time advanced over the wall time given,
    measured over half a second of running; a slow step budget gives less than asked."""
    s = sim2_session(step_budget_s=10.0)
    s.set_speed(2.0)
    for _ in range(6):
        s.advance(0.1)
    assert s.frame().header["reached"] == pytest.approx(s.t / 0.6, rel=1e-9)
    assert s.t == pytest.approx(1.2, abs=1e-9)
    slow = sim2_session(step_budget_s=0.0)  # one step per tick at most
    slow.set_speed(10.0)
    for _ in range(6):
        slow.advance(0.1)
    assert slow.reached == pytest.approx(6 * 1e-3 / 0.6) and slow.reached < 10.0
    slow.set_paused(True)
    assert slow.frame().header["reached"] is None


def test_a_large_formation_steps_on_the_compiled_loop_as_the_driver_does():
    """From COMPILED_FROM robots the live session runs its steps on the engine's compiled
    run (in segments); the states, the time and the history are the driver's to rounding,
    and a drag in between is stepped from (held robots go back to the driver)."""
    sc = parse_scenario(lattice(COMPILED_FROM))
    fast = fl.Viewer(sc)
    assert fast.step(7) == 7 and fast.step(13) == 13
    assert fast.session.frame().header["compiled"]
    ref = fl.simulate(sc.formation, sc.law, sc.q0, duration=0.02, integrator=sc.integrator,
                      backend="numpy")  # fmt: skip
    h = fast.history
    np.testing.assert_allclose(h.t, ref.t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(h.positions, ref.q, rtol=0, atol=1e-12)
    assert fast.t == pytest.approx(0.02, abs=1e-12)
    s = fast.session
    s.drag(1, *(s.q[0] + [0.05, 0.0]))
    held = s.q[0].copy()
    assert s.step(3) == 3 and np.array_equal(s.q[0], held)  # the driver holds it
    s.release()
    assert s.step(5) == 5 and not np.array_equal(s.q[0], held)
    assert s.t == pytest.approx(0.028, abs=1e-12)


def test_error_summary_names_the_worst_edges_and_the_band():
    err = np.array([0.1, -0.7, 0.3, np.nan, 0.0, -0.2, 0.5])
    assert worst_edges(err, 3).tolist() == [3, 1, 6]  # NaN first, then by |err|
    fields = error_fields(np.array([0.1, -0.7, 0.3, 0.0, -0.2, 0.5, 0.05]))
    assert fields["worst"] == {"edges": [2, 6, 3, 5, 1], "values": [-0.7, 0.5, 0.3, -0.2, 0.1]}
    assert fields["band"] == [-0.7, 0.5] and len(fields["errors"]) == 7
    many = error_fields(np.linspace(-1.0, 2.0, 40))
    assert "errors" not in many and many["worst"]["edges"] == [40, 39, 38, 37, 36]


def test_switch_times_are_where_a_restriction_turns_on_or_off():
    t = np.array([0.0, 0.1, 0.2, 0.3, 0.4])
    sigma = np.array([[-1.0, 2.0], [-0.5, 1.0], [0.0, 1.0], [0.5, -1.0], [0.5, -2.0]])
    assert switch_times(t, sigma) == [0.2, 0.3]
    assert switch_times(t, None) == [] and switch_times(t[:1], sigma[:1]) == []
