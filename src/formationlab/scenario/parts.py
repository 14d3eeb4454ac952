"""Helpers of :mod:`formationlab.scenario`: the law's and the integrator's parameters.

Private. The keys of ``[controller]`` and ``[simulation]`` other than the fixed
ones (``law``, ``integrator``, ...) are split three ways against the
registries (:meth:`formationlab.registry.Registry.split`): the chosen class's
parameters are validated by pydantic (:func:`formationlab.validation.build_dataclass`)
and passed to it; parameters of another class of the same registry are
ignored, and reported as ignored (the caller warns); any other key is an error
that suggests the nearest key, or says which table it belongs in.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from pydantic import ValidationError

from ..errors import ScenarioError, UnknownNameError, UserInputError
from ..registry import Registry, parameters_of
from ..validation import build_dataclass, nearest, validation_error

__all__ = ["Fail", "build_entry", "nested_keys"]

Fail = Callable[[str, str], ScenarioError]


def nested_keys(cls: type, fixed: Sequence[str], path: str) -> tuple[str, ...]:
    """The keys of the dotted sub-table ``path`` of a class's parameters (``""``: its table)."""
    if not path:
        return (*fixed, *parameters_of(cls))
    for part in path.split("."):
        default = _default(cls, part)
        if not dataclasses.is_dataclass(default):
            return ()
        cls = type(default)
    return parameters_of(cls)


def _default(cls: type, name: str) -> Any:
    for f in dataclasses.fields(cls):
        if f.name == name:
            if f.default is not dataclasses.MISSING:
                return f.default
            if f.default_factory is not dataclasses.MISSING:
                return f.default_factory()
    return None


def build_entry(
    registry: Registry[Any],
    other: Registry[Any],
    name: str,
    given: Mapping[str, Any],
    *,
    section: str,
    other_section: str,
    fixed: Sequence[str],
    source: str,
    text: str,
    fail: Fail,
    used_by: Sequence[str] = (),
) -> tuple[Any, list[str]]:
    """The entry ``name`` of ``registry`` built from ``given``, and the keys it ignored.

    Parameters
    ----------
    registry, other : Registry
        Where ``name`` is looked up (laws for ``[controller]``); the registry of the
        other table (integrators), to say where a misplaced key belongs.
    given : mapping
        The table's keys other than ``fixed``.
    section, other_section : str
        The table (``"controller"``), and the other table (``"simulation"``), for messages.
    used_by : sequence of str
        Other entries of ``registry`` the file also runs (a study's laws): their keys are
        not reported as ignored.

    Returns
    -------
    entry, ignored
        The built object, and the keys that belong to other entries of ``registry``
        and that no entry of ``used_by`` takes.
    """
    kind = registry.kind
    try:
        cls = registry[name]
    except UnknownNameError as exc:
        raise fail(f"{section}.{kind}", str(exc)) from None
    try:
        taken, ignored = registry.split(name, given)
    except UserInputError as exc:
        key = str(exc.key)
        takes = (*fixed, *parameters_of(cls))
        owners = other.owners(key)
        near = nearest(key, takes)
        if owners:
            hint = (
                f" {key!r} belongs to the {other.kind} {', '.join(repr(o) for o in owners)}: "
                f"put it in [{other_section}]."
            )
        elif near:
            hint = f" Did you mean {near!r}?"
        else:  # a misspelt key of another entry: "k_aa" -> "k_a" of 'angle-restricted'
            others = {k: n for n in registry for k in parameters_of(registry[n])}
            far = nearest(key, others)
            hint = f" Did you mean {far!r} (of the {kind} {others[far]!r})?" if far else ""
        raise fail(
            f"{section}.{key}",
            f"{kind} {cls.name!r} takes no key {key!r}.{hint} It takes: {', '.join(takes)}",
        ) from None
    try:
        entry = build_dataclass(cls, taken)
    except ValidationError as exc:
        known = lambda table: nested_keys(cls, fixed, table.removeprefix(section).strip("."))  # noqa: E731
        raise validation_error(exc, source=source, text=text, prefix=section, known=known) from None
    except UserInputError as exc:
        key = f"{section}.{exc.key}" if exc.key else section
        raise fail(key, str(exc)) from None
    also = set().union(*(parameters_of(registry[n]) for n in used_by if n in registry))
    return entry, [k for k in ignored if k not in also]
