"""Robots as agents: what happens when each robot acts on its own view of the formation.

* :mod:`.mismatch`: neighbours that disagree about a desired distance, and the
  steady rigid motion of the distorted formation (Mou et al., IEEE TAC 2016);
* :mod:`.asynchronous`: every robot an asyncio task with its own control period and
  jitter, exchanging measurements over a bus with delay and losses (:func:`run_async`;
  :mod:`.bus`, :mod:`.clock`);

The environments that learning uses, built from a scenario, are a layer above:
:mod:`formationlab.envs` (``parallel_env``, ``FormationEnv``, ``law_policy``; their former
address here still works and warns).
"""

import warnings
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

__all__ = [
    "AsyncResult",
    "Bus",
    "DriftTable",
    "Message",
    "SteadyMotion",
    "arun",
    "first_order_motion",
    "measure_drift",
    "mismatched_controls",
    "own_distances",
    "rigid_omega",
    "run_async",
    "steady_motion",
]


def __getattr__(name: str) -> Any:
    if name in ("FormationEnv", "parallel_env", "law_policy"):
        warnings.warn(
            f"formationlab.agents.{name} moved to formationlab.envs.{name}: import it from there",
            DeprecationWarning,
            stacklevel=2,
        )
        from .. import envs  # the environments' former address (envs is a layer above)

        return getattr(envs, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
