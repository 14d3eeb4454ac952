"""A robot model as plain numbers: what the compiled loop steps (:mod:`.stage`).

:func:`model_terms` turns a :class:`~formationlab.models.RobotModel` the compiled loop
implements into a :class:`ModelTerms` (no limit is ``inf``); other models run on
the numpy backend.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from ..errors import ParameterError
from .base import RobotModel
from .double_integrator import DoubleIntegrator
from .quadrotor import Quadrotor
from .single_integrator import SingleIntegrator
from .unicycle import Unicycle

__all__ = ["DOUBLE", "HEADING", "KERNEL_MODELS", "NEAR_IDENTITY", "POINT_KINDS", "QUADROTOR",
           "SINGLE", "ModelTerms", "model_terms"]  # fmt: skip

#: Model kinds of the kernel.
SINGLE, NEAR_IDENTITY, HEADING, DOUBLE, QUADROTOR = 0, 1, 2, 3, 4
#: Kinds whose state is a point's (positions, then velocities): the models the compiled
#: loop steps in space too (unicycles are planar).
POINT_KINDS = (SINGLE, DOUBLE, QUADROTOR)
#: Models the numba backend implements.
KERNEL_MODELS = ("single-integrator", "unicycle", "double-integrator", "quadrotor")


class ModelTerms(NamedTuple):
    """The numbers of a robot model for the kernel."""

    kind: int
    state_size: int
    offset: float  #: near-identity l (and the unicycle's stop-rule length)
    linear_gain: float
    turn_gain: float
    backwards: bool
    max_speed: float  #: inf: no limit
    max_turn_rate: float
    damping: float
    time_constant: float  #: the quadrotor's velocity lag tau (else 0)
    max_accel: float  #: the quadrotor's acceleration limit (inf: none)


def _limit(value: float | None) -> float:
    return math.inf if value is None else float(value)


def model_terms(model: RobotModel) -> ModelTerms:
    """The :class:`ModelTerms` of ``model``; a :class:`ParameterError` for other models."""
    common = {
        "max_speed": _limit(getattr(model, "max_speed", None)),
        "time_constant": 0.0,
        "max_accel": math.inf,
    }
    if type(model) is SingleIntegrator:
        return ModelTerms(
            kind=SINGLE, state_size=2, offset=0.0, linear_gain=1.0, turn_gain=0.0,
            backwards=False, max_turn_rate=math.inf, damping=0.0, **common,
        )  # fmt: skip
    if type(model) is Unicycle:
        return ModelTerms(
            kind=NEAR_IDENTITY if model.mapping == "near-identity" else HEADING, state_size=3,
            offset=float(model.offset), linear_gain=float(model.linear_gain),
            turn_gain=float(model.turn_gain), backwards=bool(model.backwards),
            max_turn_rate=_limit(model.max_turn_rate), damping=0.0, **common,
        )  # fmt: skip
    if type(model) is DoubleIntegrator:
        return ModelTerms(
            kind=DOUBLE, state_size=4, offset=0.0, linear_gain=1.0, turn_gain=0.0,
            backwards=False, max_turn_rate=math.inf, damping=float(model.damping), **common,
        )  # fmt: skip
    if type(model) is Quadrotor:
        common.update(time_constant=float(model.time_constant), max_accel=_limit(model.max_accel))
        return ModelTerms(
            kind=QUADROTOR, state_size=4, offset=0.0, linear_gain=1.0, turn_gain=0.0,
            backwards=False, max_turn_rate=math.inf, damping=0.0, **common,
        )  # fmt: skip
    raise ParameterError(
        f"the compiled kernel steps the robot models {', '.join(KERNEL_MODELS)}, not "
        f"{model.name!r} ({type(model).__name__}); use backend='numpy'"
    )
