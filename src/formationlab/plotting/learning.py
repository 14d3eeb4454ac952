"""The training curve of a learned law (``formationlab train``, docs/learning.md)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

__all__ = ["plot_training_curve", "training_figure"]


def plot_training_curve(
    curve: Mapping[str, NDArray[np.float64]], ax: Axes | None = None, *, title: str = ""
) -> list[Any]:
    """The reward of the distribution's mean, and the best and mean candidate, per
    generation; returns the lines drawn."""
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(5.0, 3.5))
    g = np.asarray(curve["generation"])
    lines = [
        *ax.plot(g, curve["centre"], color="black", label="policy (distribution mean)"),
        *ax.plot(g, curve["best"], color="tab:green", lw=0.8, label="best candidate"),
        *ax.plot(g, curve["mean"], color="tab:gray", lw=0.8, label="mean candidate"),
    ]
    ax.set_xlabel("generation")
    ax.set_ylabel("reward  -(e_d + e_o + c)")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize="small")
    if title:
        ax.set_title(title)
    return lines


def training_figure(curve: Mapping[str, NDArray[np.float64]], *, title: str = "") -> Figure:
    """A figure of :func:`plot_training_curve`."""
    fig = Figure(figsize=(5.0, 3.5), layout="constrained")
    plot_training_curve(curve, fig.add_subplot(), title=title)
    return fig
