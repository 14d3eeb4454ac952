"""Integrators of the closed loop; ``INTEGRATORS`` maps names (as in scenario files) to classes."""

from .base import (
    INTEGRATORS,
    FixedStepIntegrator,
    Integrator,
    RawSolution,
    get_integrator,
    register_integrator,
)
from .diagnostics import SwitchMonitor, switching_diagnostics
from .driver import Stepped, StopRule, drive
from .explicit import RK4, Euler
from .filippov import Filippov
from .implicit import ImplicitEuler

__all__ = [
    "INTEGRATORS",
    "RK4",
    "Euler",
    "Filippov",
    "FixedStepIntegrator",
    "ImplicitEuler",
    "Integrator",
    "RawSolution",
    "Stepped",
    "StopRule",
    "SwitchMonitor",
    "drive",
    "get_integrator",
    "register_integrator",
    "switching_diagnostics",
]
