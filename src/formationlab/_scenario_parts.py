"""Helpers of :mod:`formationlab.scenario`: law/integrator parameters and error messages.

Private: the parameters of ``[controller]`` and ``[simulation]`` are checked
against the chosen class's dataclass fields, and pydantic's validation errors
are turned into one message naming the key, its line, what was expected and
what was given.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from collections.abc import Callable, Mapping
from typing import Any

from pydantic import ValidationError

from .controllers import LAWS
from .errors import ScenarioError, UserInputError
from .integrators import INTEGRATORS

__all__ = ["format_errors", "line_of", "param_key", "params", "unknown"]

Fail = Callable[[str, str], ScenarioError]


def param_key(section: str, params: Mapping[str, Any], message: str) -> str:
    """``section.key`` for the parameter a constructor's message names, else ``section``."""
    for key in params:
        if re.search(rf"\b{re.escape(key)}\b", message):
            return f"{section}.{key}"
    return section


def unknown(kind: str, name: str, registry: Mapping[str, Any]) -> str:
    near = difflib.get_close_matches(name, list(registry), n=1)
    hint = f"; did you mean {near[0]!r}?" if near else ""
    return f"unknown {kind} {name!r}{hint} Known: {', '.join(sorted(registry))}"


def params(
    cls: Any, given: dict[str, Any], section: str, fixed: tuple[str, ...], what: str, fail: Fail
) -> dict[str, Any]:
    """Check ``given`` against the dataclass fields of ``cls``; nested dataclasses from tables."""
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    out: dict[str, Any] = {}
    for key, value in given.items():
        if key not in fields:
            takes = ", ".join([*fixed, *fields])
            registry: dict[str, Any] = {**LAWS, **INTEGRATORS}
            others = sorted(
                name
                for name, other in registry.items()
                if key in {g.name for g in dataclasses.fields(other)}
            )
            if others:
                owners = ", ".join(repr(o) for o in others)
                hint = f" {key!r} belongs to {owners}."
            else:
                near = difflib.get_close_matches(key, [*fields, *fixed], n=1)
                hint = f" Did you mean {near[0]!r}?" if near else ""
            raise fail(f"{section}.{key}", f"{what} takes no key {key!r}.{hint} It takes: {takes}")
        out[key] = _param_value(fields[key], value, f"{section}.{key}", fail)
    return out


def _default(f: dataclasses.Field[Any]) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def _param_value(f: dataclasses.Field[Any], value: Any, where: str, fail: Fail) -> Any:
    default = _default(f)
    if dataclasses.is_dataclass(default) and not isinstance(default, type):
        if not isinstance(value, dict):
            names = ", ".join(g.name for g in dataclasses.fields(default))
            raise fail(where, f"expected a table {{ {names} }}, got {value!r}")
        sub = {g.name: g for g in dataclasses.fields(default) if g.init}
        kwargs = {}
        for key, v in value.items():
            if key not in sub:
                near = difflib.get_close_matches(key, list(sub), n=1)
                hint = f" Did you mean {near[0]!r}?" if near else ""
                raise fail(f"{where}.{key}", f"unknown key.{hint} It takes: {', '.join(sub)}")
            kwargs[key] = _param_value(sub[key], v, f"{where}.{key}", fail)
        try:
            return type(default)(**kwargs)
        except UserInputError as exc:
            raise fail(where, str(exc)) from None
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise fail(where, f"expected true or false, got {value!r}")
        return value
    if isinstance(default, int | float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise fail(where, f"expected a number, got {value!r}")
        if not math.isfinite(value):
            raise fail(where, f"expected a finite number, got {value!r}")
        if isinstance(default, int) and not isinstance(value, int):
            raise fail(where, f"expected a whole number, got {value!r}")
        return type(default)(value)
    if isinstance(default, str) and not isinstance(value, str):
        raise fail(where, f"expected a string, got {value!r}")
    return value


def line_of(text: str, section: str, key: str) -> int | None:
    """1-based line of ``key`` in table ``[section]`` of ``text`` (best effort)."""
    if not text:
        return None
    current = ""
    first = key.split(".")[0] if key else ""
    for number, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        m = re.match(r"^\[\s*([A-Za-z0-9_.-]+)\s*\]", s)
        if m:
            current = m.group(1)
            if not first and current == section:
                return number
            if first and current == (f"{section}.{first}" if section else first):
                return number  # the key is a table, e.g. a misspelt [robot]
            continue
        if not first:
            continue
        if current == section and re.match(rf"^{re.escape(first)}\s*=", s):
            return number
        if not current and re.match(rf"^{re.escape(section)}\.{re.escape(first)}\s*=", s):
            return number
    return None


def _where(loc: tuple[Any, ...]) -> tuple[str, str]:
    """``("formation.edges", "item 3")`` from a pydantic location."""
    keys = [str(p) for p in loc if isinstance(p, str)]
    items = [f"item {p + 1}" for p in loc if isinstance(p, int)]
    return ".".join(keys), ", ".join(items)


def format_errors(
    exc: ValidationError, source: str, text: str, sections: Mapping[str, tuple[str, ...]]
) -> str:
    problems: list[tuple[bool, str]] = []
    for err in exc.errors(include_url=False):
        loc = tuple(err["loc"])
        where, items = _where(loc)
        section, _, key = where.partition(".")
        if len(loc) == 1:
            section, key = "", where
        kind = err["type"]
        if kind == "extra_forbidden":
            parent = ".".join(where.split(".")[:-1])
            name = where.split(".")[-1]
            known = sections.get(parent, ())
            near = difflib.get_close_matches(name, list(known), n=1)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            table = f"[{parent}]" if parent else "the top level"
            msg = f"unknown key {name!r} in {table}{hint} Known keys: {', '.join(known)}"
        elif kind == "missing" and where in sections:
            msg = f"the table [{where}] is required"
        elif kind == "missing":
            msg = "this key is required"
        elif kind == "value_error":
            msg = str(err.get("ctx", {}).get("error", err["msg"]))
        else:
            given = err.get("input")
            msg = f"{err['msg'][0].lower()}{err['msg'][1:]}, got {given!r}"
        line = line_of(text, section, key) if kind != "missing" else line_of(text, section, "")
        at = f" (line {line})" if line else ""
        label = where + (f", {items}" if items else "")
        # unknown keys first: they often explain the missing ones (a misspelt table)
        problems.append((kind != "extra_forbidden", f"{label}{at}: {msg}"))
    head = f"{source}: " if len(problems) == 1 else f"{source}: {len(problems)} problems: "
    return head + "; ".join(text for _, text in sorted(problems, key=lambda p: p[0]))
