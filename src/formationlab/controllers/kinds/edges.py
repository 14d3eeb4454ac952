"""An edge's force factor by the integer kind of its potential (for the compiled loops).

``g`` such that robot ``i`` of an edge gets ``g r_ij`` and robot ``j`` gets ``-g r_ij``.
The kinds are :data:`LOG_BARRIER` (the paper's ``phi``, :mod:`.log_barrier`) and
:data:`SQUARED` (Krick et al.'s, :mod:`.squared_distance`). A new edge potential adds its
module, its number here and its branch in :func:`edge_gain`.
"""

from __future__ import annotations

import numpy as np

from . import formula
from .log_barrier import phi_gain
from .squared_distance import squared_gain

__all__ = ["LOG_BARRIER", "SQUARED", "edge_gain"]

#: Edge potential: the paper's phi (eq. 5) or Krick et al.'s squared distance.
LOG_BARRIER, SQUARED = 0, 1


@formula
def edge_gain(kind, r2, d, a, gain):
    """``g`` of an edge seen at squared distance ``r2`` (``d`` desired, ``a`` contact); ``kind``
    is a number, the others numbers or arrays."""
    if kind == LOG_BARRIER:
        return phi_gain(np.sqrt(r2), d, a, gain)  # eq. (8)
    return gain * squared_gain(r2, d)  # Krick et al. 2009
