"""Commands ``run`` and ``validate``: scenario files in; data, plots (and animations) out."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape

from ..errors import ParameterError, UserInputError
from ._app import INTERRUPTED, FigureFormatOption, command, err_console, fail, printable, warn
from ._plan import RunPlan, check_plan, check_study, plan_run, plan_study
from ._progress import progress_bar, shows_progress
from .animate import ANIMATION_STEM, FORMATS_ALL, usable_formats, write_animation

__all__: list[str] = []

#: Files ``run`` writes besides the plots and the per-edge table (summary.json last: it
#: marks a finished run).
RUN_FILES = ("scenario.toml", "trajectory.nc", "summary.json")
#: files of an earlier run (without a manifest) that ``run --force`` replaces
EARLIER_PATTERNS = (
    *RUN_FILES, "distance_errors.parquet", "*.png", "*.pdf", "*.svg", f"{ANIMATION_STEM}.*",
)  # fmt: skip


def _say(message: str, quiet: bool) -> None:
    if not quiet:
        typer.echo(message)


def _note(message: str, quiet: bool) -> None:
    if not quiet:
        err_console.print(message, highlight=False, soft_wrap=True)


@command(
    "run",
    epilog=(
        "Example:  formationlab run examples/paper-simulation-2.toml --out runs/sim2 --animate"
    ),
)
def run(
    ctx: typer.Context,
    scenario: Annotated[Path, typer.Argument(help="Scenario file (TOML), see docs/scenarios.md.")],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output folder (created; must be empty).")
    ],
    save_every: Annotated[
        int, typer.Option(min=1, help="Store every K-th step (all steps are computed).")
    ] = 1,
    animate: Annotated[
        bool, typer.Option("--animate", help="Also write animation.gif, .mp4 and .html.")
    ] = False,
    frames: Annotated[
        int, typer.Option(min=2, help="Most frames in the animation (the run is thinned).")
    ] = 150,
    force: Annotated[
        bool,
        typer.Option(
            "--force",
            help="Replace the files of an earlier run in --out (and run even if the saved "
            "trajectory looks too large for memory or disk).",
        ),
    ] = False,
    record: Annotated[
        Path | None,
        typer.Option(
            "--record",
            metavar="FILE.mcap",
            help="Also write the run as an MCAP recording of ROS 2 messages (Foxglove, "
            "ros2 bag) to FILE.mcap, in --out unless an absolute path (needs the robots extra).",
        ),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress, no report.")] = False,
    figure_format: FigureFormatOption = "png",
) -> None:
    """Simulate a scenario and write trajectory.nc, summary.json and plots to --out.

    The trajectory (positions q, controls u, Lyapunov function V, switching functions sigma)
    goes to DIR/trajectory.nc (netCDF, open it with xarray.open_dataset), the outcome and
    final distance errors to DIR/summary.json, and plots of trajectories, controls, V and
    distance errors beside them (PNG, or the --format list: pdf and svg for LaTeX). Before
    it starts, the run prints its step count and the memory and disk it will need, and
    refuses (unless --force) a run that would not fit: store fewer steps with --save-every.
    Ctrl-C stops the run and writes the trajectory so far, with status "interrupted". Exit
    status: 0 when the run finished, 1 when the integrator stopped early (results up to then
    are written), 2 on bad input or a folder that cannot be written, 130 when interrupted
    (results up to then are written).
    """
    from ..io.figures import figure_formats
    from ..io.scenario import load_scenario

    pictures = figure_formats(figure_format)
    sc = load_scenario(scenario)
    for w in sc.warnings:
        warn(w)
    formats = usable_formats(FORMATS_ALL, explicit=False) if animate else ()
    if record is not None:  # refused before the run, not after it
        from .export import check_recording

        record = out / record  # (an absolute path stays what it is)
        check_recording(record, force=force)
    plan = _plan(sc, save_every)
    if plan is not None:
        _note(f"{sc.name}: {plan.describe()}", quiet)
        source = ctx.get_parameter_source("save_every")
        given = getattr(source, "name", "") == "COMMANDLINE"
        problem = check_plan(plan, out, save_every_given=given)
        if problem and not force:
            raise ParameterError(problem)
        if problem:
            warn(problem.split("; ")[0] + "; running it anyway (--force)")
    _note_glyphs(sc.name, quiet)
    _run(sc, scenario, out, save_every, formats, frames, force, quiet, record, pictures)


def _note_glyphs(name: str, quiet: bool) -> None:
    """Say once which characters of the name the figures cannot show (no font has them)."""
    from ..plotting.fonts import missing_characters

    missing = missing_characters(name)
    if missing:
        _note(
            f"note: the figures show ? for {missing}: no installed font has these characters "
            "(a font such as Noto Sans CJK would)",
            quiet,
        )


def _plan(sc: Any, save_every: int) -> RunPlan | None:
    """The run's size, or None for an event-driven integrator (no fixed step count)."""
    try:
        return plan_run(sc, save_every)
    except ParameterError:
        return None


def _run(
    sc: Any,
    scenario: Path,
    out: Path,
    save_every: int,
    formats: tuple[str, ...],
    frames: int,
    force: bool,
    quiet: bool,
    record: Path | None = None,
    pictures: tuple[str, ...] = ("png",),
) -> None:
    """Simulate, write the results, then the recording, the figures (in the formats
    ``pictures``), then animate.

    What took the time is written first: ``trajectory.nc``, the per-edge table and
    ``summary.json`` before the recording and the figures (which a Ctrl-C or a failure may
    stop), so that nothing that comes after can lose a finished simulation.
    """
    from ..engine.signals import held_signals
    from ..io.files import earlier_files, prepare_output_dir, remove_stale

    folder = prepare_output_dir(out, force=force)
    earlier = earlier_files(folder, EARLIER_PATTERNS) if force else []
    result = _simulate(sc, save_every, quiet)
    interrupted = result.status == "interrupted"
    written: list[str] = []
    try:  # the finished simulation is written whole: Ctrl-C (SIGTERM) waits for it
        with held_signals():
            summary, written = _write_data(folder, sc, scenario, result, save_every, quiet)
    except KeyboardInterrupt:
        remove_stale(folder, earlier, written)
        fail(
            f"interrupted while writing the results; they were written whole first: {folder} "
            f"holds {', '.join(written)} (no figures)",
            INTERRUPTED,
        )
    try:
        if record is not None:  # (listed in summary.json with the figures)
            written = [*written, *_write_record(folder, sc.name, result, record, quiet)]
        written = _write_figures(
            folder, sc, scenario, result, summary, save_every, written, quiet, pictures
        )
    except KeyboardInterrupt:
        remove_stale(folder, earlier, written)
        _say(f"{sc.name}: {_verdict(summary)}; wrote {folder}/", quiet)
        fail(
            f"interrupted while drawing the figures; the run's results are in {folder}", INTERRUPTED
        )
    if formats and not interrupted:
        _note(f"animating ({frames} frames at most) ...", quiet)
        done: list[Path] = []
        try:
            write_animation(folder, result, sc.name, frames, formats, done, progress=not quiet)
        except (KeyboardInterrupt, subprocess.CalledProcessError):
            # Ctrl-C reaches ffmpeg too, which then fails: the simulation's results stay
            written = [*written, *(p.name for p in done)]
            _write_summary(folder, sc, scenario, summary, save_every, written)
            remove_stale(folder, earlier, written)
            _say(f"{sc.name}: {_verdict(summary)}; wrote {folder}/", quiet)
            fail(
                f"interrupted while animating; the run's results are in {folder} "
                f"(animate them with `formationlab animate {folder} --force`)",
                INTERRUPTED,
            )
        written = [*written, *(p.name for p in done)]
    try:  # the last of the files: the manifest of them all, and the earlier run's let go
        with held_signals():
            if formats and not interrupted:
                _write_summary(folder, sc, scenario, summary, save_every, written)
            removed = remove_stale(folder, earlier, written)
    except KeyboardInterrupt:
        _say(f"{sc.name}: {_verdict(summary)}; wrote {folder}/", quiet)
        fail(f"interrupted as the run ended; its results are whole in {folder}", INTERRUPTED)
    if removed:
        _note(f"removed {', '.join(removed)} of the earlier run in {folder}", quiet)
    _say(f"{sc.name}: {_verdict(summary)}; wrote {folder}/", quiet)
    if summary.get("below_safety_distance"):
        warn(_below_warning(sc, summary))
    if interrupted:
        fail(f"{result.message}; the results up to then are in {folder}", INTERRUPTED)
    if result.status != "success":
        fail(f"the run stopped early: {result.message} (results up to then are in {folder})", 1)


#: robots times saved states beyond which ``run`` says what it is writing
_LARGE = 1e6


def _write_data(
    folder: Path, sc: Any, scenario: Path, result: Any, save_every: int, quiet: bool
) -> tuple[dict[str, Any], list[str]]:
    """Write scenario.toml, trajectory.nc, the per-edge table of a formation with more than
    ``LIST_LIMIT`` edges and summary.json (last: it marks the folder as holding a finished
    run); returns the summary and the names written."""
    from ..io.edges import EDGE_TABLE, write_edge_table
    from ..io.netcdf import write_trajectory
    from ..io.scenario import write_scenario
    from ..simulation.run import LIST_LIMIT

    large = result.q.size / 2 > _LARGE
    write_scenario(folder, sc)  # (with a copy of each file the law reads)
    if large:
        _note(
            f"writing trajectory.nc ({len(result.t):,} saved states; Ctrl-C now stops once "
            "it is written) ...",
            quiet,
        )
    write_trajectory(
        result,
        folder / "trajectory.nc",
        attrs={"scenario": sc.text, "scenario_name": sc.name, "save_every": save_every},
    )
    summary = result.summary()
    names = list(RUN_FILES)
    if len(sc.formation.edges) > LIST_LIMIT:
        write_edge_table(result.edge_table(), folder / EDGE_TABLE)
        summary["distance_errors_table"] = EDGE_TABLE
        names.insert(2, EDGE_TABLE)
    return summary, _write_summary(folder, sc, scenario, summary, save_every, names)


def _write_record(folder: Path, name: str, result: Any, record: Path, quiet: bool) -> list[str]:
    """Write the MCAP recording; returns its name for the manifest when it is in the folder."""
    import time

    from ..io.mcap import write_mcap
    from .export import describe_recording

    start = time.perf_counter()
    write_mcap(result, record, name=name)
    _note(describe_recording(record, time.perf_counter() - start), quiet)
    return [record.name] if record.resolve().parent == folder.resolve() else []


def _write_figures(
    folder: Path,
    sc: Any,
    scenario: Path,
    result: Any,
    summary: dict[str, Any],
    save_every: int,
    written: list[str],
    quiet: bool,
    formats: tuple[str, ...] = ("png",),
) -> list[str]:
    """Draw and save the run's figures in ``formats``, then list them in summary.json;
    returns the names."""
    from ..io.figures import save_figures
    from ..plotting.runs import run_figures

    if result.q.size / 2 > _LARGE:
        _note("drawing the figures ...", quiet)
    pictures = [
        path.name
        for name, fig in run_figures(result, prefix=sc.name).items()
        for path in save_figures(fig, folder / name, formats)
    ]
    return _write_summary(folder, sc, scenario, summary, save_every, [*written, *pictures])


def _write_summary(
    folder: Path,
    sc: Any,
    scenario: Path,
    summary: dict[str, Any],
    save_every: int,
    manifest: list[str],
) -> list[str]:
    from ..io.files import MANIFEST, atomic_write_json
    from ..resources import package_version
    from ..simulation.run import LIST_LIMIT

    edges = sc.formation.edges
    data: dict[str, Any] = {
        "scenario": sc.name,
        "description": sc.description,
        "source": str(scenario),
        **summary,
        "parameters": sc.parameters,
        **({"edges": (edges + 1).tolist()} if len(edges) <= LIST_LIMIT else {}),
        "save_every": save_every,
        "warnings": list(sc.warnings),
        "formationlab_version": package_version(),
        MANIFEST: manifest,
    }
    atomic_write_json(folder / "summary.json", data)
    return manifest


def _below_warning(sc: Any, summary: dict[str, Any]) -> str:
    """The warning of a run whose robots came closer than the filter's ``D_s``."""
    f = summary["safety"]
    return (
        f"{sc.name}: two robots came {f['min_pair_distance']:.4g} m apart, closer than the "
        f"safety filter's distance D_s = {f['filter']['distance']:g} (summary.json's "
        f"below_safety_distance); {sc.safety.below_advice}"
    )


def _verdict(s: dict[str, Any]) -> str:
    """The one-line verdict of a run's summary: the outcome, whether and when the robots
    stopped, and how long the run lasted.

    ``outcome`` judges the final shape (analysis.classify); the robots may still
    move within the distance tolerance, which the line says in the same breath
    instead of a contradictory "not converged". ``converged at t = ...`` is when they
    stopped (``converged_time``), ``ran to t = ...`` the run's last saved time
    (``final_time``, the end of ``trajectory.nc``).
    """
    tol = s["tolerances"]
    rigid = s.get("rigid_motion")
    moving = ""
    if rigid is not None:  # drifting or rotating: say how fast
        moving = f" at {rigid['speed']:.3g} m/s"
        if rigid["centre"] is not None:
            moving += f", {rigid['angular_velocity']:.3g} rad/s"
    line = f"outcome {s['outcome']}{moving}, max |r_ij - d_ij| = {s['max_distance_error']:.3g}"
    if "max_bearing_error" in s:  # a formation judged by its bearings
        line = f"outcome {s['outcome']}{moving}, max |g_ij - g*_ij| = {s['max_bearing_error']:.3g}"
    lasted = f"; ran to t = {s['final_time']:.4g} s"
    if s.get("below_safety_distance"):  # the filter's promise broken: said, never silent
        f = s["safety"]
        lasted += (
            f"; below the safety distance: two robots came {f['min_pair_distance']:.3g} m apart, "
            f"closer than D_s = {f['filter']['distance']:g}"
        )
    if s["converged_time"] is not None:
        return line + f", converged at t = {s['converged_time']:.3g} s" + lasted
    speed = min(v for v in (s["final_speed"], s["net_speed"]) if v is not None)
    if s["outcome"] in ("desired", "mirror"):
        within = tol["bearing" if "max_bearing_error" in s else "distance"]
        return (
            line
            + (
                f" (within the tolerance {within:g}), still moving at the end "
                f"({speed:.2g} m/s > {tol['speed']:g})"
            )
            + lasted
        )
    return line + f", still moving at the end ({speed:.2g} m/s > {tol['speed']:g})" + lasted


def _sensing_words(sc: Any) -> str:
    """``, sensing (...)`` and ``, faults (...)`` for the validate line ("" with neither)."""
    out = ""
    if sc.sensing is not None and not sc.sensing.ideal:
        d = sc.sensing.describe()
        parts = [f"frames {d['frames']}"] + [
            f"{k} {d[k]:g}" for k in ("frame_error", "noise", "range", "delay", "drop", "mismatch")
            if d[k] not in (0, 0.0, None)
        ]  # fmt: skip
        out += f", sensing ({', '.join(parts)}, seed {d['seed']})"
    if getattr(sc, "asynchronous", None) is not None:
        periods = ", ".join(f"{p:g}" for p in sc.asynchronous["periods"])
        out += f", asynchronous (periods {periods} s, jitter {sc.asynchronous['jitter']:g})"
    if sc.faults is not None and sc.faults.any:
        stops = ", ".join(
            f"robot {s.robot} stops at {s.at:g} s" if s.at < float("inf") else
            f"robot {s.robot} may stop (study.sweep.stop_at)" for s in sc.faults.stop
        )  # fmt: skip
        out += f", faults ({stops})"
    return out


def _simulate(sc: Any, save_every: int, quiet: bool) -> Any:
    """Run ``sc`` (its closed loop: :func:`formationlab.scenario.run_scenario`) with a
    progress bar on a terminal (long runs only)."""
    from ..scenario import run_scenario

    steps = sc.duration / getattr(sc.integrator, "dt", 1e-3)
    show = shows_progress(quiet) and steps * sc.n**2 > 2e5
    kwargs = {
        "save_every": save_every,
        "interruptible": True,  # Ctrl-C: keep the states so far (status "interrupted")
    }
    if sc.asynchronous is not None:  # every robot its own task (agents.run_async)
        from ..agents import run_async

        _note(
            f"asynchronous: periods {', '.join(f'{p:g}' for p in sc.asynchronous['periods'])} s, "
            f"jitter {sc.asynchronous['jitter']:g}", quiet,
        )  # fmt: skip
        return run_async(
            sc.formation, sc.law, sc.x0, duration=sc.duration, dt=sc.integrator.dt,
            periods=sc.asynchronous["periods"], jitter=sc.asynchronous["jitter"],
            sensing=sc.sensing, faults=sc.faults, model=sc.model, save_every=save_every,
        )  # fmt: skip
    if not show:
        if not quiet and steps * sc.n**2 > 2e5:  # a log, not a terminal: one line once running
            kwargs["progress"] = _running_note(sc.name)
        return run_scenario(sc, **kwargs)
    count = "t = {done:.2f} / {total:g} s"
    with progress_bar(f"simulating {sc.name}", total=sc.duration, count=count) as update:
        return run_scenario(sc, progress=update, **kwargs)


def _running_note(name: str) -> Callable[[float], None]:
    """A progress callback that says once, at its first call, that the run is under way."""
    said: list[bool] = []

    def note(t: float) -> None:
        if not said:
            said.append(True)
            _note(
                f"{name}: running (at t = {t:g} s); Ctrl-C stops it and keeps the states so far",
                False,
            )

    return note


@command(
    "validate",
    epilog="Example:  formationlab validate examples/*.toml",
)
def validate(
    scenarios: Annotated[list[Path], typer.Argument(help="Scenario files (TOML) to check.")],
) -> None:
    """Check scenario files and say what is wrong, without running them.

    Prints one line per file: what it describes, or the problem (key, line,
    what was expected and what was given). Exit status 2 if any file is bad.
    Checks every table the other commands read ([study] and [equilibria] too).
    """
    from ..equilibria.report import equilibria_scenario, parse_equilibria
    from ..io.scenario import load_scenario
    from ..studies.runner import StudySetup

    bad = 0
    for path in scenarios:
        try:
            sc = load_scenario(path)
            try:  # the tables other commands read
                if sc.study is not None:
                    problem = check_study(plan_study(StudySetup.from_scenario(sc)))
                    if problem:  # what `study` would refuse
                        raise sc.error("study.trials", problem)
                if sc.equilibria is not None:
                    equilibria_scenario(sc, parse_equilibria(sc))
            except UserInputError as exc:
                raise sc.locate(exc) from None
        except UserInputError as exc:
            bad += 1
            err_console.print(
                f"[bold red]error:[/] {escape(printable(str(exc)))}",
                highlight=False,
                soft_wrap=True,
            )
            continue
        for w in sc.warnings:
            warn(w if w.startswith(sc.source) else f"{path}: {w}")
        f = sc.formation
        rigid = "rigid" if f.is_rigid else "not rigid"
        shape = f"orientation {f.orientation}"
        if f.bearings is not None:  # checked to fix the shape when the scenario was read
            rigid = "infinitesimally bearing rigid"
            shape = "desired bearings " + ("given" if sc.raw.get("formation", {}).get(
                "bearings") is not None else "of the template")  # fmt: skip
        safety = ""
        if sc.obstacles:
            safety += f", {len(sc.obstacles)} obstacles"
        if sc.safety is not None and sc.safety.enabled:
            safety += f", safety filter {sc.safety.filter} (D_s = {sc.safety.distance:g})"
        safety += _sensing_words(sc)
        typer.echo(
            f"ok: {path}: {sc.name!r}, {_count(f.n, 'robot')}, {_count(len(f.edges), 'edge')} "
            f"({rigid}), "
            f"{shape}, model {sc.model.name}, law {sc.law.name}, integrator "
            f"{json.dumps(sc.parameters['integrator'])}, duration {sc.duration:g} s{safety}"
            + (f", marching ({type(sc.marching).__name__})" if sc.marching is not None else "")
        )
        plan = _plan(sc, 1)
        if plan is not None:
            typer.echo(f"    {plan.describe()}")
            problem = check_plan(plan, Path.cwd(), save_every_given=False)
            if problem:  # what `run` would refuse (disk: the current folder's)
                warn(f"{path}: {problem}")
    if bad:
        raise typer.Exit(2)


def _count(k: int, noun: str) -> str:
    """``"1 edge"``, ``"3 edges"``."""
    return f"{k} {noun}" if k == 1 else f"{k} {noun}s"
