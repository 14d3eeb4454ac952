"""Robots with inertia: double integrators ``q_ddot_i = -k_d q_dot_i + u_i(q)`` (damped gradient).

The law's control ``u_i`` (computed at the positions) acts as a force per unit
mass, with linear damping ``k_d > 0``. State ``(..., n, 4)``: ``x``, ``y``,
``vx``, ``vy``; in space ``(..., n, 6)``: ``x, y, z, vx, vy, vz``.

Lyapunov function. The distance law and the angle-restricted law are
``u = -(k_c / 2) grad V`` with ``V`` their :meth:`~formationlab.controllers.Law.potential`
(eq. 9; eq. 15 between switches). The energy

    ``E = V(q) + sum_i |q_dot_i|^2 / k_c``

has ``E_dot = grad V . q_dot + (2 / k_c) q_dot . (-k_d q_dot - (k_c / 2) grad V)
= -(2 k_d / k_c) sum_i |q_dot_i|^2 <= 0`` (:func:`energy`). For the
angle-restricted law this holds between switching instants only: ``psi_ijk`` of
eq. 14 jumps by ``alpha_ijk c_ijk = -theta`` where a restriction switches, so
``E`` jumps with ``V`` there (down when a restriction turns on, up when it turns
off; docs/robot-models.md).

Marching. A reference velocity ``v_ref`` enters as the force ``k_d v_ref``
(:attr:`DoubleIntegrator.velocity_gain`): ``q_ddot = -k_d (q_dot - v_ref) + u``.

Speed limit. With ``max_speed``, the positions move with ``sat(q_dot)`` and a
robot at the limit is braked by extra damping ``lambda_i q_dot_i`` with
``lambda_i = max(0, q_dot_i . a_i) / |q_dot_i|^2``, ``a_i = -k_d q_dot_i + u_i``:
the acceleration loses its component along ``q_dot_i`` that would speed the
robot up, and ``E_dot = -(2 / k_c) sum_i (k_d + lambda_i) |q_dot_i|^2 <= 0`` still.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ParameterError
from ..formation.geometry import row_norms
from ..validation import check_fields
from .base import RobotModel
from .limits import check_limit, limit_speed
from .registry import register_model

__all__ = ["DoubleIntegrator", "VelocityState", "energy", "initial_velocities"]


def energy(potential: ArrayLike, x: NDArray[np.float64], k_c: float) -> NDArray[np.float64]:
    """``E = V + sum_i |q_dot_i|^2 / k_c`` (module docstring); ``V (...)``, ``x (..., n, 2d)``."""
    w = x[..., x.shape[-1] // 2 :]
    return np.asarray(potential, dtype=float) + np.sum(w * w, axis=(-2, -1)) / k_c


@dataclass(frozen=True, kw_only=True)
class VelocityState(RobotModel):
    """What the models whose state is positions then velocities share (double integrators,
    quadrotors): ``(x, y, vx, vy)`` in the plane, ``(x, y, z, vx, vy, vz)`` in space, and
    the start's velocities (:func:`initial_velocities`)."""

    state_names = ("x", "y", "vx", "vy")
    initial_keys = ("velocities",)
    dims = (2, 3)

    def names_in(self, dim: int) -> tuple[str, ...]:
        return ("x", "y", "z")[:dim] + ("vx", "vy", "vz")[:dim]

    def positions(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        return x[..., : x.shape[-1] // 2]

    def point_rates(self, x: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        return v[..., : v.shape[-1] // 2]

    def initial_state(self, q0: ArrayLike, **initial: Any) -> NDArray[np.float64]:
        """Positions ``q0`` ``(..., n, d)`` then ``velocities`` (one row for all robots or
        one per robot; default 0)."""
        return initial_velocities(self.name, q0, initial)


@register_model
@dataclass(frozen=True, kw_only=True)
class DoubleIntegrator(VelocityState):
    """Damped double integrators (module docstring).

    Parameters
    ----------
    damping : float
        ``k_d`` > 0, 1/s.
    max_speed : float, optional
        Largest ``|q_dot_i|``, m/s.
    """

    name = "double-integrator"
    command_is_velocity = False  # u is a force: the velocity lags it
    damping: float = 2.0
    max_speed: float | None = None

    def __post_init__(self) -> None:
        check_fields(self, positive=("damping",))
        check_limit(self, "max_speed")

    @property
    def velocity_gain(self) -> float:
        """``k_d``: the force ``k_d v`` holds a robot at velocity ``v`` (``q_ddot = 0``)."""
        return float(self.damping)

    def derivative(self, x: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
        w = x[..., x.shape[-1] // 2 :]
        a = -self.damping * w + u  # q_ddot = -k_d q_dot + u
        if self.max_speed is not None:
            w2 = np.sum(w * w, axis=-1)
            push = np.sum(w * a, axis=-1)
            at_limit = (w2 >= self.max_speed**2) & (push > 0)
            brake = np.where(at_limit, push / np.where(w2 > 0, w2, 1.0), 0.0)
            a = a - brake[..., None] * w  # extra damping at the limit
            w = limit_speed(w, self.max_speed)
        return np.concatenate([w, a], axis=-1)

    def speed(self, x: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        """``max(|q_dot_i|, |q_dot_i + q_ddot_i / k_d|)``: the velocity now and the one it tends to.

        ``q_dot + q_ddot / k_d = u / k_d`` is the velocity the current force would
        settle to: a robot at rest but pushed (the turning point of an
        oscillation) is not stopped.
        """
        d = v.shape[-1] // 2
        w, a = v[..., :d], v[..., d:]
        terminal = w + a / self.damping
        return np.maximum(row_norms(w), row_norms(terminal))


def initial_velocities(name: str, q0: ArrayLike, initial: dict[str, Any]) -> NDArray[np.float64]:
    """The state ``(..., n, 2d)`` of positions ``q0`` ``(..., n, d)`` and their velocities:
    ``initial["velocities"]``, one row for all robots or one per robot (default 0), for
    the models whose state is positions then velocities (``name`` says which, in messages)."""
    q0 = np.asarray(q0, dtype=float)
    unknown = set(initial) - {"velocities"}
    if unknown:
        raise ParameterError(
            f"a {name}'s initial state takes velocities only, got " + ", ".join(sorted(unknown))
        )
    given = initial.get("velocities")
    w = np.zeros(q0.shape) if given is None else np.asarray(given, dtype=float)
    if not np.all(np.isfinite(w)):
        raise ParameterError(f"velocities must be finite numbers (m/s), got {given!r}")
    row = "[vx, vy, vz]" if q0.shape[-1] == 3 else "[vx, vy]"
    try:
        w = np.broadcast_to(w, q0.shape)
    except ValueError:
        raise ParameterError(
            f"give one {row} or one per robot: there are {q0.shape[-2]} robots but "
            f"velocities has shape {np.shape(w)}",
            key="velocities",
        ) from None
    return np.concatenate([q0, w], axis=-1)
