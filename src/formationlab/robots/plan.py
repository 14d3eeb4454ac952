"""What a scenario asks of real drones: the law's field, the flight heights, and what is refused.

:func:`flight_plan` reads a :class:`~formationlab.scenario.Scenario` for a flight: the
closed loop it describes (:func:`formationlab.scenario.closed_loop`, the builder every front
end uses) with the robots as single integrators, whose field ``rhs(q, t)`` is the velocity
the law (with marching and a safety filter, when the scenario has them) commands at the
positions ``q``, the same function the simulator steps. A part the drones cannot honour is
refused by name, placed at its key in the file (:data:`REFUSED`); a part honoured
differently is warned about by name (:class:`FlightWarning`).
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..errors import FormationlabWarning, ParameterError
from ..models import Quadrotor, SingleIntegrator
from ..scenario import Scenario, closed_loop

if TYPE_CHECKING:
    from ..dynamics import System

__all__ = ["REFUSED", "FlightPlan", "FlightWarning", "flight_plan", "heights"]

#: the scenario parts a flight refuses, and why (the message names the key and the fix)
REFUSED = {
    "sensing": "a flight cannot honour [sensing]: it models what robots measure of each "
    "other (noise, range, delay, losses, frames), and the drones fly on their own position "
    "estimates; remove [sensing] to fly",
    "faults": "a flight cannot honour [faults]: it stops robots of a simulation, and the "
    "scenario cannot stop a drone in the air; remove [faults] to fly",
    "obstacles": "a flight cannot honour [[obstacles]]: the drones have no map of them; "
    "remove them to fly (--fence keeps the drones in a box)",
    "asynchronous": "a flight cannot honour [asynchronous]: it steps every robot at its own "
    "period, and a flight runs every drone at one rate (--rate); remove it to fly",
    "robots.model": "a flight flies the law's velocity as each drone's setpoint: the robot "
    "models it takes are 'single-integrator' and 'quadrotor'",
}


class FlightWarning(FormationlabWarning):
    """A scenario part that a flight honours differently than a simulation (message says how)."""


@dataclass(frozen=True, kw_only=True, eq=False)
class FlightPlan:
    """A scenario read for a flight.

    Attributes
    ----------
    scenario : Scenario
    system : System
        The closed loop with single integrators: ``system.rhs(p, t)`` ``(n, d)`` is the
        law's velocity at the points ``p``.
    dim : int
        2 (the drones fly the plane at one height) or 3.
    max_speed : float or None
        The scenario's own speed limit (a quadrotor's ``max_speed``), if any.
    """

    scenario: Scenario
    system: System
    dim: int
    max_speed: float | None

    @property
    def n(self) -> int:
        return self.scenario.n

    @property
    def marching(self) -> bool:
        """Whether the formation marches (then reaching the shape does not end the flight)."""
        return self.scenario.marching is not None

    def field(self, p: NDArray[np.float64], t: float) -> NDArray[np.float64]:
        """The law's velocity ``(n, d)`` at the points ``p`` ``(n, d)`` at time ``t``."""
        return self.system.rhs(p, t)


def flight_plan(scenario: Scenario) -> FlightPlan:
    """The :class:`FlightPlan` of ``scenario``, or a refusal naming the part (:data:`REFUSED`).

    Raises
    ------
    ScenarioError
        A part the drones cannot honour, at its key.
    """
    used = {
        "sensing": scenario.sensing is not None and not scenario.sensing.ideal,
        "faults": scenario.faults is not None and scenario.faults.any,
        "obstacles": bool(scenario.obstacles),
        "asynchronous": scenario.asynchronous is not None,
        "robots.model": not isinstance(scenario.model, SingleIntegrator | Quadrotor),
    }
    for key, refused in used.items():
        if refused:
            given = f", not {scenario.model.name!r}" if key == "robots.model" else ""
            raise scenario.error(key, f"{REFUSED[key]}{given}")
    limit = scenario.model.max_speed
    if isinstance(scenario.model, Quadrotor):
        warnings.warn(
            f"{scenario.source}: robots.model 'quadrotor': the drones' own velocity response "
            "replaces its time_constant and max_accel; its max_speed "
            f"({limit}) bounds the speed together with --max-speed",
            FlightWarning,
            stacklevel=2,
        )
    points = dataclasses.replace(scenario, model=SingleIntegrator(), x0=scenario.q0)
    system = closed_loop(points)
    return FlightPlan(scenario=scenario, system=system, dim=scenario.formation.dim, max_speed=limit)


def heights(plan: FlightPlan, height: float) -> NDArray[np.float64]:
    """The heights ``(n,)`` the drones take off to, metres: ``height`` for all in the plane;
    in space the scenario's start heights shifted so that the lowest is at ``height``."""
    if not height > 0:
        raise ParameterError(
            f"--height must be above the floor (> 0 m), got {height}", key="height"
        )
    if plan.dim == 2:
        return np.full(plan.n, float(height))
    z = plan.scenario.q0[:, 2]
    return z - z.min() + height
