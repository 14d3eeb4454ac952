"""Compiled explicit-Euler runs of one formation from many starts, as one batch.

:func:`run_compiled_trials` steps ``B`` starts of the same formation under the same law
in one compiled call: the law's data are laid out once (:func:`.compiled.compiled_terms`),
the scratch space is allocated once, and each trial is the time loop of
:func:`.compiled.run_compiled` (``_run``, on one thread) from its start to the last
step, saving every ``save_every`` steps. A trial's numbers are those of its single run
(``simulate`` on the compiled path) bit for bit: the same loop and arithmetic, and
nothing of a trial is carried into the next (the close list is built anew for each;
tested against single runs). For the paper's scans and other small batches whose
paths are wanted; the study kernel (:func:`formationlab.studies.run_batch`) is the
batch for many trials that need only their final states.
"""

from __future__ import annotations

import time

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..dynamics import System
from ..status import Status
from .base import RawSolution, steps_for
from .compiled import CompiledRun, _run, _work, raw_solution, saved_rows
from .layout import RunLayout

__all__ = ["run_compiled_trials", "run_euler_compiled_trials"]


def run_compiled_trials(
    layout: RunLayout,
    q0: NDArray[np.float64],
    *,
    dt: float,
    n_steps: int,
    save_every: int,
) -> list[CompiledRun]:
    """Step each start of ``q0`` ``(B, n, 2)`` with explicit Euler, one compiled call for all.

    Returns one :class:`~.compiled.CompiledRun` per trial, as :func:`.compiled.run_compiled`
    does for one (its ``wall`` is the trial's share of the batch's wall time, in proportion
    to its steps).
    """
    n_trials, n = q0.shape[0], q0.shape[1]
    rows = saved_rows(n_steps, save_every)
    k_out = np.zeros((n_trials, rows), np.int64)
    x_out = np.zeros((n_trials, rows, n, 2))
    v_out = np.zeros((n_trials, rows, n, 2))
    info = np.zeros((n_trials, 3))  # status, last accepted step, saved rows
    clear = np.full((n_trials, 1), np.inf)
    q = np.array(q0, dtype=float)  # the runs' own copies, in the layout's numbers
    if layout.perm.size:
        q = np.ascontiguousarray(q[:, layout.perm])
    start = time.perf_counter()
    _run_trials(
        q, layout, _work(layout, n, 1), dt, n_steps, save_every, k_out, x_out, v_out, info,
        clear,
    )  # fmt: skip
    wall = time.perf_counter() - start
    steps = info[:, 1].astype(np.int64)
    share = wall / max(int(steps.sum()), 1)
    out = []
    for b in range(n_trials):
        saved, status = int(info[b, 2]), Status.from_code(int(info[b, 0]))
        run = CompiledRun(
            k_out[b, :saved], x_out[b, :saved], v_out[b, :saved], status, int(steps[b]),
            float(clear[b, 0]), share * int(steps[b]),
        )  # fmt: skip
        out.append(run)
    return out


@njit(cache=True, fastmath=False, error_model="numpy")
def _run_trials(q, L, W, dt, n_steps, save_every, k_out, x_out, v_out, info, clear):
    """Each trial ``b`` of ``q`` ``(B, n, 2)``: ``_run`` from step 0 to ``n_steps`` with a
    close list of its own (built at its first step), results in row ``b`` of the outputs."""
    pairs = np.zeros((16, 2), np.int32)
    fp = np.zeros((16, 2))
    p_rows = np.zeros(32, np.int32)
    kept = np.zeros(3)
    for b in range(q.shape[0]):
        kept[0], kept[1], kept[2] = 0.0, np.inf, 0.0  # no list yet: the first step builds it
        pairs, fp, p_rows = _run(
            q[b], L, W, pairs, fp, p_rows, dt, 0, n_steps, n_steps, save_every, k_out[b],
            x_out[b], v_out[b], info[b], clear[b], kept, False, 1,
        )  # fmt: skip


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
