"""Scenario files: their tables, validation, building, and the closed loop a scenario describes.

* :mod:`.tables`: the tables' pydantic models (the structure of a file);
* :mod:`.parse`: :func:`parse_scenario`, the frozen :class:`Scenario`;
* :mod:`.build`, :mod:`.parts`, :mod:`.robots`, :mod:`.safety`: the formation, law,
  integrator, robot model, marching and safety filter a scenario's tables build;
* :mod:`.loop`: :func:`closed_loop`, the one way from a scenario to its
  :class:`~formationlab.dynamics.System`, and :func:`run_scenario`.

Files are read by :func:`formationlab.io.scenario.load_scenario`.
"""

from .loop import closed_loop, run_scenario
from .parse import Scenario, parse_scenario
from .tables import SECTIONS, ScenarioModel

__all__ = [
    "SECTIONS",
    "Scenario",
    "ScenarioModel",
    "closed_loop",
    "parse_scenario",
    "run_scenario",
]
