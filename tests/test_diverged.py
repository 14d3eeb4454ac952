"""Trials that blow up are labelled so: not ``converged`` / ``not-converged``.

With k_c = 1e300 the first Euler step throws the robots to about 1e298; there the squared
distances overflow, the forces vanish, the speed reads zero and the kernel called the trial
``converged`` (outcome ``not-converged``, the numpy driver ``incorrect``). A final state
beyond validation.COORDINATE_LIMIT is ``non-finite``; a finite one spread beyond
status.DIVERGED_SCALE times the formation's size is ``diverged``; the outcome of both is
``diverged``.
"""

import numpy as np
import pytest

import formationlab as fl
from formationlab.outcomes.batch import BatchResult
from formationlab.status import DIVERGED_SCALE, Status
from formationlab.studies.batch import run_batch

TRIANGLE = fl.Formation.from_template([[0.0, 0.0], [1.0, 0.0], [0.5, 0.866]], diameters=0.2)


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_a_first_step_to_1e298_is_non_finite(backend: str) -> None:
    # beyond about 1e154 squared distances overflow (the law's forces come out 0 or NaN):
    # the step is not finite, and the trial keeps its start (classified from there, as
    # test_batch's first step that overflows)
    q0 = np.random.default_rng(0).uniform(-3, 3, (4, 3, 2))
    with np.errstate(all="ignore"):
        res = run_batch(
            TRIANGLE, fl.DistanceLaw(k_c=1e300), q0, dt=1e-2, duration=1.0, backend=backend
        )
    np.testing.assert_array_equal(res.q_final, q0)
    assert res.steps.tolist() == [0] * 4
    assert [Status.from_code(s) for s in res.status] == [Status.NON_FINITE] * 4
    assert res.outcome.tolist() == ["not-converged"] * 4


def final(q: np.ndarray, status: Status) -> BatchResult:
    q = np.asarray(q, float)[None]
    return BatchResult.from_final(
        TRIANGLE, x=q, v=np.zeros_like(q), status=np.array([status.code], np.int8),
        steps=np.array([10]), min_clearance=np.array([0.1]), net_speed=np.array([0.0]),
        dt=1e-2,
    )  # fmt: skip


def test_the_bounds_of_diverged() -> None:
    shape = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.866]])
    far = final(shape * 1e119, Status.CONVERGED)  # finite, absurd
    assert Status.from_code(far.status[0]) is Status.DIVERGED
    assert far.outcome.tolist() == ["diverged"] and np.isnan(far.converged_time[0])
    # the formation's size is 1 (its distances): up to DIVERGED_SCALE it is a trial as any
    near = final(shape * 0.5 * DIVERGED_SCALE, Status.CONVERGED)
    assert Status.from_code(near.status[0]) is Status.CONVERGED
    assert near.outcome.tolist() != ["diverged"]
    lost = final(shape * 1e151, Status.SUCCESS)
    assert Status.from_code(lost.status[0]) is Status.NON_FINITE
    assert lost.outcome.tolist() == ["diverged"]
