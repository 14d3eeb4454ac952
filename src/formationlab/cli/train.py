"""``formationlab train``: train a learned decentralized law with CMA-ES (docs/learning.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ._app import command, err_console, warn
from ._progress import progress_bar


@command("train")
def train(
    scenario: Annotated[
        Path, typer.Argument(help="Scenario file (TOML): its formation and [study] starts.")
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Parameters file to write (.npz).")],
    generations: Annotated[
        int, typer.Option("--generations", "-g", min=1, help="CMA-ES generations.")
    ] = 40,
    population: Annotated[
        int, typer.Option("--population", "-p", min=2, help="Candidates per generation.")
    ] = 12,
    batch: Annotated[
        int, typer.Option("--batch", "-b", min=1, help="Formations per candidate and generation.")
    ] = 48,
    seed: Annotated[
        int, typer.Option("--seed", "-s", min=0, max=2**31 - 2, help="Seed of the training.")
    ] = 0,
    eval_trials: Annotated[
        int,
        typer.Option(
            "--eval-trials",
            min=0,
            help="Trials of the study run on the trained law, stored with it (0: none).",
        ),
    ] = 200,
    eval_seed: Annotated[
        int | None,
        typer.Option("--eval-seed", min=0, help="Study seed of the evaluation (default --seed)."),
    ] = None,
    figure: Annotated[
        Path | None,
        typer.Option("--figure", help="Also draw the training curve to this file (.png, .pdf)."),
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Replace an existing OUT.")] = False,
    quiet: Annotated[
        bool, typer.Option("--quiet", "-q", help="No progress or table (warnings stay).")
    ] = False,
) -> None:
    """Train the learned law on a scenario's formation and save its network.

    Example:

        formationlab train examples/study-triangle.toml --out policy.npz --generations 40

    Each robot runs one small network on its own measurements (docs/learning.md); CMA-ES
    (the `cma` package: pip install "formationlab[learn]") searches its weights over
    batched rollouts from the study's random starts. Writes OUT (the network, the training
    curve and the evaluation's fractions) and OUT's stem + "-training.csv"; a scenario
    runs it with law = "policy" and parameters = "OUT".
    """
    import dataclasses

    from ..controllers.policy import PolicyLaw
    from ..errors import OutputExistsError, ParameterError
    from ..io.policy import write_policy
    from ..io.scenario import load_scenario
    from ..learning import TrainingConfig, evaluate_policy
    from ..learning import train as run_training
    from ..learning.evaluation import study_config

    def say(message: str) -> None:
        if not quiet:
            err_console.print(message, highlight=False)

    if out.exists() and not force:
        raise OutputExistsError(f"{out} exists; use --force to replace it, or another --out")
    if out.suffix != ".npz":
        raise ParameterError(f"--out names the parameters file, a .npz: got {out}")
    sc = load_scenario(scenario)
    for w in sc.warnings:
        warn(w if w.startswith(sc.source) else f"{sc.source}: {w}")
    sc.in_plane("train")
    study = study_config(sc, max(eval_trials, 1))
    config = TrainingConfig(generations=generations, population=population, batch=batch, seed=seed)
    center = sc.formation.template if sc.formation.template is not None else sc.q0
    with progress_bar("training", quiet=quiet, total=generations) as update:
        result = run_training(sc.formation, study.initial, config, center=center,
                              progress=lambda g, n: update(g))  # fmt: skip
    meta: dict[str, object] = {
        "scenario": sc.source,
        "training": {
            k: (list(v) if isinstance(v, tuple) else v)
            for k, v in dataclasses.asdict(config).items()
        },
    }
    say(f"reward of the trained law: {result.curve['centre'][-1]:.3f} "
        f"(generation 1: {result.curve['centre'][0]:.3f})")  # fmt: skip
    if eval_trials:
        law = PolicyLaw.from_network(result.network, parameters=str(out))
        es = seed if eval_seed is None else eval_seed
        with progress_bar("evaluating", quiet=quiet):
            summary = evaluate_policy(sc, law, trials=eval_trials, seed=es)
        meta["evaluation"] = {
            "trials": eval_trials,
            "seed": es,
            "fractions": summary["fractions"],
            "median_converged_time": summary["median_converged_time"],
        }
        shown = ", ".join(f"{k} {v:.3f}" for k, v in summary["fractions"].items() if v)
        say(f"study of {eval_trials} trials (seed {es}): {shown}")
    params, csv = write_policy(out, result.network, result.curve, meta)
    if figure is not None:
        from ..io.figures import save_figure
        from ..plotting.learning import training_figure

        save_figure(training_figure(result.curve, title=f"{sc.name}: CMA-ES"), figure)
    say(f"wrote {params} and {csv}" + (f" and {figure}" if figure is not None else ""))
