"""The integrator contract, the fixed-step schemes' base class, and the registry.

An integrator is a frozen, keyword-only dataclass (its step and tolerances)
with one method, :meth:`Integrator.run`, which integrates a closed loop
(:class:`formationlab.dynamics.System`) from ``x0`` over ``[0, duration]`` and
returns a :class:`RawSolution`. Fixed-step schemes only implement
:meth:`FixedStepIntegrator.advance` (one step of a batch of states and the
velocity it followed); the one time loop that runs them, for a single run or a
batch of trials, is :func:`formationlab.integrators.driver.drive`.
Event-driven schemes (Filippov) override ``run`` and return the same types.

A step is judged by :meth:`System.step_verdict`, the contact rule of the
package: a step that ends in contact or carries two robots through each other
is never accepted (the exact flow of the paper's laws cannot touch: ``phi_ij``
and Khatib's ``gamma_ij`` are infinite at contact, so it is the step that is
too large); the run stops with that status and a message that says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..dynamics import System
from ..registry import Registry
from ..status import Status
from ..validation import positive
from .driver import Progress, drive, position_dim

__all__ = [
    "INTEGRATORS",
    "FixedStepIntegrator",
    "Integrator",
    "RawSolution",
    "get_integrator",
    "register_integrator",
    "steps_for",
]


@dataclass(frozen=True, kw_only=True, eq=False)
class RawSolution:
    """What an integrator returns: saved times, states and velocities, status and diagnostics.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Saved times, seconds.
    x : ndarray, shape (T, n, k)
        Saved states (positions first).
    v : ndarray, shape (T, n, k)
        The velocity the run followed from each saved state: the step's
        increment over ``dt`` for a fixed-step scheme (for implicit Euler on a
        surface, the Filippov velocity), the Filippov field for ``filippov``.
    status : Status
        How the run ended.
    message : str
        What happened, in words; says what to change when the run failed.
    stats : dict
        Diagnostics: ``steps``, ``rhs_evaluations``, ``wall_time_s``,
        ``step_cost_s``, the switching diagnostics of
        :mod:`formationlab.integrators.diagnostics` (``switch_count``,
        ``sliding_time``, ``sliding_start``, ``sliding_end``, ``max_excursion``)
        and whatever the integrator adds. Counts are integers.
    min_pair_distance : float
        Least distance of two points the safety filter keeps apart, over every accepted
        step (:meth:`formationlab.safety.SafetyFilter.least_distance`); NaN without a
        filter or where the integrator does not measure it (``filippov``).
    min_robot_clearance, min_obstacle_clearance : float
        Least robot-robot clearance ``r_ij - a_ij`` and least robot-obstacle clearance
        (inf without obstacles) over every accepted step; NaN where the integrator does
        not measure them (``filippov``).
    """

    t: NDArray[np.float64]
    x: NDArray[np.float64]
    v: NDArray[np.float64]
    status: Status = Status.SUCCESS
    message: str = ""
    stats: dict[str, Any] = field(default_factory=dict)
    dim: int = 2  #: the position columns of the state: 2 in the plane, 3 in space
    min_pair_distance: float = math.nan
    min_robot_clearance: float = math.nan
    min_obstacle_clearance: float = math.nan

    @property
    def q(self) -> NDArray[np.float64]:
        """Saved positions ``(T, n, dim)``."""
        return self.x[..., : self.dim]


@dataclass(frozen=True, kw_only=True)
class Integrator:
    """Base class of integrators."""

    name: ClassVar[str] = ""
    #: an explicit scheme: may step a sensed system (commands held over a step)
    explicit: ClassVar[bool] = False

    def run(
        self,
        system: System,
        x0: NDArray[np.float64],
        duration: float,
        *,
        save_every: int = 1,
        progress: Progress | None = None,
        interruptible: bool = False,
    ) -> RawSolution:
        """Integrate ``system`` from ``x0`` (shape ``(n, k)``) over ``[0, duration]``."""
        raise NotImplementedError


@dataclass(frozen=True, kw_only=True)
class FixedStepIntegrator(Integrator):
    """A one-step scheme with constant step ``dt``; subclasses implement :meth:`advance`."""

    dt: float = 1e-3

    def __post_init__(self) -> None:
        positive(self.dt, "dt", owner=type(self).__name__)

    #: right-hand-side evaluations per step (for the cost statistics)
    evaluations_per_step: ClassVar[int] = 1

    def advance(
        self,
        system: System,
        x: NDArray[np.float64],
        dt: float,
        counters: dict[str, float],
        t: float = 0.0,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """One step of length ``dt`` from each state of ``x`` ``(..., n, k)`` at time ``t``.

        Returns the next states and the velocity each step followed, both of the
        shape of ``x``. ``t`` is for a field that depends on time
        (``System.rhs(x, t)``: a marching reference). A scheme may add its own counts to
        ``counters``
        (``extra_rhs_evaluations`` is added to ``rhs_evaluations``).
        """
        raise NotImplementedError

    def step(
        self, system: System, x: NDArray[np.float64], dt: float, t: float = 0.0
    ) -> NDArray[np.float64]:
        """The state after one step of ``dt`` from ``x`` (shape ``(..., n, k)``) at time ``t``."""
        return self.advance(system, np.asarray(x, dtype=float), dt, {}, t)[0]

    def run(
        self,
        system: System,
        x0: NDArray[np.float64],
        duration: float,
        *,
        save_every: int = 1,
        progress: Progress | None = None,
        interruptible: bool = False,
    ) -> RawSolution:
        out = drive(
            system, self, np.asarray(x0, dtype=float)[None],
            n_steps=steps_for(duration, self.dt), save_every=save_every, diagnostics=True,
            progress=progress, interruptible=interruptible,
        )  # fmt: skip
        t, x, v = out.trajectory(0)
        return RawSolution(
            t=t, x=x, v=v, status=out.statuses()[0], message=out.message[0], stats=out.stats,
            dim=position_dim(system), min_pair_distance=float(out.min_pair_distance[0]),
            min_robot_clearance=float(out.min_clearance[0]),
            min_obstacle_clearance=float(out.min_obstacle_clearance[0]),
        )  # fmt: skip


def steps_for(duration: float, dt: float) -> int:
    """Number of steps of ``dt`` in ``duration`` (the last one may end a little late)."""
    positive(duration, "duration")
    return max(1, int(np.ceil(duration / dt - 1e-9)))


#: The integrators by name (as in scenario files); case-insensitive, with suggestions.
INTEGRATORS: Registry[Integrator] = Registry("integrator")
IntegratorT = TypeVar("IntegratorT", bound=type[Integrator])


def register_integrator(cls: IntegratorT) -> IntegratorT:
    """Class decorator: make an integrator available by its ``name``."""
    return INTEGRATORS.register(cls)


def get_integrator(name: str, **params: object) -> Integrator:
    """The integrator registered as ``name`` (any case), built with ``params``.

    A parameter of another integrator (``dt`` for ``"filippov"``) is ignored with an
    :class:`~formationlab.errors.IgnoredKeyWarning`; an unknown one is an error.
    """
    return INTEGRATORS.build(name, **params)
