"""Simulations: one run (:func:`simulate`) and several starts of one formation.

* :mod:`.run`: :func:`simulate`, :class:`SimulationResult`, and the builder and runner of
  a closed loop that scenarios use (:func:`build_system`, :func:`run_system`);
* :mod:`.batch`: :func:`~.batch.simulate_batch`, the runs of several starts, each its own
  ``simulate`` bit for bit.

The paper's reproduction, which runs simulations and batches of the study kernel, is
:mod:`formationlab.studies.paper`.
"""

from .run import LIST_LIMIT, SimulationResult, build_system, run_system, simulate

__all__ = ["LIST_LIMIT", "SimulationResult", "build_system", "run_system", "simulate"]
