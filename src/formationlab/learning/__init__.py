"""Learning a decentralized law: evolution strategies over batched rollouts (docs/learning.md).

:mod:`.rollout` steps ``B`` formations at once under the learned law
(:mod:`formationlab.controllers.policy`), :mod:`.reward` scores how they ended,
:mod:`.evolution` searches the network's parameters with CMA-ES (the ``cma`` package, the
``learn`` extra) and :mod:`.evaluation` runs a policy as a study does, for the fractions
stored with the trained parameters.
"""

from .evaluation import evaluate_policy
from .evolution import Training, TrainingConfig, train
from .reward import episode_reward
from .rollout import Rollout, rollout

__all__ = [
    "Rollout",
    "Training",
    "TrainingConfig",
    "episode_reward",
    "evaluate_policy",
    "rollout",
    "train",
]
