"""Commands ``export ...``: a scenario or a run written for another tool.

``formationlab export robotarium SCENARIO``: a standalone Robotarium controller
(:mod:`formationlab.io.robotarium`); ``formationlab export mcap RUN_DIR``: a run's
``trajectory.nc`` as an MCAP recording of ROS 2 messages (Foxglove, ``ros2 bag``;
:mod:`formationlab.io.mcap`). The group is :data:`export_app`; a new exporter is one more
``@command(..., on=export_app)``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from ..errors import OutputExistsError, ParameterError
from ._app import command, group, warn
from .animate import add_to_manifest, open_run, run_trajectory

__all__ = ["export_app"]

export_app = group(
    "export", "Write a scenario or a run for another tool: robot testbeds, recordings."
)


@command(
    "robotarium",
    on=export_app,
    epilog="Example:  formationlab export robotarium examples/paper-simulation-1.toml "
    "--out controller.py",
)
def robotarium(
    scenario: Annotated[Path, typer.Argument(help="Scenario file (TOML), in the plane.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="The script to write (.py).")],
    steps: Annotated[
        int | None,
        typer.Option(help="Step budget (0.033 s each); default the scenario's duration."),
    ] = None,
    tolerance: Annotated[
        float | None,
        typer.Option(help="Largest distance error (m) of a reached formation (default 0.01)."),
    ] = None,
    headless: Annotated[
        bool,
        typer.Option(
            "--headless",
            help="Run rps's simulator without its window, as fast as it computes.",
        ),
    ] = False,
    force: Annotated[bool, typer.Option("--force", help="Replace OUT if it exists.")] = False,
) -> None:
    """Write a standalone Robotarium controller (numpy and rps) for a scenario.

    The formation, the law and the start are scaled to the arena (3.2 m x 2 m);
    what was scaled, and by how much, is printed and written at the top of the
    script. The script moves near-identity points through the Robotarium's
    barrier certificate and stops when the formation is reached or its step
    budget ends (docs/robots.md).
    """
    from ..io.files import atomic_write_text
    from ..io.robotarium import robotarium_script
    from ..io.robotarium_plan import robotarium_plan
    from ..io.scenario import load_scenario
    from ..validation import positive, whole

    if steps is not None:
        whole(steps, "--steps")
    given = {} if tolerance is None else {"tolerance": positive(tolerance, "--tolerance")}
    if out.exists() and not force:
        raise OutputExistsError(f"{out} exists; add --force to replace it")
    plan = robotarium_plan(load_scenario(scenario), steps=steps, **given)
    for w in plan.warnings:
        warn(w)
    atomic_write_text(out, robotarium_script(plan, headless=headless))
    typer.echo(f"wrote {out}: {plan.formation.n} robots, law {plan.law.name}; scaled:")
    for note in plan.notes:
        typer.echo(f"  {note}")


#: the recording's name in the run's folder when --out is not given
RECORDING = "recording.mcap"


def check_recording(target: Path, *, force: bool) -> None:
    """Refuse, before any work, a target that is not ``.mcap``, that exists (unless
    ``force``), or a missing ``robots`` extra."""
    if target.suffix.lower() != ".mcap":
        raise ParameterError(f"an MCAP recording's file name ends in .mcap, not {target.name!r}")
    from ..io.mcap import check_extra

    check_extra()
    if target.is_dir():
        raise OutputExistsError(f"{target} is a folder; give a file name ending in .mcap")
    if target.exists() and not force:
        raise OutputExistsError(f"{target} already exists; pass --force to replace it")


def describe_recording(path: Path, seconds: float) -> str:
    """``wrote PATH (1.2 MB, 2100 messages, 0.8 s)``."""
    from mcap.reader import make_reader  # the robots extra (checked before writing)

    with open(path, "rb") as fh:
        stats = make_reader(fh).get_summary()
    count = stats.statistics.message_count if stats and stats.statistics else 0
    size = path.stat().st_size
    return f"wrote {path} ({size / 1e6:.3g} MB, {count} messages, {seconds:.2g} s)"


@command(
    "mcap",
    on=export_app,
    epilog="Example:  formationlab export mcap runs/sim2 --out sim2.mcap",
)
def export_mcap(
    folder: Annotated[
        Path, typer.Argument(metavar="RUN_DIR", help="Output folder of `formationlab run`.")
    ],
    out: Annotated[
        Path | None,
        typer.Option("--out", "-o", help=f"The .mcap file (default: RUN_DIR/{RECORDING})."),
    ] = None,
    every: Annotated[
        int, typer.Option(min=1, help="Record every K-th saved state (default: all).")
    ] = 1,
    force: Annotated[bool, typer.Option("--force", help="Replace an existing file.")] = False,
) -> None:
    """Write a run as an MCAP recording of ROS 2 messages (Foxglove, ros2 bag).

    Reads RUN_DIR/trajectory.nc and writes, per saved state, the robots' poses
    (/formation/poses, /robot_<k>/pose), the graph, the active restrictions
    and their switching lines as markers (/formation/graph), V
    (/formation/lyapunov) and the distance errors (/formation/distance_errors),
    in frame "world", stamped with the simulation time. About 1,300 states of
    three robots are written a second: --every K keeps every K-th. Needs the
    robots extra: pip install "formationlab[robots]". See docs/robots.md.
    """
    from ..io.mcap import write_mcap

    nc = run_trajectory(folder)
    target = out if out is not None else folder / RECORDING
    check_recording(target, force=force)
    start = time.perf_counter()
    with open_run(nc) as ds:
        write_mcap(ds.load(), target, every=every)
    typer.echo(describe_recording(target, time.perf_counter() - start))
    if target.resolve().parent == folder.resolve():
        add_to_manifest(folder, [target.name])
