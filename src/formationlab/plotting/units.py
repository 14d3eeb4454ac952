"""The units of the quantities on a figure's axes, written once.

Positions in metres, time in seconds, velocities in m/s. The gains of the paper's laws
carry the units that make ``u_i`` a velocity (eqs. 8, 11): the potentials ``phi_ij`` of
eq. (5) are dimensionless, so ``k_c`` is in m^2/s; ``psi_ijk`` of eq. (14) is in m^2
(``c_ijk`` is a cross product of two relative positions), so ``k_a`` is in 1/s and the
threshold ``theta`` in m^2.
"""

from __future__ import annotations

__all__ = ["PARAMETER_UNITS", "with_unit"]

#: unit of a scenario parameter that a study sweeps or an equilibrium is followed in
PARAMETER_UNITS: dict[str, str] = {
    "k_c": "m²/s",
    "k_a": "1/s",
    "theta": "m²",
    "diameter": "m",
    "distance": "m",
    "noise": "m",
    "range": "m",
    "frame_error": "rad",
    "delay": "s",
    "stop_at": "s",
    "dt": "s",
    "duration": "s",
}


def with_unit(name: str) -> str:
    """``name`` as an axis label with its unit, ``"k_a [1/s]"``; a parameter of no known
    unit (a count, a probability, a user's own key) as ``"drop (dimensionless)"``."""
    unit = PARAMETER_UNITS.get(name.rsplit(".", 1)[-1])
    return f"{name} [{unit}]" if unit else f"{name} (dimensionless)"
