"""``formationlab paper``: reproduce section 4 of the paper (figures 4-12 and summary.json)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ._app import FigureFormatOption, command, err_console
from ._progress import stage_bar


@command("paper")
def paper(
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Folder for figures and summary.json.")
    ] = Path("paper-out"),
    force: Annotated[
        bool, typer.Option("--force", help="Replace the files of an earlier run in OUT.")
    ] = False,
    diameter: Annotated[
        float, typer.Option(help="Robot diameter rho (the paper gives none); < 1.")
    ] = 0.2,
    duration: Annotated[float, typer.Option(help="Simulated time in seconds.")] = 10.0,
    dt: Annotated[float, typer.Option(help="Integrator step in seconds.")] = 1e-3,
    integrator: Annotated[
        str, typer.Option(help="euler (as the paper), rk4, or another registered integrator.")
    ] = "euler",
    perturbation: Annotated[
        float,
        typer.Option(
            help="Added to robot 1's x in simulation 2 to leave the symmetric subspace (0: exact)."
        ),
    ] = 1e-6,
    figure_format: FigureFormatOption = "png",
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress, no report.")] = False,
) -> None:
    """Reproduce the paper's section 4: both simulations, figures 4-12, summary.json.

    Example:

        formationlab paper --out paper-out

    Writes OUT/fig04_trajectories.png ... OUT/fig12_lyapunov.png (or .pdf, .svg: --format),
    two extra figures of the unperturbed simulation 2, and OUT/summary.json with the
    outcome, final positions, distance errors and orientation of each run (docs/paper.md).
    """
    from ..io import atomic_write_json, figure_formats, prepare_output_dir, save_figures
    from ..io.files import MANIFEST, earlier_files, remove_stale
    from ..plotting.paper import paper_figures
    from ..studies.paper import PaperSetup, reproduce

    formats = figure_formats(figure_format)
    setup = PaperSetup(
        diameter=diameter,
        duration=duration,
        dt=dt,
        integrator=integrator,
        perturbation=perturbation,
    )
    folder = prepare_output_dir(out, force=force)
    earlier = earlier_files(folder, ("summary.json", "*.png", "*.pdf", "*.svg")) if force else []
    # the three runs, the two scans (studies.paper.reproduce) and the figures
    with stage_bar("reproducing section 4", 6, quiet=quiet) as now:
        rep = reproduce(setup, progress=now)
        now("figures")
        figures = [
            path.name
            for stem, fig in paper_figures(rep).items()
            for path in save_figures(fig, folder / stem, formats)
        ]
    summary = rep.summary()
    manifest = [*figures, "summary.json"]
    atomic_write_json(folder / "summary.json", {**summary, MANIFEST: manifest})
    remove_stale(folder, earlier, manifest)
    if quiet:
        return
    for key in ("simulation_1", "simulation_2", "simulation_2_unperturbed"):
        s = summary[key]
        err_console.print(
            f"{key:26s} outcome={s['outcome']:10s} orientation={s['orientation']} "
            f"max |r_ij - d_ij| = {s['max_distance_error']:.2e}",
            highlight=False,
            soft_wrap=True,
        )
    err_console.print(
        f"wrote figures and summary.json to {folder}", highlight=False, soft_wrap=True
    )
