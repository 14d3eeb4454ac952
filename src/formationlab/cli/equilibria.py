"""Command ``equilibria``: where a law's runs end, and whether those ends attract."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from ..errors import ParameterError
from ._app import command

__all__: list[str] = []

_TABLE_KEYS = {
    "starts",
    "seed",
    "duration",
    "collinear",
    "integrator",
    "dt",
    "follow",
    "follow_steps",
}


def _parse_follow(text: str) -> tuple[str, float, float]:
    """``"k_a=0.5:12"`` -> ``("k_a", 0.5, 12.0)``."""
    try:
        name, rng = text.split("=", 1)
        lo, hi = (float(x) for x in rng.split(":"))
    except ValueError:
        raise ParameterError(
            f"--follow takes PARAM=FROM:TO, e.g. k_a=0.5:12, got {text!r}"
        ) from None
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo >= hi:
        raise ParameterError(f"--follow needs FROM < TO, got {lo:g}:{hi:g}")
    return name.strip(), lo, hi


@command(
    "equilibria",
    epilog="Example:  formationlab equilibria examples/paper-simulation-2.toml --out eq/sim2",
)
def equilibria(
    scenario: Annotated[Path, typer.Argument(help="Scenario file (TOML), see docs/scenarios.md.")],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output folder (created; must be empty).")
    ],
    from_study: Annotated[
        Path | None,
        typer.Option("--from-study", help="Use the end states of this study's trials."),
    ] = None,
    starts: Annotated[
        int | None,
        typer.Option(
            min=0, help="Random starts (default 200, or starts in the scenario's equilibria table)."
        ),
    ] = None,
    seed: Annotated[int | None, typer.Option(help="Seed of the random starts (default 0).")] = None,
    law: Annotated[
        str | None,
        typer.Option(
            "--law",
            help="Use this law instead of the scenario's (its controller values where shared).",
        ),
    ] = None,
    follow: Annotated[
        str | None,
        typer.Option(help="Follow each undesired equilibrium in a gain: PARAM=FROM:TO."),
    ] = None,
    integrator: Annotated[
        str | None,
        typer.Option(
            help="Integrator that settles the random starts: rk4 (smooth laws' default), "
            "implicit-euler (switching laws' default; exact sliding, slow with many surfaces), "
            "euler.",
        ),
    ] = None,
    follow_steps: Annotated[
        int | None,
        typer.Option(min=2, help="Values of the gain in --follow (default 24, evenly spaced)."),
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Replace the files of an earlier run in --out.")
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No report.")] = False,
) -> None:
    """Find, refine and classify the equilibria a scenario's law can end in.

    Candidates are the end states of random starts (a fifth of them with all
    robots on a line, where saddles live), or of a study's trials
    (--from-study), plus the end of the scenario's own run. Each is refined
    with a root finder, duplicates up to translation, rotation and allowed
    relabellings are merged, and each equilibrium is classified by the
    eigenvalues of the closed loop's Jacobian: stable, saddle (with its number
    of unstable directions), degenerate, or filippov (on a switching surface).
    --law compares another law on the same formation. Writes
    DIR/equilibria.json and DIR/gallery.png (desired shape first); with
    --follow also DIR/continuation.json and DIR/continuation.png.
    """
    from .. import simulate
    from ..equilibria import catalogue, random_starts, settle
    from ..equilibria import follow as follow_branch
    from ..io.equilibria import read_study_end_states, write_equilibria
    from ..io.figures import save_figure
    from ..io.files import atomic_write_json, prepare_output_dir
    from ..io.scenario import load_scenario

    sc = load_scenario(scenario)
    if law is not None and law != sc.law.name:
        sc = dataclasses.replace(sc, law=_law_named(law, sc.law))
    table: dict[str, Any] = dict(sc.equilibria or {})
    unknown = set(table) - _TABLE_KEYS
    if unknown:
        raise ParameterError(
            f"unknown key(s) {', '.join(sorted(unknown))} in [equilibria]; "
            f"known: {', '.join(sorted(_TABLE_KEYS))}"
        )
    n_starts = int(starts if starts is not None else table.get("starts", 200))
    seed_value = int(seed if seed is not None else table.get("seed", 0))
    duration = float(table.get("duration", 60.0))
    collinear = float(table.get("collinear", 0.2))
    integ_name = integrator if integrator is not None else table.get("integrator")
    settler: Any = None
    if integ_name is not None:
        from ..integrators import INTEGRATORS, FixedStepIntegrator, get_integrator

        fixed = sorted(k for k, v in INTEGRATORS.items() if issubclass(v, FixedStepIntegrator))
        if str(integ_name) not in fixed:
            raise ParameterError(
                f"cannot settle a batch of starts with the integrator {integ_name!r}; "
                f"use one of {', '.join(fixed)}"
            )
        built = get_integrator(str(integ_name), dt=float(table.get("dt", 0.01)))
        settler = built if isinstance(built, FixedStepIntegrator) else None
    follow = follow if follow is not None else table.get("follow")
    follow_steps = int(follow_steps or table.get("follow_steps", 24))
    spec = _parse_follow(follow) if follow else None
    if spec and not hasattr(sc.law, spec[0]):
        raise ParameterError(f"the law {sc.law.name!r} has no parameter {spec[0]!r} to follow")
    folder = prepare_output_dir(out, force=force, markers=("equilibria.json",))

    own = simulate(sc.formation, sc.law, sc.q0, duration=sc.duration, integrator=sc.integrator)
    cands = [own.q[-1][None]]
    outs = [np.array([own.outcome()])]
    source: dict[str, Any] = {"scenario_run": 1}
    if from_study is not None:
        numbers = {
            f.name: getattr(sc.law, f.name)
            for f in dataclasses.fields(sc.law)
            if isinstance(getattr(sc.law, f.name), int | float)
        }
        q, o = read_study_end_states(from_study, sc.n, sc.law.name, numbers)
        cands.append(q)
        outs.append(o)
        source["study"] = {"path": str(from_study), "trials": len(q)}
    elif n_starts:
        rng = np.random.default_rng(seed_value)
        q0 = random_starts(sc.formation, n_starts, rng, collinear=collinear)
        settled = settle(sc.formation, sc.law, q0, duration=duration, integrator=settler)
        cands.append(settled.q_final)
        outs.append(settled.outcome)
        source["random_starts"] = {
            "count": n_starts,
            "seed": seed_value,
            "duration": duration,
            "collinear": collinear,
            "integrator": (settler or _default_settler(sc.law)).name,
        }
    cat = catalogue(sc.formation, sc.law, np.concatenate(cands), outcomes=np.concatenate(outs))
    data = {
        "scenario": sc.name,
        "parameters": sc.parameters,
        "source": source,
        **cat.to_dict(),
    }
    files = ["equilibria.json", "gallery.png"]
    save_figure(_gallery(cat, sc.name), folder / "gallery.png")
    if spec:
        name, lo, hi = spec
        branches, labels, rows = [], [], []
        for k, eq in enumerate(cat.equilibria):
            if eq.desired:
                continue
            b = _both_ways(follow_branch, sc, eq, name, lo, hi, follow_steps)
            branches.append(b)
            labels.append(f"#{k + 1} ({eq.stability})")
            rows.append(
                {
                    "id": k + 1,
                    "values": b.values.tolist(),
                    "stability": [e.stability for e in b.equilibria],
                    "growth_rate": [e.growth_rate for e in b.equilibria],
                    "attractive": [e.attractive for e in b.equilibria],
                    "distances": [e.distances.tolist() for e in b.equilibria],
                    "positions": [e.q.tolist() for e in b.equilibria],
                    "end": b.end,
                }
            )
        atomic_write_json(folder / "continuation.json", {"parameter": name, "branches": rows})
        from ..plotting.equilibria import continuation_figure

        save_figure(continuation_figure(branches, labels=labels), folder / "continuation.png")
        files += ["continuation.json", "continuation.png"]
    write_equilibria({**data, "files": files}, folder / "equilibria.json")
    if not quiet:
        for k, (eq, count) in enumerate(zip(cat.equilibria, cat.counts, strict=True)):
            extra = f", {eq.unstable_directions} unstable" if eq.unstable_directions else ""
            typer.echo(
                f"#{k + 1} {eq.outcome} {eq.stability}{extra}: "
                f"{count} trials, max Re(lambda) = {eq.growth_rate:.4g}"
            )
        if cat.skipped:
            typer.echo(
                "skipped end states: "
                + ", ".join(f"{k} {v}" for k, v in sorted(cat.skipped.items()))
            )
        typer.echo(f"wrote {folder}/")


def _gallery(cat: Any, name: str) -> Any:
    from ..plotting.equilibria import gallery_figure

    return gallery_figure(cat, title=f"{name}: equilibria of the {cat.law.name} law")


def _both_ways(
    follow_branch: Any, sc: Any, eq: Any, name: str, lo: float, hi: float, k: int
) -> Any:
    """Follow ``eq`` from the scenario's value of ``name`` down to ``lo`` and up to ``hi``."""
    from ..equilibria import Branch

    v0 = float(getattr(sc.law, name))
    grid = np.linspace(lo, hi, k)
    up = follow_branch(sc.formation, sc.law, eq.q, name, [v0, *grid[grid > v0]])
    down = follow_branch(sc.formation, sc.law, eq.q, name, [v0, *grid[grid < v0][::-1]])
    values = np.concatenate([down.values[::-1], up.values[1:]])
    eqs = [*down.equilibria[::-1], *up.equilibria[1:]]
    return Branch(
        parameter=name, values=values, equilibria=eqs, end=f"down: {down.end}; up: {up.end}"
    )


def _law_named(name: str, base: Any) -> Any:
    """The law ``name`` with the parameters it shares with ``base`` (others default)."""
    from ..controllers import LAWS, get_law

    if name not in LAWS:
        get_law(name)  # raises the error that lists the known laws
    own = {f.name for f in dataclasses.fields(LAWS[name]) if f.init}
    shared = {f.name: getattr(base, f.name) for f in dataclasses.fields(base) if f.name in own}
    return get_law(name, **shared)


def _default_settler(law: Any) -> Any:
    from ..integrators import RK4, ImplicitEuler

    return RK4(dt=0.01) if law.smooth else ImplicitEuler(dt=0.01)
