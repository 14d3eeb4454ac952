"""The barrier condition's bound: how fast a barrier ``h`` may fall, written once.

Every row of the safety filters reads ``h_dot >= -bound(h)`` with ``h_dot = grad h . u``
(a pair's ``h = |q_i - q_j|^2 - D_s^2``, an obstacle piece's ``h = |q - p*|^2 - rho^2``);
the decentralized filter gives each robot of a pair half of it.

* The **continuous** condition of Wang, Ames and Egerstedt ("Safety barrier certificates
  for collisions-free multirobot systems", IEEE T-RO 33(3), 2017), as the Robotarium runs
  it: ``bound = gamma h^3``. It keeps ``h >= 0`` along the flow, and along an explicit
  Euler step of length ``dt`` only while ``dt gamma h^2 <= 1``.
* The **discrete** condition: ``bound = min(gamma h^3, h / dt)`` where ``h > 0``,
  ``gamma h^3`` where ``h <= 0`` (rows of pairs inside the distance, which ask ``h`` to
  grow). ``|r|^2`` and the squared distance to a convex piece are convex, so along a
  straight step ``h(q + s u) >= h + s h_dot >= h (1 - s / dt) >= 0`` for ``s`` in
  ``[0, dt]``: an explicit Euler step of single integrators that starts clear ends clear
  and stays clear along the way, whatever ``gamma``, ``dt`` and the command. Where
  ``dt gamma h^2 <= 1`` it is the continuous bound, bit for bit; it is also a class-K bound
  of ``h``, so it keeps the flow safe too (docs/safety.md, "Discrete-time safety of an
  Euler step").

:func:`barrier_bound` is the formula (numba compiles it inline into the filters' loops);
:func:`barrier_bounds` its compiled elementwise form, which the numpy filters call on
arrays (the same arithmetic, so both paths build the same rows).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numba import vectorize
from numpy.typing import ArrayLike, NDArray

from .._jit import formula

__all__ = ["CONDITIONS", "Condition", "barrier_bound", "barrier_bounds"]

Condition = Literal["discrete", "continuous"]
#: the barrier conditions by name (``SafetyFilter.condition``, the ``[safety]`` table)
CONDITIONS: tuple[str, ...] = ("discrete", "continuous")


@formula
def barrier_bound(h, gamma, step):
    """``b`` of the row ``h_dot >= -b`` of a barrier ``h`` under gain ``gamma``.

    ``step`` is the explicit Euler step the row guards (``dt``), or 0 for the continuous
    condition: ``gamma h^3`` (Wang et al. 2017), capped at ``h / step`` where ``h > 0`` and
    ``step gamma h^2 > 1``.
    """
    flow = gamma * h**3  # h_dot >= -gamma h^3 (Wang, Ames, Egerstedt 2017)
    if step > 0.0 and h > 0.0 and step * flow > h:
        return h / step  # h_{k+1} >= h_k + dt h_dot >= 0 (convexity of h)
    return flow


#: :func:`barrier_bound` elementwise (a numpy ufunc compiled by numba)
_bounds = vectorize(["float64(float64, float64, float64)"], cache=True)(barrier_bound)


def barrier_bounds(h: ArrayLike, gamma: float, step: float) -> NDArray[np.float64]:
    """:func:`barrier_bound` of every ``h`` (any shape), with the same arithmetic."""
    # (the compiled ufunc may evaluate h / step ahead of its test, also where step = 0, and
    # numpy would report the division it then discards)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(_bounds(h, gamma, step))
