"""Commands ``run``, ``validate``, ``animate``: scenario files in; data, plots, animations out."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape

from ..errors import OutputExistsError, UserInputError
from ._app import command, err_console, fail, warn

__all__: list[str] = []

#: Files ``run`` writes besides the plots (summary.json last: it marks a finished run).
RUN_FILES = ("scenario.toml", "trajectory.nc", "summary.json")
ANIMATION_STEM = "animation"


def _say(message: str, quiet: bool) -> None:
    if not quiet:
        typer.echo(message)


@command(
    "run",
    epilog=(
        "Example:  formationlab run examples/paper-simulation-2.toml --out runs/sim2 --animate"
    ),
)
def run(
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
        bool, typer.Option("--force", help="Replace the files of an earlier run in --out.")
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress, no report.")] = False,
) -> None:
    """Simulate a scenario and write trajectory.nc, summary.json and plots to --out.

    The trajectory (positions q, controls u, Lyapunov function V, switching
    functions sigma) goes to DIR/trajectory.nc (netCDF, open it with
    xarray.open_dataset), the outcome and final distance errors to
    DIR/summary.json, and PNG plots of trajectories, controls, V and distance
    errors beside them. Exit status: 0 when the run finished, 1 when the
    integrator stopped early (results up to then are written), 2 on bad input.
    """
    from .. import __version__, simulate
    from ..io.figures import save_figure
    from ..io.files import atomic_write_json, atomic_write_text, prepare_output_dir
    from ..io.netcdf import write_trajectory
    from ..io.scenario import load_scenario

    sc = load_scenario(scenario)
    for w in sc.warnings:
        warn(w)
    folder = prepare_output_dir(out, force=force)
    result = _simulate(simulate, sc, save_every, quiet)
    atomic_write_text(folder / "scenario.toml", sc.text)
    write_trajectory(
        result,
        folder / "trajectory.nc",
        attrs={"scenario": sc.text, "scenario_name": sc.name, "save_every": save_every},
    )
    from ..plotting.runs import run_figures

    pictures = []
    for name, fig in run_figures(result, prefix=sc.name).items():
        pictures.append(save_figure(fig, folder / f"{name}.png").name)
    if animate:
        if not quiet:
            err_console.print(f"animating ({frames} frames at most) ...", highlight=False)
        pictures += [p.name for p in _animate(folder, result, sc.name, frames)]
    summary: dict[str, Any] = {
        "scenario": sc.name,
        "description": sc.description,
        "source": str(scenario),
        **result.summary(),
        "parameters": sc.parameters,
        "n_robots": sc.n,
        "edges": [[int(i) + 1, int(j) + 1] for i, j in sc.formation.edges],
        "save_every": save_every,
        "warnings": list(sc.warnings),
        "formationlab_version": __version__,
        "files": [*RUN_FILES, *pictures],
    }
    atomic_write_json(folder / "summary.json", summary)
    conv = summary["converged_time"]
    _say(
        f"{sc.name}: outcome {summary['outcome']}, max |r_ij - d_ij| = "
        f"{summary['max_distance_error']:.3g}, "
        + (f"converged at t = {conv:.3g} s" if conv is not None else "not converged")
        + f"; wrote {folder}/",
        quiet,
    )
    if result.status != "success":
        fail(f"the run stopped early: {result.message} (results up to then are in {folder})", 1)


def _simulate(simulate: Any, sc: Any, save_every: int, quiet: bool) -> Any:
    """Run ``sc`` with a progress bar on a terminal (long runs only)."""
    steps = sc.duration / getattr(sc.integrator, "dt", 1e-3)
    show = not quiet and err_console.is_terminal and steps * sc.n**2 > 2e5
    kwargs = {
        "duration": sc.duration, "integrator": sc.integrator, "save_every": save_every,
        "obstacles": sc.obstacles, "safety": sc.safety,
    }  # fmt: skip
    if not show:
        return simulate(sc.formation, sc.law, sc.q0, **kwargs)
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    columns = (
        TextColumn("simulating {task.description}"),
        BarColumn(),
        TextColumn("t = {task.completed:.2f} / {task.total:g} s"),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=err_console, transient=True) as bar:
        task = bar.add_task(sc.name, total=sc.duration)
        return simulate(
            sc.formation,
            sc.law,
            sc.q0,
            progress=lambda t: bar.update(task, completed=t),
            **kwargs,
        )


def _animate(
    folder: Path,
    result_or_ds: Any,
    title: str,
    frames: int,
    formats: tuple[str, ...] = ("gif", "mp4", "html"),
) -> list[Path]:
    from ..io.animation import save_animation
    from ..plotting.animation import animate_run

    safety: dict[str, Any] = {}
    if hasattr(result_or_ds, "formation"):
        r = result_or_ds
        t, q, edges, diam = r.t, r.q, r.formation.edges, r.formation.diameters
        if r.safety is not None:
            safety = {
                "obstacles": r.safety.obstacles, "active": r.safety.active,
                "active_pairs": r.safety.active_pairs,
            }  # fmt: skip
    else:
        ds = result_or_ds
        t, q = ds["time"].values, ds["q"].values
        edges, diam = ds["edge_robots"].values - 1, ds["diameter"].values
        if "filter_active" in ds:
            safety = {
                "obstacles": json.loads(str(ds.attrs.get("obstacles", "[]"))),
                "active": ds["filter_active"].values.astype(bool),
                "active_pairs": ds["active_pair"].values.reshape(-1, 3) - [0, 1, 1],
            }
    anim = animate_run(t, q, edges=edges, diameters=diam, max_frames=frames, title=title, **safety)
    return save_animation(anim, folder / ANIMATION_STEM, formats=formats)


@command(
    "animate",
    epilog="Example:  formationlab animate runs/sim2 --frames 100 --format gif",
)
def animate_cmd(
    folder: Annotated[Path, typer.Argument(help="Output folder of `formationlab run`.")],
    frames: Annotated[
        int, typer.Option(min=2, help="Most frames in the animation (the run is thinned).")
    ] = 150,
    fmt: Annotated[
        list[str] | None,
        typer.Option("--format", "-f", help="gif, mp4 or html; repeat for several (default: all)."),
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Replace an existing animation in the folder.")
    ] = False,
) -> None:
    """Animate a finished run: robots as discs of their diameters and the graph's edges.

    Reads DIR/trajectory.nc and writes DIR/animation.gif (pillow),
    DIR/animation.mp4 (ffmpeg from imageio-ffmpeg) and DIR/animation.html (a
    self-contained player), with at most --frames frames evenly spaced in time.
    """
    from ..io.animation import FORMATS
    from ..io.netcdf import load_trajectory

    formats = tuple(dict.fromkeys(fmt or FORMATS))
    bad = [f for f in formats if f not in FORMATS]
    if bad:
        raise UserInputError(
            f"unknown animation format {bad[0]!r}; choose from {', '.join(FORMATS)}"
        )
    if not folder.is_dir():
        raise UserInputError(
            f"{folder} is not a folder; give the --out folder of `formationlab run`"
        )
    nc = folder / "trajectory.nc"
    if not nc.is_file():
        raise UserInputError(
            f"{folder} holds no trajectory.nc; run `formationlab run SCENARIO --out {folder}` first"
        )
    existing = [
        (folder / ANIMATION_STEM).with_suffix(FORMATS[f]).name
        for f in formats
        if (folder / ANIMATION_STEM).with_suffix(FORMATS[f]).exists()
    ]
    if existing and not force:
        raise OutputExistsError(
            f"{folder} already holds {', '.join(existing)}; pass --force to replace it"
        )
    try:
        ds = load_trajectory(nc)
    except (OSError, ValueError) as exc:
        raise UserInputError(f"cannot read {nc} as netCDF: {exc}") from None
    if "q" not in ds or "edge_robots" not in ds:
        raise UserInputError(f"{nc} is not a formationlab trajectory (no q or edge_robots)")
    title = str(ds.attrs.get("scenario_name", folder.name))
    for p in _animate(folder, ds, title, frames, formats):
        typer.echo(f"wrote {p}")


@command(
    "validate",
    epilog="Example:  formationlab validate examples/*.toml",
)
def validate(
    scenarios: Annotated[list[Path], typer.Argument(help="Scenario files (TOML) to check.")],
) -> None:
    """Check scenario files and say what is wrong, without running them.

    Checks every table the other commands read ([study] and [equilibria] too).
    Prints one line per file: what it describes, or the problem (key, line,
    what was expected and what was given). Exit status 2 if any file is bad.
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
                    StudySetup.from_scenario(sc)
                if sc.equilibria is not None:
                    equilibria_scenario(sc, parse_equilibria(sc))
            except UserInputError as exc:
                raise sc.locate(exc) from None
        except UserInputError as exc:
            bad += 1
            err_console.print(
                f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True
            )
            continue
        for w in sc.warnings:
            warn(w if w.startswith(sc.source) else f"{path}: {w}")
        f = sc.formation
        rigid = "rigid" if f.is_rigid else "not rigid"
        safety = ""
        if sc.obstacles:
            safety += f", {len(sc.obstacles)} obstacles"
        if sc.safety is not None and sc.safety.enabled:
            safety += f", safety filter {sc.safety.filter} (D_s = {sc.safety.distance:g})"
        typer.echo(
            f"ok: {path}: {sc.name!r}, {f.n} robots, {len(f.edges)} edges ({rigid}), "
            f"orientation {f.orientation}, law {sc.law.name}, integrator "
            f"{json.dumps(sc.parameters['integrator'])}, duration {sc.duration:g} s{safety}"
        )
    if bad:
        raise typer.Exit(2)
