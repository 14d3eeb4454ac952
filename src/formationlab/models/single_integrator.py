"""The paper's robots: omnidirectional single integrators, ``q_dot_i = u_i`` (eq. 1)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..formation.geometry import row_norms
from .base import RobotModel
from .limits import check_limit, limit_speed
from .registry import register_model

__all__ = ["SingleIntegrator"]


@register_model
@dataclass(frozen=True, kw_only=True)
class SingleIntegrator(RobotModel):
    """``q_dot_i = sat(u_i)`` (eq. 1): the state is the positions, shape ``(..., n, d)``,
    in the plane (``d = 2``, the paper's) or in space (``d = 3``).

    Parameters
    ----------
    max_speed : float, optional
        Largest speed, m/s: the command is scaled down to it, keeping its direction
        (:func:`~formationlab.models.limits.limit_speed`). None: no limit (eq. 1 as printed).
    """

    name = "single-integrator"
    dims = (2, 3)
    max_speed: float | None = None

    def __post_init__(self) -> None:
        check_limit(self, "max_speed")

    def names_in(self, dim: int) -> tuple[str, ...]:
        return ("x", "y", "z")[:dim]

    def positions(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        return x  # the state is the positions, in the plane or in space

    def point_rates(self, x: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        return v

    def speed(self, x: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        return row_norms(v)

    def derivative(self, x: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
        return limit_speed(u, self.max_speed)  # eq. (1)
