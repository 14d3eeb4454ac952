"""The signed-area penalty ``1/2 k_s (A_abc - A*_abc)^2`` of a triangle and its force.

Reference: B. D. O. Anderson, Z. Sun, T. Sugie, S. Azuma and K. Sakurama, "Formation shape
control with distance and area constraints", IFAC Journal of Systems and Control 1:2-12,
2017 (and Sugie et al., "On a hierarchical control strategy for multi-agent formation
without reflection", IEEE CDC 2018). ``A_abc = c_abc / 2``; ``grad_a A_abc = 1/2 k x r_bc``
(the paper's eq. 23 for ``c_abc = 2 A_abc``).
"""

from __future__ import annotations

from . import formula
from .restriction import triangle_product

__all__ = ["area_force", "area_gain", "signed_area"]


@formula
def signed_area(ax, ay, bx, by, cx, cy):
    """``A_abc = c_abc / 2``, positive when ``(a, b, c)`` turns counter-clockwise."""
    return 0.5 * triangle_product(ax, ay, bx, by, cx, cy)


@formula
def area_gain(area, target, gain):
    """``gain (A - A*) / 2``: the factor of ``k x r_bc`` in ``-gain grad_a V_A`` at vertex ``a``
    (``V_A = 1/2 (A - A*)^2``, ``grad_a A = 1/2 k x r_bc``)."""
    return gain * 0.5 * (area - target)


@formula
def area_force(g, bx, by, cx, cy):
    """Vertex ``a``'s term ``-g k x r_bc`` as ``(x, y)``, ``g`` from :func:`area_gain`."""
    return g * (cy - by), -(g * (cx - bx))
