"""Environments for learning: the robots of a scenario as the agents of PettingZoo.

* :mod:`.pettingzoo`: the robots of a scenario as the agents of a PettingZoo parallel
  environment (:func:`parallel_env`, :class:`FormationEnv`; needs the ``agents`` extra,
  ``pip install formationlab[agents]``, imported only when used);
* :mod:`.policy`: the scenario's law as every agent's policy (:func:`law_policy`).

They sit above the scenario layer (an environment is built from a scenario file) and below
the outer layer of plotting, files and commands.
"""

from typing import Any

from .policy import law_policy

__all__ = ["FormationEnv", "law_policy", "parallel_env"]


def __getattr__(name: str) -> Any:
    if name in ("FormationEnv", "parallel_env"):
        from . import pettingzoo  # imports PettingZoo, an optional extra: only when asked

        return getattr(pettingzoo, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
