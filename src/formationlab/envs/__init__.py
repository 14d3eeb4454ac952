"""Environments for learning: the robots of a scenario as the agents of PettingZoo.

* :mod:`.pettingzoo`: the robots of a scenario as the agents of a PettingZoo parallel
  environment (:func:`parallel_env`, :class:`FormationEnv`; needs the ``agents`` extra,
  ``pip install formationlab[agents]``, imported only when used);
* :mod:`.vector`: ``B`` formations stepped at once on the engine's compiled stages, as a
  Gymnasium ``VectorEnv`` (:class:`FormationVectorEnv`, the same extra; registered as
  ``gymnasium.make_vec("formationlab/FormationVector-v0", num_envs=B, scenario=...)``);
* :mod:`.policy`: the scenario's law as every agent's policy (:func:`law_policy`, and
  :func:`vector_law_policy` for the vectorised environment);
* :mod:`.torchrl`: the vectorised environment as a TorchRL ``EnvBase`` (the ``torch``
  extra).

They sit above the scenario layer (an environment is built from a scenario file) and below
the outer layer of plotting, files and commands.
"""

from typing import Any

from .policy import law_policy, vector_law_policy

__all__ = ["FormationEnv", "FormationVectorEnv", "law_policy", "parallel_env", "vector_law_policy"]


def __getattr__(name: str) -> Any:
    if name in ("FormationEnv", "parallel_env"):
        from . import pettingzoo  # imports PettingZoo, an optional extra: only when asked

        return getattr(pettingzoo, name)
    if name == "FormationVectorEnv":
        from . import vector  # imports Gymnasium, an optional extra: only when asked

        return vector.FormationVectorEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
