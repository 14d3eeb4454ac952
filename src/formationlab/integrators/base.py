"""The integrator contract, the fixed-step loop, and the registry.

An integrator is a frozen, keyword-only dataclass (its step and tolerances)
with one method, :meth:`Integrator.run`, which integrates a closed loop
(:class:`formationlab.dynamics.System`) from ``q0`` over ``[0, duration]`` and
returns a :class:`RawSolution`. Fixed-step schemes only implement
:meth:`FixedStepIntegrator.step`; event-driven ones override ``run``.

A step that would bring two robots to ``r_ij <= a_ij`` is never accepted: the
exact flow of the paper's laws cannot do that (``phi_ij`` and Khatib's
``gamma_ij`` are infinite at contact), so it is the step that is too large.
The run stops with status ``"step-collision"`` and a message that says so.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar, Literal, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..dynamics import System
from ..errors import ParameterError
from .diagnostics import SwitchMonitor

__all__ = [
    "INTEGRATORS",
    "FixedStepIntegrator",
    "Integrator",
    "RawSolution",
    "Status",
    "get_integrator",
    "register_integrator",
]

Status = Literal["success", "step-collision", "non-finite", "event-limit", "interrupted"]
Progress = Callable[[float], None]


@dataclass(frozen=True, kw_only=True)
class RawSolution:
    """What an integrator returns: saved times and states, status and diagnostics.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Saved times, seconds.
    q : ndarray, shape (T, n, 2)
        Saved positions.
    status : str
        ``"success"``, ``"step-collision"``, ``"non-finite"``, ``"event-limit"``
        (an event-driven integrator met more switching events than it allows) or
        ``"interrupted"`` (Ctrl-C: the states up to the last accepted step).
    message : str
        What happened, in words; says what to change when the run failed.
    stats : dict
        Diagnostics: ``steps``, ``rhs_evaluations``, ``wall_time_s``,
        ``step_cost_s``, the switching diagnostics of
        :mod:`formationlab.integrators.diagnostics` (``switch_count``,
        ``sliding_time``, ``sliding_start``, ``sliding_end``, ``max_excursion``)
        and whatever the integrator adds.
    """

    t: NDArray[np.float64]
    q: NDArray[np.float64]
    status: Status = "success"
    message: str = ""
    stats: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class Integrator:
    """Base class of integrators."""

    name: ClassVar[str] = ""

    def run(
        self,
        system: System,
        q0: NDArray[np.float64],
        duration: float,
        *,
        save_every: int = 1,
        progress: Progress | None = None,
    ) -> RawSolution:
        """Integrate ``system`` from ``q0`` (shape ``(n, 2)``) over ``[0, duration]``."""
        raise NotImplementedError


@dataclass(frozen=True, kw_only=True)
class FixedStepIntegrator(Integrator):
    """A one-step scheme with constant step ``dt``; subclasses implement :meth:`step`."""

    dt: float = 1e-3

    def __post_init__(self) -> None:
        if not (isinstance(self.dt, int | float) and np.isfinite(self.dt) and self.dt > 0):
            raise ParameterError(
                f"{type(self).__name__}.dt must be a finite number > 0, got {self.dt!r}"
            )

    #: right-hand-side evaluations per step (for the cost statistics)
    evaluations_per_step: ClassVar[int] = 1

    def step(self, system: System, q: NDArray[np.float64], dt: float) -> NDArray[np.float64]:
        """One step from ``q`` (shape ``(n, 2)``) of length ``dt``."""
        raise NotImplementedError

    def _advance(
        self, system: System, q: NDArray[np.float64], dt: float, counters: dict[str, float]
    ) -> NDArray[np.float64]:
        """The step the run loop takes; a scheme may add to ``counters`` (its own stats;
        ``extra_rhs_evaluations`` is added to ``rhs_evaluations``)."""
        return self.step(system, q, dt)

    def run(
        self,
        system: System,
        q0: NDArray[np.float64],
        duration: float,
        *,
        save_every: int = 1,
        progress: Progress | None = None,
    ) -> RawSolution:
        n_steps = steps_for(duration, self.dt)
        q = np.array(q0, dtype=float)
        ts, qs = [0.0], [q.copy()]
        status: Status = "success"
        message = f"integrated {n_steps} steps of dt = {self.dt:g} s"
        start = time.perf_counter()
        report = max(1, n_steps // 100)
        monitor = SwitchMonitor(sigma0=system.sigma(q), t0=0.0)
        counters: dict[str, float] = {}
        k = accepted = 0
        shown = start
        try:
            for k in range(1, n_steps + 1):
                q_new = self._advance(system, q, self.dt, counters)
                if not np.all(np.isfinite(q_new)):
                    status = "non-finite"
                    message = (
                        f"the step to t = {k * self.dt:g} s produced NaN or infinite positions; "
                        f"reduce dt (now {self.dt:g} s)"
                    )
                    break
                gap = system.swept_clearance(q, q_new)
                if gap <= 0:
                    status = "step-collision"
                    message = contact_message(system, q_new, k * self.dt, self.dt)
                    break
                q = q_new
                accepted = k
                monitor.record(k * self.dt, system.sigma(q))
                if k % save_every == 0 or k == n_steps:
                    ts.append(k * self.dt)
                    qs.append(q.copy())
                if progress is not None and (
                    k % report == 0 or (k % 64 == 0 and time.perf_counter() - shown >= 0.5)
                ):
                    progress(k * self.dt)  # every 1 % of the run, and at least twice a second
                    shown = time.perf_counter()
            else:
                k = n_steps + 1
        except KeyboardInterrupt:  # Ctrl-C: keep the states so far
            status = "interrupted"
            message = f"interrupted by the user at t = {accepted * self.dt:g} s"
            k = accepted + 1
            del ts[len(qs) :]  # Ctrl-C between the two appends
        if status != "success" and (not ts or ts[-1] != (k - 1) * self.dt):
            ts.append((k - 1) * self.dt)  # keep the last accepted state
            qs.append(q.copy())
        wall = time.perf_counter() - start
        done = k - 1
        stats = {
            "steps": float(done),
            "rhs_evaluations": float(done * self.evaluations_per_step)
            + counters.pop("extra_rhs_evaluations", 0.0),
            "wall_time_s": wall,
            "step_cost_s": wall / max(done, 1),
            **monitor.stats(),
            **counters,
        }
        return RawSolution(
            t=np.asarray(ts), q=np.asarray(qs), status=status, message=message, stats=stats
        )


def steps_for(duration: float, dt: float) -> int:
    """Number of steps of ``dt`` in ``duration`` (the last one may end a little late)."""
    if not (np.isfinite(duration) and duration > 0):
        raise ParameterError(f"duration must be a finite number > 0, got {duration!r}")
    return max(1, int(np.ceil(duration / dt - 1e-9)))


def contact_message(system: System, q: NDArray[np.float64], t: float, dt: float) -> str:
    """Name the pair that a rejected step brought to contact, and what to do."""
    f = system.formation
    iu, ju = np.triu_indices(f.n, k=1)
    r = np.linalg.norm(q[ju] - q[iu], axis=-1)
    p = int(np.argmin(r - f.contact_matrix[iu, ju]))
    i, j = iu[p] + 1, ju[p] + 1
    return (
        f"the step to t = {t:g} s would bring robots {i} and {j} to r = {r[p]:.4g} <= "
        f"a_{i}{j} = {f.contact_matrix[iu[p], ju[p]]:g}; the exact flow cannot touch, so the "
        f"step is too large: reduce dt (now {dt:g} s), e.g. to {dt / 10:g} s"
    )


INTEGRATORS: dict[str, type[Integrator]] = {}
IntegratorT = TypeVar("IntegratorT", bound=type[Integrator])


def register_integrator(cls: IntegratorT) -> IntegratorT:
    """Class decorator: make an integrator available by its ``name``."""
    INTEGRATORS[cls.name] = cls
    return cls


def get_integrator(name: str, **params: object) -> Integrator:
    """The integrator registered as ``name``, built with ``params``."""
    try:
        cls = INTEGRATORS[name]
    except KeyError:
        known = ", ".join(sorted(INTEGRATORS))
        raise ParameterError(f"unknown integrator {name!r}; known integrators: {known}") from None
    return cls(**params)  # type: ignore[arg-type]
