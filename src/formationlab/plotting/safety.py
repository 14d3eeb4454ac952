"""Obstacles and the safety filter's activity in plots of a run.

:func:`draw_obstacles` draws circle and polygon obstacles (objects of
:mod:`formationlab.safety`, or their scenario form ``{"circle": {...}}`` /
``{"polygon": [...]}`` as stored in ``trajectory.nc``); :func:`plot_filter_activity`
is the figure of when each robot had an active constraint, with the least pair
distance against the filter's ``D_s`` and the least obstacle clearance.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.patches import Circle, Polygon

from .colors import robot_colors

__all__ = [
    "ACTIVE_COLOR",
    "draw_obstacles",
    "draw_safety",
    "obstacle_shapes",
    "plot_filter_activity",
]

#: Colour of active constraints (robot rings, pair lines, activity raster).
ACTIVE_COLOR = "crimson"


def obstacle_shapes(obstacles: Iterable[Any]) -> list[tuple[str, Any]]:
    """``("circle", (center, radius))`` / ``("polygon", vertices)`` of objects or mappings."""
    out: list[tuple[str, Any]] = []
    for ob in obstacles:
        if isinstance(ob, dict):
            if "circle" in ob:
                c = ob["circle"]
                out.append(("circle", (np.asarray(c["center"], float), float(c["radius"]))))
            else:
                out.append(("polygon", np.asarray(ob["polygon"], float)))
        elif hasattr(ob, "radius"):
            out.append(("circle", (np.asarray(ob.center, float), float(ob.radius))))
        else:
            out.append(("polygon", np.asarray(ob.vertices, float)))
    return out


def draw_obstacles(ax: Axes, obstacles: Iterable[Any], *, label: bool = True) -> list[Any]:
    """Draw the obstacles as grey hatched shapes numbered from 1; returns the patches."""
    artists: list[Any] = []
    for k, (kind, shape) in enumerate(obstacle_shapes(obstacles)):
        style = {"facecolor": "0.75", "edgecolor": "0.3", "hatch": "//", "zorder": 0.5}
        if kind == "circle":
            center, radius = shape
            patch: Any = Circle(tuple(center), radius, **style)
            where = center
        else:
            patch = Polygon(shape, closed=True, **style)
            where = shape.mean(axis=0)
        ax.add_patch(patch)
        artists.append(patch)
        if label:
            artists.append(ax.annotate(f"O{k + 1}", tuple(where), ha="center", va="center"))
    return artists


def _limits(ax: Axes, obstacles: Iterable[Any]) -> None:
    """Widen the data limits of ``ax`` to hold the obstacles."""
    for kind, shape in obstacle_shapes(obstacles):
        if kind == "circle":
            c, r = shape
            pts = np.array([c - r, c + r])
        else:
            pts = shape
        ax.update_datalim(pts)


def draw_safety(ax: Axes, result: Any) -> list[Any]:
    """Obstacles, and where on its path each robot had an active constraint (red dots).

    Pairs whose constraint is active at the end are joined by a red line.
    """
    rec = result.safety
    q = np.asarray(result.q, float)
    artists = draw_obstacles(ax, rec.obstacles)
    _limits(ax, rec.obstacles)
    on = rec.active
    if on.any():
        pts = q[on]
        artists.append(
            ax.scatter(pts[:, 0], pts[:, 1], s=4, color=ACTIVE_COLOR, zorder=2.5,
                       label="constraint active")
        )  # fmt: skip
    last = rec.pair_matrix(len(q) - 1)
    for i, j in zip(*np.nonzero(np.triu(last)), strict=True):
        artists += ax.plot(*q[-1, [i, j]].T, color=ACTIVE_COLOR, lw=2.0, zorder=2.6)
    return artists


def plot_filter_activity(
    result: Any, ax: Axes | None = None, *, ax_distance: Axes | None = None
) -> list[Any]:
    """When each robot had an active constraint (``ax``), least pair distance and clearance.

    ``result`` is a :class:`~formationlab.SimulationResult` with a ``safety`` record.
    Without ``ax`` a figure with both panels is made; with ``ax`` only, the distances
    are left out unless ``ax_distance`` is given.
    """
    rec = result.safety
    t = np.asarray(result.t, float)
    n = rec.active.shape[1]
    if ax is None:
        import matplotlib.pyplot as plt

        _, (ax, ax_distance) = plt.subplots(2, 1, figsize=(6.0, 5.0), sharex=True)
    colors = robot_colors(n)
    artists: list[Any] = []
    for i in range(n):
        on = rec.active[:, i]
        artists += ax.plot(t[on], np.full(on.sum(), i + 1), "|", color=colors[i], ms=8)
    ax.set_yticks(range(1, n + 1) if n <= 12 else np.linspace(1, n, 6).round())
    ax.set_ylim(0.5, n + 0.5)
    ax.set_ylabel("robot number")
    kind = "none" if rec.filter is None else rec.filter.filter
    ax.set_title(f"active safety constraints (filter {kind})")
    if ax_distance is None:
        return artists
    ax2 = ax_distance
    artists += ax2.plot(t, rec.pair_distance, color="k", label="least |q_i - q_j|")
    if rec.filter is not None:
        artists.append(ax2.axhline(rec.filter.distance, color=ACTIVE_COLOR, ls="--", label="$D_s$"))
    if rec.obstacles:
        artists += ax2.plot(t, rec.obstacle_clearance, color="tab:blue", label="obstacle clearance")
        artists.append(ax2.axhline(0.0, color="0.5", lw=0.6))
    ax2.set_xlabel("time [s]")
    ax2.set_ylabel("distance [m]")
    ax2.legend(loc="best", fontsize="small")
    return artists
