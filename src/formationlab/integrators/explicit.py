"""Explicit fixed-step schemes: forward Euler and classic Runge-Kutta 4.

Explicit Euler is what the paper's figures need: at a switching surface of the
angle-restricted law it chatters across with an amplitude of order ``k_a dt``
(see ``docs/integrators.md``). RK4 is fourth order away from the surfaces only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..dynamics import System
from .base import FixedStepIntegrator, register_integrator

__all__ = ["RK4", "Euler"]


@register_integrator
@dataclass(frozen=True, kw_only=True)
class Euler(FixedStepIntegrator):
    """Forward Euler, ``q_{k+1} = q_k + dt f(q_k)``: first order away from switching surfaces."""

    name = "euler"
    explicit = True

    def advance(
        self,
        system: System,
        x: NDArray[np.float64],
        dt: float,
        counters: dict[str, float],
        t: float = 0.0,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        v = system.rhs(x, t)
        return x + dt * v, v


@register_integrator
@dataclass(frozen=True, kw_only=True)
class RK4(FixedStepIntegrator):
    """Classic fourth-order Runge-Kutta; fourth order only where the field is smooth."""

    name = "rk4"
    explicit = True
    evaluations_per_step = 4

    def advance(
        self,
        system: System,
        x: NDArray[np.float64],
        dt: float,
        counters: dict[str, float],
        t: float = 0.0,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        k1 = system.rhs(x, t)
        k2 = system.rhs(x + 0.5 * dt * k1, t + 0.5 * dt)
        k3 = system.rhs(x + 0.5 * dt * k2, t + 0.5 * dt)
        k4 = system.rhs(x + dt * k3, t + dt)
        total = k1 + 2 * k2 + 2 * k3 + k4
        return x + dt / 6.0 * total, total / 6.0
