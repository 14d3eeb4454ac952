"""Differential-drive robots: unicycles, ``(x, y, theta)_dot = (v cos theta, v sin theta, omega)``.

The law's single-integrator control ``u_i`` becomes a speed and a turn rate
through a named transform (:mod:`formationlab.models.transforms`):
``"near-identity"`` (the law acts on hand points ``p_i = q_i + l h_i``, which then
move exactly as single integrators) or ``"heading"`` (the Robotarium's
``si_to_uni`` dynamics; the law acts on the centres). Contact is tested on the
centres ``q_i`` with the robots' diameters, as for every model. The speed and the
turn rate are limited together (:func:`~formationlab.models.limits.limit_unicycle`).

State ``(..., n, 3)``: ``x``, ``y``, ``theta`` (radians).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ParameterError
from ..validation import check_fields, one_of
from .base import RobotModel
from .limits import check_limit, limit_unicycle
from .registry import register_model
from .transforms import TRANSFORMS, HeadingTransform, NearIdentity, Transform

__all__ = ["MAPPING_KEYS", "Unicycle"]

#: The parameters each transform takes (the others are ignored, with a warning in files).
MAPPING_KEYS = {
    NearIdentity.name: ("offset",),
    HeadingTransform.name: ("linear_gain", "turn_gain", "backwards"),
}


@register_model
@dataclass(frozen=True, kw_only=True)
class Unicycle(RobotModel):
    """Unicycle robots (module docstring).

    Parameters
    ----------
    mapping : {"near-identity", "heading"}
        How ``u_i`` becomes ``(v_i, omega_i)``.
    offset : float
        Near-identity ``l``, metres (> 0).
    linear_gain, turn_gain : float
        The heading transform's ``k_v`` and ``omega_max`` (rad/s).
    backwards : bool
        The heading transform may drive backwards.
    max_speed : float, optional
        Largest ``|v|``, m/s.
    max_turn_rate : float, optional
        Largest ``|omega|``, rad/s.
    """

    name = "unicycle"
    state_names = ("x", "y", "theta")
    initial_keys = ("headings",)
    mapping: str = "near-identity"
    offset: float = 0.05
    linear_gain: float = 1.0
    turn_gain: float = math.pi
    backwards: bool = False
    max_speed: float | None = None
    max_turn_rate: float | None = None

    def __post_init__(self) -> None:
        one_of(self.mapping, "mapping", tuple(TRANSFORMS), owner="Unicycle")
        check_fields(self, positive=("offset",))  # also the length of the stop rule's speed
        check_limit(self, "max_speed", "max_turn_rate")
        _ = self.transform  # validates the transform's parameters

    @cached_property
    def transform(self) -> Transform:
        """The transform named by :attr:`mapping`, with its parameters."""
        if self.mapping == NearIdentity.name:
            return NearIdentity(offset=self.offset)
        return HeadingTransform(
            linear_gain=self.linear_gain, turn_gain=self.turn_gain, backwards=self.backwards
        )

    @property
    def points_follow_command(self) -> bool:
        """Near-identity hand points move with the command; under ``"heading"`` a robot
        turns towards it first."""
        return self.mapping == NearIdentity.name

    def points(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.transform.points(x[..., :2], x[..., 2])

    def point_rates(self, x: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        """``q_dot + l theta_dot h_perp`` for near-identity hand points, else ``q_dot``."""
        if self.mapping != NearIdentity.name:
            return v[..., :2]
        theta, turn = x[..., 2], self.offset * v[..., 2]
        return v[..., :2] + np.stack([-turn * np.sin(theta), turn * np.cos(theta)], axis=-1)

    def commands(
        self, x: NDArray[np.float64], u: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Limited speed and turn rate ``(..., n)`` for the controls ``u`` ``(..., n, 2)``."""
        v, omega = self.transform.commands(u, x[..., 2])
        return limit_unicycle(v, omega, self.max_speed, self.max_turn_rate)

    def derivative(self, x: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
        v, omega = self.commands(x, u)
        theta = x[..., 2]
        return np.stack([v * np.cos(theta), v * np.sin(theta), omega], axis=-1)

    @property
    def reach(self) -> float:
        """The length ``l`` of :meth:`speed`: the offset (either transform)."""
        return float(self.offset)

    def speed(self, x: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        """``|q_dot_i| + l |theta_dot_i|``: the fastest point within ``l`` of the centre."""
        return super().speed(x, v) + self.reach * np.abs(v[..., 2])

    def initial_state(self, q0: ArrayLike, **initial: Any) -> NDArray[np.float64]:
        """``(x, y, theta)`` from centres ``q0`` ``(..., n, 2)`` and ``headings``.

        ``headings``: radians, one number or one per robot ``(..., n)``; default 0.
        """
        q0 = np.asarray(q0, dtype=float)
        unknown = set(initial) - {"headings"}
        if unknown:
            raise ParameterError(
                f"a unicycle's initial state takes headings only, got {', '.join(sorted(unknown))}"
            )
        headings = initial.get("headings")
        theta = np.zeros(q0.shape[:-1]) if headings is None else np.asarray(headings, float)
        if not np.all(np.isfinite(theta)):
            raise ParameterError(f"headings must be finite numbers (radians), got {headings!r}")
        try:
            theta = np.broadcast_to(theta, q0.shape[:-1])
        except ValueError:
            raise ParameterError(
                f"give one heading or one per robot: there are {q0.shape[-2]} robots but "
                f"headings has shape {np.shape(theta)}",
                key="headings",
            ) from None
        return np.concatenate([q0, theta[..., None]], axis=-1)
