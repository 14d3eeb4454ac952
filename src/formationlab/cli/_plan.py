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

__all__ = ["RunPlan", "available_disk", "available_memory", "check_plan", "plan_run"]

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
