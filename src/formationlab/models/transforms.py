"""Single-integrator-to-unicycle transforms: from a law's velocity ``u_i`` to ``(v_i, omega_i)``.

A unicycle ``x_dot = v cos(theta)``, ``y_dot = v sin(theta)``, ``theta_dot = omega``
cannot follow an arbitrary velocity; two standard transforms turn the
single-integrator control ``u_i`` of a law into a speed and a turn rate. Each is
a frozen dataclass with ``points(q, theta)`` (where the law acts) and
``commands(u, theta) -> (v, omega)``; pure functions, no state.

* :class:`NearIdentity` (``"near-identity"``): the law acts on the hand point
  ``p_i = q_i + l h_i``, ``h_i = (cos theta_i, sin theta_i)``, a distance ``l``
  ahead of the centre; ``v_i = u_i . h_i`` and ``omega_i = u_i . h_i_perp / l``
  give ``p_dot_i = v_i h_i + l omega_i h_i_perp = u_i`` exactly, so the hand
  points are single integrators (Olfati-Saber, "Near-identity diffeomorphisms
  and exponential epsilon-tracking and epsilon-stabilization of first-order
  nonholonomic SE(2) vehicles", ACC 2002).
* :class:`HeadingTransform` (``"heading"``): the Robotarium's ``si_to_uni``
  dynamics (Pickem et al., "The Robotarium: a remotely accessible swarm
  robotics research testbed", ICRA 2017; ``create_si_to_uni_dynamics``): the law
  acts on the centres, ``v_i = k_v u_i . h_i`` and
  ``omega_i = omega_max atan2(u_i . h_i_perp, u_i . h_i) / (pi / 2)``: the robot
  turns towards ``u_i`` at up to ``omega_max`` and drives along its heading.
  With ``backwards`` (``create_si_to_uni_dynamics_with_backwards_motion``),
  ``omega_i = omega_max atan((u_i . h_i_perp) / (u_i . h_i)) / (pi / 2)``: it
  turns towards ``u_i`` or ``-u_i``, whichever is nearer, and may reverse.

Arrays: positions and controls ``(..., n, 2)``, headings, speeds and turn rates ``(..., n)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from ..validation import check_fields

__all__ = ["TRANSFORMS", "HeadingTransform", "NearIdentity", "Transform", "heading_vectors"]


def heading_vectors(theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """``h = (cos theta, sin theta)``; ``(..., n) -> (..., n, 2)``."""
    return np.stack([np.cos(theta), np.sin(theta)], axis=-1)


def _along_across(
    u: NDArray[np.float64], theta: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``u . h`` and ``u . h_perp``, ``h_perp = (-sin theta, cos theta)``; each ``(..., n)``."""
    c, s = np.cos(theta), np.sin(theta)
    return c * u[..., 0] + s * u[..., 1], -s * u[..., 0] + c * u[..., 1]


@dataclass(frozen=True, kw_only=True)
class Transform:
    """Base class of the transforms (module docstring)."""

    name: ClassVar[str] = ""

    def points(self, q: NDArray[np.float64], theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """Where the law acts, ``(..., n, 2)``: the centres ``q`` unless the transform says."""
        return q

    def commands(
        self, u: NDArray[np.float64], theta: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Speed ``v`` and turn rate ``omega`` ``(..., n)`` for controls ``u`` ``(..., n, 2)``."""
        raise NotImplementedError


@dataclass(frozen=True, kw_only=True)
class NearIdentity(Transform):
    """The near-identity transform with offset ``l`` (module docstring).

    Parameters
    ----------
    offset : float
        ``l``, metres ahead of the centre; > 0.
    """

    name = "near-identity"
    offset: float = 0.05

    def __post_init__(self) -> None:
        check_fields(self, positive=("offset",))

    def points(self, q: NDArray[np.float64], theta: NDArray[np.float64]) -> NDArray[np.float64]:
        return q + self.offset * heading_vectors(theta)  # p = q + l h

    def commands(
        self, u: NDArray[np.float64], theta: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        along, across = _along_across(u, theta)
        return along, across / self.offset  # v = u . h, omega = u . h_perp / l


@dataclass(frozen=True, kw_only=True)
class HeadingTransform(Transform):
    """The Robotarium's ``si_to_uni`` dynamics (module docstring).

    Parameters
    ----------
    linear_gain : float
        ``k_v`` > 0.
    turn_gain : float
        ``omega_max``, rad/s, the turn rate towards a control straight behind; > 0.
    backwards : bool
        Turn towards ``u`` or ``-u``, whichever is nearer, and drive backwards to follow ``-u``.
    """

    name = "heading"
    linear_gain: float = 1.0
    turn_gain: float = math.pi
    backwards: bool = False

    def __post_init__(self) -> None:
        check_fields(self, positive=("linear_gain", "turn_gain"))

    def commands(
        self, u: NDArray[np.float64], theta: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        along, across = _along_across(u, theta)
        if self.backwards:
            with np.errstate(divide="ignore", invalid="ignore"):
                turn = np.arctan(across / along)
            turn = np.where(along == 0.0, np.sign(across) * (np.pi / 2), turn)
        else:
            turn = np.arctan2(across, along)
        return self.linear_gain * along, self.turn_gain * turn / (np.pi / 2)


#: The transforms by name (the ``mapping`` key of a unicycle).
TRANSFORMS: dict[str, type[Transform]] = {
    NearIdentity.name: NearIdentity,
    HeadingTransform.name: HeadingTransform,
}
