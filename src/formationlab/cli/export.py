"""Commands ``export ...``: a scenario written for another tool (``export robotarium``).

The group is :data:`export_app`; a new exporter is one more ``@command(..., on=export_app)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import OutputExistsError
from ._app import command, group, warn

__all__ = ["export_app"]

export_app = group("export", "Write a scenario for another tool: robot testbeds, recordings.")


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
    from ..io.robotarium import robotarium_plan, robotarium_script
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
