"""The tables of a scenario file as strict pydantic models (private to ``scenario``).

Structure only: types, shapes, finite numbers, known keys. The mathematics
(distances against diameters, graphs, orientations) is checked by the builders
of :class:`~formationlab.Formation`; the law's and the integrator's keys by
:mod:`formationlab._scenario_parts`.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

__all__ = [
    "SECTIONS",
    "ControllerModel",
    "FormationModel",
    "RobotsModel",
    "SafetyModel",
    "ScenarioModel",
    "SimulationModel",
]

_STRICT = ConfigDict(strict=True, extra="forbid", allow_inf_nan=False, frozen=True)


def _finite(v: Any, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ValueError(f"{what} must be a number, got {v!r}")
    if not math.isfinite(v):
        raise ValueError(f"{what} must be a finite number, got {v!r}")
    return float(v)


def _one_or_list(v: Any, what: str) -> float | list[float]:
    """One finite number, or a non-empty list of finite numbers."""
    if isinstance(v, list):
        if not v:
            raise ValueError(f"{what} must be one number or a non-empty list, got []")
        return [_finite(x, f"{what}, item {t + 1},") for t, x in enumerate(v)]
    return _finite(v, what)


def _points(v: Any, what: str) -> list[list[float]]:
    """A list of ``[x, y]`` pairs of finite numbers."""
    if not isinstance(v, list) or not v:
        raise ValueError(f"{what} must be a list of [x, y] pairs, got {v!r}")
    out = []
    for t, row in enumerate(v):
        if not isinstance(row, list) or len(row) != 2:
            raise ValueError(f"{what}, row {t + 1}, must be a pair [x, y], got {row!r}")
        out.append([_finite(x, f"{what}, row {t + 1},") for x in row])
    return out


class RobotsModel(BaseModel):
    """``[robots]``: initial positions and diameters."""

    model_config = _STRICT
    positions: list[list[float]]
    diameters: float | list[float] = 0.2

    @field_validator("positions", mode="before")
    @classmethod
    def _positions(cls, v: Any) -> list[list[float]]:
        pts = _points(v, "positions")
        if len(pts) < 2:
            raise ValueError(f"a formation needs at least 2 robots, got {len(pts)} position")
        return pts

    @field_validator("diameters", mode="before")
    @classmethod
    def _diameters(cls, v: Any) -> float | list[float]:
        d = _one_or_list(v, "diameters")
        if any(x < 0 for x in np.atleast_1d(d)):
            raise ValueError(f"diameters must be >= 0, got {v!r}")
        return d


class FormationModel(BaseModel):
    """``[formation]``: graph, desired distances, desired orientation."""

    model_config = _STRICT
    edges: Literal["complete"] | list[list[int]] = "complete"
    distances: float | list[float] | None = None
    template: list[list[float]] | None = None
    orientation: Literal["free", "template", "mirror", "table"] | None = None
    alpha: list[list[float]] | None = None

    @field_validator("edges", mode="before")
    @classmethod
    def _edges(cls, v: Any) -> str | list[list[int]]:
        if isinstance(v, str):
            if v != "complete":
                raise ValueError(f'edges must be "complete" or a list of pairs [i, j], got {v!r}')
            return v
        if not isinstance(v, list) or not v:
            raise ValueError(f'edges must be "complete" or a list of pairs [i, j], got {v!r}')
        for t, row in enumerate(v):
            ok = isinstance(row, list) and len(row) == 2
            ok = ok and all(isinstance(x, int) and not isinstance(x, bool) for x in row)
            if not ok:
                raise ValueError(
                    f"edges, item {t + 1}, must be a pair of robot numbers [i, j], got {row!r}"
                )
        return v

    @field_validator("distances", mode="before")
    @classmethod
    def _distances(cls, v: Any) -> float | list[float] | None:
        return None if v is None else _one_or_list(v, "distances")

    @field_validator("template", mode="before")
    @classmethod
    def _template(cls, v: Any) -> list[list[float]] | None:
        return None if v is None else _points(v, "template")

    @field_validator("alpha", mode="before")
    @classmethod
    def _alpha(cls, v: Any) -> list[list[float]]:
        if not isinstance(v, list) or not v:
            raise ValueError(f"alpha must be a list of rows [i, j, k, value], got {v!r}")
        for t, row in enumerate(v):
            ok = isinstance(row, list) and len(row) == 4
            ok = ok and all(isinstance(x, int) and not isinstance(x, bool) for x in row[:3])
            if not ok:
                raise ValueError(
                    f"alpha, row {t + 1}, must be [i, j, k, value] with robot numbers i, j, k, "
                    f"got {row!r}"
                )
            _finite(row[3], f"alpha, row {t + 1}, value")
        return [[float(x) for x in row] for row in v]


class ControllerModel(BaseModel):
    """``[controller]``: the law's name, how alpha is valued, and the law's parameters.

    Parameters other than ``law`` and ``alpha_values`` are kept as given and
    checked against the chosen law's dataclass fields by :func:`parse_scenario`.
    """

    model_config = ConfigDict(strict=True, extra="allow", allow_inf_nan=False, frozen=True)
    law: str = "angle-restricted"
    alpha_values: Literal["sign", "angle"] = "sign"


class SimulationModel(BaseModel):
    """``[simulation]``: integrator, its parameters (``dt``, ...), and the duration."""

    model_config = ConfigDict(strict=True, extra="allow", allow_inf_nan=False, frozen=True)
    integrator: str = "euler"
    duration: float = Field(gt=0)

    @field_validator("duration", mode="before")
    @classmethod
    def _duration(cls, v: Any) -> float:
        return _finite(v, "duration")


class SafetyModel(BaseModel):
    """``[safety]``: the safety filter between the law and the robots (``docs/safety.md``).

    Contact distances and obstacles are checked by :mod:`formationlab._scenario_safety`.
    """

    model_config = _STRICT
    filter: Literal["none", "barrier", "barrier-decentralized"] = "none"
    distance: float = 0.25
    gamma: float = 100.0
    max_speed: float | None = None
    speed_sides: int = 8
    sensing_radius: float | None = None
    obstacle_distance: float | None = None

    @field_validator("distance", "sensing_radius", "obstacle_distance", "max_speed", mode="before")
    @classmethod
    def _positive(cls, v: Any, info: Any) -> float:
        x = _finite(v, info.field_name)
        if x <= 0:
            raise ValueError(f"{info.field_name} must be > 0 (m), got {v!r}")
        return x

    @field_validator("gamma", mode="before")
    @classmethod
    def _gamma(cls, v: Any) -> float:
        x = _finite(v, "gamma")
        if x < 0:
            raise ValueError(
                f"gamma must be >= 0 (the barrier gain: 0 lets no pair approach at all, "
                f"larger values let pairs approach faster; default 100), got {v!r}"
            )
        return x

    @field_validator("speed_sides", mode="before")
    @classmethod
    def _sides(cls, v: Any) -> int:
        if isinstance(v, bool) or not isinstance(v, int) or v < 4:
            raise ValueError(f"speed_sides must be a whole number >= 4, got {v!r}")
        return v


class ScenarioModel(BaseModel):
    """The whole file. ``[study]`` and ``[equilibria]`` are passed through unvalidated."""

    model_config = _STRICT
    name: str | None = None
    description: str = ""
    robots: RobotsModel
    formation: FormationModel = FormationModel()
    controller: ControllerModel = ControllerModel()
    simulation: SimulationModel
    study: dict[str, Any] | None = None
    equilibria: dict[str, Any] | None = None
    obstacles: list[dict[str, Any]] | None = None
    safety: SafetyModel | None = None


#: The keys each table accepts (the fixed ones; laws and integrators add theirs).
SECTIONS: dict[str, tuple[str, ...]] = {
    "": tuple(ScenarioModel.model_fields),
    "robots": tuple(RobotsModel.model_fields),
    "formation": tuple(FormationModel.model_fields),
    "controller": tuple(ControllerModel.model_fields),
    "simulation": tuple(SimulationModel.model_fields),
    "safety": tuple(SafetyModel.model_fields),
}
