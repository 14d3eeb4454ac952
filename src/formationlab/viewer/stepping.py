"""Large live formations stepped on the engine's compiled loop, a segment at a time.

The live session (:mod:`.session`) steps a formation with the stepping driver's body, one
numpy step per call (:class:`formationlab.integrators.driver.Stepping`): milliseconds a
step at a thousand robots, so that "x1" played at a tenth of real time. From
:data:`COMPILED_FROM` robots, when the closed loop can run compiled (explicit Euler, a law
with kernel terms, a robot model of ``models/terms.py``: what ``simulate`` runs compiled,
:func:`formationlab.integrators.compiled.compiled_terms`), the session runs its steps in
segments on the engine's compiled single run instead
(:class:`formationlab.integrators.compiled.SingleRun`, on the law's lists layout, built
once per law), with the same semantics as the driver, to rounding (tested against it).
A segment starts from the session's state and time, so a drag or a perturbation between
two segments is seen by the next. What keeps the driver's path: a robot held by the
pointer (it is held before each step is judged), sensing and faults (their measurement
channel draws step by step), a marching reference that is a function of time, and any
other integrator.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from ..dynamics import System
from ..engine.layout import RunLayout
from ..integrators import FixedStepIntegrator
from ..integrators.compiled import SingleRun, compiled_terms
from ..status import Status

__all__ = ["COMPILED_FROM", "CompiledSteps", "Segment"]

#: Robots from which the live session steps on the compiled loop: below, a numpy step
#: costs a small part of a frame's budget (measured, ``benchmarks/bench_viewer_speed.py
#: --counts``: 0.21 ms per step at 25 robots, 0.42 ms at 50, 0.96 ms at 200, against
#: 0.011-0.017 ms compiled), and the driver's path is bit for bit ``simulate``'s.
COMPILED_FROM = 50
#: Most saved numbers (robots x states) of one segment: past it, the segment keeps every
#: few steps only (the session's history is thinned past its own budget anyway).
SEGMENT_SAVED_MAX = 400_000


@dataclasses.dataclass(frozen=True, kw_only=True, eq=False)
class Segment:
    """What a compiled segment did.

    Attributes
    ----------
    steps : int
        Steps accepted (fewer than asked when the contact rule refused one).
    k : ndarray of int64, shape (S,)
        The steps kept along the way, counted from the segment's start (the last is ``steps``).
    x : ndarray, shape (S, n, k)
        The states at those steps (robot 1 is row 0).
    status : Status
        ``SUCCESS``, or why a step was refused (``step-collision``, ``non-finite`` ...).
    message : str
        The driver's words for a refused step (empty on success).
    """

    steps: int
    k: NDArray[np.int64]
    x: NDArray[np.float64]
    status: Status
    message: str


class CompiledSteps:
    """The compiled loop of one closed loop and integrator, run in segments from any state.

    Build it with :meth:`for_system`, which says whether the loop can run compiled.
    """

    def __init__(self, system: System, integrator: FixedStepIntegrator, layout: RunLayout):
        self.system, self.integrator, self.layout = system, integrator, layout

    @classmethod
    def for_system(cls, system: System, integrator: FixedStepIntegrator) -> CompiledSteps | None:
        """The compiled steps of ``system`` under ``integrator``, or None where the live
        session keeps the driver's path (module docstring)."""
        if system.formation.n < COMPILED_FROM or getattr(system.marching, "time_dependent", False):
            return None
        if system.sensed or (system.faults is not None and system.faults.any):
            return None
        layout = compiled_terms(system, integrator)
        if not isinstance(layout, RunLayout):  # (None: it cannot run compiled)
            return None
        return cls(system, integrator, layout)

    def run(self, x: NDArray[np.float64], t0: float, steps: int) -> Segment:
        """``steps`` steps from the state ``x`` ``(n, k)`` at time ``t0``.

        The states are kept every step while the segment's saved numbers stay within
        :data:`SEGMENT_SAVED_MAX`, else every few steps; the last accepted state always.
        """
        dt = float(self.integrator.dt)
        every = max(1, math.ceil(steps * x.size / SEGMENT_SAVED_MAX))
        run = SingleRun(self.layout, x, dt=dt, n_steps=steps, save_every=every, system=self.system)
        run.advance(steps)
        k, xs, v = run.saved()
        status, message = run.status, ""
        if status is not Status.SUCCESS:  # the driver's words, from the last accepted state
            x_next = xs[-1] + dt * v[-1]
            when = t0 + (run.step + 1) * dt
            message = self.system.step_message(xs[-1], x_next, status, when, dt)
        return Segment(steps=run.step, k=k, x=xs, status=status, message=message)
