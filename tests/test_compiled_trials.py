"""Runs of one formation from several starts as one compiled batch (``simulate_batch``)
against their single runs through ``simulate``: the same numbers bit for bit, trial by
trial, with repulsion through the close list, restrictions switching, the robots
renumbered, and a trial that ends on a rejected step followed by one that does not."""

import numpy as np
import pytest
from test_compiled import ladder

import formationlab as fl
from formationlab.integrators import compiled
from formationlab.simulation.batch import simulate_batch

KEYS = ("steps", "rhs_evaluations", "switch_count", "diagnostics_from", "backend", "threads")


def assert_same(batch: fl.SimulationResult, single: fl.SimulationResult) -> None:
    assert single.stats["backend"] == batch.stats["backend"] == "numba"
    assert batch.status == single.status and batch.message == single.message
    for name in ("t", "x", "xdot", "V", "sigma"):
        np.testing.assert_array_equal(getattr(batch, name), getattr(single, name), err_msg=name)
    assert {k: batch.stats.get(k) for k in KEYS} == {k: single.stats.get(k) for k in KEYS}


@pytest.mark.parametrize("law", ["distance", "angle-restricted"])
@pytest.mark.parametrize("renumbered", [False, True])
def test_a_batch_of_ladders_equals_its_single_runs(law, renumbered, monkeypatch):
    if renumbered:  # the robots' order of large formations, on a small one
        monkeypatch.setattr(compiled, "REORDER_FROM", 8)
    f, q1 = ladder(20, seed=1)
    spread = 2.0 * (q1 - q1.mean(axis=0))  # no close pair at first: an empty close list
    starts = np.stack([spread, q1, ladder(20, seed=2)[1]])
    lw = fl.get_law(law, **({"k_a": 0.3, "theta": 0.58} if law == "angle-restricted" else {}))
    kw = {"duration": 0.3, "save_every": 7}
    runs = simulate_batch(f, lw, starts, **kw)
    assert len(runs) == 3
    for q0, run in zip(starts, runs, strict=True):
        assert_same(run, fl.simulate(f, lw, q0, **kw))
    assert not np.array_equal(runs[0].q, runs[1].q)  # the trials are the starts' own
    q = runs[1].q[0]
    r = np.linalg.norm(q[:, None] - q[None], axis=-1) - 0.3 + 2 * np.eye(f.n)
    assert np.any((r < lw.repulsion.influence) & ~f.adjacency)  # repulsion is at work


def test_a_trial_that_collides_leaves_the_next_trial_alone():
    f = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    law = fl.get_law("squared-distance", k=30.0)
    starts = np.array([[[0.0, 0.0], [1.3, 0.2]], [[0.0, 0.0], [0.35, 0.0]]])
    kw = {"duration": 1.0, "integrator": fl.Euler(dt=0.02)}
    runs = simulate_batch(f, law, starts, **kw)
    assert [str(r.status) for r in runs] == ["step-collision", "success"]
    for q0, run in zip(starts, runs, strict=True):
        assert_same(run, fl.simulate(f, law, q0, **kw))


def test_a_batch_takes_the_compiled_path_only():
    f = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
    starts = np.array([[[-1.2, -0.9], [1.4, -0.7], [0.1, 1.3]]])
    with pytest.raises(fl.errors.ParameterError, match="explicit Euler"):
        simulate_batch(f, "distance", starts, duration=0.1, integrator=fl.RK4(dt=1e-3))
    with pytest.raises(fl.FormationError, match=r"\(B, 3, 2\)"):
        simulate_batch(f, "distance", starts[0], duration=0.1)
