"""``formationlab study``: a Monte-Carlo study of a scenario (docs/studies.md)."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer

from ..errors import ParameterError
from ._app import FigureFormatOption, command, err_console, fail, warn
from ._plan import check_study, plan_study
from ._progress import progress_bar, shows_progress

#: files of an earlier study that ``study --force`` removes
STUDY_PATTERNS = ("trials.parquet", "summary.json", "scenario.toml", "*.png", "*.pdf", "*.svg")


@command("study")
def study(
    scenario: Annotated[Path, typer.Argument(help="Scenario file (TOML) with a [study] table.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Folder for the results.")],
    trials: Annotated[
        int | None,
        typer.Option("--trials", "-n", min=1, help="Trials per group (overrides study.trials)."),
    ] = None,
    seed: Annotated[
        int, typer.Option("--seed", "-s", min=0, max=2**63 - 1, help="Seed of the study (>= 0).")
    ] = 0,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help='Run chunks on dask.distributed: "local" (a LocalCluster of processes) or a '
            "scheduler's address (tcp://host:8786). Default: this machine, without dask."
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="With --scheduler local: the cluster's processes (default one per core). "
            "Without --scheduler: above 1, a pool of single-threaded processes instead of this "
            "process's multi-threaded kernel (default 1).",
        ),
    ] = None,
    chunk_size: Annotated[
        int | None,
        typer.Option("--chunk-size", min=1, help="Trials per chunk (overrides study.chunk_size)."),
    ] = None,
    dt: Annotated[
        float | None, typer.Option("--dt", help="Euler step in seconds (overrides study.dt).")
    ] = None,
    duration: Annotated[
        float | None,
        typer.Option("--duration", help="Simulated seconds per trial (overrides study.duration)."),
    ] = None,
    settle: Annotated[
        bool | None,
        typer.Option(
            "--settle/--no-settle",
            help="Settle the not-converged trials of switching laws with implicit Euler "
            "(overrides study.settle.enabled; default off: it can cost many times the study).",
        ),
    ] = None,
    safety_filter: Annotated[
        str | None,
        typer.Option(
            "--filter",
            help='Safety filter of every trial: "none", "barrier" or "barrier-decentralized" '
            "(overrides safety.filter; the other [safety] keys apply).",
        ),
    ] = None,
    sweep: Annotated[
        list[str] | None,
        typer.Option(
            "--sweep",
            help="KEY=V1,V2,... : sweep KEY over these values instead of the file's "
            "[study.sweep] (repeat for a product, e.g. --sweep noise=0,0.01,0.02).",
        ),
    ] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="Finish an interrupted study in OUT.")
    ] = False,
    force: Annotated[
        bool, typer.Option("--force", help="Replace the files of an earlier study in OUT.")
    ] = False,
    quiet: Annotated[
        bool, typer.Option("--quiet", "-q", help="No progress, notes or table (warnings stay).")
    ] = False,
    figure_format: FigureFormatOption = "png",
) -> None:
    """Run many random starts of a scenario's laws and count the outcomes.

    Example:

        formationlab study examples/study-triangle.toml --trials 2000 --seed 1 --out out/tri

    Writes OUT/trials.parquet (one row per trial), OUT/summary.json (outcome counts,
    fractions and 95% Wilson intervals per law and sweep point; with study.settle enabled,
    also after settling not-converged trials with implicit Euler), figures (fractions*.png,
    desired*.png, shapes_<law>.png; or .pdf, .svg: --format) and OUT/chunks/ (finished
    chunks, for --resume). The same --seed gives the same trials whatever --workers,
    --scheduler or the chunk size.
    """
    from ..io.figures import figure_formats
    from ..io.scenario import load_scenario
    from ..io.trials import ChunkFolder
    from ..studies import parse_study
    from ..studies.runner import StudySetup, run_study

    def say(message: str) -> None:
        if not quiet:
            err_console.print(message, highlight=False)

    formats = figure_formats(figure_format)
    sc = load_scenario(scenario)
    for w in sc.warnings:
        warn(w if w.startswith(sc.source) else f"{sc.source}: {w}")
    config = parse_study(
        sc.study,
        trials=trials,
        chunk_size=chunk_size,
        dt=dt,
        duration=duration,
        settle=settle,
        sweep=_sweep_option(sweep) if sweep else None,
        source=sc.source,
        text=sc.text,
    )
    if sc.asynchronous is not None:
        warn(
            f"{sc.source}: [asynchronous] is not used by studies: their trials step every robot "
            "at dt (the sensed synchronous path; `formationlab run` takes the table)"
        )
    if safety_filter is not None:
        sc = _with_filter(sc, safety_filter)
    setup = StudySetup.from_scenario(sc, config)
    problem = check_study(plan_study(setup))
    if problem:  # before anything is written or allocated
        if trials is not None:
            raise ParameterError(f"--trials {trials}: {problem}")
        raise sc.error("study.trials", problem)
    _, note = setup.backend
    if note:
        say(f"note: {note}")
    identity = setup.identity(seed)
    store = ChunkFolder(out, identity)
    if resume:
        if not out.is_dir():
            fail(f"nothing to resume: {out} does not exist; run without --resume")
        from ..io.claim import claim_folder

        claim_folder(out)  # (one writer at a time, as prepare_output_dir claims a new study's)
        kept = store.check_resumable()
        try:
            say(f"resuming: {kept} finished chunks kept in {store.folder}")
        except KeyboardInterrupt:
            _kept(store)
    else:
        from ..io import prepare_output_dir

        prepare_output_dir(out, force=force)
        if force:
            _clear_earlier_study(out, store)
        store.start()
    try:
        if sc.integrator.name != "euler":
            say(
                f"note: studies use the batched explicit Euler kernel (dt = {setup.dt:g}), not "
                f"the scenario's {sc.integrator.name!r}"
            )
        say(
            f"{len(setup.groups)} groups x {config.trials} trials, dt = {setup.dt:g}, "
            f"duration = {setup.duration:g}, seed = {seed}"
        )
    except KeyboardInterrupt:
        _kept(store)
    result = _run_with_progress(
        run_study,
        setup,
        seed=seed,
        scheduler=scheduler,
        workers=workers,
        store=store,
        resume=resume,
        notify=say,
        quiet=quiet,
    )
    _write_outputs(out, sc, result, identity, quiet, formats)


def _sweep_option(given: list[str]) -> dict[str, list[float]]:
    """``--sweep KEY=V1,V2`` options as a sweep table; a clear error for a bad one."""
    out: dict[str, list[float]] = {}
    for item in given:
        key, eq, values = item.partition("=")
        key = key.strip()
        try:
            numbers = [float(v) for v in values.split(",") if v.strip()]
        except ValueError:
            numbers = []
        if not eq or not key or not numbers:
            fail(
                f"--sweep {item!r}: give KEY=V1,V2,... with numbers, e.g. --sweep noise=0,0.01,0.02"
            )
        if key in out:
            fail(f"--sweep names {key!r} twice; give all its values in one option")
        out[key] = numbers
    return out


def _clear_earlier_study(out: Path, store: Any) -> None:
    """Under --force: remove the files and chunks of an earlier study in ``out`` (its
    figures may have other names than this study's, and its chunks are not resumable)."""
    import shutil

    from ..io.files import earlier_files, remove_stale

    remove_stale(out, earlier_files(out, STUDY_PATTERNS), [])
    if store.root.is_dir():
        for old in store.root.iterdir():
            if old.is_dir() and (old / "manifest.json").is_file():
                shutil.rmtree(old)


def _with_filter(sc: Any, name: str) -> Any:
    """The scenario with ``safety.filter = name`` (validated against its contact distances)."""
    import dataclasses

    from ..errors import UserInputError
    from ..safety import SafetyFilter

    base = sc.safety if sc.safety is not None else SafetyFilter()
    try:
        safety = dataclasses.replace(base, filter=name)
        safety.check_diameters(sc.formation.diameters)
        safety.check_model(sc.model)
    except UserInputError as exc:
        raise UserInputError(f"--filter {name}: {exc}") from None
    return dataclasses.replace(sc, safety=safety)


def _run_with_progress(run: Any, *args: Any, store: Any, quiet: bool = False, **kwargs: Any) -> Any:
    try:
        with progress_bar("trials", quiet=quiet) as update:
            shown = shows_progress(quiet)
            return run(*args, store=store, progress=update if shown else _log(quiet), **kwargs)
    except KeyboardInterrupt:
        _kept(store)


def _kept(store: Any) -> NoReturn:
    """End an interrupted study, saying which chunks are kept for ``--resume``."""
    fail(
        f"interrupted; {store.finished()} finished chunks are kept in {store.folder}: "
        "run the same command with --resume to finish",
        code=130,
    )


def _log(quiet: bool) -> Any:
    """Progress for a log (standard error not a terminal: no bar): a line when the trials
    start (or resume) and one when the first chunk has finished, which say that Ctrl-C keeps
    the finished chunks; nothing with ``quiet``."""
    said: list[int] = []

    def note(done: int, total: int) -> None:
        if quiet or len(said) > 1:
            return
        if not said:
            start = "resuming: " if done else ""
            err_console.print(
                f"trials: {start}{done:,} of {total:,} done; Ctrl-C keeps the finished chunks "
                "for --resume",
                highlight=False,
            )
        elif done > said[0]:
            err_console.print(f"trials: first chunk finished ({done:,} of {total:,})",
                              highlight=False)  # fmt: skip
        else:
            return
        said.append(done)

    return note


def _write_outputs(
    out: Path,
    sc: Any,
    result: Any,
    identity: dict[str, Any],
    quiet: bool = False,
    formats: tuple[str, ...] = ("png",),
) -> None:
    from ..io import atomic_write_json, save_figures
    from ..io.files import MANIFEST
    from ..io.scenario import write_scenario
    from ..io.trials import write_trials
    from ..plotting.studies import study_figures
    from ..resources import package_version

    write_trials(result.trials, out / "trials.parquet")
    write_scenario(out, sc)  # (with a copy of each file the law reads)
    figures = [
        path.name
        for stem, fig in study_figures(result.summary, result.trials, sc.formation.edges).items()
        for path in save_figures(fig, out / stem, formats, dpi=100)
    ]
    summary = {
        "scenario": sc.name,
        "scenario_file": sc.source,
        "command": "formationlab " + shlex.join(sys.argv[1:]) if sys.argv else None,
        "formationlab_version": package_version(),
        "fingerprint": identity["fingerprint"],
        **result.summary,
        MANIFEST: ["trials.parquet", "scenario.toml", *figures, "summary.json", "chunks"],
    }
    atomic_write_json(out / "summary.json", summary)
    below = sum(int(g.get("below_safety_distance", 0)) for g in summary.get("groups", []))
    if below and sc.safety is not None:
        warn(
            f"{below} of {len(result.trials)} trials had two robots closer than the safety "
            f"filter's distance D_s = {sc.safety.distance:g} (trials.parquet's "
            f"below_safety_distance; {sc.safety.below_advice})"
        )
    if not quiet:
        _print_table(summary)
        err_console.print(
            f"wrote trials.parquet, summary.json and figures to {out}", highlight=False
        )


def _cells(g: dict[str, Any], outs: list[str], sep: str = " ") -> list[str]:
    """``"0.745 [0.718, 0.770]"`` per outcome; ``sep="\\n"``: the interval on a second line."""
    cells = []
    for o in outs:
        lo, hi = g["ci95"][o]
        interval = f"[{lo:.3f}, {hi:.3f}]" if sep == " " else f"{lo:.3f}-{hi:.3f}"
        cells.append(f"{g['fractions'][o]:.3f}{sep}{interval}")
    return cells


def _rows(summary: dict[str, Any]) -> list[tuple[dict[str, Any], str]]:
    """The table's rows: each group, and its settled outcomes (style ``dim``) when settled."""
    rows = []
    for g in summary["groups"]:
        rows.append((g, ""))
        if g.get("settled"):  # a second row: the outcomes after implicit-Euler settling
            after = {"fractions": g["settled_fractions"], "ci95": g["settled_ci95"]}
            rows.append(({**g, **after}, "dim"))
    return rows


def _wide_table(summary: dict[str, Any]) -> Any:
    from rich.table import Table

    outs = summary["outcomes"]
    safety = summary.get("safety") or {}
    extra = ""
    if safety:
        f = safety.get("filter")
        extra = f", filter {f['filter'] if f else 'none'}, {len(safety['obstacles'])} obstacles"
    table = Table(title=f"{summary['scenario']}{extra}: outcome fractions (95% Wilson interval)")
    table.add_column("law")
    table.add_column("parameters")
    table.add_column("trials", justify="right")
    for o in outs:
        table.add_column(o, justify="right")
    for g, style in _rows(summary):
        if style:
            table.add_row("", f"  settled {g['settled']}", "", *_cells(g, outs), style=style)
        else:
            params = ", ".join(f"{k}={v:g}" for k, v in g["parameters"].items())
            table.add_row(g["law"], params, str(g["trials"]), *_cells(g, outs))
    return table


def _narrow_table(summary: dict[str, Any]) -> Any:
    """The table for a narrow terminal: a group's law, parameters and trials in one cell,
    each fraction above its interval, and hyphenated outcome names on two lines."""
    from rich import box
    from rich.table import Table

    outs = summary["outcomes"]
    table = Table(
        title=f"{summary['scenario']}: outcome fractions\n(95% Wilson interval below)",
        box=box.SIMPLE_HEAD,
        padding=0,
        show_edge=False,
    )
    table.add_column("law", overflow="fold")
    for o in outs:
        table.add_column(o.replace("-", "-\n"), justify="right")
    for g, style in _rows(summary):
        if style:
            label = f"  settled {g['settled']}"
        else:
            params = ", ".join(f"{k}={v:g}" for k, v in g["parameters"].items())
            label = "\n".join([g["law"], *([params] if params else []), f"{g['trials']} trials"])
        table.add_row(label, *_cells(g, outs, "\n"), style=style or None, end_section=True)
    return table


def _print_table(summary: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.measure import Measurement

    console = Console()  # the terminal's width (COLUMNS, else 80 when not a terminal)
    table = _wide_table(summary)
    natural = Measurement.get(console, console.options.update(width=10_000), table).maximum
    if natural > console.width:
        table = _narrow_table(summary)
    console.print(table)
    if summary.get("settle", {}).get("enabled"):
        console.print(
            f"settled with implicit Euler: {summary.get('settled_trials', 0):,} not-converged "
            "trials (rows 'settled N')",
            highlight=False,
        )
    steps, wall = summary["trial_steps"], summary["wall_time_s"]
    rate = summary.get("trial_steps_per_s")
    compile_time = summary.get("compile_time_s") or 0.0
    console.print(
        f"{steps:,} trial-steps in {wall:.1f} s"
        + (f" ({rate:.3g} trial-steps/s)" if rate else " (resumed)")
        + (
            f", after {compile_time:.1f} s preparing the compiled kernels"
            if compile_time > 0.5
            else ""
        ),
        highlight=False,
    )
