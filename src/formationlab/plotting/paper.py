"""The figures of the paper's section 4 (figures 4-12), plus the unperturbed simulation 2."""

from __future__ import annotations

from typing import Any

from matplotlib.figure import Figure

from .runs import plot_controls, plot_distance_errors, plot_lyapunov, plot_trajectories

__all__ = ["PAPER_FIGURES", "paper_figures"]

#: file stem -> (run, plot function, options, caption after the paper)
PAPER_FIGURES: dict[str, tuple[str, Any, dict[str, Any], str]] = {
    "fig04_trajectories": (
        "simulation_1",
        plot_trajectories,
        {},
        "Fig. 4: trajectories, restrictions not active",
    ),
    "fig05_velocity_x": (
        "simulation_1",
        plot_controls,
        {"axis": 0},
        "Fig. 5: control actions (velocities) in x",
    ),
    "fig06_velocity_y": (
        "simulation_1",
        plot_controls,
        {"axis": 1},
        "Fig. 6: control actions (velocities) in y",
    ),
    "fig07_lyapunov": (
        "simulation_1",
        plot_lyapunov,
        {"log": True},
        "Fig. 7: Lyapunov function V_n",
    ),
    "fig08_trajectories": (
        "simulation_2",
        plot_trajectories,
        {},
        "Fig. 8: trajectories, restrictions active",
    ),
    "fig09_distance_errors": (
        "simulation_2",
        plot_distance_errors,
        {},
        "Fig. 9: inter-robot distance errors, restrictions active",
    ),
    "fig10_velocity_x": (
        "simulation_2",
        plot_controls,
        {"axis": 0},
        "Fig. 10: control actions (velocities) in x",
    ),
    "fig11_velocity_y": (
        "simulation_2",
        plot_controls,
        {"axis": 1},
        "Fig. 11: control actions (velocities) in y",
    ),
    "fig12_lyapunov": (
        "simulation_2",
        plot_lyapunov,
        {"log": True},
        "Fig. 12: Lyapunov function V_n, restrictions active",
    ),
    "extra_sim2_unperturbed_trajectories": (
        "simulation_2_unperturbed",
        plot_trajectories,
        {},
        "Simulation 2 without perturbation: stuck in the symmetric subspace",
    ),
    "extra_sim2_unperturbed_lyapunov": (
        "simulation_2_unperturbed",
        plot_lyapunov,
        {},
        "Simulation 2 without perturbation: Lyapunov function V_n",
    ),
}


def paper_figures(reproduction: Any, *, zoom: float | None = 3.0) -> dict[str, Figure]:
    """Figures 4-12 of the paper, and two extras, from a ``PaperReproduction``.

    ``zoom`` limits the time axis of the time plots to the first ``zoom`` seconds,
    where everything happens (None: the whole run).
    """
    out: dict[str, Figure] = {}
    for stem, (run, fn, opts, caption) in PAPER_FIGURES.items():
        res = getattr(reproduction, run)
        square = fn is plot_trajectories
        fig = Figure(figsize=(5.5, 5.5) if square else (6.0, 3.6), layout="constrained")
        ax = fig.add_subplot()
        fn(res, ax=ax, title=caption, **opts)
        if not square and zoom is not None:
            ax.set_xlim(res.t[0], min(zoom, res.t[-1]))
        out[stem] = fig
    return out
