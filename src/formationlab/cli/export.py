"""Command group ``export``: a run or a scenario in the formats robotics tools read.

``formationlab export mcap RUN_DIR``: a run's ``trajectory.nc`` as an MCAP recording of
ROS 2 messages (Foxglove, ``ros2 bag``; :mod:`formationlab.io.mcap`).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from ..errors import OutputExistsError, ParameterError
from ._app import _Group, app, command
from .animate import add_to_manifest, open_run, run_trajectory

__all__ = ["export_app"]

export_app = typer.Typer(
    name="export",
    help="Write a run or a scenario in the formats robotics tools read.",
    no_args_is_help=True,
    cls=_Group,
)
app.add_typer(export_app)

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
    robots extra: pip install "formationlab\\[robots]". See docs/robots.md.
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
