"""The asynchronous runner (formationlab.agents.asynchronous) against the synchronous loop.

* equal periods (= dt), no jitter: the run is ``simulate`` with explicit Euler, for
  every law with kernel terms, single integrators and unicycles, also with local
  frames, mismatch, a delay of whole steps and a robot that stops (to 1e-12);
* a delay of k periods: every command is the law's at the state k periods earlier
  (computed here from the saved states with the centralized law);
* losses: a command is always the law's at the state of some earlier wake-up of the
  same robot, never later, and the fraction of held measurements is the drop rate;
* the scheduler wakes robots due together in robot order; a seed fixes the run;
* the paper's triangle (section 4, simulation 1) still reaches its formation with
  periods of 1, 2 and 5 ms and jitter; contact ends the run with the package's status;
* bad arguments raise ParameterError with a message naming the argument.
"""

from __future__ import annotations

import asyncio
import math
from pathlib import Path

import numpy as np
import pytest

import formationlab as fl
from formationlab.agents import Bus, Message, run_async
from formationlab.agents.clock import VirtualClock
from formationlab.controllers import SignedAreaLaw, SquaredDistanceLaw
from formationlab.errors import ParameterError
from formationlab.scenario import parse_scenario
from formationlab.sensing import Faults, Sensing, Stop

ROOT = Path(__file__).resolve().parents[1]
Q0 = np.array([[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]])
HEADINGS = [0.3, 1.9, -2.4]


def paper(number: int):
    return parse_scenario((ROOT / f"examples/paper-simulation-{number}.toml").read_text())


SIM1, SIM2 = paper(1), paper(2)

LAWS = {
    "distance": (SIM1.formation, fl.DistanceLaw(k_c=2.0)),
    "angle-restricted": (SIM1.formation, SIM1.law),
    "angle-restricted-active": (SIM2.formation, SIM2.law),  # restrictions on from the start
    "squared-distance": (SIM1.formation, SquaredDistanceLaw(k=0.5)),
    "signed-area": (SIM1.formation, SignedAreaLaw(k=0.5, k_s=1.0)),
}
MODELS = {"single": ("single-integrator", {}), "unicycle": ("unicycle", {"headings": HEADINGS})}


def sync(formation, law, *, duration, dt, model="single-integrator", **kwargs):
    return fl.simulate(formation, law, Q0, duration=duration, integrator=fl.Euler(dt=dt),
                       model=model, backend="numpy", **kwargs)  # fmt: skip


def assert_same_run(a, s, tol=1e-12):
    """The same run to ``tol`` relative to the largest number (the unicycle's turn rate
    is the command over the 5 cm offset: large and sensitive to rounding)."""
    assert a.status == s.status
    assert a.t.shape == s.t.shape
    np.testing.assert_allclose(a.t, s.t, rtol=0, atol=1e-15)
    for got, want in ((a.x, s.x), (a.xdot, s.xdot)):
        np.testing.assert_allclose(got, want, rtol=0, atol=tol * max(1.0, np.abs(want).max()))


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("name", LAWS)
def test_equal_periods_are_the_synchronous_run(name, model):
    formation, law = LAWS[name]
    m, initial = MODELS[model]
    s = sync(formation, law, duration=0.2, dt=1e-3, model=m, **initial)
    a = run_async(formation, law, Q0, duration=0.2, dt=1e-3, model=m, **initial)
    assert np.ptp(s.x[..., :2], axis=0).max() > 0.1  # the robots moved: a real comparison
    assert_same_run(a, s)
    assert a.updates.tolist() == [201, 201, 201]


@pytest.mark.parametrize(
    "sensing, faults",
    [
        (Sensing(frames="local", mismatch=0.05, seed=3), None),
        (Sensing(delay=3e-3), None),
        (None, Faults(stop=[Stop(robot=2, at=0.05)])),
    ],
    ids=["local-frames-mismatch", "delay-3-steps", "robot-2-stops"],
)
@pytest.mark.parametrize("model", MODELS)
def test_equal_periods_match_the_synchronous_sensing_and_faults(sensing, faults, model):
    formation, law = LAWS["distance"]
    m, initial = MODELS[model]
    kwargs = {"sensing": sensing, "faults": faults, **initial}
    s = sync(formation, law, duration=0.15, dt=1e-3, model=m, **kwargs)
    a = run_async(formation, law, Q0, duration=0.15, dt=1e-3, model=m, **kwargs)
    assert_same_run(a, s)
    if faults is not None:  # robot 2 has not moved since t = 0.05
        late = a.t >= 0.05
        assert np.all(a.x[late, 1] == a.x[np.argmax(late), 1])
        assert np.ptp(a.x[late, 0, :2], axis=0).max() > 0.01


def test_a_delay_of_k_periods_uses_the_measurement_of_k_periods_before():
    formation, law = LAWS["distance"]
    dt, periods, delay = 1e-3, np.array([1, 2, 4]) * 1e-3, 4e-3  # 4, 2 and 1 periods
    a = run_async(formation, law, Q0, duration=0.1, dt=dt, periods=periods,
                  sensing=Sensing(delay=delay))  # fmt: skip
    grid = {round(t / dt): k for k, t in enumerate(a.t)}
    for i in range(3):
        times, commands = a.update_times[i], a.commands[i]
        np.testing.assert_allclose(np.diff(times), periods[i], rtol=0, atol=1e-15)
        for t, u in zip(times, commands, strict=True):
            if t < delay - 1e-12:  # nothing has arrived: the robot sees no one
                np.testing.assert_array_equal(u, 0.0)
                continue
            q_then = a.q[grid[round((t - delay) / dt)]]
            np.testing.assert_allclose(u, law.control(formation, q_then)[i], rtol=0, atol=1e-12)


def test_a_lost_measurement_leaves_the_last_one_in_place():
    formation = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    law, drop = fl.DistanceLaw(k_c=2.0), 0.3
    q0 = [[0.0, 0.0], [3.0, 0.5]]
    a = run_async(formation, law, q0, duration=0.4, dt=1e-3, sensing=Sensing(drop=drop), seed=7)
    at = {round(t * 1e3): k for k, t in enumerate(a.t)}
    for i in range(2):
        # the law's command of robot i at each of its wake-ups: what a fresh measurement gives
        fresh = np.array([law.control(formation, a.q[at[round(t * 1e3)]])[i]
                          for t in a.update_times[i]])  # fmt: skip
        used, last = [], -1
        for m, u in enumerate(a.commands[i]):
            match = np.flatnonzero(np.all(np.abs(fresh[: m + 1] - u) <= 1e-12, axis=-1))
            if match.size == 0:  # nothing received yet
                np.testing.assert_array_equal(u, 0.0)
                assert last == -1
                continue
            k = int(match[-1])
            assert k >= last  # held, never older than what was held before
            used.append(k < m)
            last = k
        n = len(used)
        held = sum(used)
        assert abs(held - drop * n) <= 4 * math.sqrt(n * drop * (1 - drop))
    assert a.stats["messages_lost"] > 0


def test_the_bus_delays_drops_and_holds():
    bus = Bus(2, delay=0.25, drop=0.4, rngs=[np.random.default_rng(s) for s in (1, 2)])
    delivered = []
    for k in range(400):
        t = 0.1 * k
        if bus.publish(Message(topic="z", sender=1, recipient=0, stamp=t, payload=k)):
            delivered.append(k)
        bus.publish(Message(topic="other", sender=1, recipient=0, stamp=t, payload=-k),
                    lossy=False)  # fmt: skip
        got = bus.latest(0, "z", t).get(1)
        due = [j for j in delivered if 0.1 * j + 0.25 <= t + 1e-12]
        assert (got.payload if got else None) == (due[-1] if due else None)
        other = bus.latest(0, "other", t).get(1)  # never lost: the one sent 3 stamps before
        assert (other.payload if other else None) == (-(k - 3) if k >= 3 else None)
    assert abs(bus.lost - 0.4 * 400) <= 4 * math.sqrt(400 * 0.4 * 0.6)
    assert bus.latest(1, "z", 100.0) == {}


def test_robots_due_together_wake_in_robot_order():
    order: list[tuple[float, int]] = []

    async def robot(i, clock, times):
        for t in times:
            await clock.sleep_until(t, i)
            order.append((clock.now, i))

    async def main():
        clock = VirtualClock()
        schedules = [[0.0, 0.3, 0.6], [0.0, 0.2, 0.6], [0.1, 0.3, 0.6]]
        clock.start([robot(i, clock, s) for i, s in reversed(list(enumerate(schedules)))])
        await clock.idle()
        while (due := clock.next_time()) is not None:
            await clock.wake(due)
        await clock.close()

    asyncio.run(main())
    assert order == sorted(order)
    assert len(order) == 9


def test_the_same_seed_gives_the_same_run():
    formation, law = LAWS["distance"]
    kwargs = {"duration": 0.1, "dt": 1e-3, "periods": [1e-3, 2e-3, 3e-3], "jitter": 0.4,
              "sensing": Sensing(noise=0.01, drop=0.2, delay=2.5e-3, frames="local")}  # fmt: skip
    a, b = run_async(formation, law, Q0, **kwargs), run_async(formation, law, Q0, **kwargs)
    c = run_async(formation, law, Q0, seed=1, **kwargs)
    np.testing.assert_array_equal(a.x, b.x)
    for ta, tb, tc in zip(a.update_times, b.update_times, c.update_times, strict=True):
        np.testing.assert_array_equal(ta, tb)
        assert ta.shape != tc.shape or not np.array_equal(ta, tc)
    assert not np.array_equal(a.x, c.x)
    assert a.seed == 0 and c.seed == 1


def test_unequal_periods_reach_the_paper_triangle():
    periods, jitter = np.array([1e-3, 2e-3, 5e-3]), 0.3
    a = run_async(SIM1.formation, SIM1.law, Q0, duration=3.5, dt=1e-3, periods=periods,
                  jitter=jitter)  # fmt: skip
    assert a.status == "success"
    assert a.outcome() == "desired"
    assert a.shape_error[-1] < 1e-6
    for times, T in zip(a.update_times, periods, strict=True):
        gaps = np.diff(times)
        assert np.all(gaps > (1 - jitter) * T - 1e-15) and np.all(gaps < (1 + jitter) * T)
        assert 3.5 / T - 1 <= len(times) <= 3.5 / T + 1
    assert len(set(np.round(np.diff(a.update_times[0]), 12))) > 10  # the jitter is there


@pytest.mark.parametrize(
    "d0, dt, status", [(5.0, 0.8, "step-collision"), (5.0, 1.0, "step-too-large")]
)
def test_contact_ends_the_run_with_the_package_status(d0, dt, status):
    formation = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    law, q0 = fl.DistanceLaw(k_c=2.0), [[0.0, 0.0], [d0, 0.0]]
    s = fl.simulate(formation, law, q0, duration=5.0, integrator=fl.Euler(dt=dt),
                    backend="numpy")  # fmt: skip
    a = run_async(formation, law, q0, duration=5.0, dt=dt)
    assert s.status == status  # the case is a contact case
    assert a.status == s.status and a.message == s.message
    np.testing.assert_allclose(a.x, s.x, rtol=0, atol=1e-12)
    assert a.outcome() == "collision"


def test_a_held_command_runs_a_slow_robot_into_a_stopped_one():
    # robot 1 stopped, robot 2 updates every 2 s: it moves at its first command u until
    # |q_2 - q_1| <= a = 0.2, at t* = (2 - 0.2) / |u| (about 1.3 s), long before it looks again
    formation = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    law, q0, dt = fl.DistanceLaw(k_c=2.0), np.array([[0.0, 0.0], [2.0, 0.0]]), 0.01
    b = run_async(formation, law, q0, duration=5.0, dt=dt, periods=[dt, 2.0],
                  faults=Faults(stop=[Stop(robot=1)]))  # fmt: skip
    u = law.control(formation, q0)[1]
    t_star = (2.0 - 0.2) / np.linalg.norm(u)
    assert b.status == "step-collision" and b.outcome() == "collision"
    assert b.updates[1] == 1 and "holds its command" in b.message
    assert b.t[-1] == pytest.approx(dt * math.floor(t_star / dt), abs=1e-9)
    np.testing.assert_allclose(b.q[-1, 1], q0[1] + b.t[-1] * u, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(b.q[-1, 0], q0[0])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"periods": [1e-3, 0.0, 1e-3]}, r"periods, robot 2, must be a finite number > 0"),
        ({"periods": [1e-3, -1e-3, 1e-3]}, r"robot 2"),
        ({"periods": [1e-3, math.nan, 1e-3]}, r"robot 2"),
        ({"periods": [1e-3, 1e-3]}, r"one number or one per robot \(3 robots"),
        ({"periods": 0.0}, r"robot 1, must be a finite number > 0"),
        (
            {"periods": np.int64(-2)},
            r"robot 1, must be a finite number > 0 \(seconds\), got np.int64\(-2\)",
        ),
        ({"periods": [[1e-3] * 3]}, r"one number or one per robot"),
        ({"jitter": 1.0}, r"jitter is a fraction of each period in \[0, 1\), got 1.0"),
        ({"jitter": -0.1}, r"jitter must be a finite number >= 0"),
        ({"dt": 0.0}, r"dt must be a finite number > 0"),
        ({"duration": -1.0}, r"duration must be a finite number > 0"),
        ({"seed": -1}, r"seed must be a whole number in \[0, 2\*\*63\)"),
        ({"sensing": {"noise": 0.1}}, r"sensing must be a Sensing"),
        ({"faults": Faults(stop=[Stop(robot=4)])}, r"robot 4 does not exist"),
        ({"save_every": 0}, r"save_every must be an integer >= 1"),
    ],
)
def test_bad_arguments_are_refused_clearly(kwargs, match):
    formation, law = LAWS["distance"]
    args = {"duration": 0.01, "dt": 1e-3, **kwargs}
    with pytest.raises(ParameterError, match=match):
        run_async(formation, law, Q0, **args)
