"""The tables of a scenario file as strict pydantic models (private to ``scenario``).

Structure only: types, shapes, finite numbers, known keys. The mathematics
(distances against diameters, graphs, orientations) is checked by the builders
of :class:`~formationlab.Formation`; the law's and the integrator's keys by
:mod:`formationlab.scenario.parts`.
"""

from __future__ import annotations

import math
import unicodedata
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from ..formation.templates import LATTICES
from ..validation import choices, field_words, suggest

__all__ = [
    "EDGE_NAMES",
    "SECTIONS",
    "ControllerModel",
    "FormationModel",
    "Lattice",
    "MarchingModel",
    "RobotsModel",
    "SafetyModel",
    "ScenarioModel",
    "SimulationModel",
    "StartAround",
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
    """A list of ``[x, y]`` pairs of finite numbers, or (a formation in space) of
    ``[x, y, z]`` triples; every row alike."""
    if not isinstance(v, list) or not v:
        raise ValueError(
            f"{what} must be a list of [x, y] pairs (or [x, y, z] in space), got {v!r}"
        )
    out = []
    for t, row in enumerate(v):
        size = len(out[0]) if out else None
        if not isinstance(row, list) or len(row) not in (2, 3) or size not in (None, len(row)):
            want = "a pair [x, y] or a triple [x, y, z]" if size is None else (
                "a pair [x, y], as row 1" if size == 2 else "a triple [x, y, z], as row 1"
            )  # fmt: skip
            raise ValueError(f"{what}, row {t + 1}, must be {want}, got {row!r}")
        out.append([_finite(x, f"{what}, row {t + 1},") for x in row])
    return out


def _sub_table(
    cls: type[BaseModel], v: dict[str, Any], what: str, known: dict[str, str],
    required: tuple[str, ...],
) -> Any:  # fmt: skip
    """An inline table ``v`` of the key ``what`` as the model ``cls``, whose fields state
    its ranges; the first error names the sub-key (``template.count must be ...``)."""
    _table(v, what, known, required)
    try:
        return cls.model_validate(v)
    except ValidationError as exc:
        err = exc.errors()[0]
        key = ".".join([what, *(str(p) for p in err["loc"])])
        raise ValueError(f"{key} {field_words(cls, err)}, got {err.get('input')!r}") from None


def _table(v: dict[str, Any], what: str, known: dict[str, str], required: tuple[str, ...]) -> None:
    """Check the keys of an inline table: only ``known`` ones, and the ``required`` ones."""
    for key in v:
        if key not in known:
            hint = suggest(str(key), known) or "."
            raise ValueError(
                f"{what} has no key {key!r}{hint} It takes "
                + ", ".join(f"{k} ({m})" for k, m in known.items())
            )
    for key in required:
        if key not in v:
            raise ValueError(f"{what} needs the key {key!r} ({known[key]})")


class StartAround(BaseModel):
    """``positions = { around = "template", sigma = ..., seed = ... }``: a perturbed template.

    Robot ``i`` starts at template point ``i`` plus Gaussian noise of standard
    deviation ``sigma`` per coordinate, drawn with ``numpy.random.default_rng(seed)``.
    """

    model_config = _STRICT
    around: Literal["template"] = "template"
    sigma: float = Field(ge=0)
    seed: int = Field(default=0, ge=0)


_START_KEYS = {
    "around": '"template"',
    "sigma": "noise std per coordinate, >= 0",
    "seed": "whole number >= 0, default 0",
}


def _start_around(v: dict[str, Any]) -> StartAround:
    return _sub_table(StartAround, v, "positions", _START_KEYS, ("around", "sigma"))


class Lattice(BaseModel):
    """``template = { lattice = "triangular", count = 100, spacing = 1.0 }``: a lattice patch."""

    model_config = _STRICT
    lattice: str
    count: int = Field(ge=2)
    spacing: float = Field(default=1.0, gt=0)

    @field_validator("lattice")
    @classmethod
    def _known(cls, kind: str) -> str:
        if kind not in LATTICES:
            raise ValueError(f"unknown lattice {kind!r}{choices(kind, LATTICES)}")
        return kind


_LATTICE_KEYS = {
    "lattice": '"' + '", "'.join(LATTICES) + '"',
    "count": "number of robots, >= 2",
    "spacing": "nearest-neighbour distance in metres, >= 1e-50, default 1",
}


def _lattice(v: dict[str, Any]) -> Lattice:
    return _sub_table(Lattice, v, "template", _LATTICE_KEYS, ("lattice", "count"))


#: The graph names of ``formation.edges`` (tables: ``{ knn = k }``, ``{ within = r }``).
EDGE_NAMES = ("complete", "delaunay", "henneberg")

_EDGE_FORMS = (
    '"complete", "delaunay", "henneberg", { knn = k }, { within = r } or a list of pairs [i, j]'
)


class _Knn(BaseModel):
    model_config = _STRICT
    knn: int = Field(ge=1)


class _Within(BaseModel):
    model_config = _STRICT
    within: float = Field(gt=0)


def _edge_rule(v: dict[str, Any]) -> dict[str, int | float]:
    if len(v) != 1 or next(iter(v)) not in ("knn", "within"):
        keys = ", ".join(repr(k) for k in v) or "none"
        hint = suggest(str(next(iter(v))), ("knn", "within")) if len(v) == 1 else ""
        raise ValueError(f"a graph table is {{ knn = k }} or {{ within = r }}, got {keys}{hint}")
    rule = _Knn if "knn" in v else _Within
    known = {"knn": "whole number >= 1"} if "knn" in v else {"within": "distance > 0"}
    return _sub_table(rule, v, "edges", known, tuple(known)).model_dump()


class RobotsModel(BaseModel):
    """``[robots]``: initial positions (a list, or around the template), diameters, the robot
    model and its keys.

    Keys other than these are kept as given and checked against the chosen
    model's parameters and initial keys by :mod:`formationlab.scenario.robots`.
    """

    model_config = ConfigDict(strict=True, extra="allow", allow_inf_nan=False, frozen=True)
    positions: list[list[float]] | StartAround
    diameters: float | list[float] = 0.2
    model: str = "single-integrator"

    @field_validator("positions", mode="before")
    @classmethod
    def _positions(cls, v: Any) -> list[list[float]] | StartAround:
        if isinstance(v, dict):
            return _start_around(v)
        pts = _points(v, "positions")
        if len(pts) < 2:
            raise ValueError(f"a formation needs at least 2 robots, got {len(pts)} position")
        return pts

    @field_validator("diameters", mode="before")
    @classmethod
    def _diameters(cls, v: Any) -> float | list[float]:
        return _one_or_list(v, "diameters")  # its range: Formation, with the key's line


class FormationModel(BaseModel):
    """``[formation]``: graph, desired distances, desired orientation, desired bearings."""

    model_config = _STRICT
    edges: str | dict[str, int | float] | list[list[int]] = "complete"
    distances: float | list[float] | None = None
    template: list[list[float]] | Lattice | None = None
    orientation: Literal["free", "template", "mirror", "table"] | None = None
    alpha: list[list[float]] | None = None
    bearings: list[list[float]] | None = None

    @field_validator("bearings", mode="before")
    @classmethod
    def _bearings(cls, v: Any) -> list[list[float]]:
        return _points(v, "bearings")  # one [x, y] per edge; their checks: Formation

    @field_validator("edges", mode="before")
    @classmethod
    def _edges(cls, v: Any) -> str | dict[str, int | float] | list[list[int]]:
        if isinstance(v, str):
            if v not in EDGE_NAMES:
                hint = suggest(v, (*EDGE_NAMES, "knn", "within"))
                raise ValueError(f"edges must be {_EDGE_FORMS}, got {v!r}{hint}")
            return v
        if isinstance(v, dict):
            return _edge_rule(v)
        if not isinstance(v, list) or not v:
            raise ValueError(f"edges must be {_EDGE_FORMS}, got {v!r}")
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
    def _template(cls, v: Any) -> list[list[float]] | Lattice | None:
        if isinstance(v, dict):
            return _lattice(v)
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


class MarchingModel(BaseModel):
    """``[marching]``: a reference velocity, a leader, or motion parameters."""

    model_config = _STRICT
    velocity: list[float] | list[list[float]]  # one pair, or one per leader
    leader: int | list[int] | None = None  # robot numbers: checked by Marching
    kind: Literal["reference", "motion-parameters"] = "reference"
    angular_velocity: float | None = None

    @field_validator("velocity", mode="before")
    @classmethod
    def _velocity(cls, v: Any) -> list[float] | list[list[float]]:
        # [vx, vy] in the plane, [vx, vy, vz] in space: Marching.check holds it to the formation
        if isinstance(v, list) and v and all(isinstance(row, list) for row in v):
            if not all(len(row) in (2, 3) for row in v):  # one row per leader: Marching counts
                raise ValueError(
                    f"each leader's velocity must be [vx, vy] (in space [vx, vy, vz]), got {v!r}"
                )
            return [[_finite(x, "velocity") for x in row] for row in v]
        if not isinstance(v, list) or len(v) not in (2, 3):
            raise ValueError(
                f"velocity must be [vx, vy] in m/s (in space [vx, vy, vz]; or, with several "
                f"leaders, one per leader), got {v!r}"
            )
        return [_finite(x, "velocity") for x in v]

    @field_validator("angular_velocity", mode="before")
    @classmethod
    def _angular(cls, v: Any) -> float | None:
        return None if v is None else _finite(v, "angular_velocity")


class SafetyModel(BaseModel):
    """``[safety]``: the safety filter between the law and the robots (``docs/safety.md``).

    Types here; ranges by :class:`~formationlab.safety.SafetyFilter` itself, contact
    distances and obstacles by :mod:`formationlab.scenario.safety`.
    """

    model_config = _STRICT
    filter: Literal["none", "barrier", "barrier-decentralized"] = "none"
    distance: float = 0.25
    gamma: float = 100.0
    max_speed: float | None = None
    speed_sides: int = 8
    sensing_radius: float | None = None
    obstacle_distance: float | None = None
    condition: Literal["discrete", "continuous"] = "discrete"

    @field_validator(
        "distance", "sensing_radius", "obstacle_distance", "max_speed", "gamma", mode="before"
    )
    @classmethod
    def _number(cls, v: Any, info: Any) -> float:
        return _finite(v, info.field_name)  # its range: SafetyFilter, with the key's line

    @field_validator("speed_sides", mode="before")
    @classmethod
    def _sides(cls, v: Any) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise ValueError(f"speed_sides must be a whole number >= 4, got {v!r}")
        return v


class SensingModel(BaseModel):
    """``[sensing]``: how the robots measure each other (:class:`formationlab.sensing.Sensing`).

    Types here; ranges by :class:`~formationlab.sensing.Sensing` itself, the delay against
    the step by :mod:`formationlab.scenario`.
    """

    model_config = _STRICT
    frames: Literal["global", "local"] = "global"
    frame_error: float = 0.0
    noise: float = 0.0
    range: float | None = None
    delay: float = 0.0
    drop: float = 0.0
    mismatch: float = 0.0
    seed: int = 0


class StopModel(BaseModel):
    """One robot that stops: ``{ robot = 2, at = 3.0 }`` (robot numbers from 1; ``at = inf``:
    never, unless a study's ``stop_at`` sweep says when)."""

    model_config = ConfigDict(strict=True, extra="forbid", allow_inf_nan=True, frozen=True)
    robot: int
    at: float = 0.0


class FaultsModel(BaseModel):
    """``[faults]``: robots that stop moving (:class:`formationlab.sensing.Faults`)."""

    model_config = _STRICT
    stop: list[StopModel] = []


class AsynchronousModel(BaseModel):
    """``[asynchronous]``: run every robot as its own task (:func:`formationlab.agents.run_async`).

    ``periods``: one control period (s) for all robots or one per robot (robot 1 first),
    default the step ``dt``; ``jitter``: each wake-up is late by up to this fraction of a
    period, in ``[0, 1)``. Values are checked by the runner's own validation.
    """

    model_config = _STRICT
    periods: float | list[float] | None = None
    jitter: float = 0.0


class ScenarioModel(BaseModel):
    """The whole file. ``[study]`` and ``[equilibria]`` are passed through unvalidated."""

    model_config = _STRICT
    name: str | None = None
    description: str = ""
    robots: RobotsModel
    formation: FormationModel = FormationModel()
    controller: ControllerModel = ControllerModel()
    simulation: SimulationModel
    marching: MarchingModel | None = None
    study: dict[str, Any] | None = None
    equilibria: dict[str, Any] | None = None
    obstacles: list[dict[str, Any]] | None = None
    safety: SafetyModel | None = None
    sensing: SensingModel | None = None
    faults: FaultsModel | None = None
    asynchronous: AsynchronousModel | None = None

    @field_validator("name", "description")
    @classmethod
    def _printable(cls, v: str | None) -> str | None:
        """No control characters (a NUL cannot be written to the results' files): tabs and,
        in the description, newlines are allowed."""
        bad = [c for c in v or "" if unicodedata.category(c) == "Cc" and c not in "\t\n"]
        if bad:
            raise ValueError(
                f"must be printable text, got the control character {bad[0]!r} in {v!r}; remove it"
            )
        return v


#: The keys each table accepts (the fixed ones; laws and integrators add theirs).
SECTIONS: dict[str, tuple[str, ...]] = {
    "": tuple(ScenarioModel.model_fields),
    "robots": tuple(RobotsModel.model_fields),
    "formation": tuple(FormationModel.model_fields),
    "controller": tuple(ControllerModel.model_fields),
    "simulation": tuple(SimulationModel.model_fields),
    "marching": tuple(MarchingModel.model_fields),
    "safety": tuple(SafetyModel.model_fields),
    "sensing": tuple(SensingModel.model_fields),
    "faults": tuple(FaultsModel.model_fields),
    "asynchronous": tuple(AsynchronousModel.model_fields),
}
