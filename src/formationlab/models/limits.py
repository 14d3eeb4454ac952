"""Actuator limits: direction-preserving saturation of a commanded velocity.

A robot that cannot move faster than ``v_max`` gets the command scaled down,
not clipped per axis: ``sat(u_i) = u_i min(1, v_max / |u_i|)`` keeps the
direction of ``u_i``. For a gradient law ``u = -grad V`` this keeps ``V``
non-increasing: ``V_dot = sum_i grad_i V . sat(u_i) = -sum_i s_i |u_i|^2 <= 0``
with ``s_i = min(1, v_max / |u_i|) > 0``.

A unicycle's speed and turn rate are limited together, by one factor
``s = min(1, v_max / |v|, omega_max / |omega|)`` on ``(v, omega)``: the path's
curvature ``omega / v`` is kept, and for the near-identity transform the hand
point's velocity (linear in ``(v, omega)``) keeps its direction, so the same
argument holds for the hand points.

Arrays: velocities ``(..., n, 2)``, speeds and turn rates ``(..., n)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..formation.geometry import row_norms
from ..validation import check_fields

__all__ = ["check_limit", "limit_speed", "limit_unicycle", "scale_factor"]


def check_limit(owner: object, *names: str) -> None:
    """Each limit of ``owner`` named in ``names`` is None (no limit) or a finite number > 0."""
    check_fields(owner, positive=tuple(n for n in names if getattr(owner, n) is not None))


def scale_factor(size: NDArray[np.float64], limit: float | None) -> NDArray[np.float64]:
    """``min(1, limit / size)`` elementwise (1 without a limit or where ``size`` is 0)."""
    if limit is None:
        return np.ones_like(size)
    return np.where(size > limit, limit / np.where(size > limit, size, 1.0), 1.0)


def limit_speed(u: NDArray[np.float64], max_speed: float | None) -> NDArray[np.float64]:
    """``u_i min(1, v_max / |u_i|)`` per robot; ``(..., n, d) -> (..., n, d)``."""
    if max_speed is None:
        return u
    size = row_norms(u)
    return u * scale_factor(size, max_speed)[..., None]


def limit_unicycle(
    v: NDArray[np.float64],
    omega: NDArray[np.float64],
    max_speed: float | None,
    max_turn_rate: float | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(s v, s omega)`` with ``s = min(1, v_max / |v|, omega_max / |omega|)``; ``(..., n)``."""
    if max_speed is None and max_turn_rate is None:
        return v, omega
    s = np.minimum(scale_factor(np.abs(v), max_speed), scale_factor(np.abs(omega), max_turn_rate))
    return s * v, s * omega
