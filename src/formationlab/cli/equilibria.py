"""Command ``equilibria``: where a law's runs end, and whether those ends attract."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from ._app import INTERRUPTED, FigureFormatOption, command, err_console, fail, warn
from ._progress import shows_progress, stage_bar

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from ..controllers import Law

__all__: list[str] = []


def _log(message: str, quiet: bool) -> None:
    if not quiet:
        err_console.print(message, highlight=False, soft_wrap=True)


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
    resume: Annotated[
        bool,
        typer.Option(
            "--resume",
            help="Finish an interrupted search in --out: the random starts it settled are kept.",
        ),
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress, no report.")] = False,
    figure_format: FigureFormatOption = "png",
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
    --follow also DIR/continuation.json and DIR/continuation.png (figures in
    the --format list: pdf and svg for LaTeX). The random starts settle in blocks
    kept in DIR/settled/ until the search ends: Ctrl-C keeps them, and --resume
    settles only the rest.
    """
    import dataclasses
    import shutil

    from ..equilibria.blocks import BLOCK
    from ..equilibria.report import equilibria_scenario, find_equilibria, parse_equilibria
    from ..io.equilibria import SettledFolder, read_study_end_states, write_equilibria
    from ..io.figures import figure_formats, save_figures
    from ..io.files import atomic_write_json, prepare_output_dir
    from ..io.scenario import load_scenario
    from ..plotting.equilibria import continuation_figure, gallery_figure

    formats = figure_formats(figure_format)
    sc = load_scenario(scenario)
    for w in sc.warnings:
        warn(w if w.startswith(sc.source) else f"{sc.source}: {w}")
    if sc.model.name != "single-integrator" or sc.marching is not None:
        warn(
            f"{sc.source}: equilibria covers single integrators only: it finds and classifies "
            f"the zeros of the law (u = 0), which the {sc.model.name} robots share at their "
            "points, but their stability is that of single integrators; [robots] model "
            "and [marching] are not used"
        )
    config = parse_equilibria(
        sc,
        starts=starts,
        seed=seed,
        law=law,
        follow=follow,
        integrator=integrator,
        follow_steps=follow_steps,
    )
    sc = equilibria_scenario(sc, config)  # an unknown law or parameter: fail before writing
    identity = {"scenario": sc.text, "equilibria": dataclasses.asdict(config)}
    store = SettledFolder(out, identity)
    if resume:
        if not out.is_dir():
            fail(f"nothing to resume: {out} does not exist; run without --resume")
        from ..io.claim import claim_folder

        claim_folder(out)  # (one writer at a time, as prepare_output_dir claims a new one)
        folder = out
        _log(f"resuming: {store.check_resumable():,} settled starts kept in {store.folder}", quiet)
    else:
        folder = prepare_output_dir(out, force=force, markers=("equilibria.json",))
        if force and store.root.exists():
            shutil.rmtree(store.root)  # (an earlier search's blocks)
        store.start()

    def study_ends(law_: Law) -> tuple[NDArray[np.float64], NDArray[np.str_]]:
        assert from_study is not None
        numbers = {k: v for k, v in dataclasses.asdict(law_).items() if isinstance(v, int | float)}
        return read_study_end_states(from_study, sc.n, law_.name, numbers, dim=sc.formation.dim)

    # find_equilibria's stages (three, four with --follow), then the figures
    stages = 4 + (config.follow_spec is not None)
    logged = not quiet and not shows_progress(quiet)  # a log: a line per stage instead

    def stage(now: Callable[[str], None]) -> Callable[[str], None]:
        def said(name: str) -> None:
            now(name)
            _log(f"equilibria: {name} ...", not logged)

        return said

    def settled(done: int, total: int) -> None:
        if done and done == min(total, BLOCK):  # (once: the first block)
            _log(f"equilibria: {done:,} of {total:,} random starts settled; Ctrl-C keeps the "
                 "settled ones for --resume", not logged)  # fmt: skip

    with stage_bar("equilibria", stages, quiet=quiet) as now:
        try:
            report = find_equilibria(
                sc,
                config,
                end_states=study_ends if from_study is not None else None,
                end_states_source=str(from_study) if from_study is not None else None,
                progress=stage(now),
                store=store,
                settled=settled,
            )
        except KeyboardInterrupt:
            fail(
                f"interrupted; {store.settled():,} settled random starts are kept in "
                f"{store.folder}: run the same command with --resume to finish (no "
                "equilibria.json yet)",
                INTERRUPTED,
            )
        files = ["equilibria.json"]
        # the search's result first: a Ctrl-C while drawing loses no equilibrium
        write_equilibria({**report.to_dict(), "files": files}, folder / "equilibria.json")
        shutil.rmtree(store.root, ignore_errors=True)  # (the search has ended)
        stage(now)("figures")
        try:
            cat, name = report.catalogue, report.scenario.name
            title = f"{name}: equilibria of the {cat.law.name} law"
            gallery = save_figures(gallery_figure(cat, title=title), folder / "gallery", formats)
            files += [p.name for p in gallery]
            continuation = report.continuation()
            if continuation is not None:
                atomic_write_json(folder / "continuation.json", continuation)
                figure = continuation_figure(report.branches, labels=report.labels)
                drawn = save_figures(figure, folder / "continuation", formats)
                files += ["continuation.json", *(p.name for p in drawn)]
        except KeyboardInterrupt:
            write_equilibria({**report.to_dict(), "files": files}, folder / "equilibria.json")
            fail(
                f"interrupted while drawing the figures; the equilibria are in "
                f"{folder / 'equilibria.json'} ({', '.join(files)} written)",
                INTERRUPTED,
            )
    write_equilibria({**report.to_dict(), "files": files}, folder / "equilibria.json")
    if not quiet:
        for line in report.lines():
            typer.echo(line)
        typer.echo(f"wrote {folder}/")
