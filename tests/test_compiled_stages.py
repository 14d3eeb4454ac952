"""Marching, sensing and faults in single runs on the engine's compiled loop, against the
numpy driver.

``simulate`` with ``backend="numba"`` runs marching as a stage of the loop
(``marching/stage.py``: a reference velocity for every robot, one that is a function of
time, a leader, Garcia de Marina et al.'s motion parameters) on either layout, and the
robots' own measurements (``sensing/stage.py``: local frames, noise, range, delay, losses,
mismatch, a robot that stops) on the pairs layout, as batches do, with the noise and losses
of each block of steps drawn from the sensing's seed between calls. Each is compared with
the stepping driver (``backend="numpy"``) to rounding, for every robot model, alone and all
at once with obstacles and a filter, and marching at swarm size with the robots renumbered.
"""

import warnings

import numpy as np
import pytest
from test_compiled import TRIANGLE, ladder
from test_compiled_models import assert_follows

import formationlab as fl
from formationlab.errors import FormationlabWarning
from formationlab.formation.spec import DENSE_LIMIT
from formationlab.integrators import compiled
from formationlab.marching import Marching, MotionParameters
from formationlab.models import DoubleIntegrator, Quadrotor, SingleIntegrator, Unicycle
from formationlab.safety import SafetyFilter
from formationlab.safety.obstacles import Circle
from formationlab.sensing import BLOCK, Faults, Sensing, Stop

MODELS = {
    "single": SingleIntegrator(),
    "single-limited": SingleIntegrator(max_speed=0.6),
    "double": DoubleIntegrator(damping=2.0),
    # both of its limits active at the start (the command and the lag's acceleration)
    "quadrotor": Quadrotor(time_constant=0.15, max_accel=3.0, max_speed=0.8),
    "unicycle-heading": Unicycle(mapping="heading"),
    "unicycle-near-identity": Unicycle(mapping="near-identity", offset=0.1),
}
START = np.array([[-1.2, -0.9], [1.4, -0.7], [0.1, 1.3]])


def _marches(f):
    return {
        "every": Marching(velocity=[0.3, -0.2]),
        "timed": Marching(velocity=lambda t: [0.4 * np.cos(2 * t), 0.4 * np.sin(2 * t)]),
        "leader": Marching(velocity=[0.3, 0.1], leader=2),
        # each leader its own velocity (a scaling maneuver), constant and in time
        "leaders-each": Marching(velocity=[[0.3, 0.1], [-0.2, 0.15]], leader=(3, 1)),
        "leaders-each-timed": Marching(
            velocity=lambda t: [[0.3 * np.cos(t), 0.1], [-0.2, 0.15 * np.sin(3 * t)]],
            leader=(1, 2),
        ),
        "motion": MotionParameters.design(f, [0.2, 0.1], angular_velocity=0.4),
    }


#: each sensing key alone, and a robot that stops
SENSED = {
    "frames": {"sensing": Sensing(frames="local", seed=3)},
    "noise": {"sensing": Sensing(noise=0.03, seed=4)},
    "range": {"sensing": Sensing(range=2.0)},
    "delay": {"sensing": Sensing(delay=0.05)},
    "drop": {"sensing": Sensing(drop=0.4, seed=5)},
    "mismatch": {"sensing": Sensing(mismatch=0.05, seed=6)},
    "stop": {"faults": Faults(stop=[Stop(robot=2, at=0.5)])},
}


def both(formation, law, q0, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FormationlabWarning)  # heading-mapped unicycles
        a = fl.simulate(formation, law, q0, backend="numba", **kw)
        b = fl.simulate(formation, law, q0, backend="numpy", **kw)
    return a, b


@pytest.mark.parametrize(
    "how", ["every", "timed", "leader", "leaders-each", "leaders-each-timed", "motion"]
)
@pytest.mark.parametrize("model", sorted(MODELS))
def test_every_march_and_model_follows_the_driver(model, how):
    march = _marches(TRIANGLE)[how]
    kw = {"duration": 1.0, "save_every": 7, "model": MODELS[model]}
    a, b = both(TRIANGLE, fl.get_law("distance"), START, marching=march, **kw)
    assert_follows(a, b, scale=2.0)
    still = fl.simulate(TRIANGLE, "distance", START, backend="numba", **kw)
    assert np.abs(a.q[-1] - still.q[-1]).max() > 0.05  # the march moved the robots


@pytest.mark.parametrize("how", ["every", "leader", "leaders-each", "motion"])
def test_marching_at_swarm_size_with_the_robots_renumbered(how, monkeypatch):
    monkeypatch.setattr(compiled, "REORDER_FROM", 8)  # the loop's numbers are not the robots'
    f, q0 = ladder(DENSE_LIMIT + 16, seed=2)
    march = _marches(f)[how]
    lead = {"leader": {f.n - 5: [0.3, 0.1]}, "leaders-each": {f.n - 5: [0.3, 0.1], 7: [-0.2, 0]}}
    if how in lead:
        velocity = list(lead[how].values())
        march = Marching(velocity=velocity if len(velocity) > 1 else velocity[0],
                         leader=tuple(lead[how]))  # fmt: skip
    law = fl.get_law("angle-restricted", k_a=0.3, theta=0.58)
    a, b = both(f, law, q0, marching=march, duration=0.2, save_every=25)
    assert_follows(a, b, scale=float(np.abs(q0).max()) + 1.0)
    for robot, velocity in lead.get(how, {}).items():  # each leader alone moves at its v_ref
        v = np.diff(a.q[:, robot - 1], axis=0) / np.diff(a.t)[:, None]
        np.testing.assert_allclose(v, np.broadcast_to(velocity, v.shape), atol=1e-9)


@pytest.mark.parametrize("case", sorted(SENSED))
@pytest.mark.parametrize("model", sorted(set(MODELS) - {"single-limited"}))
def test_every_sensing_case_and_model_follows_the_driver(model, case):
    dt = 1e-2
    duration = 3.0  # 300 steps: more than one block of draws
    assert duration / dt > BLOCK
    kw = {"duration": duration, "save_every": 3, "model": MODELS[model], **SENSED[case]}
    a, b = both(TRIANGLE, fl.get_law("distance"), START, integrator=fl.Euler(dt=dt), **kw)
    assert_follows(a, b, scale=2.0, tol=1e-12 * dt / 1e-3)
    plain = fl.simulate(TRIANGLE, "distance", START, integrator=fl.Euler(dt=dt),
                        model=MODELS[model], duration=duration)  # fmt: skip
    if case != "frames":  # (the distance law is the same in every robot's frame)
        assert np.abs(a.x[-1] - plain.x[-1]).max() > 1e-6  # the sensing made a difference


@pytest.mark.parametrize("kind", ["barrier-decentralized", "barrier"])
@pytest.mark.parametrize("model", ["single", "unicycle-near-identity"])
def test_everything_at_once(model, kind):
    sensing = Sensing(frames="local", noise=0.01, drop=0.2, delay=0.02, mismatch=0.02, seed=9)
    faults = Faults(stop=[Stop(robot=3, at=1.5)])
    safety = SafetyFilter(filter=kind, distance=0.25, gamma=50.0)
    obstacles = (Circle(center=[0.2, -1.6], radius=0.2),)
    kw = {
        "duration": 3.0, "save_every": 5, "model": MODELS[model], "integrator": fl.Euler(dt=1e-2),
        "sensing": sensing, "faults": faults, "safety": safety, "obstacles": obstacles,
        "marching": Marching(velocity=[0.1, 0.05]),
    }  # fmt: skip
    a, b = both(TRIANGLE, fl.get_law("distance"), START, **kw)
    assert_follows(a, b, scale=3.0, tol=1e-11)
    assert np.abs(a.x[-1, 2] - a.x[int(1.5 / 0.05) + 1, 2]).max() == 0.0  # robot 3 stopped


def test_a_sensed_swarm_above_the_dense_limit_follows_the_driver():
    f, q0 = ladder(DENSE_LIMIT + 16, seed=5)
    law = fl.get_law("angle-restricted", k_a=0.3, theta=0.58)
    kw = {"duration": 0.3, "save_every": 10, "sensing": Sensing(frames="local", range=1.2)}
    a, b = both(f, law, q0, **kw)
    assert_follows(a, b, scale=float(np.abs(q0).max()))


def test_an_interrupted_sensed_run_keeps_what_it_ran(monkeypatch):
    calls = []

    def progress(t):
        calls.append(t)
        if len(calls) == 3:
            raise KeyboardInterrupt

    kw = {"duration": 50.0, "sensing": Sensing(noise=0.01, seed=1), "progress": progress}
    res = fl.simulate(TRIANGLE, "distance", START, backend="numba", interruptible=True, **kw)
    assert res.status == "interrupted" and 0 < res.t[-1] < 50.0
    ref = fl.simulate(TRIANGLE, "distance", START, backend="numpy",
                      duration=float(res.t[-1]), sensing=kw["sensing"])  # fmt: skip
    np.testing.assert_allclose(res.x[-1], ref.x[-1], rtol=0, atol=1e-12 * 2.0)
