"""The groups of a study: every law at every point of its parameter sweep.

A group is one law with one set of parameters on one formation; the trials of a
study are run once per group. A law runs only the sweep points of the keys it
has (its dataclass fields, ``eta``/``influence`` of its repulsion, and the robot
parameter ``diameter``), and takes the scenario law's parameters that it shares
by name. The sensing keys (``frame_error``, ``noise``, ``range``, ``delay``, ``drop``, ``mismatch``:
the scenario's ``[sensing]`` with that key changed) and the fault key ``stop_at``
(the time at which the robots of the scenario's ``[faults] stop`` stop) apply to
every law.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..controllers import LAWS, Law
from ..errors import ParameterError, UserInputError
from ..formation.spec import Formation
from ..sensing import Faults, Sensing, Stop
from ..validation import choices, nearest
from .config import StudyConfig

__all__ = ["FAULT_KEYS", "REPULSION_KEYS", "ROBOT_KEYS", "SENSING_KEYS", "Group", "study_groups"]

REPULSION_KEYS = ("eta", "influence")
#: Sweep keys that set a property of the robots.
ROBOT_KEYS = ("diameter",)
#: Sweep keys of the sensing model (fields of :class:`~formationlab.sensing.Sensing`).
SENSING_KEYS = ("frame_error", "noise", "range", "delay", "drop", "mismatch")
#: Sweep keys of the faults: when the robots of ``[faults] stop`` stop.
FAULT_KEYS = ("stop_at",)
#: Sweep keys that apply to every law.
EVERY_LAW = (*ROBOT_KEYS, *SENSING_KEYS, *FAULT_KEYS)


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
    sensing : Sensing or None
        How the robots sense (the scenario's, with the point's sensing keys).
    faults : Faults or None
        The robots that stop (the scenario's, with the point's ``stop_at``).
    """

    index: int
    law: Law
    formation: Formation
    parameters: dict[str, float]
    sensing: Sensing | None = None
    faults: Faults | None = None

    @property
    def sensed(self) -> bool:
        """Whether the trials need the sensed (numpy driver) path."""
        return (self.sensing is not None and not self.sensing.ideal) or (
            self.faults is not None and self.faults.any
        )

    def describe(self) -> dict[str, Any]:
        """JSON-ready: ``law``, ``parameters`` and the law's full ``law_parameters``."""
        return {
            "group": self.index,
            "law": self.law.name,
            "parameters": dict(self.parameters),
            "law_parameters": dataclasses.asdict(self.law),
            "diameters": self.formation.diameters.tolist(),
            # (absent without sensing or faults: earlier fingerprints are kept)
            **({"sensing": self.sensing.describe()} if self.sensing is not None else {}),
            **({"faults": self.faults.describe()} if self.faults is not None else {}),
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
    return key in EVERY_LAW or key in names or (key in REPULSION_KEYS and "repulsion" in names)


def _sensed(
    point: dict[str, float], sensing: Sensing | None, faults: Faults | None
) -> tuple[Sensing | None, Faults | None]:
    """The point's sensing and faults: the scenario's with the swept keys changed."""
    given: dict[str, Any] = {k: v for k, v in point.items() if k in SENSING_KEYS}
    if given:
        sensing = dataclasses.replace(sensing or Sensing(), **given)
    if "stop_at" in point:
        assert faults is not None  # checked by study_groups
        faults = Faults(stop=[Stop(robot=s.robot, at=point["stop_at"]) for s in faults.stop])
    return sensing, faults


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
    sensing: Sensing | None = None,
    faults: Faults | None = None,
) -> list[Group]:
    """The groups of a study: every law of ``config.laws`` at every point of its sweep.

    A law runs the product of the sweep lists of the keys that apply to it
    (its dataclass fields, ``eta``/``influence`` of its repulsion, ``diameter``).
    ``laws`` gives the base law of each name (a scenario's
    :meth:`~formationlab.scenario.Scenario.law_named`: the file's keys that it takes);
    without it, a law takes the parameters it shares with ``law``. ``sensing`` and
    ``faults`` are the scenario's; the sensing and fault keys of a point change them.

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
            known = [*takes, *REPULSION_KEYS, *EVERY_LAW]
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
    if "stop_at" in keys and (faults is None or not faults.any):
        raise ParameterError(
            "study.sweep.stop_at sets when the robots of [faults] stop stop, but the scenario "
            "names none: add [faults] stop = [{ robot = 2 }] (the robot that fails)",
            key="study.sweep.stop_at",
        )
    groups: list[Group] = []
    for name in names:
        base = laws[name] if laws is not None and name in laws else _base_law(name, law)
        mine = [k for k in keys if _applies(k, type(base))]
        for values in itertools.product(*(config.sweep[k] for k in mine)):
            point = {k: float(v) for k, v in zip(mine, values, strict=True)}
            try:
                g_law, g_formation = _apply(base, formation, point)
                g_sensing, g_faults = _sensed(point, sensing, faults)
            except UserInputError as exc:
                where = ", ".join(f"{k} = {v:g}" for k, v in point.items())
                raise ParameterError(
                    f"study.sweep ({name}, {where}): {exc}", key="study.sweep"
                ) from None
            groups.append(
                Group(
                    index=len(groups),
                    law=g_law,
                    formation=g_formation,
                    parameters=point,
                    sensing=g_sensing,
                    faults=g_faults,
                )
            )
    return groups
