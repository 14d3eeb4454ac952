"""Robots as agents: what happens when each robot acts on its own view of the formation.

* :mod:`.mismatch`: neighbours that disagree about a desired distance, and the
  steady rigid motion of the distorted formation (Mou et al., IEEE TAC 2016);
* :mod:`.asynchronous`: every robot an asyncio task with its own control period and
  jitter, exchanging measurements over a bus with delay and losses (:func:`run_async`;
  :mod:`.bus`, :mod:`.clock`);
* :mod:`.env`: the robots of a scenario as the agents of a PettingZoo parallel
  environment (:func:`parallel_env`; needs the ``agents`` extra,
  ``pip install formationlab[agents]``, imported only when used);
* :mod:`.policy`: the scenario's law as every agent's policy (:func:`law_policy`).
"""

from typing import Any

from .asynchronous import AsyncResult, arun, run_async
from .bus import Bus, Message
from .mismatch import (
    DriftTable,
    SteadyMotion,
    first_order_motion,
    measure_drift,
    mismatched_controls,
    own_distances,
    rigid_omega,
    steady_motion,
)
from .policy import law_policy

__all__ = [
    "AsyncResult",
    "Bus",
    "DriftTable",
    "FormationEnv",
    "Message",
    "SteadyMotion",
    "arun",
    "first_order_motion",
    "law_policy",
    "measure_drift",
    "mismatched_controls",
    "own_distances",
    "parallel_env",
    "rigid_omega",
    "run_async",
    "steady_motion",
]


def __getattr__(name: str) -> Any:  # the environment imports PettingZoo: only when asked
    if name in ("FormationEnv", "parallel_env"):
        from . import env

        return getattr(env, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
