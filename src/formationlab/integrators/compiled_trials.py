"""Compiled explicit-Euler runs of one formation from many starts, as one batch.

:func:`run_compiled_trials` steps ``B`` starts of the same formation under the same law:
the law's data are laid out once (:func:`.compiled.compiled_terms`) and each trial is the
single run of :func:`.compiled.run_compiled` (:class:`.compiled.SingleRun`, on one thread)
from its start to the last step, saving every ``save_every`` steps. A trial's numbers are
those of its single run (``simulate`` on the compiled path) bit for bit: the same loop and
arithmetic, and nothing of a trial is carried into the next (the close list is built anew
for each; tested against single runs). For the paper's scans and other small batches
whose paths are wanted; the study kernel (:func:`formationlab.studies.run_batch`) is the
batch for many trials that need only their final states.
"""

from __future__ import annotations

import time

import numpy as np
from numpy.typing import NDArray

from ..dynamics import System
from ..engine.layout import RunLayout
from .base import RawSolution, steps_for
from .compiled import CompiledRun, SingleRun, raw_solution

__all__ = ["run_compiled_trials", "run_euler_compiled_trials"]


def run_compiled_trials(
    layout: RunLayout,
    q0: NDArray[np.float64],
    *,
    dt: float,
    n_steps: int,
    save_every: int,
) -> list[CompiledRun]:
    """Step each start of ``q0`` ``(B, n, 2)`` with explicit Euler, one after the other.

    Returns one :class:`~.compiled.CompiledRun` per trial, as :func:`.compiled.run_compiled`
    does for one (its ``wall`` is the trial's share of the batch's wall time, in proportion
    to its steps).
    """
    start = time.perf_counter()
    runs = []
    for q in q0:
        run = SingleRun(layout, q, dt=dt, n_steps=n_steps, save_every=save_every)
        run.advance(n_steps)
        runs.append(run)
    wall = time.perf_counter() - start
    share = wall / max(sum(run.step for run in runs), 1)
    out = []
    for run in runs:
        k, x, v = run.saved()
        steps = run.step
        out.append(CompiledRun(k, x, v, run.status, steps, run.min_clearance, share * steps))
    return out


def run_euler_compiled_trials(
    layout: RunLayout,
    system: System,
    x0: NDArray[np.float64],
    *,
    dt: float,
    duration: float,
    save_every: int,
    diagnostics: bool = True,
) -> list[RawSolution]:
    """:func:`.compiled.run_euler_compiled` for each start of ``x0`` ``(B, n, 2)``, as one
    batch: one :class:`RawSolution` per trial, each that of the trial's single run."""
    n_steps = steps_for(duration, dt)
    runs = run_compiled_trials(layout, x0, dt=dt, n_steps=n_steps, save_every=save_every)
    return [
        raw_solution(out, system, dt=dt, save_every=save_every, diagnostics=diagnostics)
        for out in runs
    ]
