"""Plots. The only part of formationlab that imports matplotlib.

Plot pieces take ``ax=`` (a new figure when omitted) and return the artists
they drew; ``*_figures`` functions return whole figures by name for the
command line to save.
"""

from __future__ import annotations

from typing import Any

from .paper import PAPER_FIGURES, paper_figures
from .runs import (
    plot_controls,
    plot_distance_errors,
    plot_lyapunov,
    plot_trajectories,
    run_figures,
)
from .studies import plot_fractions, plot_shape, study_figures

__all__ = [
    "PAPER_FIGURES",
    "paper_figures",
    "plot_controls",
    "plot_distance_errors",
    "plot_fractions",
    "plot_lyapunov",
    "plot_result",
    "plot_shape",
    "plot_trajectories",
    "run_figures",
    "study_figures",
]

_KINDS = {
    "trajectories": plot_trajectories,
    "controls": plot_controls,
    "lyapunov": plot_lyapunov,
    "errors": plot_distance_errors,
}


def plot_result(result: Any, kind: str = "trajectories", ax: Any = None, **kwargs: Any) -> Any:
    """Dispatch ``SimulationResult.plot``: ``kind`` is one of ``trajectories``, ``controls``,
    ``lyapunov``, ``errors``."""
    try:
        fn = _KINDS[kind]
    except KeyError:
        raise ValueError(f"unknown plot kind {kind!r}; choose one of {', '.join(_KINDS)}") from None
    return fn(result, ax=ax, **kwargs)
