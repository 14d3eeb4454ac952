"""Command ``fly``: fly a scenario on Crazyflies (or on the simulated link, ``sim://``)."""

from __future__ import annotations

import csv
import logging
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated

import typer

from ._app import command, err_console, fail, warn

__all__: list[str] = []


class _OneLine(logging.Handler):
    """cflib's log records as one ``cflib:`` line each, without the tracebacks it writes into
    some of its messages."""

    def emit(self, record: logging.LogRecord) -> None:
        line = (record.getMessage().strip().splitlines() or [""])[0]
        err_console.print(f"cflib: {line}", highlight=False, markup=False)


@contextmanager
def _cflib_lines() -> Iterator[None]:
    """While the command runs, cflib's warnings and errors print as one line each (cflib logs
    a failed link with its traceback; the command's own ``error:`` line says what failed)."""
    logger = logging.getLogger("cflib")
    handler, propagate = _OneLine(logging.WARNING), logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate


@command(
    "fly",
    epilog=(
        "Examples:  formationlab fly examples/paper-simulation-1.toml "
        "--uris radio://0/80/2M/E7E7E7E701,radio://0/80/2M/E7E7E7E702,radio://0/80/2M/E7E7E7E703"
        "\n\n           formationlab fly examples/paper-simulation-1.toml "
        "--uris sim://1,sim://2,sim://3 --fence -4,4,-4,4,0,2   (a dry run, simulated)"
    ),
)
def fly(
    scenario: Annotated[Path, typer.Argument(help="Scenario file (TOML), see docs/scenarios.md.")],
    uris: Annotated[
        str,
        typer.Option(
            help="One URI per robot, robot 1 first, comma-separated (sim://... : simulated)."
        ),
    ],
    rate: Annotated[float, typer.Option(help="Control rate, Hz (at most 100).")] = 20.0,
    height: Annotated[
        float, typer.Option(help="Flight height of the plane (lowest drone in space), m.")
    ] = 0.5,
    max_speed: Annotated[float, typer.Option(help="Largest speed sent to a drone, m/s.")] = 0.3,
    fence: Annotated[
        str, typer.Option(help="Geofence x0,x1,y0,y1,z0,z1 in metres (outside it: land).")
    ] = "-2,2,-2,2,0,2",
    duration: Annotated[
        float | None, typer.Option(help="Longest time in formation, s (default the scenario's).")
    ] = None,
    tolerance: Annotated[
        float, typer.Option(help="Distance error at which the formation is reached, m.")
    ] = 0.05,
    log: Annotated[
        Path | None,
        typer.Option(help="Write every control period's positions and setpoints (CSV)."),
    ] = None,
) -> None:
    r"""Take off, fly the scenario's law on the positions the drones report, land.

    Every drone lands when the formation is reached (after hovering in it),
    when the duration is over, on Ctrl-C or SIGTERM, when the law fails, a
    link is lost, a position goes stale or a drone leaves the fence.
    Crazyflies need `pip install "formationlab\[robots]"` (cflib). Exit
    status: 0 after reaching the formation or the duration, 1 after any other
    landing, 2 on bad input or a flight that could not start, 130 or 143 when
    interrupted. Not flown on real drones by its authors: read docs/robots.md.
    """
    from ..io.scenario import load_scenario
    from ..robots import Fence, FlightConfig, Landing
    from ..robots import fly as fly_scenario

    sc = load_scenario(scenario)
    for w in sc.warnings:
        warn(w)
    config = FlightConfig(
        rate=rate, height=height, max_speed=max_speed, fence=Fence.parse(fence),
        duration=duration, tolerance=tolerance,
    )  # fmt: skip
    with _cflib_lines():
        result = fly_scenario(sc, [u.strip() for u in uris.split(",") if u.strip()], config=config)
    if log is not None:
        with open(log, "w", newline="") as f:
            out = csv.writer(f)
            out.writerow(["t", "robot", "x", "y", "z", "vx", "vy", "vz"])
            for t, q, v in zip(result.t, result.q, result.v, strict=True):
                for i in range(q.shape[0]):
                    out.writerow([f"{t:.4f}", i + 1, *(f"{c:.6g}" for c in (*q[i], *v[i]))])
    for problem in result.problems:
        warn(problem)
    err_console.print(f"landed: {result.landing.value}: {result.message}", highlight=False)
    if result.landing is Landing.INTERRUPTED:
        fail("interrupted: every drone landed", code=128 + (result.signal or 2))
    if result.landing not in (Landing.REACHED, Landing.DURATION):
        fail(f"landed early: {result.message}", code=1)
    typer.echo(f"{sc.name}: {result.landing.value}; {len(result.t)} control periods")
