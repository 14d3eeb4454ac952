"""The paper's robots: omnidirectional single integrators, ``q_dot_i = u_i`` (eq. 1)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .base import RobotModel
from .registry import register_model

__all__ = ["SingleIntegrator"]


@register_model
@dataclass(frozen=True, kw_only=True)
class SingleIntegrator(RobotModel):
    """``q_dot_i = u_i`` (eq. 1): the state is the positions, shape ``(..., n, 2)``."""

    name = "single-integrator"

    def derivative(self, x: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
        return u  # eq. (1)
