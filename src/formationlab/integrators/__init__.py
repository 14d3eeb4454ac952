"""Integrators of the closed loop; ``INTEGRATORS`` maps names (as in scenario files) to classes."""

from .base import (
    INTEGRATORS,
    FixedStepIntegrator,
    Integrator,
    RawSolution,
    get_integrator,
    register_integrator,
)
from .explicit import RK4, Euler

__all__ = [
    "INTEGRATORS",
    "RK4",
    "Euler",
    "FixedStepIntegrator",
    "Integrator",
    "RawSolution",
    "get_integrator",
    "register_integrator",
]
