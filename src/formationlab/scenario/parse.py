"""Scenarios: a formation, a law, an integrator and an initial state, described as data.

A scenario is what a user writes in a TOML file (see ``docs/scenarios.md`` for
every key). :func:`parse_scenario` validates it (structure with pydantic, the
mathematics with the builders of :class:`~formationlab.Formation`, the law's
and the integrator's own checks) and returns a frozen :class:`Scenario`; every
problem becomes a :class:`~formationlab.errors.ScenarioError` whose message
names the key, what was expected and what was given. Robot numbers in
scenarios are 1-based, as in the paper.

Laws and integrators are looked up by name in the registries
:data:`formationlab.controllers.LAWS` and :data:`formationlab.integrators.INTEGRATORS`
when a scenario is parsed, so laws and integrators registered later are
accepted without changing this module; the keys of ``[controller]`` and
``[simulation]`` are validated by pydantic against the chosen class's dataclass
fields. A key of another law or integrator is ignored with an
:class:`~formationlab.errors.IgnoredKeyWarning` (unless a law of ``[study] laws``
takes it); a key none has is an error with a suggestion. The tables' pydantic
models are in :mod:`formationlab.scenario.tables`.

This module reads no files: :func:`formationlab.io.scenario.load_scenario` does.
:func:`closed_loop` (:mod:`formationlab.scenario.loop`) is the one way from a scenario
to the :class:`~formationlab.dynamics.System` it describes; :func:`run_scenario` runs it
as ``formationlab run`` does.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import warnings as _warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from numpy.typing import NDArray
from pydantic import ValidationError

from ..agents.asynchronous import check_schedule
from ..controllers import LAWS, Law
from ..controllers.base import file_keys
from ..errors import IgnoredKeyWarning, ScenarioError, UserInputError
from ..formation.spec import Formation
from ..integrators import INTEGRATORS, FixedStepIntegrator, Integrator
from ..marching import March
from ..models import MODELS, RobotModel, SingleIntegrator
from ..sensing import SENSING_LIMIT, Faults, Sensing, Stop, delay_ring
from ..simulation.run import initial_state
from ..validation import line_of, steps_within, validation_error
from .build import (
    FIXED,
    build_formation,
    initial_positions,
    restrictions_on_at_target,
    stem,
)
from .parts import Fail, build_entry
from .robots import build_marching, build_robot_model
from .safety import build_safety
from .tables import SECTIONS, ScenarioModel

__all__ = [
    "SECTIONS",
    "Scenario",
    "ScenarioModel",
    "parse_scenario",
]


@dataclass(frozen=True, kw_only=True, eq=False)
class Scenario:
    """A validated scenario: everything needed to run a simulation.

    Attributes
    ----------
    name : str
        The scenario's name (``name`` key, else the file's stem).
    text : str
        The scenario as TOML (the file's text, as read).
    source : str
        Where it came from (a path, or ``"<string>"``).
    description : str
        Free text from the file.
    formation : Formation
        Robots, graph, desired distances and orientation.
    law : Law
        The control law with its parameters.
    integrator : Integrator
        The integrator with its parameters.
    duration : float
        Simulated time, seconds.
    q0 : ndarray, shape (n, 2)
        Initial positions (robot centres); robot 1 is row 0.
    model : RobotModel
        The robots (``[robots] model`` and its keys); single integrators by default.
    x0 : ndarray, shape (n, k)
        The model's initial state (positions, then headings or velocities).
    marching : Marching or MotionParameters or None
        ``[marching]``, if given.
    raw : dict
        The parsed TOML.
    controller : dict
        The law parameters of ``[controller]`` as given, those of other laws included
        (:meth:`law_named` builds any law from the ones it takes).
    study, equilibria : dict or None
        The raw ``[study]`` and ``[equilibria]`` tables (validated by their users).
    warnings : tuple of str
        Things that are allowed but probably unintended (a non-rigid graph, keys
        that have no effect, ...).
    obstacles : tuple of Circle or Polygon
        The ``[[obstacles]]`` tables (:mod:`formationlab.safety`), clear of the starts.
    safety : SafetyFilter or None
        The ``[safety]`` table (None when absent), checked against the contact distances.
    sensing : Sensing or None
        The ``[sensing]`` table (:mod:`formationlab.sensing`), None when absent; its delay
        is a whole number of steps of the integrator.
    faults : Faults or None
        The ``[faults]`` table, None when absent; its robots exist.
    asynchronous : dict or None
        The ``[asynchronous]`` table (``periods``: an array ``(n,)`` of seconds,
        ``jitter``), None when absent: ``run`` then steps every robot as its own task
        (:func:`formationlab.agents.run_async`) with the integrator's ``dt`` as physics step.
    """

    name: str
    text: str
    source: str
    description: str
    formation: Formation
    law: Law
    integrator: Integrator
    duration: float
    q0: NDArray[np.float64]
    raw: dict[str, Any]
    controller: dict[str, Any] = field(default_factory=dict)
    study: dict[str, Any] | None = None
    equilibria: dict[str, Any] | None = None
    warnings: tuple[str, ...] = field(default=())
    model: RobotModel = field(default_factory=SingleIntegrator)
    x0: NDArray[np.float64] = field(default=None)  # type: ignore[arg-type]
    marching: March | None = None

    def __post_init__(self) -> None:
        if self.x0 is None:
            object.__setattr__(self, "x0", self.q0)

    obstacles: tuple[Any, ...] = ()
    safety: Any = None
    sensing: Sensing | None = None
    faults: Faults | None = None
    asynchronous: dict[str, Any] | None = None

    @property
    def n(self) -> int:
        """Number of robots."""
        return self.formation.n

    @property
    def parameters(self) -> dict[str, Any]:
        """The law's and the integrator's parameters, JSON-ready."""
        return {
            "model": {"name": self.model.name, **dataclasses.asdict(self.model)},
            "law": {"name": self.law.name, **dataclasses.asdict(self.law)},
            "integrator": {"name": self.integrator.name, **dataclasses.asdict(self.integrator)},
            "duration": self.duration,
        }

    def law_named(self, name: str) -> Law:
        """The law ``name`` built from the ``[controller]`` keys it takes (its defaults else).

        The scenario's own law for its own name. Used by studies (``[study] laws``) and
        ``equilibria --law``, so every law gets the file's keys whatever the file's law.

        Raises
        ------
        ScenarioError
            An unknown law, or a value this law refuses (with the key and its line).
        """
        if name in LAWS and LAWS.canonical(name) == self.law.name:
            return self.law
        given = {
            k: v for k, v in self.controller.items() if name not in LAWS or k in _fields(LAWS[name])
        }
        law, _ = build_entry(
            LAWS,
            INTEGRATORS,
            name,
            given,
            section="controller",
            other_section="simulation",
            fixed=FIXED["controller"],
            source=self.source,
            text=self.text,
            fail=self.error,
        )
        return law  # type: ignore[no-any-return]

    def error(self, key: str, message: str) -> ScenarioError:
        """A :class:`ScenarioError` about the dotted ``key``: ``source: key (line N): message``."""
        line = line_of(self.text, key)
        at = f" (line {line})" if line else ""
        return ScenarioError(f"{self.source}: {key}{at}: {message}", key=key)

    def in_plane(self, what: str, instead: str = "`formationlab run` runs it") -> None:
        """Refuse, placed at the template (or the start), a formation in space for ``what``
        (a command or a part) that takes formations in the plane only so far; ``instead``
        says what does take it."""
        if self.formation.dim == 2:
            return
        key = "formation.template" if self.formation.template is not None else "robots.positions"
        raise self.error(
            key,
            f"{what} takes formations in the plane so far, and this one is in space (3-D "
            f"points); {instead} (docs/three-d.md says what works in space)",
        )

    def locate(self, exc: UserInputError, table: str = "") -> ScenarioError:
        """``exc`` placed in the file: its ``key`` (under ``table``) with the key's line."""
        if isinstance(exc, ScenarioError) and exc.key and str(exc).startswith(self.source):
            return exc
        key = ".".join(p for p in (table, exc.key or "") if p)
        if not key:
            return ScenarioError(f"{self.source}: {exc}")
        return self.error(key, str(exc).removeprefix(f"{key}: "))


#: nesting of arrays and inline tables beyond which a scenario is refused by name (a
#: scenario's deepest value, a list of pairs, is two deep)
_DEEP = 32


def _too_deep(text: str, source: str) -> str:
    """The message for TOML nested too deep to parse: the key and line where it gets deep."""
    depth, quote, table, key, where = 0, "", "", "", ""
    for number, row in enumerate(text.splitlines(), start=1):
        if depth == 0 and not quote:
            head = row.split("=", 1)[0].strip()
            if row.lstrip().startswith("[") and "=" not in row:
                table = row.strip().strip("[]").strip()
            elif "=" in row and head and not head.startswith("#"):
                key = f"{table}.{head}" if table else head
        for i, c in enumerate(row):
            if quote:
                quote = "" if c == quote and row[i - 1 : i] != "\\" else quote
            elif c == "#":
                break  # a comment
            elif c in "\"'":
                quote = c
            elif c in "[{" and (depth or "=" in row[:i]):
                depth += 1
                if depth > _DEEP:
                    where = f"{key} (line {number})" if key else f"line {number}"
                    break
            elif c in "]}" and depth:
                depth -= 1
        if where:
            break
    return (
        f"{source}: {where or 'a value'}: arrays or tables nested more than {_DEEP} deep, "
        "too deep to read; positions are a list of pairs, [[x, y], ...]"
    )


def _fields(cls: type) -> set[str]:
    return {f.name for f in dataclasses.fields(cls) if f.init}


# --------------------------------------------------------------------------- parsing


def parse_scenario(text_or_dict: str | Mapping[str, Any], source: str = "<string>") -> Scenario:
    """Validate a scenario given as TOML text or as an already parsed table.

    Parameters
    ----------
    text_or_dict : str or mapping
        The TOML text of a scenario file, or the table it parses to.
    source : str
        Where it came from, for messages (a path or ``"<string>"``).

    Returns
    -------
    Scenario

    Raises
    ------
    ScenarioError
        With a message naming the key, what was expected and what was given.
    """
    if isinstance(text_or_dict, str):
        text = text_or_dict
        try:
            raw = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ScenarioError(
                f"{source}: TOML syntax error: {exc}; see https://toml.io for the syntax"
            ) from None
        except RecursionError:  # arrays or tables nested thousands deep
            raise ScenarioError(_too_deep(text, source)) from None
    else:
        raw = _plain(dict(text_or_dict))
        try:
            text = tomli_w.dumps(raw)
        except TypeError as exc:
            raise ScenarioError(
                f"{source}: the scenario holds a value TOML cannot hold: {exc}"
            ) from None
    try:
        model = ScenarioModel.model_validate(raw)
    except ValidationError as exc:
        raise validation_error(
            exc,
            source=source,
            text=text,
            known=lambda table: SECTIONS.get(table, ()),
            tables=[t for t in SECTIONS if t],
        ) from None
    return _build(model, raw, text, source)


def _judged(
    formation: Formation, law: Any, used_by: list[str], frm: Any, fail: Fail, warnings: list[str]
) -> Formation:
    """The formation as the scenario's law is judged on it (``Law.formation_for``: the
    bearing law's bearings, derived from the template and checked to fix the shape), kept
    whole for a study's other laws; given bearings that no law reads are warned about."""
    key = "formation.bearings" if frm.bearings is not None else "formation.template"
    try:
        judged = law.formation_for(formation)
        readers = [law.name] if judged.bearings is not None else []
        for name in used_by:
            if name in LAWS and LAWS[name]().formation_for(formation).bearings is not None:
                readers.append(name)
    except UserInputError as exc:
        raise fail(key, str(exc)) from None
    if frm.bearings is not None and not readers:
        warnings.append(
            f"formation.bearings: law {law.name!r} is judged by its distances and reads no "
            'bearings; use law = "bearing" (or a study law "bearing") to use them'
        )
    return judged if judged.bearings is not None else formation


def _relative_to(given: dict[str, Any], source: str) -> dict[str, Any]:
    """``[controller]`` with every law's file keys (fields marked ``metadata={"path":
    True}``, the policy law's ``parameters``) read relative to the scenario file: a
    relative path joined to the file's folder (to the working folder for a scenario given
    as text)."""
    keys = {key for cls in LAWS.values() for key in file_keys(cls)}
    folder = Path(source).parent if source != "<string>" else Path()
    for key in keys & given.keys():
        value = given[key]
        if isinstance(value, str) and value and not Path(value).is_absolute():
            given[key] = str(folder / value)
    return given


def _plain(obj: Any) -> Any:
    """Tuples and numpy values to lists and Python scalars (TOML's own types)."""
    if isinstance(obj, Mapping):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple | np.ndarray):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _build(model: ScenarioModel, raw: dict[str, Any], text: str, source: str) -> Scenario:
    rob, frm, ctl, sim = model.robots, model.formation, model.controller, model.simulation
    warnings: list[str] = []

    def fail(where: str, message: str) -> ScenarioError:
        line = line_of(text, where)
        at = f" (line {line})" if line else ""
        return ScenarioError(f"{source}: {where}{at}: {message}", key=where)

    formation = build_formation(rob, frm, ctl.alpha_values, fail, warnings)
    q0 = initial_positions(rob, formation, fail)
    q0.setflags(write=False)  # the scenario is frozen, its arrays too
    obstacles, safety = build_safety(
        model.obstacles, model.safety, formation, q0, source=source, text=text, warnings=warnings
    )

    robot, initial, ignored_model = build_robot_model(
        rob, formation.n, source=source, text=text, fail=fail, warnings=warnings
    )
    try:
        x0 = initial_state(formation, robot, q0, **initial)
    except UserInputError as exc:
        raise fail(f"robots.{exc.key or 'positions'}", str(exc)) from None
    x0.setflags(write=False)
    if safety is not None:
        try:
            safety.check_model(robot)
        except UserInputError as exc:
            raise fail(f"safety.{exc.key}", str(exc)) from None
    marching = build_marching(model.marching, formation, fail)

    study_laws = (model.study or {}).get("laws")
    used_by = [str(x) for x in study_laws] if isinstance(study_laws, list) else []
    given = _relative_to(dict(ctl.model_extra or {}), source)
    law, ignored_law = build_entry(
        LAWS,
        INTEGRATORS,
        ctl.law,
        given,
        section="controller",
        other_section="simulation",
        fixed=FIXED["controller"],
        used_by=used_by,
        source=source,
        text=text,
        fail=fail,
    )
    formation = _judged(formation, law, used_by, frm, fail, warnings)
    if not formation.has_orientation and "k_a" in _fields(type(law)):
        warnings.append(
            f"law {law.name!r} has an angular term but the orientation is free, so it acts as "
            'the distance law; set formation.orientation (e.g. "template") to use it'
        )
    thin = restrictions_on_at_target(formation, law)
    if thin:
        warnings.append(thin)
    integrator, ignored_integrator = build_entry(
        INTEGRATORS,
        LAWS,
        sim.integrator,
        dict(sim.model_extra or {}),
        section="simulation",
        other_section="controller",
        fixed=FIXED["simulation"],
        source=source,
        text=text,
        fail=fail,
    )
    for table, registry, name, ignored in (
        ("robots", MODELS, robot.name, ignored_model),
        ("controller", LAWS, law.name, ignored_law),
        ("simulation", INTEGRATORS, integrator.name, ignored_integrator),
    ):
        if ignored:
            line = line_of(text, f"{table}.{ignored[0]}")
            at = f" (line {line})" if line else ""
            message = f"{source}: [{table}]{at}: {registry.ignored_message(name, ignored)}"
            warnings.append(message)
            _warnings.warn(message, IgnoredKeyWarning, stacklevel=3)
    # the duration first: the sensing's delay and the robots' periods are judged against it
    duration = _whole_steps(float(sim.duration), integrator, text, source, fail, warnings)
    sensing, faults = _sensing(model, formation, integrator, fail)
    asynchronous = _asynchronous(model, formation, integrator, fail)
    return Scenario(
        name=model.name or stem(source),
        text=text,
        source=source,
        description=model.description,
        formation=formation,
        law=law,
        integrator=integrator,
        duration=duration,
        q0=q0,
        raw=raw,
        controller=given,
        study=model.study,
        equilibria=model.equilibria,
        warnings=tuple(warnings),
        model=robot,
        x0=x0,
        marching=marching,
        obstacles=obstacles,
        safety=safety,
        sensing=sensing,
        faults=faults,
        asynchronous=asynchronous,
    )


def _whole_steps(
    duration: float, integrator: Integrator, text: str, source: str, fail: Any, warnings: list[str]
) -> float:
    """The duration as a whole number of steps of a fixed-step integrator's ``dt``.

    A ``dt`` longer than the duration is refused (the one step would end past it); a
    duration that is not a multiple of ``dt`` is rounded to the nearest one, with a warning
    (the run used to take one more step and end past the duration).
    """
    dt = getattr(integrator, "dt", None)
    if not isinstance(dt, float | int) or isinstance(dt, bool):
        return duration
    if dt > duration * (1.0 + 1e-9):
        raise fail(
            "simulation.dt",
            f"dt = {dt:g} s is longer than the duration, {duration:g} s: its one step would end "
            f"past the duration; use dt <= duration (e.g. dt = {duration / 1000:g})",
        )
    try:
        steps_within(duration, dt, "simulation.dt")
    except UserInputError as exc:
        raise fail("simulation.dt", str(exc)) from None
    steps = round(duration / dt)
    rounded = steps * dt
    if abs(rounded - duration) > 1e-9 * duration:
        line = line_of(text, "simulation.duration")
        at = f" (line {line})" if line else ""
        message = (
            f"{source}: simulation.duration{at}: {duration:g} s is not a whole number of steps "
            f"of dt = {dt:g} s; running {steps:,} steps, to t = {rounded:g} s (set the "
            f"duration to a multiple of dt to choose)"
        )
        warnings.append(message)
        return rounded
    return duration


def _asynchronous(
    model: ScenarioModel, formation: Formation, integrator: Integrator, fail: Any
) -> dict[str, Any] | None:
    """The ``[asynchronous]`` table, checked by the runner's own rules."""
    table = model.asynchronous
    if table is None:
        return None
    if integrator.name != "euler":
        raise fail(
            "simulation.integrator",
            "[asynchronous] steps the world with explicit Euler at the integrator's dt between "
            f'the robots\' updates; set integrator = "euler" (got {integrator.name!r})',
        )
    for given, what in (
        (model.marching is not None, "[marching]"),
        (bool(model.obstacles), "[[obstacles]]"),
        (model.safety is not None and model.safety.filter != "none", "a safety filter"),
    ):
        if given:
            raise fail(
                "asynchronous",
                f"the asynchronous runner does not take {what} yet: remove it, or remove "
                "[asynchronous] (the synchronous run takes it)",
            )
    try:
        dt = float(integrator.dt)  # type: ignore[attr-defined]
        duration = float(model.simulation.duration)
        periods, jitter = check_schedule(table.periods, table.jitter, formation.n, dt, duration)
    except UserInputError as exc:
        raise fail(f"asynchronous.{exc.key or 'periods'}", str(exc)) from None
    return {"periods": periods, "jitter": jitter}


def _sensing(
    model: ScenarioModel, formation: Formation, integrator: Integrator, fail: Any
) -> tuple[Sensing | None, Faults | None]:
    """The ``[sensing]`` and ``[faults]`` tables, checked against the formation and the step."""
    sensing = faults = None
    if model.sensing is not None:
        given = model.sensing.model_dump()
        if given["range"] is None:
            given["range"] = math.inf
        try:
            sensing = Sensing(**given)
        except UserInputError as exc:
            raise fail(exc.key or "sensing", str(exc).removeprefix(f"{exc.key} ")) from None
        if not sensing.ideal:
            if not getattr(integrator, "explicit", False):
                raise fail(
                    "simulation.integrator",
                    f"[sensing] needs an explicit fixed-step integrator (euler or rk4): a robot "
                    f"measures once per step and holds its command; {integrator.name!r} is "
                    "not one",
                )
            if formation.n > SENSING_LIMIT:
                raise fail(
                    "sensing",
                    f"[sensing] models formations of at most {SENSING_LIMIT} robots; this one "
                    f"has {formation.n}: remove [sensing] for larger swarms",
                )
            if sensing.delay > 0:
                try:
                    dt = float(integrator.dt)  # type: ignore[attr-defined]
                    delay_ring(sensing.delay, dt, formation.n)
                except UserInputError as exc:
                    raise fail("sensing.delay", str(exc)) from None
    if model.faults is not None:
        try:
            faults = Faults(stop=[Stop(robot=s.robot, at=s.at) for s in model.faults.stop])
            faults.check(formation.n)
        except UserInputError as exc:
            raise fail(exc.key or "faults", str(exc)) from None
        late = faults.later()
        if late and not isinstance(integrator, FixedStepIntegrator):
            raise fail(
                "simulation.integrator",
                f"robot {late[0].robot} stops at t = {late[0].at:g} s ([faults]), so the field "
                f"depends on time, and {integrator.name!r} steps only fields that do not: use "
                "a fixed-step integrator (euler, rk4, implicit-euler)",
            )
    return sensing, faults
