"""The vectorised environment as a TorchRL environment (``pip install formationlab[torch]``).

:func:`torchrl_env` wraps a :class:`~formationlab.envs.vector.FormationVectorEnv` of ``B``
formations in TorchRL's ``GymWrapper`` (TorchRL, "TorchRL: A data-driven decision-making
library for PyTorch", Bou et al., ICLR 2024), which reads Gymnasium's vector API: batch size
``(B,)``, observations ``(B, n, obs)``, actions ``(B, n, 2)``, every robot's reward
``(B, n, 1)`` (TorchRL's multi-agent convention puts the agents on the dimension after the
batch), and the environment's own automatic reset. The arrays stay numpy on the
environment's side; torch only holds the copies the learner sees. Torch is needed here and
nowhere else.

TorchRL keeps the environment's ``infos`` as tensors: the episode's ``outcome`` (a name,
or ``""`` while it runs) becomes ``outcome_code``, its index in
:data:`~formationlab.outcomes.tolerances.OUTCOMES` (``-1`` while it runs).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import VectorWrapper

from ..outcomes.tolerances import OUTCOMES
from ..scenario import Scenario
from .vector import FormationVectorEnv

try:
    from torchrl.envs import GymWrapper
except ImportError as exc:  # optional extra
    raise ImportError(
        "formationlab.envs.torchrl needs torch and torchrl, the 'torch' extra: "
        "pip install formationlab[torch]"
    ) from exc

__all__ = ["outcome_codes", "torchrl_env"]


def outcome_codes(outcome: np.ndarray) -> np.ndarray:
    """Each name of ``outcome`` ``(B,)`` as its index in ``OUTCOMES``; ``""`` is ``-1``."""
    index = {name: k for k, name in enumerate(OUTCOMES)}
    return np.array([index.get(str(o), -1) for o in outcome], dtype=np.int64)


class _TensorInfos(VectorWrapper):
    """The environment with every ``infos`` entry an array of numbers (``outcome`` as its
    code) and every robot's reward in a ``reward_space`` of shape ``(B, n, 1)``."""

    def __init__(self, env: FormationVectorEnv) -> None:
        super().__init__(env)
        self.autoreset_mode = env.autoreset_mode
        b, n = env.num_envs, env.formation.n
        self.reward_space = spaces.Box(-np.inf, np.inf, (b, n, 1), np.float32)

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, infos = self.env.reset(**kwargs)
        return obs, self._numbers(infos)

    def step(self, actions: Any) -> tuple[Any, ...]:
        obs, reward, done, cut, infos = self.env.step(actions)
        return obs, reward, done, cut, self._numbers(infos)

    def _numbers(self, infos: dict[str, Any]) -> dict[str, Any]:
        out = {k: v for k, v in infos.items() if k not in ("outcome", "_outcome")}
        b = self.env.num_envs
        out["outcome_code"] = outcome_codes(infos.get("outcome", np.full(b, "")))
        return out


def torchrl_env(
    scenario: Scenario | str | os.PathLike[str],
    *,
    num_envs: int,
    device: str = "cpu",
    **kwargs: Any,
) -> Any:
    """``B`` formations of ``scenario`` as a TorchRL environment of batch size ``(B,)``.

    ``kwargs`` go to :class:`~formationlab.envs.vector.FormationVectorEnv` (sensing,
    faults, rewards, ...); ``device`` is where TorchRL puts its tensors.
    """
    vec = FormationVectorEnv(scenario, num_envs=num_envs, **kwargs)
    return GymWrapper(_TensorInfos(vec), device=device)
