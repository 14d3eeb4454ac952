"""What a run will cost before it starts: steps, memory, output size, and whether they fit.

``run`` and ``validate`` print :meth:`RunPlan.describe`; ``run`` refuses a run
whose saved trajectory would not fit in memory or on disk (:func:`check_plan`)
unless ``--force``, and suggests the ``--save-every`` that makes it fit.

The memory of a run is what the integrator keeps per saved state (the state
and its Python list entry) plus what the post-processing (controls, Lyapunov
function, switching functions) allocates per state, for at most the states of
one slice of the post-processing (:mod:`formationlab.formation.chunked`: it works slice by
slice along time). The latter depends on the law and the formation, so it is
measured, not guessed: the law is evaluated on a small stack of copies of the
initial state under :mod:`tracemalloc`, which counts numpy's allocations.

The size of ``trajectory.nc`` is that of its data before compression: an upper
bound (trajectories compress by a factor of about 1.1 to 2).

A study's size (:class:`StudyPlan`, :func:`plan_study`) is its trial-steps (all groups'
trials times the steps of each) and the memory of its table of trials, which ``study``
holds whole before it writes ``trials.parquet``; ``validate`` and ``study`` refuse a
study beyond either (:func:`check_study`), at the key that sets the trials, with the
largest number of trials that fits (which is accepted).
"""

from __future__ import annotations

import dataclasses
import math
import shutil
import tracemalloc
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..formation.chunked import BUDGET, row_bytes
from ..resources import available_memory
from ..resources import size as _size

__all__ = [
    "TRIAL_STEP_LIMIT",
    "RunPlan",
    "StudyPlan",
    "available_disk",
    "available_memory",
    "check_plan",
    "check_study",
    "plan_run",
    "plan_study",
]

#: states in the stack whose post-processing is measured (fewer for many robots: each
#: state of a swarm costs a k-d tree, and 400,000 robot-states measure well enough)
_PROBE = 64
_PROBE_ROBOTS = 400_000
#: share of the available memory (and disk) a run may plan to use
_SHARE = 0.8
#: Python's cost of a saved state beyond its data: the ndarray object, the
#: time as a float object, and two list slots (bytes, CPython 3.11 on 64 bits)
_OBJECT_BYTES = 112 + 24 + 16


@dataclass(frozen=True, kw_only=True)
class RunPlan:
    """The size of a run, from its scenario and ``save_every``.

    Attributes
    ----------
    steps : int
        Integrator steps.
    saved : int
        States kept (every ``save_every``-th step, the first and the last).
    save_every : int
    memory_per_state : float
        Bytes of memory per saved state (integrator's list, stacked arrays).
    post_per_state : float
        Bytes the post-processing allocates per state it evaluates at once.
    post_states : int
        Most states the post-processing evaluates at once (one slice along time).
    output_per_state : float
        Bytes of ``trajectory.nc`` per saved state, before compression.
    output_fixed : float
        Bytes of ``trajectory.nc`` that do not grow with time (header, coordinates, the
        graph), before compression.
    """

    steps: int
    saved: int
    save_every: int
    memory_per_state: float
    output_per_state: float
    post_per_state: float = 0.0
    post_states: int = 1 << 62
    output_fixed: float = 64e3

    @property
    def memory(self) -> float:
        """Estimated peak memory of the saved trajectory and its post-processing, or the
        file ``trajectory.nc`` composed in memory before it is written, bytes."""
        post = min(self.saved, self.post_states) * self.post_per_state
        return self.saved * self.memory_per_state + max(post, self.output)

    @property
    def output(self) -> float:
        """Estimated size of ``trajectory.nc`` before compression (an upper bound), bytes."""
        return self.saved * self.output_per_state + self.output_fixed

    def with_save_every(self, save_every: int) -> RunPlan:
        """The same run storing every ``save_every``-th step."""
        return dataclasses.replace(
            self, saved=_saved(self.steps, save_every), save_every=save_every
        )

    def describe(self) -> str:
        """``"10,000 steps, 10,001 saved: ~13 MB of memory, trajectory.nc at most ~2.1 MB"``."""
        saved = "all saved" if self.save_every == 1 else f"{self.saved:,} saved"
        return (
            f"{self.steps:,} steps, {saved}: ~{_size(self.memory)} of memory, "
            f"trajectory.nc at most ~{_size(self.output)}"
        )


def _saved(steps: int, save_every: int) -> int:
    return steps // save_every + 1 + (steps % save_every != 0)


def plan_run(sc: Any, save_every: int) -> RunPlan:
    """The :class:`RunPlan` of scenario ``sc`` (a :class:`formationlab.scenario.Scenario`)."""
    from ..integrators.base import steps_for

    dt = getattr(sc.integrator, "dt", None)
    if dt is None:  # an event-driven integrator: as many saved states as it likes
        raise ParameterError("no fixed step: the run's size is not known in advance")
    steps = steps_for(sc.duration, float(dt))
    f, law = sc.formation, sc.law
    # a few states, fewer of a formation of many robots or edges (whose every state's
    # evaluation lists them all)
    probe = int(np.clip(_PROBE_ROBOTS // max(f.n, len(f.edges)), 1, _PROBE))
    q = np.broadcast_to(np.asarray(sc.q0, float), (probe, f.n, f.dim)).copy()
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        sigma = law.switching(f, q)  # what simulate computes over the saved states
        law.potential(f, q)
        post = (tracemalloc.get_traced_memory()[1] - base) / probe
    finally:
        tracemalloc.stop()
    n, m, s = f.n, len(f.edges), int(sigma.shape[-1])
    floats = 2 * f.dim * n + 1 + m + s  # q, u, V, distance errors, sigma
    stored = _OBJECT_BYTES + 16 * n + 8 * floats  # the integrator's list and the arrays
    return RunPlan(
        steps=steps,
        saved=_saved(steps, save_every),
        save_every=save_every,
        memory_per_state=stored,
        output_per_state=8.0 * (floats + 1),  # + time
        post_per_state=post,
        output_fixed=64e3 + 16.0 * n + 40.0 * m + 16.0 * s,  # robots, edges (and labels)
        post_states=max(1, int(BUDGET // row_bytes(f))),  # one slice (chunked.over_time)
    )


def available_disk(folder: Path) -> float | None:
    """Free bytes on the disk that holds ``folder`` (or its nearest existing parent)."""
    for p in (folder, *folder.absolute().parents):
        if p.exists():
            try:
                return float(shutil.disk_usage(p).free)
            except OSError:
                return None
    return None


def check_plan(plan: RunPlan, out: Path, *, save_every_given: bool) -> str | None:
    """Why the run does not fit (with the ``--save-every`` that fits), or None if it does."""
    memory, disk = available_memory(), available_disk(out)
    budgets = []
    if memory is not None and plan.memory > _SHARE * memory:
        budgets.append((f"~{_size(plan.memory)} of memory, {_size(memory)} available", "memory"))
    if disk is not None and plan.output > _SHARE * disk:
        budgets.append((f"a ~{_size(plan.output)} trajectory.nc, {_size(disk)} free", "disk"))
    if not budgets:
        return None
    states = math.inf
    if memory is not None:
        room = 0.5 * _SHARE * memory  # k states take k m + min(k, P) p: either bound fits
        every = room / (plan.memory_per_state + plan.post_per_state)
        sliced = (room - plan.post_states * plan.post_per_state) / plan.memory_per_state
        states = min(states, max(every, sliced))
    if disk is not None:
        states = min(states, 0.5 * _SHARE * (disk - plan.output_fixed) / plan.output_per_state)
    k = max(plan.save_every + 1, math.ceil(plan.steps / max(states - 2, 1)))
    what = " and ".join(b[0] for b in budgets)
    given = f" with --save-every {plan.save_every}" if save_every_given else ""
    return (
        f"the run is too large{given}: {plan.steps:,} steps, {plan.saved:,} saved states need "
        f"{what}; store fewer states with --save-every {k} (it keeps "
        f"{_saved(plan.steps, k):,}), shorten the run, or pass --force to run it anyway"
    )


# ----------------------------------------------------------------------------- studies

#: the most trial-steps one study may take: more is a mistyped number (1e13 trial-steps of
#: the paper's triangle take about two days at the 6e7 trial-steps/s of docs/studies.md)
TRIAL_STEP_LIMIT = 1e13
#: columns of ``trials.parquet`` besides the positions (docs/studies.md lists them), and the
#: copies of the table a study holds at its end (the chunks' frames, their concatenation,
#: the parquet writer's): a million trials of three robots measured 0.73 GB at the peak
_TRIAL_COLUMNS = 24
_TABLE_COPIES = 3


@dataclass(frozen=True, kw_only=True)
class StudyPlan:
    """The size of a study: ``trials`` per group in ``groups`` groups, ``steps`` per trial,
    of ``robots`` robots in ``dim`` dimensions."""

    trials: int
    groups: int
    steps: int
    robots: int
    dim: int = 2

    @property
    def trial_steps(self) -> float:
        """Explicit Euler steps of all trials (an upper bound: trials stop when they settle)."""
        return float(self.trials) * self.groups * self.steps

    @property
    def per_trial(self) -> float:
        """Bytes of memory per trial at the study's end (its row of the table, in copies)."""
        return 8.0 * _TABLE_COPIES * (_TRIAL_COLUMNS + 2 * self.robots * self.dim)

    @property
    def memory(self) -> float:
        """Bytes of memory of the table of trials at the study's end."""
        return float(self.trials) * self.groups * self.per_trial


def plan_study(setup: Any, trials: int | None = None) -> StudyPlan:
    """The :class:`StudyPlan` of a :class:`formationlab.studies.runner.StudySetup` (with
    ``trials`` per group instead of its table's, when given)."""
    from ..integrators.base import steps_for

    return StudyPlan(
        trials=int(setup.config.trials if trials is None else trials),
        groups=len(setup.groups),
        steps=steps_for(setup.duration, setup.dt),
        robots=setup.formation.n,
        dim=setup.formation.dim,
    )


def check_study(plan: StudyPlan) -> str | None:
    """Why the study is too large (its trials, with the most that fit), or None if it fits."""
    memory = available_memory()
    most = TRIAL_STEP_LIMIT / (plan.groups * plan.steps)
    too: list[str] = []
    if plan.trial_steps > TRIAL_STEP_LIMIT:
        too.append(f"{plan.trial_steps:.3g} trial-steps, more than {TRIAL_STEP_LIMIT:.0e}")
    if memory is not None:
        most = min(most, _SHARE * memory / (plan.groups * plan.per_trial))
        if plan.memory > _SHARE * memory:
            too.append(f"~{_size(plan.memory)} of memory for its table of trials, "
                       f"{_size(memory)} available")  # fmt: skip
    if not too:
        return None
    groups = f" x {plan.groups:,} groups" if plan.groups > 1 else ""
    fix = f"use at most {math.floor(most):,} trials" if most >= 1 else "shorten the trials"
    return (
        f"{plan.trials:,} trials{groups} of {plan.steps:,} steps need {' and '.join(too)}: "
        f"{fix} (or fewer steps: a longer dt or a shorter duration)"
    )
