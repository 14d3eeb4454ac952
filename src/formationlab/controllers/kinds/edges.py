"""An edge's force by the integer kind of its term (for the compiled loops and numpy).

:func:`edge_force` is robot ``i``'s term ``f`` of an edge seen at ``r_ij``; robot ``j`` gets
``-f``. The kinds are :data:`LOG_BARRIER` (the paper's ``phi``, :mod:`.log_barrier`) and
:data:`SQUARED` (Krick et al.'s, :mod:`.squared_distance`), whose force is ``g r_ij``, and
:data:`BEARING` (Zhao and Zelazo's bearing-only term, :mod:`.bearing`), which is not along
``r_ij`` and reads the edge's desired bearing ``(bx, by)``. :func:`edge_force_at` takes the
edge's length as well, where a loop has computed it already. A new kind of edge term adds its
module, its number here and its branch in :func:`edge_force_at`; the loops that gather edges
call only these two functions."""

from __future__ import annotations

import numpy as np

from . import formula
from .bearing import bearing_force
from .log_barrier import phi_gain
from .squared_distance import squared_gain

__all__ = ["BEARING", "LOG_BARRIER", "SQUARED", "edge_force", "edge_force_at", "edge_gain"]

#: Edge term: the paper's phi (eq. 5), Krick et al.'s squared distance, Zhao and Zelazo's
#: bearing projection.
LOG_BARRIER, SQUARED, BEARING = 0, 1, 2


@formula
def edge_force(kind, rx, ry, d, a, gain, bx, by):
    """Robot ``i``'s term ``(fx, fy)`` of an edge seen at ``r_ij = (rx, ry)`` (``d`` desired
    distance, ``a`` contact, ``(bx, by)`` desired bearing, read by :data:`BEARING` only)."""
    return edge_force_at(kind, rx, ry, np.sqrt(rx * rx + ry * ry), d, a, gain, bx, by)


@formula
def edge_force_at(kind, rx, ry, r, d, a, gain, bx, by):
    """:func:`edge_force` with the edge's length ``r = |r_ij|`` given, where a loop has it
    already (the compiled loop computes each pair's length once per state)."""
    if kind == BEARING:
        return bearing_force(rx, ry, bx, by, gain)  # Zhao and Zelazo 2016, eq. (11)
    g = edge_gain(kind, r, rx * rx + ry * ry, d, a, gain)
    return g * rx, g * ry


@formula
def edge_gain(kind, r, r2, d, a, gain):
    """The factor ``g`` of an edge term along ``r_ij`` (robot ``i``'s term is ``g r_ij``), in
    any dimension: ``r = |r_ij|`` and ``r2 = r_ij . r_ij`` (as summed by the caller), for
    :data:`LOG_BARRIER` and :data:`SQUARED` (the bearing term is not along ``r_ij``)."""
    if kind == LOG_BARRIER:
        return phi_gain(r, d, a, gain)  # eq. (8)
    return gain * squared_gain(r2, d)  # Krick et al. 2009
