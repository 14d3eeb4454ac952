"""Krick et al.'s edge potential ``1/4 (r^2 - d^2)^2`` and its force.

Reference: L. Krick, M. E. Broucke and B. A. Francis, "Stabilisation of infinitesimally
rigid formations of multi-robot networks", International Journal of Control 82(3):423-439,
2009.
"""

from __future__ import annotations

from . import formula

__all__ = ["squared_gain", "squared_value"]


@formula
def squared_value(r2, d):
    """``1/4 (r^2 - d^2)^2`` of an edge seen at squared distance ``r2``."""
    e = r2 - d * d
    return 0.25 * (e * e)


@formula
def squared_gain(r2, d):
    """``(d/dr (1/4 (r^2 - d^2)^2)) / r = r^2 - d^2``: robot ``i`` gets ``k`` times this times
    ``r_ij`` (Krick et al. 2009)."""
    return r2 - d * d
