"""The groups of a study: every law at every point of its parameter sweep.

A group is one law with one set of parameters on one formation; the trials of a
study are run once per group. A law runs only the sweep points of the keys it
has (its dataclass fields, ``eta``/``influence`` of its repulsion, and the robot
parameter ``diameter``), and takes the scenario law's parameters that it shares
by name.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..controllers import LAWS, Law
from ..errors import ParameterError, UserInputError
from ..spec import Formation
from ..validation import choices, nearest
from .config import StudyConfig

__all__ = ["REPULSION_KEYS", "ROBOT_KEYS", "Group", "study_groups"]

REPULSION_KEYS = ("eta", "influence")
#: Sweep keys that set a property of the robots.
ROBOT_KEYS = ("diameter",)


# ----------------------------------------------------------------------------- groups


@dataclass(frozen=True, kw_only=True, eq=False)
class Group:
    """One law at one point of the sweep.

    Attributes
    ----------
    index : int
        0-based position in the study (the ``group`` column of the trials).
    law : Law
        The law with the point's parameters.
    formation : Formation
        The formation with the point's robot parameters (``diameter``).
    parameters : dict
        The swept parameters that apply to this law, ``{key: value}``.
    """

    index: int
    law: Law
    formation: Formation
    parameters: dict[str, float]

    def describe(self) -> dict[str, Any]:
        """JSON-ready: ``law``, ``parameters`` and the law's full ``law_parameters``."""
        return {
            "group": self.index,
            "law": self.law.name,
            "parameters": dict(self.parameters),
            "law_parameters": dataclasses.asdict(self.law),
            "diameters": self.formation.diameters.tolist(),
        }


def _fields(cls: type) -> set[str]:
    return {f.name for f in dataclasses.fields(cls) if f.init}


def _base_law(name: str, law: Law) -> Law:
    """Law ``name`` with the parameters it shares (by name) with the scenario's ``law``."""
    if name == law.name:
        return law
    cls = LAWS[name]
    shared = _fields(cls) & _fields(type(law))
    return cls(**{k: getattr(law, k) for k in shared})


def _applies(key: str, cls: type) -> bool:
    names = _fields(cls)
    return key in ROBOT_KEYS or key in names or (key in REPULSION_KEYS and "repulsion" in names)


def _apply(law: Law, formation: Formation, point: dict[str, float]) -> tuple[Law, Formation]:
    names = _fields(type(law))
    params: dict[str, Any] = {k: v for k, v in point.items() if k in names}
    rep = {k: v for k, v in point.items() if k in REPULSION_KEYS and k not in names}
    if rep:
        params["repulsion"] = dataclasses.replace(law.repulsion, **rep)  # type: ignore[attr-defined]
    if "diameter" in point:
        formation = formation.with_diameters(point["diameter"])
    return law.with_params(**params) if params else law, formation


def study_groups(
    formation: Formation,
    law: Law,
    config: StudyConfig,
    *,
    laws: Mapping[str, Law] | None = None,
) -> list[Group]:
    """The groups of a study: every law of ``config.laws`` at every point of its sweep.

    A law runs the product of the sweep lists of the keys that apply to it
    (its dataclass fields, ``eta``/``influence`` of its repulsion, ``diameter``).
    ``laws`` gives the base law of each name (a scenario's
    :meth:`~formationlab.scenario.Scenario.law_named`: the file's keys that it takes);
    without it, a law takes the parameters it shares with ``law``.

    Raises
    ------
    ParameterError
        An unknown law, a sweep key that applies to none of the laws, or a sweep
        value a law or the formation rejects.
    """
    try:
        names = tuple(LAWS.canonical(n) for n in config.laws or (law.name,))
    except UserInputError as exc:
        raise ParameterError(f"study.laws: {exc}", key="study.laws") from None
    keys = list(config.sweep)
    for key in keys:
        if not any(_applies(key, LAWS[name]) for name in names):
            takes = sorted(set().union(*(_fields(LAWS[n]) for n in names)) - {"repulsion"})
            known = [*takes, *REPULSION_KEYS, *ROBOT_KEYS]
            hint = choices(key, known, "Sweepable")
            if hint.startswith("."):  # a parameter of a law the study does not run?
                others = {k: n for n in LAWS for k in _fields(LAWS[n]) if n not in names}
                far = nearest(key, others)
                if far:
                    hint = (
                        f"; did you mean {far!r} (of the law {others[far]!r}: add it to "
                        f"study.laws)?{hint.removeprefix('.')}"
                    )
            raise ParameterError(
                f"study.sweep.{key}: no law of the study ({', '.join(names)}) has a parameter "
                f"{key!r}{hint}",
                key=f"study.sweep.{key}",
            )
    groups: list[Group] = []
    for name in names:
        base = laws[name] if laws is not None and name in laws else _base_law(name, law)
        mine = [k for k in keys if _applies(k, type(base))]
        for values in itertools.product(*(config.sweep[k] for k in mine)):
            point = {k: float(v) for k, v in zip(mine, values, strict=True)}
            try:
                g_law, g_formation = _apply(base, formation, point)
            except UserInputError as exc:
                where = ", ".join(f"{k} = {v:g}" for k, v in point.items())
                raise ParameterError(
                    f"study.sweep ({name}, {where}): {exc}", key="study.sweep"
                ) from None
            groups.append(
                Group(index=len(groups), law=g_law, formation=g_formation, parameters=point)
            )
    return groups
