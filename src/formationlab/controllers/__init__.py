"""Control laws: the paper's two laws and the laws they are compared with.

``LAWS`` maps a law's name (as written in scenario files) to its class.
"""

from .angle_restricted import AngleRestrictedLaw, active_restrictions, grad_psi, psi_sum
from .base import (
    LAWS,
    Law,
    ObstacleRepulsion,
    Repulsion,
    file_keys,
    get_law,
    laws_in,
    register,
)
from .bearing import BearingLaw
from .chirality_restricted import ChiralityRestrictedLaw
from .distance import DistanceLaw, grad_phi, phi_sum
from .policy import PolicyLaw
from .signed_area import SignedAreaLaw
from .squared_distance import SquaredDistanceLaw

__all__ = [
    "LAWS",
    "AngleRestrictedLaw",
    "BearingLaw",
    "ChiralityRestrictedLaw",
    "DistanceLaw",
    "Law",
    "ObstacleRepulsion",
    "PolicyLaw",
    "Repulsion",
    "SignedAreaLaw",
    "SquaredDistanceLaw",
    "active_restrictions",
    "file_keys",
    "get_law",
    "grad_phi",
    "grad_psi",
    "laws_in",
    "phi_sum",
    "psi_sum",
    "register",
]
