"""The equilibria of a scenario's law, as the ``equilibria`` command reports them.

:class:`EquilibriaConfig` is the ``[equilibria]`` table of a scenario (validated
by pydantic; :func:`parse_equilibria` places its errors in the file), and
:func:`find_equilibria` runs the pipeline of this package on a scenario:
candidates from the scenario's own run plus random starts settled by a
fixed-step integrator (:func:`~formationlab.equilibria.settle`), or a study's
end states; :func:`~formationlab.equilibria.catalogue` of them; and, with
``follow``, every undesired equilibrium continued in one gain
(:func:`~formationlab.equilibria.follow`). It returns an
:class:`EquilibriaReport`; writing files is the caller's (``formationlab.io``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from pydantic import ConfigDict, Field, ValidationError, ValidationInfo, field_validator
from pydantic.dataclasses import dataclass as pydantic_dataclass

from ..controllers import LAWS, Law
from ..dynamics import System
from ..errors import ParameterError, UserInputError
from ..integrators import INTEGRATORS, RK4, FixedStepIntegrator, ImplicitEuler
from ..simulation.run import simulate
from ..validation import steps_within, validation_error
from .blocks import SettledStore, settle_in_blocks
from .catalogue import Catalogue, catalogue
from .continuation import Branch, follow
from .search import random_starts

#: the most random starts one search settles (each is a run of the formation)
STARTS_LIMIT = 1_000_000

if TYPE_CHECKING:
    from ..scenario.parse import Scenario

__all__ = [
    "EquilibriaConfig",
    "EquilibriaReport",
    "equilibria_scenario",
    "find_equilibria",
    "parse_equilibria",
]

EndStates = Callable[[Law], tuple[NDArray[np.float64], NDArray[np.str_]]]


def _parse_follow(text: str) -> tuple[str, float, float]:
    """``"k_a=0.5:12"`` -> ``("k_a", 0.5, 12.0)``."""
    try:
        name, rng = text.split("=", 1)
        lo, hi = (float(x) for x in rng.split(":"))
    except ValueError:
        raise ParameterError(
            f"expected PARAM=FROM:TO, e.g. k_a=0.5:12, got {text!r}", key="follow"
        ) from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo >= hi:
        raise ParameterError(f"expected FROM < TO, got {lo:g}:{hi:g}", key="follow")
    return name.strip(), lo, hi


@pydantic_dataclass(
    frozen=True,
    kw_only=True,
    config=ConfigDict(strict=True, extra="forbid", allow_inf_nan=False),
)
class EquilibriaConfig:
    """The ``[equilibria]`` table (command-line options of the same names win).

    Attributes
    ----------
    starts : int
        Random starts (>= 0; default 200), a fraction ``collinear`` of them on a line.
    seed : int
        Seed of the random starts (>= 0; default 0).
    duration : float
        Longest settling run of each start, seconds (default 60).
    collinear : float
        Fraction of the starts with all robots on one line, in [0, 1] (default 0.2).
    coplanar : float
        For a formation in space, the fraction of the starts with all robots on one plane,
        in [0, 1] (default 0.2; taken after the collinear ones). Not used in the plane.
    integrator : str, optional
        Fixed-step integrator of the settling runs (default: ``rk4`` for smooth laws,
        ``implicit-euler`` for switching laws).
    dt : float
        Its step, seconds (default 0.01).
    follow : str, optional
        ``PARAM=FROM:TO``: follow each undesired equilibrium in a gain.
    follow_steps : int
        Values of the gain in ``follow`` (>= 2; default 24, evenly spaced).
    law : str, optional
        Another law instead of the scenario's (with the ``[controller]`` keys it takes).
    """

    starts: int = Field(default=200, ge=0, le=STARTS_LIMIT)
    seed: int = Field(default=0, ge=0)
    duration: float = Field(default=60.0, gt=0, le=1e7)
    collinear: float = Field(default=0.2, ge=0, le=1)
    coplanar: float = Field(default=0.2, ge=0, le=1)
    integrator: str | None = None
    dt: float = Field(default=0.01, gt=0)
    follow: str | None = None
    follow_steps: int = Field(default=24, ge=2)
    law: str | None = None

    @field_validator("dt")
    @classmethod
    def _steps(cls, v: float, info: ValidationInfo) -> float:
        duration = info.data.get("duration")
        if duration is not None:
            steps_within(duration, v, "dt")
        return v

    @field_validator("follow")
    @classmethod
    def _follow(cls, v: str | None) -> str | None:
        if v is not None:
            _parse_follow(v)
        return v

    @field_validator("integrator")
    @classmethod
    def _integrator(cls, v: str | None) -> str | None:
        if v is None:
            return v
        name = INTEGRATORS.canonical(v)
        fixed = [k for k, c in INTEGRATORS.items() if issubclass(c, FixedStepIntegrator)]
        if name not in fixed:
            raise ParameterError(
                f"cannot settle a batch of starts with the integrator {v!r}; "
                f"use one of {', '.join(fixed)}"
            )
        return name

    @property
    def follow_spec(self) -> tuple[str, float, float] | None:
        """``(parameter, from, to)`` of ``follow``, or ``None``."""
        return None if self.follow is None else _parse_follow(self.follow)

    def settler(self, law: Law) -> FixedStepIntegrator:
        """The integrator of the settling runs for ``law``."""
        if self.integrator is None:
            return RK4(dt=self.dt) if law.smooth else ImplicitEuler(dt=self.dt)
        cls = INTEGRATORS[self.integrator]  # a fixed-step one: checked by the validator
        return cls(dt=self.dt)  # type: ignore[return-value,call-arg]


def parse_equilibria(sc: Scenario, **overrides: Any) -> EquilibriaConfig:
    """The scenario's ``[equilibria]`` table with ``overrides`` (``None`` values skipped).

    Raises
    ------
    ScenarioError
        Naming the key (``equilibria.duration``) and its line, what was expected and
        what was given; a bad override is named as its option (``--follow``).
    """
    fields = [f.name for f in dataclasses.fields(EquilibriaConfig)]
    try:
        config = EquilibriaConfig(**(sc.equilibria or {}))
    except ValidationError as exc:
        raise validation_error(
            exc, source=sc.source, text=sc.text, prefix="equilibria", known=lambda _: fields
        ) from None
    try:
        return dataclasses.replace(config, **{k: v for k, v in overrides.items() if v is not None})
    except ValidationError as exc:
        raise validation_error(exc, source="command line", options=True) from None


@dataclasses.dataclass(frozen=True, kw_only=True, eq=False)
class EquilibriaReport:
    """What :func:`find_equilibria` found.

    Attributes
    ----------
    scenario : Scenario
        The scenario run (with ``config.law`` if given).
    catalogue : Catalogue
        The distinct equilibria, desired first, with counts.
    source : dict
        JSON-ready: where the candidates came from.
    branches : list of Branch
        With ``follow``: one branch per undesired equilibrium.
    labels : list of str
        ``"#k (stability)"`` of each branch.
    """

    scenario: Scenario
    catalogue: Catalogue
    source: dict[str, Any]
    parameter: str | None = None
    branches: list[Branch] = dataclasses.field(default_factory=list)
    labels: list[str] = dataclasses.field(default_factory=list)
    ids: list[int] = dataclasses.field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready content of ``equilibria.json`` (without the list of files)."""
        sc = self.scenario
        return {
            "scenario": sc.name,
            "parameters": sc.parameters,
            "source": self.source,
            **self.catalogue.to_dict(),
        }

    def continuation(self) -> dict[str, Any] | None:
        """JSON-ready content of ``continuation.json``, or ``None`` without ``follow``."""
        if self.parameter is None:
            return None
        rows = [
            {
                "id": k,
                "values": b.values.tolist(),
                "stability": [e.stability for e in b.equilibria],
                "growth_rate": [e.growth_rate for e in b.equilibria],
                "attractive": [e.attractive for e in b.equilibria],
                "distances": [e.distances.tolist() for e in b.equilibria],
                "positions": [e.q.tolist() for e in b.equilibria],
                "speed": [e.speed for e in b.equilibria],
                "angular_velocity": [e.omega for e in b.equilibria],
                "axis": [None if e.axis is None else e.axis.tolist() for e in b.equilibria],
                "end": b.end,
            }
            for k, b in zip(self.ids, self.branches, strict=True)
        ]
        return {"parameter": self.parameter, "branches": rows}

    def lines(self) -> list[str]:
        """The report in words: one line per equilibrium, then the skipped end states."""
        cat = self.catalogue
        out = []
        for k, (eq, count) in enumerate(zip(cat.equilibria, cat.counts, strict=True)):
            extra = f", {eq.unstable_directions} unstable" if eq.unstable_directions else ""
            speed = float(np.linalg.norm(eq.velocity))
            if eq.outcome == "drifting":
                extra += f", |v| = {speed:.4g} m/s"
            elif eq.outcome == "rotating":
                extra += f", omega = {eq.omega:.4g} rad/s, |v| = {speed:.4g} m/s"
                if eq.axis is not None:  # in space: a screw
                    axis = ", ".join(f"{c:.3g}" for c in eq.axis)
                    advance = float(eq.motion.axial_velocity)
                    extra += f", axis ({axis}), advance {advance:.4g} m/s"
            if eq.constraints:
                extra += f", deadlock on {', '.join(eq.constraints)}"
            out.append(
                f"#{k + 1} {eq.outcome} {eq.stability}{extra}: "
                f"{count} trials, max Re(lambda) = {eq.growth_rate:.4g}"
            )
        if cat.skipped:
            skipped = ", ".join(f"{k} {v}" for k, v in sorted(cat.skipped.items()))
            out.append(f"skipped end states: {skipped}")
        return out


def equilibria_scenario(sc: Scenario, config: EquilibriaConfig) -> Scenario:
    """The scenario with ``config.law`` (if given), checked against ``config.follow``.

    Raises
    ------
    ScenarioError, ParameterError
        An unknown law, or a followed parameter the law does not have.
    """
    if config.law is not None:
        try:
            LAWS.canonical(config.law)  # (an unknown law is the equilibria table's key)
        except UserInputError as exc:
            raise sc.locate(ParameterError(str(exc), key="equilibria.law")) from None
        sc = dataclasses.replace(sc, law=sc.law_named(config.law))
    spec = config.follow_spec
    if spec and not hasattr(sc.law, spec[0]):
        raise sc.locate(
            ParameterError(
                f"the law {sc.law.name!r} has no parameter {spec[0]!r} to follow",
                key="equilibria.follow",
            )
        )
    return sc


def find_equilibria(
    sc: Scenario,
    config: EquilibriaConfig | None = None,
    *,
    end_states: EndStates | None = None,
    end_states_source: str | None = None,
    progress: Callable[[str], None] | None = None,
    store: SettledStore | None = None,
    settled: Callable[[int, int], None] | None = None,
) -> EquilibriaReport:
    """Find, refine, classify and (optionally) follow the equilibria of a scenario's law.

    Parameters
    ----------
    sc : Scenario
        The scenario; its own run's end state is always a candidate.
    config : EquilibriaConfig, optional
        Default: the scenario's ``[equilibria]`` table (:func:`parse_equilibria`).
    end_states : callable, optional
        ``end_states(law) -> (q, outcomes)``, shapes ``(B, n, d)`` and ``(B,)``: the end
        states of a study's trials of ``law``, used instead of random starts.
    end_states_source : str, optional
        Where ``end_states`` read from (recorded in ``source``).
    progress : callable, optional
        ``progress(stage)``, called as each of its stages starts (three, four with a
        ``follow`` gain): the scenario's run, the random starts (or the study's end
        states), the refinement and classification, following the equilibria.
    store : SettledStore, optional
        Keeps the random starts' settled blocks, and gives back those it holds (a resumed
        search: :func:`~formationlab.equilibria.blocks.settle_in_blocks`).
    settled : callable, optional
        ``settled(done, total)``: the random starts settled so far, after each block.

    Returns
    -------
    EquilibriaReport
    """
    config = config or parse_equilibria(sc)
    sc = equilibria_scenario(sc, config)
    law, spec = sc.law, config.follow_spec
    formation = law.formation_for(sc.formation)  # as the law is judged (bearings kept or not)
    safety = {"obstacles": sc.obstacles, "safety": sc.safety}
    say = progress or (lambda _stage: None)
    say("the scenario's run")
    own = simulate(
        sc.formation, law, sc.q0, duration=sc.duration, integrator=sc.integrator, **safety
    )
    system = None
    if sc.obstacles or (sc.safety is not None and sc.safety.enabled):
        system = System(formation=sc.formation, law=law, **safety)
    cands = [own.q[-1][None]]
    outs = [np.array([own.outcome()])]
    source: dict[str, Any] = {"scenario_run": 1}
    say("the random starts" if end_states is None else "the study's end states")
    if end_states is not None:
        q, o = end_states(law)
        cands.append(q)
        outs.append(o)
        source["study"] = {"path": end_states_source, "trials": len(q)}
    elif config.starts:
        rng = np.random.default_rng(config.seed)
        q0 = random_starts(
            sc.formation,
            config.starts,
            rng,
            collinear=config.collinear,
            coplanar=config.coplanar,
        )
        settler = config.settler(law)
        if sc.obstacles:  # starts touching an obstacle are left out
            keep = system.obstacle_clearances(q0).min(axis=(-2, -1)) > 0  # type: ignore[union-attr]
            q0 = q0[keep]
        q_end, o_end = settle_in_blocks(
            sc.formation, law, q0, duration=config.duration, integrator=settler, system=system,
            store=store, progress=settled,
        )  # fmt: skip
        cands.append(q_end)
        outs.append(o_end)
        source["random_starts"] = {
            "count": config.starts,
            "seed": config.seed,
            "duration": config.duration,
            "collinear": config.collinear,
            "integrator": settler.name,
        }
        if sc.formation.dim == 3:
            source["random_starts"]["coplanar"] = config.coplanar
    say(f"refining and classifying {sum(len(c) for c in cands):,} candidates")
    cat = catalogue(
        formation, law, np.concatenate(cands), outcomes=np.concatenate(outs), system=system
    )
    report = EquilibriaReport(scenario=sc, catalogue=cat, source=source)
    if spec is None:
        return report
    name, lo, hi = spec
    say(f"following the equilibria in {name}")
    branches, labels, ids = [], [], []
    for k, eq in enumerate(cat.equilibria):
        if eq.desired:
            continue
        branches.append(_both_ways(sc, eq.q, name, lo, hi, config.follow_steps, eq.moving))
        labels.append(f"#{k + 1} ({eq.stability})")
        ids.append(k + 1)
    return dataclasses.replace(report, parameter=name, branches=branches, labels=labels, ids=ids)


def _both_ways(
    sc: Scenario,
    q: NDArray[np.float64],
    name: str,
    lo: float,
    hi: float,
    k: int,
    moving: bool = False,
) -> Branch:
    """Follow the equilibrium at ``q`` from the scenario's value of ``name`` to ``lo``, ``hi``."""
    v0 = float(getattr(sc.law, name))
    grid = np.linspace(lo, hi, k)
    up = follow(sc.formation, sc.law, q, name, [v0, *grid[grid > v0]], moving=moving)
    down = follow(sc.formation, sc.law, q, name, [v0, *grid[grid < v0][::-1]], moving=moving)
    values = np.concatenate([down.values[::-1], up.values[1:]])
    eqs = [*down.equilibria[::-1], *up.equilibria[1:]]
    return Branch(
        parameter=name, values=values, equilibria=eqs, end=f"down: {down.end}; up: {up.end}"
    )
