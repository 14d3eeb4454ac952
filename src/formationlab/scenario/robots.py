"""Building a scenario's robot model, its initial state and its marching (private).

``[robots]`` names the model (``model = "unicycle"``); its other keys than
``positions``, ``diameters`` and ``model`` are split against the model
registry (:data:`formationlab.models.MODELS`) as the laws' keys are: the
chosen model's parameters are validated and passed to it, its initial keys
(``headings``, ``velocities``) build the initial state, keys of another model
(or of the other unicycle transform) are ignored with a warning, any other key
is an error with a suggestion. ``[marching]`` becomes a
:class:`~formationlab.marching.Marching` or
:class:`~formationlab.marching.MotionParameters`.
"""

from __future__ import annotations

import math
import warnings as _warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..controllers import LAWS
from ..errors import IgnoredKeyWarning, UserInputError
from ..formation.spec import Formation
from ..marching import March, Marching, MotionParameters
from ..models import MODELS, RobotModel
from ..models.registry import initial_keys
from ..models.unicycle import MAPPING_KEYS
from ..validation import line_of
from .parts import Fail, build_entry

__all__ = ["ROBOT_FIXED", "build_marching", "build_robot_model", "initial_keys"]

#: The keys of ``[robots]`` that are not a model's parameters or initial keys.
ROBOT_FIXED = ("positions", "diameters", "model")


def build_robot_model(
    rob: Any, n: int, *, source: str, text: str, fail: Fail, warnings: list[str]
) -> tuple[RobotModel, dict[str, Any], list[str]]:
    """The model of ``[robots]``, its initial keys' values, and the ignored keys (to warn)."""
    extra = dict(rob.model_extra or {})
    owners = initial_keys()
    given = {k: v for k, v in extra.items() if k not in owners}
    try:
        cls = MODELS[rob.model]
    except UserInputError as exc:
        raise fail("robots.model", str(exc)) from None
    model, ignored = build_entry(
        MODELS, LAWS, rob.model, given, section="robots", other_section="controller",
        fixed=(*ROBOT_FIXED, *cls.initial_keys), source=source, text=text, fail=fail,
    )  # fmt: skip
    own = type(model).initial_keys
    initial = {}
    for key in (k for k in extra if k in owners):
        if key in own:
            initial[key] = _initial_value(key, extra[key], n, fail)
        else:
            ignored.append(key)
    mapping = getattr(model, "mapping", None)
    if mapping is not None:
        other = {k for m, keys in MAPPING_KEYS.items() if m != mapping for k in keys}
        off = [k for k in given if k in other]
        if off:
            line = line_of(text, f"robots.{off[0]}")
            at = f" (line {line})" if line else ""
            message = (
                f"{source}: [robots]{at}: {', '.join(off)} {'has' if len(off) == 1 else 'have'} "
                f"no effect with mapping = {mapping!r} (keys of the other transform); remove "
                f"{'it' if len(off) == 1 else 'them'} or change the mapping"
            )
            warnings.append(message)
            _warnings.warn(message, IgnoredKeyWarning, stacklevel=4)
    return model, initial, ignored


def _initial_value(key: str, value: Any, n: int, fail: Fail) -> NDArray[np.float64]:
    where = f"robots.{key}"
    if key == "headings":
        items = value if isinstance(value, list) else [value]
        if not items or not all(_is_number(x) for x in items):
            raise fail(
                where, f"headings must be one number or one per robot (radians), got {value!r}"
            )
        if not all(math.isfinite(x) for x in items):
            raise fail(where, f"headings must be finite numbers (radians), got {value!r}")
        if isinstance(value, list) and len(value) != n:
            raise fail(
                where,
                f"give one heading or one per robot: there are {n} positions but {len(value)} "
                "headings",
            )
        return np.asarray(value, dtype=float)
    if key == "velocities":
        rows: Sequence[Any] = value if value and isinstance(value[0], list) else [value]
        ok = isinstance(value, list) and all(
            isinstance(r, list) and len(r) in (2, 3) and all(_is_number(x) for x in r) for r in rows
        )  # (the model checks the rows against the formation's space)
        if not ok:
            raise fail(
                where,
                "velocities must be [vx, vy] or one [vx, vy] per robot ([vx, vy, vz] in space), "
                f"got {value!r}",
            )
        if not all(math.isfinite(x) for r in rows for x in r):
            raise fail(where, f"velocities must be finite numbers (m/s), got {value!r}")
        if isinstance(value[0], list) and len(value) != n:
            raise fail(
                where,
                f"give one [vx, vy] or one per robot: there are {n} positions but {len(value)} "
                "velocities",
            )
        return np.asarray(value, dtype=float)
    raise fail(where, f"no model takes the initial key {key!r}")  # pragma: no cover


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def build_marching(mar: Any, formation: Formation, fail: Fail) -> March | None:
    """The marching of a validated ``[marching]`` table (None without one)."""
    if mar is None:
        return None
    if mar.kind == "motion-parameters":
        if formation.dim != 2:
            raise fail(
                "marching.kind",
                "motion parameters are designed on the shape in the plane (a rotation about "
                'its centroid); a formation in space marches with kind = "reference" (every '
                "robot, or leader = [...])",
            )
        if isinstance(mar.velocity[0], list):
            raise fail(
                "marching.velocity",
                "motion parameters move the whole formation with one velocity [vx, vy]; one "
                'per leader goes with kind = "reference" and leader = [...]',
            )
        if mar.leader is not None:
            raise fail(
                "marching.leader",
                'motion parameters move every robot: a leader goes with kind = "reference"',
            )
        try:
            return MotionParameters.design(
                formation, mar.velocity, angular_velocity=mar.angular_velocity or 0.0
            )
        except UserInputError as exc:
            raise fail("marching.kind", str(exc)) from None
    if mar.angular_velocity is not None:
        raise fail(
            "marching.angular_velocity",
            'a rotation needs motion parameters: set kind = "motion-parameters"',
        )
    leader = tuple(mar.leader) if isinstance(mar.leader, list) else mar.leader
    try:
        marching = Marching(velocity=mar.velocity, leader=leader)
        marching.check(formation)
    except UserInputError as exc:
        raise fail(f"marching.{exc.key or 'leader'}", str(exc)) from None
    return marching
