"""A quadrotor as a formation law sees it: a velocity that follows the command with a lag.

A small quadrotor (a Crazyflie, say) is not commanded through its motors by a formation
law: its own controllers (attitude, then velocity) track a velocity setpoint, and what the
law sees is the closed loop of that tracking. To first order it is a lag with time constant
``tau``, within the vehicle's acceleration and speed limits:

    q_dot_i = w_i,    w_dot_i = sat_a((sat_v(u_i) - w_i) / tau)

with ``u_i`` the law's command (a velocity setpoint), ``sat_v`` the speed limit
``max_speed`` and ``sat_a`` the acceleration limit ``max_accel``, both scaling a vector
down to its limit and keeping its direction (:func:`~formationlab.models.limits.limit_speed`).
State ``(..., n, 2d)``: the positions, then the velocities, in the plane (``d = 2``) or in
space (``d = 3``); the point the law acts on is the centre.

Lyapunov function. Without the limits this is the damped double integrator
(:mod:`.double_integrator`) with damping ``k_d = 1 / tau`` and force ``k_d u``: for a law
``u = -(k_c / 2) grad V``,

    ``E = V(q) + (tau / k_c) sum_i |w_i|^2``,
    ``E_dot = grad V . w + (2 / k_c) w . (u - w) = -(2 / k_c) sum_i |w_i|^2 <= 0``

(:func:`energy`). The limits break the certificate: with ``s_i = min(1, v_max / |u_i|)``
the setpoint's saturation adds ``-(2 / k_c)(1 - s_i) u_i . w_i`` to ``E_dot``, of either
sign while the robot has not caught up with the command. The defaults (``tau = 0.25 s``,
``max_accel = 2 m/s^2``, ``max_speed = 1 m/s``) are of the order of what small indoor
quadrotors fly at in formation; identify yours from a step response of its velocity
controller (docs/robot-models.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..formation.geometry import row_norms
from ..validation import check_fields
from .double_integrator import VelocityState
from .limits import check_limit, limit_speed
from .registry import register_model

__all__ = ["Quadrotor", "quadrotor_energy"]


def quadrotor_energy(
    potential: ArrayLike, x: NDArray[np.float64], k_c: float, tau: float
) -> NDArray[np.float64]:
    """``E = V + (tau / k_c) sum_i |w_i|^2`` (module docstring); ``V (...)``, ``x (..., n, 2d)``."""
    w = x[..., x.shape[-1] // 2 :]
    return np.asarray(potential, dtype=float) + tau * np.sum(w * w, axis=(-2, -1)) / k_c


@register_model
@dataclass(frozen=True, kw_only=True)
class Quadrotor(VelocityState):
    """A quadrotor under its velocity controller: first-order velocity lag with limits.

    Parameters
    ----------
    time_constant : float
        ``tau`` > 0, s: how fast the velocity follows the setpoint.
    max_accel : float, optional
        Largest ``|w_dot_i|``, m/s^2 (None: no limit).
    max_speed : float, optional
        Largest setpoint speed ``|sat_v(u_i)|``, m/s (None: no limit); a robot started
        slower never exceeds it.
    """

    name = "quadrotor"
    time_constant: float = 0.25
    max_accel: float | None = 2.0
    max_speed: float | None = 1.0

    def __post_init__(self) -> None:
        check_fields(self, positive=("time_constant",))
        check_limit(self, "max_accel", "max_speed")

    @property
    def points_follow_command(self) -> bool:
        """False: the velocity lags the command (the safety filter's premise fails)."""
        return False

    def derivative(self, x: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
        w = x[..., x.shape[-1] // 2 :]
        a = (limit_speed(u, self.max_speed) - w) / self.time_constant  # the lag
        return np.concatenate([w, limit_speed(a, self.max_accel)], axis=-1)

    def speed(self, x: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        """``max(|w_i|, |w_i + tau w_dot_i|)``: the velocity now and the one it tends to (a
        hovering robot commanded to move is not stopped)."""
        d = v.shape[-1] // 2
        w, a = v[..., :d], v[..., d:]
        terminal = w + self.time_constant * a
        return np.maximum(row_norms(w), row_norms(terminal))
