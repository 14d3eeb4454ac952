"""The robot-model contract: what a motion model provides to the closed loop.

A robot model turns the control ``u_i`` of a law (a single-integrator
velocity, eq. 1 of the paper) into the motion of a robot whose state may be
more than its position. The state of ``n`` robots is an array ``(..., n, k)``
with ``k = state_size`` numbers per robot, **positions first**
(``x[..., :2]``), then whatever the model adds (a heading, a velocity).

Extension contract
------------------
Subclass :class:`RobotModel` as a frozen, keyword-only dataclass holding the
model's parameters (validated in ``__post_init__``), set ``name``,
``state_names`` (which fixes ``state_size``) and ``initial_keys`` (the keys of a
scenario's ``[robots]`` table that build the extra state), implement
:meth:`derivative`, and where needed :meth:`points` (the points the law acts
on, e.g. a unicycle's hand point), :meth:`initial_state` and :meth:`speed`
(how fast a robot moves, for the stop rule). Register it with
:func:`formationlab.models.register_model`. Nothing else in the package
changes: the integrators step ``System.rhs``, contact is tested on
:meth:`positions`, the law sees :meth:`points`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ParameterError

__all__ = ["RobotModel"]


@dataclass(frozen=True, kw_only=True)
class RobotModel:
    """Base class of robot motion models (module docstring)."""

    name: ClassVar[str] = ""
    #: names of the per-robot state columns; the first two are the position
    state_names: ClassVar[tuple[str, ...]] = ("x", "y")
    #: keys of a scenario's ``[robots]`` table that :meth:`initial_state` takes
    initial_keys: ClassVar[tuple[str, ...]] = ()
    #: whether the law's control is a velocity command of :meth:`points` (the safety
    #: filter certifies it as one); False for a model whose command is a force
    command_is_velocity: ClassVar[bool] = True
    #: the spaces (``Formation.dim``) the model moves in; its state's columns are in the
    #: plane's terms (``state_names``) unless the model says how it extends to space
    dims: ClassVar[tuple[int, ...]] = (2,)

    def check_space(self, dim: int) -> None:
        """Refuse, by name, a formation in a space (``Formation.dim``) the model does not
        move in."""
        if dim not in self.dims:
            raise ParameterError(
                f"the robot model {self.name!r} moves in the plane, and this formation is in "
                f'space ({dim}-D): use model = "single-integrator"'
            )

    def names_in(self, dim: int) -> tuple[str, ...]:
        """The names of the state's columns for a formation in ``dim`` dimensions."""
        return self.state_names

    @classmethod
    def state_size(cls) -> int:
        """Numbers per robot in the state (``len(state_names)``)."""
        return len(cls.state_names)

    @classmethod
    def parameter_names(cls) -> tuple[str, ...]:
        """The model's parameters (its dataclass fields), as scenario keys."""
        return tuple(f.name for f in fields(cls))

    @property
    def velocity_gain(self) -> float:
        """The command that holds a robot at velocity ``v`` is ``velocity_gain * v``.

        1 for models whose command is a velocity; a marching reference velocity
        (:mod:`formationlab.marching`) is scaled by it.
        """
        return 1.0

    @property
    def points_follow_command(self) -> bool:
        """Whether :meth:`points` move with the law's command as their velocity (single
        integrators, near-identity unicycles), the premise of the safety filter's certificate."""
        return self.command_is_velocity

    @property
    def has_heading(self) -> bool:
        """Whether the state holds a heading (:meth:`heading`): a robot's own frame."""
        return "theta" in self.state_names

    def heading(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Each robot's heading ``(..., n)`` (radians), for a model with one."""
        if not self.has_heading:
            raise NotImplementedError(f"the robot model {self.name!r} has no heading")
        return x[..., self.state_names.index("theta")]

    def positions(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Robot centres ``(..., n, 2)`` of states ``(..., n, k)`` (contact is tested on them)."""
        return x[..., :2]

    def points(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Points the law acts on, ``(..., n, 2)``; the centres unless the model says otherwise."""
        return self.positions(x)

    def point_rates(self, x: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        """Velocities ``(..., n, 2)`` of :meth:`points`, given states and rates ``(..., n, k)``."""
        return v[..., :2]

    def derivative(self, x: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
        """``x_dot`` ``(..., n, k)`` given the law's control ``u`` ``(..., n, 2)`` at the points."""
        raise NotImplementedError

    def speed(self, x: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        """How fast each robot moves, ``(..., n)``, given states and their rates ``(..., n, k)``.

        The stop rule of the driver and the kernel (a trial has stopped when every
        robot's speed is at most ``StopRule.speed``). The centre's speed unless the
        model says otherwise: a robot that turns on the spot or is being
        accelerated from rest is not stopped.
        """
        w = v[..., :2]
        return np.sqrt(w[..., 0] * w[..., 0] + w[..., 1] * w[..., 1])

    def initial_state(self, q0: ArrayLike, **initial: Any) -> NDArray[np.float64]:
        """The state ``(..., n, k)`` whose positions are ``q0`` ``(..., n, 2)``.

        ``initial`` holds the values of :attr:`initial_keys` given in the
        scenario (e.g. headings); a model with no extra state takes none.
        """
        q0 = np.asarray(q0, dtype=float)
        if self.state_size() == 2:
            return q0.copy()
        raise NotImplementedError
