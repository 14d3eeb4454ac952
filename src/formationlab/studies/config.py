"""The ``[study]`` table of a scenario: what a Monte-Carlo study runs.

Every key, its default and its meaning (``docs/studies.md`` shows examples):

``trials`` (int >= 1, default 1000)
    Trials per group (a group is one law at one point of the sweep).
    ``formationlab study --trials N`` overrides it.
``initial`` (table, default ``{ kind = "box", half_width = 3.0 }``)
    How initial positions are drawn. ``{ kind = "box", half_width = w }``: every
    robot uniform in ``[-w, w]^2``, independently. ``{ kind = "gaussian",
    sigma = s }``: every coordinate of every robot ``N(c, s^2)`` around a centre
    ``c``, the formation's template if it has one, else the scenario's
    ``robots.positions``. Either way, a draw in which two robots overlap
    (``r_ij <= a_ij``) is rejected and drawn again.
``laws`` (list of law names, default: the scenario's law)
    The laws compared. Each is built with the parameters of the scenario's
    ``[controller]`` that it has (same name), its own defaults for the rest.
``sweep`` (table of lists, default empty)
    ``key = [v1, v2, ...]``; the study runs the product of all lists. A key is a
    parameter of a law (``k_c``, ``k_a``, ``theta``, ...), of its repulsion
    (``eta``, ``influence``) or of the robots (``diameter``: every robot's
    diameter). A law runs only the points of the keys it has: with
    ``k_a = [...]`` the distance law runs once, not once per ``k_a``.
``tolerances`` (table, default ``{ distance = 1e-2, speed = 1e-3, window = 1e-2,
shape = 2e-2, drift_window = 2.0 }``)
    Of the outcome classification (:class:`formationlab.Tolerances`); ``window``
    is also the interval of the kernel's convergence test, ``shape`` and
    ``drift_window`` decide ``drifting`` and ``rotating``
    (:mod:`formationlab.outcomes.rigid_motion`).
``chunk_size`` (int >= 1, default 1000)
    Trials per unit of work (a chunk is what a worker runs and what ``--resume``
    keeps). Results do not depend on it.
``dt``, ``duration`` (float > 0, default: the scenario's ``[simulation]``)
    Step of the batched explicit Euler kernel and simulated time per trial.
``backend`` (``"numba"`` or ``"numpy"``, default ``"numba"``)
    The batched kernel's implementation; both give the same results.
``settle`` (table, default ``{ enabled = false, duration = 5.0, dt = 0.01 }``)
    Settling of the trials that the explicit Euler kernel leaves ``not-converged``
    under a law with switching surfaces (``not law.smooth``): each is continued from
    its final state with implicit Euler (:class:`formationlab.integrators.ImplicitEuler`,
    step ``dt``) for at most ``duration`` seconds, until its robots move slower than
    ``tolerances.speed``, and classified again (:func:`formationlab.equilibria.settle`).
    Off by default: it multiplies the cost of a study with many such trials.

This module reads no files; the command line passes it the parsed table.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from ..outcomes.analysis import Tolerances
from ..validation import validation_error

__all__ = ["BoxInitial", "GaussianInitial", "SettleModel", "StudyConfig", "parse_study"]

_STRICT = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


class BoxInitial(BaseModel):
    """Every robot uniform in the square ``[-half_width, half_width]^2``."""

    model_config = _STRICT
    kind: Literal["box"] = "box"
    half_width: float = Field(default=3.0, gt=0)


class GaussianInitial(BaseModel):
    """Every coordinate ``N(c, sigma^2)`` around a centre shape ``c`` (template or scenario)."""

    model_config = _STRICT
    kind: Literal["gaussian"]
    sigma: float = Field(gt=0)


Initial = Annotated[BoxInitial | GaussianInitial, Field(discriminator="kind")]


class TolerancesModel(BaseModel):
    """``[study.tolerances]``: see :class:`formationlab.Tolerances`."""

    model_config = _STRICT
    distance: float = Field(default=1e-2, gt=0)
    bearing: float = Field(default=1e-2, gt=0)
    speed: float = Field(default=1e-3, gt=0)
    window: float = Field(default=1e-2, gt=0)
    shape: float = Field(default=2e-2, gt=0)
    drift_window: float = Field(default=2.0, gt=0)


class SettleModel(BaseModel):
    """``[study.settle]``: implicit-Euler settling of not-converged trials of switching laws."""

    model_config = _STRICT
    enabled: bool = False
    duration: float = Field(default=5.0, gt=0, le=1000.0)
    dt: float = Field(default=0.01, gt=0)

    @model_validator(mode="after")
    def _steps(self) -> SettleModel:
        if self.dt > self.duration:
            raise ValueError(
                f"dt = {self.dt:g} is longer than duration = {self.duration:g}; "
                "give a step shorter than the duration"
            )
        if self.duration / self.dt > 1e6:
            raise ValueError(
                f"duration / dt = {self.duration / self.dt:.3g} steps per trial; "
                "at most 1e6: shorten the duration or lengthen the step"
            )
        return self


class StudyConfig(BaseModel):
    """A validated ``[study]`` table (module docstring lists the keys)."""

    model_config = _STRICT
    trials: int = Field(default=1000, ge=1)
    initial: Initial = BoxInitial()
    laws: tuple[str, ...] | None = None
    sweep: dict[str, tuple[float, ...]] = Field(default_factory=dict)
    tolerances: TolerancesModel = TolerancesModel()
    chunk_size: int = Field(default=1000, ge=1)
    dt: float | None = Field(default=None, gt=0)
    duration: float | None = Field(default=None, gt=0)
    backend: Literal["numba", "numpy"] = "numba"
    settle: SettleModel = SettleModel()

    @field_validator("laws")
    @classmethod
    def _laws(cls, v: tuple[str, ...] | None) -> tuple[str, ...] | None:
        if v is None:
            return v
        if not v:
            raise ValueError("give at least one law name, or leave laws out")
        dup = sorted({x for x in v if v.count(x) > 1})
        if dup:
            raise ValueError(f"law {dup[0]!r} is listed twice")
        return v

    @field_validator("sweep")
    @classmethod
    def _sweep(cls, v: dict[str, tuple[float, ...]]) -> dict[str, tuple[float, ...]]:
        for key, values in v.items():
            if not values:
                raise ValueError(f"sweep.{key} is empty; give at least one value")
            if any(not math.isfinite(x) for x in values):
                raise ValueError(f"sweep.{key} must hold finite numbers, got {list(values)}")
            if len(set(values)) != len(values):
                raise ValueError(f"sweep.{key} repeats a value: {list(values)}")
        return v

    @property
    def tol(self) -> Tolerances:
        """The tolerances as :class:`formationlab.Tolerances`."""
        t = self.tolerances
        return Tolerances(**t.model_dump())

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form, every default filled in."""
        return self.model_dump(mode="json")


def parse_study(
    table: dict[str, Any] | None,
    *,
    trials: int | None = None,
    chunk_size: int | None = None,
    dt: float | None = None,
    duration: float | None = None,
    settle: bool | None = None,
    sweep: dict[str, list[float]] | None = None,
    source: str = "scenario",
    text: str = "",
) -> StudyConfig:
    """Validate a ``[study]`` table (``None``: all defaults), with command-line overrides.

    ``trials``, ``chunk_size``, ``dt`` and ``duration``, when given, replace the table's;
    ``settle``, when given, replaces ``settle.enabled`` (keeping its ``duration`` and ``dt``);
    ``sweep``, when given, replaces the table's ``sweep``.
    ``source`` and ``text`` (the scenario file and its TOML) place errors in the file.

    Raises
    ------
    ScenarioError
        Naming the key (``study.initial.half_width``) and its line, what was expected and
        what was given; ``key`` is the first problem's key.
    """
    data = dict(table or {})
    for key, value in (
        ("trials", trials),
        ("chunk_size", chunk_size),
        ("dt", dt),
        ("duration", duration),
    ):
        if value is not None:
            data[key] = value
    if sweep is not None:
        data["sweep"] = sweep
    if settle is not None:
        table_settle = data.get("settle")
        data["settle"] = {
            **(table_settle if isinstance(table_settle, dict) else {}),
            "enabled": settle,
        }
    try:
        return StudyConfig.model_validate(data)
    except ValidationError as exc:
        raise validation_error(
            exc, source=source, text=text, prefix="study", known=_known_keys, tags=_TAGS
        ) from None


#: pydantic puts the member of a tagged union in the location: initial.box.half_width
_TAGS = ("box", "gaussian")


def _known_keys(table: str) -> list[str]:
    models: dict[str, Any] = {
        "study": StudyConfig,
        "study.initial": BoxInitial,
        "study.tolerances": TolerancesModel,
        "study.settle": SettleModel,
    }
    model = models.get(table, StudyConfig)
    keys = list(model.model_fields)
    if model is BoxInitial:
        keys += ["sigma (kind = gaussian)"]
    return keys
