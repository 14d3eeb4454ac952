"""The vectorised environment as a TorchRL environment (``pip install formationlab[torch]``).

:func:`torchrl_env` wraps a :class:`~formationlab.envs.vector.FormationVectorEnv` of ``B``
formations in TorchRL's ``GymWrapper`` (TorchRL, "TorchRL: A data-driven decision-making
library for PyTorch", Bou et al., ICLR 2024), which reads Gymnasium's vector API: batch size
``(B,)``, observations ``(B, n, obs)``, actions ``(B, n, 2)``, every robot's reward ``(B, n)``
(TorchRL's multi-agent convention puts the agents on the dimension after the batch), and
the environment's own automatic reset. The arrays stay numpy on the environment's side;
torch only holds the copies the learner sees. Torch is needed here and nowhere else.
"""

from __future__ import annotations

import os
from typing import Any

from ..scenario import Scenario
from .vector import FormationVectorEnv

try:
    from torchrl.envs import GymWrapper
except ImportError as exc:  # optional extra
    raise ImportError(
        "formationlab.envs.torchrl needs torch and torchrl, the 'torch' extra: "
        "pip install formationlab[torch]"
    ) from exc

__all__ = ["torchrl_env"]


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
    return GymWrapper(FormationVectorEnv(scenario, num_envs=num_envs, **kwargs), device=device)
