"""One validation layer: number checks, suggestions, and pydantic errors as one message.

Checks of single values (:func:`positive`, :func:`nonnegative`, :func:`whole`,
:func:`fraction`, :func:`one_of`, and :func:`check_fields` for a dataclass's
``__post_init__``) raise :class:`~formationlab.errors.ParameterError` with the
parameter in ``key`` and a message that names it, the rule and the value given.

:func:`validation_error` turns a pydantic ``ValidationError`` (of a scenario
table, a ``[study]`` or ``[equilibria]`` table, a law's or an integrator's
parameters) into one :class:`~formationlab.errors.ScenarioError` naming each
key, its line in the file, what was expected and what was given; ``key`` is the
first problem's key. :func:`line_of` finds a dotted key in a TOML text.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import numbers
import re
import tomllib
import typing
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError, create_model

from .errors import ParameterError, ScenarioError, UserInputError

__all__ = [
    "COORDINATE_LIMIT",
    "STEP_LIMIT",
    "build_dataclass",
    "check_fields",
    "choices",
    "coordinates",
    "field_words",
    "fraction",
    "line_of",
    "nearest",
    "nonnegative",
    "number",
    "one_of",
    "parameter_model",
    "positive",
    "seed",
    "steps_within",
    "suggest",
    "validation_error",
    "whole",
]


def _label(name: str, owner: str | None) -> str:
    return f"{owner}.{name}" if owner else name


def number(
    value: Any,
    name: str,
    *,
    low: float,
    strict: bool,
    below: float | None = None,
    allow_inf: bool = False,
    owner: str | None = None,
) -> float:
    """``value`` as a float if it is a number ``> low`` (``strict``) or ``>= low``, and
    ``< below`` when given; finite unless ``allow_inf``. Else a :class:`ParameterError`
    naming ``owner.name``, the rule and the value (the one check of numeric parameters)."""
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)
    v = float(value) if ok else math.nan
    ok = ok and not math.isnan(v) and (allow_inf or math.isfinite(v))
    ok = ok and (v > low if strict else v >= low) and (below is None or v < below)
    if not ok:
        bound = f"> {low:g}" if strict else f">= {low:g}"
        if below is not None:
            bound = f"in [{low:g}, {below:g})"
        kind = "a number" if allow_inf else "a finite number"
        raise ParameterError(
            f"{_label(name, owner)} must be {kind} {bound}, got {value!r}", key=name
        )
    return v


def positive(value: Any, name: str, *, owner: str | None = None) -> float:
    """``value`` as a float if it is a finite number > 0, else a :class:`ParameterError`."""
    return number(value, name, low=0.0, strict=True, owner=owner)


def nonnegative(value: Any, name: str, *, owner: str | None = None) -> float:
    """``value`` as a float if it is a finite number >= 0, else a :class:`ParameterError`."""
    return number(value, name, low=0.0, strict=False, owner=owner)


def fraction(value: Any, name: str, *, owner: str | None = None) -> float:
    """``value`` as a float if it is a number in [0, 1], else a :class:`ParameterError`."""
    v = number(value, name, low=0.0, strict=False, owner=owner)
    if v > 1.0:
        raise ParameterError(f"{_label(name, owner)} must be in [0, 1], got {value!r}", key=name)
    return v


#: The largest coordinate a position may have: distances are computed from squared
#: differences, which overflow double precision beyond about 1e154.
COORDINATE_LIMIT = 1e150


#: The most steps of ``dt`` one run or trial may take: more is a step or a duration
#: mistyped (a billion steps of three robots take about an hour on the compiled loop).
STEP_LIMIT = 1e9


def steps_within(duration: float, dt: float, key: str) -> None:
    """Refuse a ``duration`` of more than :data:`STEP_LIMIT` steps of ``dt`` (with ``key``)."""
    steps = duration / dt
    if not steps <= STEP_LIMIT:
        raise ParameterError(
            f"duration / dt = {duration:g} s / {dt:g} s = {steps:.3g} steps, more than "
            f"{STEP_LIMIT:.0e} for one run: lengthen dt or shorten the duration",
            key=key,
        )


def coordinates(q: Any, name: str) -> None:
    """Refuse positions ``(..., n, d)`` with a coordinate beyond :data:`COORDINATE_LIMIT`."""
    largest = float(np.max(np.abs(q), initial=0.0))
    if largest > COORDINATE_LIMIT:
        raise ParameterError(
            f"{name} has coordinates up to {largest:.3g}, beyond {COORDINATE_LIMIT:g}: "
            "squared distances would overflow double precision; scale the scenario "
            "(positions, distances, diameters) to moderate numbers",
            key=name,
        )


def whole(value: Any, name: str, *, minimum: int = 1, owner: str | None = None) -> int:
    """``value`` as an int if it is an integer >= ``minimum``, else a :class:`ParameterError`."""
    ok = isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)
    if not ok or value < minimum:
        raise ParameterError(
            f"{_label(name, owner)} must be an integer >= {minimum}, got {value!r}", key=name
        )
    return int(value)


def seed(value: Any, name: str = "seed", *, owner: str | None = None) -> int:
    """``value`` as an int if it is a whole number in ``[0, 2**63)`` (a seed of numpy's
    generators, stored as int64), else a :class:`ParameterError`."""
    ok = isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)
    if not (ok and 0 <= value < 2**63):
        raise ParameterError(
            f"{_label(name, owner)} must be a whole number in [0, 2**63), got {value!r}",
            key=name,
        )
    return int(value)


def one_of(value: Any, name: str, choices: Sequence[str], *, owner: str | None = None) -> str:
    """``value`` if it is one of ``choices``, else a :class:`ParameterError` with a suggestion."""
    if value not in choices:
        hint = suggest(str(value), choices)
        raise ParameterError(
            f"{_label(name, owner)} must be one of {', '.join(choices)}, got {value!r}{hint}",
            key=name,
        )
    return str(value)


def check_fields(
    obj: object,
    *,
    positive: Iterable[str] = (),
    nonnegative: Iterable[str] = (),
    whole: Iterable[str] = (),
) -> None:
    """Check fields of a configuration dataclass (call from ``__post_init__``).

    Messages name the field as ``ClassName.field``.
    """
    owner = type(obj).__name__
    for name in positive:
        _positive(getattr(obj, name), name, owner=owner)
    for name in nonnegative:
        _nonnegative(getattr(obj, name), name, owner=owner)
    for name in whole:
        _whole(getattr(obj, name), name, owner=owner)


_positive, _nonnegative, _whole = positive, nonnegative, whole


def nearest(name: str, known: Iterable[str]) -> str | None:
    """The known name nearest to ``name`` (difflib, any case), or ``None``."""
    lower = {k.lower(): k for k in known}
    near = difflib.get_close_matches(name.lower(), list(lower), n=1)
    return lower[near[0]] if near else None


def suggest(name: str, known: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` for the known name nearest to ``name`` (any case), or ``""``."""
    near = nearest(name, known)
    return f"; did you mean {near!r}?" if near else ""


def choices(name: str, known: Iterable[str], label: str = "Known") -> str:
    """``"; did you mean 'x'? Known: a, b"`` (or ``". Known: a, b"`` without a near name)."""
    known = list(known)
    hint = suggest(name, known) or "."
    return f"{hint} {label}: {', '.join(known)}" if known else hint


# ------------------------------------------------------------- dataclass parameters

_STRICT = ConfigDict(strict=True, extra="forbid", allow_inf_nan=False, frozen=True)


@functools.cache
def parameter_model(cls: type) -> type[BaseModel]:
    """A strict pydantic model of the ``init`` fields of the configuration dataclass ``cls``.

    Every field is optional (``None``: keep the dataclass's default); a field whose
    type is itself a dataclass (a law's ``repulsion``) becomes a nested model. Strict:
    ``"2"`` or ``true`` is not a number, ``2.5`` is not an integer, ``nan`` is refused.
    """
    try:
        hints = typing.get_type_hints(cls)
    except (NameError, TypeError):  # annotations that do not resolve: accept anything
        hints = {}
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        tp = hints.get(f.name, Any)
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            tp = parameter_model(tp)
        fields[f.name] = (tp | None, None)
    return create_model(f"{cls.__name__}Parameters", __config__=_STRICT, **fields)


def build_dataclass(cls: type, table: Mapping[str, Any]) -> Any:
    """``cls(**table)`` with the values validated by :func:`parameter_model` first.

    Raises
    ------
    pydantic.ValidationError
        A value of the wrong type (locations are the table's keys).
    UserInputError
        The class's own check refused a value; ``key`` is the dotted key in ``table``.
    """
    return _instance(cls, parameter_model(cls).model_validate(dict(table)))


def _instance(cls: type, model: BaseModel) -> Any:
    kwargs: dict[str, Any] = {}
    for key in model.model_fields_set:
        value = getattr(model, key)
        if isinstance(value, BaseModel):  # a nested dataclass (its model was validated)
            try:
                value = _instance(typing.get_type_hints(cls)[key], value)
            except UserInputError as exc:
                exc.key = f"{key}.{exc.key}" if exc.key else key
                raise
        kwargs[key] = value
    return cls(**kwargs)


# ------------------------------------------------------------------------ TOML lines

_TABLE = re.compile(r"^\[\[?\s*([A-Za-z0-9_.\"' -]+?)\s*\]\]?")


_BARE_KEY = re.compile(r"^([A-Za-z0-9_.\"' -]+?)\s*=")
_PIECE = r"""(?:"(?:[^"\\]|\\.)*"|'[^']*'|[A-Za-z0-9_-]+)"""
_QUOTED_KEY = re.compile(rf"^({_PIECE}(?:\s*\.\s*{_PIECE})*)\s*=")


def _key_path(line: str) -> list[str] | None:
    """The dotted key a ``key = value`` line sets, as its parts, or None (not such a line).

    A quoted key may hold any character (``"ü" = 1``, ``"\\u0000" = 1``): TOML's own
    reading of the key gives its parts."""
    m = _BARE_KEY.match(line)
    if m:
        return [p.strip().strip("\"'") for p in m.group(1).split(".")]
    m = _QUOTED_KEY.match(line) if line[:1] in "\"'" else None
    if not m:
        return None
    try:
        table: Any = tomllib.loads(f"{m.group(1)} = 0")
    except tomllib.TOMLDecodeError:
        return None
    parts = []
    while isinstance(table, dict) and table:
        parts.append(next(iter(table)))
        table = table[parts[-1]]
    return parts


def line_of(text: str, key: str) -> int | None:
    """1-based line of the dotted ``key`` (``"controller.k_c"``, ``"study.sweep.kA"``) in ``text``.

    The deepest match wins: the line ``kA = ...`` under ``[study.sweep]``, else
    the line ``sweep = ...`` under ``[study]``, else the header of the table
    ``[study]``. Best effort (``None`` when not found).
    """
    if not text or not key:
        return None
    parts = key.split(".")
    best: tuple[int, int] | None = None  # (depth, line)
    table: list[str] = []
    for number, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        m = _TABLE.match(s)
        if m:
            table = [p.strip().strip("\"'") for p in m.group(1).split(".")]
            depth = len(table)
            if table == parts[:depth] and (best is None or depth > best[0]):
                best = (depth, number)
            continue
        keys = _key_path(s)
        if keys is None:
            continue
        path = table + keys
        depth = 0
        while depth < min(len(path), len(parts)) and path[depth] == parts[depth]:
            depth += 1
        if depth > len(table) and (best is None or depth > best[0]):
            best = (depth, number)
    return None if best is None else best[1]


# --------------------------------------------------------------------- pydantic errors

Known = Callable[[str], Sequence[str]]

_EXPECTED = {
    "float_type": "expected a number",
    "float_parsing": "expected a number",
    "int_type": "expected a whole number",
    "int_from_float": "expected a whole number",
    "int_parsing": "expected a whole number",
    "bool_type": "expected true or false (a boolean)",
    "bool_parsing": "expected true or false (a boolean)",
    "string_type": "expected a string",
    "finite_number": "expected a finite number",
    "list_type": "expected a list",
    "tuple_type": "expected a list",
    "dict_type": "expected a table",
    "model_type": "expected a table",
    "model_attributes_type": "expected a table",
    "dataclass_type": "expected a table",
}


#: pydantic's range errors: the bound's name in the error's context and its sign
_BOUNDS = {
    "greater_than_equal": ("ge", ">="),
    "greater_than": ("gt", ">"),
    "less_than_equal": ("le", "<="),
    "less_than": ("lt", "<"),
}


def field_words(cls: type[BaseModel], err: Any) -> str:
    """What a pydantic error ``err`` of a field of the model ``cls`` says, in the words of
    :func:`number` and :func:`whole` ("must be a whole number >= 2"): for the inline tables
    of scenario files, whose ranges are the models' field constraints. (The keys of the
    tables themselves get the same words from :func:`validation_error`.)"""
    ctx = err.get("ctx") or {}
    name = str(err["loc"][0]) if err["loc"] else ""
    field = cls.model_fields.get(name)
    kind = "a whole number" if field is not None and field.annotation in (int, "int") else ""
    for bound, word in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")):
        if bound in ctx:
            return f"must be {kind + ' ' if kind else ''}{word} {ctx[bound]:g}"
    if err["type"] == "literal_error":
        return "takes " + str(ctx.get("expected", "")).replace("'", '"')
    if err["type"] in ("int_type", "int_from_float"):
        return "must be a whole number"
    if err["type"] in ("float_type", "finite_number"):
        return "must be a finite number"
    return str(err["msg"]).lower()


def _path(loc: Sequence[Any], prefix: str, tags: Sequence[str] = ()) -> tuple[str, str]:
    """``("study.initial.half_width", "item 3")`` from a pydantic location."""
    keys = [str(p) for i, p in enumerate(loc) if isinstance(p, str) and not (i and p in tags)]
    items = [f"item {p + 1}" for p in loc if isinstance(p, int)]
    return ".".join([prefix, *keys] if prefix else keys), ", ".join(items)


def validation_error(
    exc: ValidationError,
    *,
    source: str,
    text: str = "",
    prefix: str = "",
    known: Known | None = None,
    tables: Iterable[str] = (),
    tags: Sequence[str] = (),
    options: bool = False,
) -> ScenarioError:
    """One :class:`ScenarioError` for every problem of a pydantic ``ValidationError``.

    Parameters
    ----------
    exc : ValidationError
        Of a table validated at ``prefix`` (``""``: the whole file, ``"study"``, ...).
    source : str
        The file (or ``"<string>"``), first in the message.
    text : str
        The file's TOML text, for line numbers.
    prefix : str
        Dotted key of the validated table in the file.
    known : callable, optional
        ``known(table)`` lists the keys a dotted table takes (for unknown keys).
    tables : iterable of str
        Dotted keys that are tables: a missing one is "the table [x] is required".
    tags : sequence of str
        Tags of tagged unions, which pydantic puts in locations (dropped from keys).
    options : bool
        The values came from command-line options: name them ``--key-name``.
    """
    tables = set(tables)
    problems: list[tuple[bool, str, str]] = []
    for err in exc.errors(include_url=False):
        where, items = _path(tuple(err["loc"]), prefix, tags)
        kind = err["type"]
        given = err.get("input")
        if kind in ("extra_forbidden", "unexpected_keyword_argument"):
            parent, _, name = where.rpartition(".")
            keys = list(known(parent)) if known else []
            table = f"[{parent}]" if parent else "the top level"
            msg = f"unknown key {name!r} in {table}{choices(name, keys, 'Known keys')}"
        elif kind == "missing":
            msg = f"the table [{where}] is required" if where in tables else "this key is required"
        elif kind in ("value_error", "assertion_error"):
            cause = err.get("ctx", {}).get("error")
            msg = str(cause if cause is not None else err["msg"])
            sub = getattr(cause, "key", None)
            if isinstance(cause, UserInputError) and sub and not where.endswith(sub):
                where = f"{where}.{sub}" if where else sub
        elif kind in _EXPECTED:
            msg = f"{_EXPECTED[kind]}, got {given!r}"
        elif kind in _BOUNDS:  # a range: in the words of `number` and `whole`
            bound, word = _BOUNDS[kind]
            msg = f"must be {word} {err['ctx'][bound]:g}, got {given!r}"
        else:
            msg = f"{err['msg'][0].lower()}{err['msg'][1:]}, got {given!r}"
        line = line_of(text, where)
        at = f" (line {line})" if line else ""
        label = f"--{where.replace('_', '-')}" if options else where
        label += f", {items}" if items else ""
        # unknown keys first: they often explain the missing ones (a misspelt table)
        first = kind not in ("extra_forbidden", "unexpected_keyword_argument")
        problems.append((first, f"{label}{at}: {msg}", where))
    problems.sort(key=lambda p: p[0])
    head = f"{source}: " if len(problems) == 1 else f"{source}: {len(problems)} problems: "
    key = problems[0][2] if problems else None
    return ScenarioError(head + "; ".join(p[1] for p in problems), key=key or None)
