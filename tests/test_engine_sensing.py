"""The compiled loop's sensing stage (sensing/stage.py) against the stepping driver.

``run_batch(..., backend="numba", sensing=..., faults=...)`` must be the numpy driver's
run trial by trial: the same statuses and steps, the same final states to 1e-12 (the
kernel follows the driver's arithmetic, so they are in fact equal), for every law, each
sensing key alone and a robot that stops, on the triangle and the square with both
diagonals; with noise and losses the kernel uses the channel's draws, so a trial is the
same alone and in a batch, and the same as on the numpy path.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from _scenarios import clear_starts

import formationlab as fl
from formationlab.controllers import laws_in
from formationlab.dynamics import System
from formationlab.io.scenario import load_scenario
from formationlab.models import DoubleIntegrator, Unicycle
from formationlab.safety import SafetyFilter
from formationlab.scenario import parse_scenario
from formationlab.sensing import BLOCK, Faults, Sensing, Stop
from formationlab.studies.batch import batch_backend, run_batch
from formationlab.studies.config import BoxInitial
from formationlab.studies.sampling import model_initial_states, trial_initial_states

TRIANGLE = fl.Formation.from_template([[0, 0], [1, 0], [0.5, 0.8]], diameters=0.2)
SQUARE = parse_scenario(
    Path(__file__).parents[1].joinpath("examples/square-with-diagonals.toml").read_text()
).formation
DT = 1e-2
EXAMPLES = Path(__file__).parents[1] / "examples"

#: each sensing key alone, and a robot that stops
CASES = {
    "frames": (Sensing(frames="local"), None),
    "frame_error": (Sensing(frame_error=0.05), None),
    "noise": (Sensing(noise=0.02), None),
    "range": (Sensing(range=1.5), None),
    "delay": (Sensing(delay=0.05), None),
    "drop": (Sensing(drop=0.5), None),
    "mismatch": (Sensing(mismatch=0.05), None),
    "stop": (None, Faults(stop=[Stop(robot=2, at=0.5)])),
}


def _both(f, law, q0, duration, sensing, faults, seeds):
    kw = dict(dt=DT, duration=duration, sensing=sensing, faults=faults, seeds=seeds)
    return (run_batch(f, law, q0, backend="numba", **kw),
            run_batch(f, law, q0, backend="numpy", **kw))  # fmt: skip


def _same(a, b) -> None:
    np.testing.assert_array_equal(a.status, b.status)
    np.testing.assert_array_equal(a.steps, b.steps)
    scale = np.abs(b.q_final).max()
    np.testing.assert_allclose(a.q_final, b.q_final, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(a.u_final, b.u_final, rtol=0, atol=1e-12 * max(1.0, scale))
    np.testing.assert_allclose(a.min_clearance, b.min_clearance, rtol=1e-12)
    np.testing.assert_allclose(a.net_speed, b.net_speed, rtol=1e-10, equal_nan=True)
    assert list(a.outcome) == list(b.outcome)


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("name", laws_in(2))
@pytest.mark.parametrize("formation", [TRIANGLE, SQUARE], ids=["triangle", "square"])
def test_the_kernel_is_the_driver_trial_by_trial(
    formation: fl.Formation, name: str, case: str
) -> None:
    sensing, faults = CASES[case]
    law = fl.get_law(name)
    q0 = clear_starts(formation.n, 6, 1)
    seeds = [(5, t) for t in range(len(q0))]
    fast, reference = _both(formation, law, q0, 3.0, sensing, faults, seeds)
    _same(fast, reference)
    plain = run_batch(formation, law, q0, dt=DT, duration=3.0)
    gap = np.abs(fast.q_final - plain.q_final).max()
    # rotated frames (at random, or the common frame with errors) leave the distance laws
    # unchanged (to rounding), but not the bearing law, which compares its measured bearings
    # with the common frame's g*; a mismatch of desired distances changes every law but the
    # bearing law, which reads no distance
    turned = case in ("frames", "frame_error")
    unchanged = case == "mismatch" if name == "bearing" else turned
    if unchanged:
        assert gap < 1e-9
    else:  # the case is not the paper's run in disguise: the kernel applied it
        assert gap > 1e-6


def test_everything_at_once_over_several_blocks() -> None:
    """Frames, noise, range, delay, losses, mismatch and a stop, for more than BLOCK steps."""
    s = Sensing(frames="local", noise=0.01, range=2.5, delay=0.03, drop=0.3, mismatch=0.02)
    faults = Faults(stop=[Stop(robot=3, at=1.0)])
    q0 = clear_starts(SQUARE.n, 5, 2)
    seeds = [(9, t) for t in range(5)]
    duration = 3 * BLOCK * DT
    fast, reference = _both(SQUARE, fl.AngleRestrictedLaw(), q0, duration, s, faults, seeds)
    _same(fast, reference)
    assert fast.steps.max() > 2 * BLOCK  # the draws of later blocks were used


def test_a_trial_is_the_same_alone_and_in_a_batch() -> None:
    s = Sensing(frames="local", noise=0.02, drop=0.3, mismatch=0.03, delay=0.02)
    q0 = clear_starts(TRIANGLE.n, 7, 3)
    seeds = [(4, t) for t in range(7)]
    law = fl.DistanceLaw()
    whole = run_batch(TRIANGLE, law, q0, dt=DT, duration=6.0, sensing=s, seeds=seeds)
    assert whole.steps.min() > BLOCK  # noisy trials run past the first block
    for t in (0, 4, 6):
        alone = run_batch(
            TRIANGLE, law, q0[t : t + 1], dt=DT, duration=6.0, sensing=s, seeds=seeds[t : t + 1]
        )
        np.testing.assert_array_equal(alone.q_final[0], whole.q_final[t])
        assert alone.steps[0] == whole.steps[t]
    # and another seed is another run
    other = run_batch(TRIANGLE, law, q0[:1], dt=DT, duration=6.0, sensing=s, seeds=[(4, 1)])
    assert np.abs(other.q_final[0] - whole.q_final[0]).max() > 1e-4


def test_sensed_batches_of_every_model_stay_compiled() -> None:
    for model in (None, fl.SingleIntegrator(), Unicycle()):
        assert batch_backend("numba", sensed=True, model=model) == ("numba", "")
    assert batch_backend("numpy", sensed=True) == ("numpy", "")


#: the robot models under sensing (unicycles measure in their headings' frames)
MODELS = [
    fl.SingleIntegrator(max_speed=0.6),
    Unicycle(offset=0.05),
    Unicycle(mapping="heading", max_turn_rate=2.0),
    DoubleIntegrator(damping=2.0),
]
#: what a robot senses: its own frame and range, late, noisy, lossy, mismatched; or a stop
MIXES = {
    "frames-range-delay": (Sensing(frames="local", range=2.5, delay=0.02), None),
    "noise-drop-mismatch-stop": (
        Sensing(noise=0.01, drop=0.3, mismatch=0.03),
        Faults(stop=[Stop(robot=1, at=0.4)]),
    ),
}


def _model_starts(formation, model, batch, seed):
    q0 = clear_starts(formation.n, batch, seed)
    return model_initial_states(formation, model, q0, seed, np.arange(batch))


def _close(a, b) -> None:
    """Trial by trial the driver's run: unicycles' carried headings round within an ulp of
    the library's (models/stage.py), so states agree to 1e-9, not bit for bit."""
    np.testing.assert_array_equal(a.status, b.status)
    np.testing.assert_array_equal(a.steps, b.steps)
    np.testing.assert_allclose(a.q_final, b.q_final, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.min_clearance, b.min_clearance, rtol=0, atol=1e-9)
    assert list(a.outcome) == list(b.outcome)


@pytest.mark.parametrize("mix", list(MIXES))
@pytest.mark.parametrize("model", MODELS, ids=lambda m: repr(m)[:40])
def test_every_model_senses_on_the_compiled_loop_as_in_the_driver(model, mix) -> None:
    sensing, faults = MIXES[mix]
    x0 = _model_starts(TRIANGLE, model, 4, 2)
    seeds = [(3, t) for t in range(len(x0))]
    kw = dict(dt=DT, duration=2.0, sensing=sensing, faults=faults, seeds=seeds, model=model)
    law = fl.AngleRestrictedLaw(k_a=3.0, theta=0.5)
    fast = run_batch(TRIANGLE, law, x0, backend="numba", **kw)
    reference = run_batch(TRIANGLE, law, x0, backend="numpy", **kw)
    _close(fast, reference)
    plain = run_batch(TRIANGLE, law, x0, dt=DT, duration=2.0, model=model)
    assert np.abs(fast.q_final - plain.q_final).max() > 1e-6  # the sensing was applied


@pytest.mark.slow
def test_sensing_with_obstacles_and_a_filter_on_the_compiled_loop() -> None:
    # both filters in one test: they share one compiled kernel (about a minute to compile),
    # which two test workers would each compile at the same time
    for kind in ("barrier-decentralized", "barrier"):
        _sensing_with_obstacles_and_a_filter(kind)


def _sensing_with_obstacles_and_a_filter(kind: str) -> None:
    sc = load_scenario(EXAMPLES / "triangle-obstacle.toml")
    f = sc.formation
    q0 = trial_initial_states(f, BoxInitial(half_width=3.0), 3, np.arange(30),
                              obstacles=sc.obstacles)  # fmt: skip
    clear = System(formation=f, law=fl.DistanceLaw(), obstacles=sc.obstacles)
    q0 = q0[clear.obstacle_clearances(q0).min(axis=(-2, -1)) > 0.1][:6]
    sensing = Sensing(frames="local", noise=0.01, delay=0.02)
    kw = dict(
        dt=1e-3,
        duration=1.5,
        sensing=sensing,
        seeds=[(1, t) for t in range(len(q0))],
        obstacles=sc.obstacles,
        safety=SafetyFilter(filter=kind, distance=0.3),
    )
    fast = run_batch(f, fl.DistanceLaw(), q0, backend="numba", **kw)
    reference = run_batch(f, fl.DistanceLaw(), q0, backend="numpy", **kw)
    _close(fast, reference)
