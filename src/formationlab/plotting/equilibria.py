"""Pictures of equilibria: the gallery of shapes and continuation curves.

A formation in space is drawn on matplotlib's 3-D axes (:func:`plot_equilibrium_3d`),
one scale on the three axes, as :func:`~formationlab.plotting.runs.plot_trajectories_3d`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Circle

from .fonts import displayable, font_context
from .units import with_unit

__all__ = [
    "arrow_seconds",
    "continuation_figure",
    "gallery_figure",
    "plot_equilibrium",
    "plot_equilibrium_3d",
]

_COLOURS = {
    "stable": "tab:green",
    "saddle": "tab:orange",
    "degenerate": "tab:gray",
    "filippov": "tab:purple",
}


def plot_equilibrium(
    formation: Any, eq: Any, ax: Any = None, *, title: str = "", span: float | None = None
) -> list[Any]:
    """Draw one equilibrium: robots (to scale, numbered 1..n) and the formation's edges.

    Edges are coloured by ``r_ij - d_ij`` (blue short, red long, black met);
    the frame's colour is the class (green stable, orange saddle, purple
    Filippov, grey degenerate). A relative equilibrium (drifting or rotating)
    carries the arrow of its centroid's velocity (:func:`arrow_seconds` of motion) and,
    when it rotates, a cross at the centre of the rotation. ``span`` fixes the
    width shown (a common scale for a gallery). Returns the artists.
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(3, 3))
    q = np.asarray(eq.q)
    artists: list[Any] = []
    err = eq.distances - formation.distances
    for (i, j), e in zip(formation.edges, err, strict=True):
        (line,) = ax.plot(*q[[i, j]].T, color=_edge_colour(e), lw=1.2, zorder=1)
        artists.append(line)
    for i, (x, y) in enumerate(q):
        c = Circle((x, y), formation.diameters[i] / 2, fc="white", ec="k", zorder=2)
        ax.add_patch(c)
        artists.append(c)
        artists.append(ax.annotate(str(i + 1), (x, y), ha="center", va="center", fontsize=8))
    if span is None:
        span = _span(q, formation)
    if getattr(eq, "moving", False):  # a relative equilibrium: the centroid's velocity
        c = q.mean(axis=0)
        v = np.asarray(eq.velocity, dtype=float)
        artists.append(
            ax.annotate(
                "", xy=tuple(c + arrow_seconds(v, span) * v), xytext=tuple(c),
                arrowprops={"arrowstyle": "-|>", "color": "tab:purple", "lw": 1.5},
            )
        )  # fmt: skip
        if eq.centre is not None:
            artists.append(ax.plot(*eq.centre, marker="+", color="tab:brown", ms=8)[0])
    ax.set_aspect("equal")
    centre = (q.max(axis=0) + q.min(axis=0)) / 2
    ax.set_xlim(centre[0] - span / 2, centre[0] + span / 2)
    ax.set_ylim(centre[1] - span / 2, centre[1] + span / 2)
    ax.set_xticks([])
    ax.set_yticks([])
    for side in ax.spines.values():
        side.set_edgecolor(_COLOURS.get(eq.stability, "k"))
        side.set_linewidth(2)
    if title:
        ax.set_title(title, fontsize=8)
    return artists


def _edge_colour(e: float) -> str:
    return "k" if abs(e) < 1e-2 else ("tab:red" if e > 0 else "tab:blue")


def plot_equilibrium_3d(
    formation: Any, eq: Any, ax: Any = None, *, title: str = "", span: float | None = None
) -> list[Any]:
    """Draw one equilibrium in space on 3-D axes: robots (numbered 1..n) and the edges.

    As :func:`plot_equilibrium`: edges coloured by ``r_ij - d_ij`` (blue short, red long,
    black met); the title's colour is the class (green stable, orange saddle, purple
    Filippov, grey degenerate), 3-D axes having no frame to colour. ``span`` fixes the side
    of the cube shown (a common scale for a gallery). ``ax`` must be a 3-D axes
    (``fig.add_subplot(projection="3d")``); None makes one. Returns the artists.
    """
    if ax is None:
        ax = plt.figure(figsize=(3, 3)).add_subplot(projection="3d")
    q = np.asarray(eq.q)
    artists: list[Any] = []
    err = eq.distances - formation.distances
    for (i, j), e in zip(formation.edges, err, strict=True):
        artists += ax.plot(*q[[i, j]].T, color=_edge_colour(e), lw=1.2)
    artists.append(ax.scatter(*q.T, s=40, c="white", edgecolors="k", depthshade=False))
    for i, p in enumerate(q):
        artists.append(ax.text(*p, f" {i + 1}", fontsize=8))
    if span is None:
        span = _span(q, formation)
    centre = (q.max(axis=0) + q.min(axis=0)) / 2
    for k, axis in enumerate((ax.set_xlim, ax.set_ylim, ax.set_zlim)):
        axis(centre[k] - span / 2, centre[k] + span / 2)
    ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_zticks([])
    if title:
        ax.set_title(title, fontsize=8, color=_COLOURS.get(eq.stability, "k"))
    return artists


def arrow_seconds(v: Any, span: float) -> float:
    """Seconds of motion drawn by a velocity arrow: 1 s, less if it would leave the panel."""
    speed = float(np.hypot(*np.asarray(v, dtype=float)))
    return min(1.0, 0.4 * span / speed) if speed > 0 else 1.0


def _span(q: Any, formation: Any) -> float:
    return float(np.ptp(q, axis=0).max()) + float(formation.diameters.max()) + 0.2


def gallery_figure(catalogue: Any, *, columns: int = 4, title: str = "", limit: int = 12) -> Any:
    """The equilibria of a catalogue, the desired one first, with class and count.

    At most ``limit`` panels (the catalogue's order: desired, then by count);
    the title says how many more there are. A formation in space: 3-D panels
    (:func:`plot_equilibrium_3d`).
    """
    eqs = catalogue.equilibria[:limit]
    more = len(catalogue.equilibria) - len(eqs)
    if more:
        title = f"{title} (+{more} more, see equilibria.json)"
    k = max(len(eqs), 1)
    cols = min(columns, k)
    rows = -(-k // cols)
    title = displayable(title)  # holds the user's scenario name: any script
    space = catalogue.formation.dim == 3
    with font_context():
        fig, axes = plt.subplots(
            rows, cols, figsize=(2.6 * cols, 3.1 * rows + 0.4), squeeze=False, layout="constrained",
            subplot_kw={"projection": "3d"} if space else None,
        )  # fmt: skip
    for ax in axes.ravel()[len(eqs) :]:
        ax.axis("off")
    span = max((_span(eq.q, catalogue.formation) for eq in eqs), default=1.0)
    for idx, (eq, count, ax) in enumerate(zip(eqs, catalogue.counts, axes.ravel(), strict=False)):
        kind = eq.stability
        if eq.unstable_directions:
            kind += f" ({eq.unstable_directions} unstable)"
        if eq.attractive:
            kind += ", attractive"
        label = f"#{idx + 1}" + ("" if eq.outcome == "incorrect" else f" {eq.outcome}")
        lines = [f"{label}: {kind}", f"{count} trial{'' if count == 1 else 's'}"]
        if eq.surfaces:
            lines.append("on " + ", ".join(eq.surfaces))
        elif eq.active:
            lines.append("active " + ", ".join(eq.active))
        if eq.moving:
            speed = float(np.linalg.norm(eq.velocity))
            drawn = "" if space else f" (arrow: {arrow_seconds(eq.velocity, span):.2g} s)"
            lines.append(f"|v| = {speed:.3g} m/s{drawn}")
        if eq.outcome == "rotating":
            turn = "(+: centre)" if eq.axis is None else "(about the axis)"
            lines.append(f"omega = {eq.omega:.3g} rad/s {turn}")
        draw = plot_equilibrium_3d if space else plot_equilibrium
        draw(catalogue.formation, eq, ax, title="\n".join(lines), span=span)
    if not eqs:
        axes[0, 0].text(0.5, 0.5, "no equilibrium found", ha="center", va="center")
    if title:
        with font_context():
            fig.suptitle(title)
    return fig


def continuation_figure(branches: Sequence[Any], *, labels: Sequence[str] | None = None) -> Any:
    """How equilibria move as a gain changes: size and largest eigenvalue real part.

    Each branch (:class:`formationlab.equilibria.Branch`) gives the RMS
    distance of the robots to their centroid and the largest real part of
    the eigenvalues (> 0: unstable) against the parameter.
    """
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.4))
    for b, branch in enumerate(branches):
        lab = labels[b] if labels else f"branch {b + 1}"
        if not len(branch.values):
            continue
        size = [
            float(np.sqrt(np.mean(np.sum((e.q - e.q.mean(0)) ** 2, axis=-1))))
            for e in branch.equilibria
        ]
        grow = [e.growth_rate for e in branch.equilibria]
        (line,) = ax1.plot(branch.values, size, marker=".", label=lab)
        ax2.plot(branch.values, grow, marker=".", color=line.get_color(), label=lab)
    ax1.set_xlabel(with_unit(branches[0].parameter) if branches else "parameter")
    ax1.set_ylabel("RMS distance to centroid [m]")
    ax2.set_xlabel(with_unit(branches[0].parameter) if branches else "parameter")
    ax2.set_ylabel("largest Re(eigenvalue) [1/s]")
    ax2.axhline(0.0, color="k", lw=0.6)
    ax1.legend(fontsize=7)
    fig.tight_layout()
    return fig
