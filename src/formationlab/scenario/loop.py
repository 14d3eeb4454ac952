"""From a scenario to its closed loop: the one way every front end builds its ``System``.

:func:`closed_loop` turns a :class:`~formationlab.scenario.Scenario` into the
:class:`~formationlab.dynamics.System` it describes, with every part it holds: the
formation, the law, the robot model, marching, obstacles, the safety filter, sensing
and faults (obstacles and filter checked against the start by
:func:`formationlab.simulation.run.build_system`, the builder :func:`~formationlab.simulate`
uses). ``formationlab run`` (:func:`run_scenario`), the live viewer, the notebook
widget and the PettingZoo environment call it, so none of them can drop a part.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal

from ..errors import UserInputError
from ..simulation.run import build_system, run_system

if TYPE_CHECKING:
    from ..dynamics import System
    from ..sensing import Faults, Sensing
    from ..simulation.run import SimulationResult
    from .parse import Scenario

__all__ = ["SCENARIO", "closed_loop", "run_scenario"]

#: "the scenario's own": the default of :func:`closed_loop`'s ``sensing`` and ``faults``
SCENARIO: Any = type("ScenarioDefault", (), {"__repr__": lambda self: "SCENARIO"})()


def closed_loop(
    scenario: Scenario, *, sensing: Sensing | None = SCENARIO, faults: Faults | None = SCENARIO
) -> System:
    """The closed loop of ``scenario``: every part it holds, validated against its start.

    Parameters
    ----------
    scenario : Scenario
        A validated scenario.
    sensing, faults : Sensing or Faults or None, optional
        Replace the scenario's ``[sensing]`` or ``[faults]`` (None: none); default the
        scenario's own.

    Returns
    -------
    System
        ``System(formation, law, model, marching, obstacles, safety, sensing, faults)``.

    Raises
    ------
    ScenarioError
        A part that does not fit the others, placed at its key in the file.
    """
    sensing = scenario.sensing if sensing is SCENARIO else sensing
    faults = scenario.faults if faults is SCENARIO else faults
    try:
        return build_system(
            scenario.formation, scenario.law, scenario.model, scenario.x0,
            marching=scenario.marching, obstacles=scenario.obstacles, safety=scenario.safety,
            sensing=sensing, faults=faults,
        )  # fmt: skip
    except UserInputError as exc:
        raise scenario.locate(exc) from None


def run_scenario(
    scenario: Scenario,
    *,
    save_every: int = 1,
    progress: Callable[[float], None] | None = None,
    interruptible: bool = False,
    backend: Literal["auto", "numpy", "numba"] = "auto",
) -> SimulationResult:
    """Simulate ``scenario`` as ``formationlab run`` does: its closed loop, its integrator,
    its duration (:func:`formationlab.simulation.run.run_system`).

    Raises
    ------
    ScenarioError
        For a scenario with ``[asynchronous]`` (run it with
        :func:`formationlab.agents.run_async`, as ``formationlab run`` does).
    """
    if scenario.asynchronous is not None:
        raise scenario.error(
            "asynchronous",
            "[asynchronous] steps every robot as its own task: run it with "
            "formationlab.agents.run_async (formationlab run does)",
        )
    return run_system(
        closed_loop(scenario), scenario.integrator, scenario.x0, duration=scenario.duration,
        save_every=save_every, progress=progress, interruptible=interruptible, backend=backend,
    )  # fmt: skip
