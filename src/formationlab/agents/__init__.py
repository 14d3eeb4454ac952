"""Robots as agents.

* :mod:`.env`: the robots of a scenario as the agents of a PettingZoo parallel
  environment (:func:`parallel_env`; needs the ``agents`` extra,
  ``pip install formationlab[agents]``, imported only when used);
* :mod:`.policy`: the scenario's law as every agent's policy (:func:`law_policy`).
"""

from typing import Any

from .policy import law_policy

__all__ = ["FormationEnv", "law_policy", "parallel_env"]


def __getattr__(name: str) -> Any:  # the environment imports PettingZoo: only when asked
    if name in ("FormationEnv", "parallel_env"):
        from . import env

        return getattr(env, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
