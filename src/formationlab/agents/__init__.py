"""Robots as agents: what happens when each robot acts on its own view of the formation.

* :mod:`.mismatch`: neighbours that disagree about a desired distance, and the
  steady rigid motion of the distorted formation (Mou et al., IEEE TAC 2016).
"""

from .mismatch import (
    DriftTable,
    SteadyMotion,
    first_order_motion,
    measure_drift,
    mismatched_controls,
    own_distances,
    rigid_omega,
    steady_motion,
)

__all__ = [
    "DriftTable",
    "SteadyMotion",
    "first_order_motion",
    "measure_drift",
    "mismatched_controls",
    "own_distances",
    "rigid_omega",
    "steady_motion",
]
