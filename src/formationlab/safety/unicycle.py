"""Unicycles through the near-identity point, as the Robotarium filters them.

A unicycle ``x_dot = v cos(theta)``, ``y_dot = v sin(theta)``, ``theta_dot = omega`` is
not a single integrator, but the point ``p = q + l (cos theta, sin theta)`` a distance
``l > 0`` ahead of it is: ``p_dot = R(theta) diag(1, l) (v, omega)``, an invertible map
(Olfati-Saber, "Near-identity diffeomorphisms and exponential epsilon-tracking and
epsilon-stabilization of first-order nonholonomic SE(2) vehicles", ACC 2002). The
Robotarium's unicycle barrier certificate maps the unicycles to these points, runs
the single-integrator filter on them, and maps the safe point velocities back.

Safety radius. ``|q_i - p_i| = l``, so ``|p_i - p_j| >= D_s + 2 l`` implies
``|q_i - q_j| >= D_s`` (triangle inequality): :func:`point_safety_distance` returns
``D_s + 2 l``, the distance to give the filter on the points. (The Robotarium's Python
``create_unicycle_barrier_certificate`` adds ``l`` once, which does not guarantee
``D_s`` between the centres; its MATLAB ``barrierUnicycle`` adds ``2 l``, as here.) An
obstacle distance ``D_o`` becomes ``D_o + l`` for the same reason.

Arrays: positions ``(..., n, 2)``, headings and speeds ``(..., n)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ParameterError

__all__ = [
    "point_safety_distance",
    "point_to_unicycle",
    "point_velocity",
    "unicycle_points",
    "unicycle_velocity",
]


def _offset(offset: float) -> float:
    if not (isinstance(offset, int | float) and np.isfinite(offset) and offset > 0):
        raise ParameterError(
            f"the near-identity offset l must be a finite number > 0, got {offset!r}"
        )
    return float(offset)


def _heading(theta: ArrayLike) -> NDArray[np.float64]:
    theta = np.asarray(theta, dtype=float)
    return np.stack([np.cos(theta), np.sin(theta)], axis=-1)


def unicycle_points(q: ArrayLike, theta: ArrayLike, offset: float) -> NDArray[np.float64]:
    """``p = q + l (cos theta, sin theta)``; ``(..., n, 2), (..., n) -> (..., n, 2)``."""
    return np.asarray(q, dtype=float) + _offset(offset) * _heading(theta)


def point_to_unicycle(p: ArrayLike, theta: ArrayLike, offset: float) -> NDArray[np.float64]:
    """Inverse of :func:`unicycle_points`: ``q = p - l (cos theta, sin theta)``."""
    return np.asarray(p, dtype=float) - _offset(offset) * _heading(theta)


def point_velocity(
    v: ArrayLike, omega: ArrayLike, theta: ArrayLike, offset: float
) -> NDArray[np.float64]:
    """``p_dot = v (cos theta, sin theta) + l omega (-sin theta, cos theta)``; ``(..., n, 2)``."""
    ell = _offset(offset)
    c, s = np.cos(theta), np.sin(theta)
    v, omega = np.asarray(v, dtype=float), np.asarray(omega, dtype=float)
    return np.stack([v * c - ell * omega * s, v * s + ell * omega * c], axis=-1)


def unicycle_velocity(
    p_dot: ArrayLike, theta: ArrayLike, offset: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Inverse of :func:`point_velocity`: ``v = e . p_dot``, ``omega = (e_perp . p_dot) / l``.

    ``e = (cos theta, sin theta)``, ``e_perp = (-sin theta, cos theta)``. Returns ``v`` and
    ``omega``, each of shape ``(..., n)``.
    """
    ell = _offset(offset)
    p_dot = np.asarray(p_dot, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    v = c * p_dot[..., 0] + s * p_dot[..., 1]
    omega = (-s * p_dot[..., 0] + c * p_dot[..., 1]) / ell
    return v, omega


def point_safety_distance(distance: float, offset: float) -> float:
    """``D_s + 2 l``: the distance between near-identity points that keeps centres ``D_s`` apart."""
    return float(distance) + 2.0 * _offset(offset)
