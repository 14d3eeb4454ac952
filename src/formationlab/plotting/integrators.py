"""How each integrator behaves on a switching surface: the figure of ``docs/integrators.md``.

The runs are made elsewhere (``benchmarks/bench_integrators.py``); this module
only draws them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["plot_switching_function", "sliding_figure"]


def plot_switching_function(
    result: Any,
    *,
    surface: int = 0,
    window: tuple[float, float] | None = None,
    ax: Any = None,
    label: str | None = None,
    **kwargs: Any,
) -> list[Any]:
    """Plot ``sigma_s(t)`` of one surface of a run, with the surface ``sigma = 0``.

    Parameters
    ----------
    result : SimulationResult
        A run of a law with switching surfaces (``result.sigma`` of shape ``(T, s)``).
    surface : int
        0-based index of the surface (``result.restriction_labels`` names them).
    window : (float, float), optional
        Time interval to show, seconds.
    ax : matplotlib Axes, optional
        Where to draw; a new figure when omitted.
    label : str, optional
        Legend label of the curve.

    Returns
    -------
    list of Artist
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(5, 3))
    t, sigma = result.t, result.sigma[:, surface]
    if window is not None:
        keep = (t >= window[0]) & (t <= window[1])
        t, sigma = t[keep], sigma[keep]
    kwargs.setdefault("lw", 0.9)
    artists = ax.plot(t, sigma, label=label, **kwargs)
    artists.append(ax.axhline(0.0, color="0.5", lw=0.6, ls="--"))
    ax.set_xlabel("t [s]")
    name = result.restriction_labels[surface] if hasattr(result, "restriction_labels") else ""
    ax.set_ylabel(f"sigma ({name})" if name else "sigma")
    return artists


def sliding_figure(
    results: Mapping[str, Any],
    *,
    window: tuple[float, float] | None = None,
    ylim: tuple[float, float] | None = None,
    surface: int = 0,
) -> Any:
    """One panel per integrator: ``sigma(t)`` through a sliding phase, with its diagnostics.

    Parameters
    ----------
    results : mapping of str to SimulationResult
        Runs of the same start, keyed by a label such as ``"explicit Euler, dt = 1e-2"``.
    window : (float, float), optional
        Time interval to show, seconds.
    ylim : (float, float), optional
        Common limits of ``sigma`` (e.g. to zoom on the surface past the approach).
    surface : int
        0-based index of the surface to show.

    Returns
    -------
    matplotlib Figure
    """
    import matplotlib.pyplot as plt

    n = len(results)
    cols = 2 if n > 1 else 1
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 2.8 * rows), sharex=True)
    axes = np.atleast_1d(axes).ravel()
    for ax, (label, res) in zip(axes, results.items(), strict=False):
        plot_switching_function(res, surface=surface, window=window, ax=ax, marker=".", ms=2)
        if ylim is not None:
            ax.set_ylim(*ylim)
        d = res.stats
        ax.set_title(
            f"{label}\nswitches {d.get('switch_count', 0):.0f}, "
            f"sliding {d.get('sliding_time', 0):.3f} s, "
            f"max |sigma| {d.get('max_excursion', 0):.2g}",
            fontsize=9,
        )
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.tight_layout()
    return fig
