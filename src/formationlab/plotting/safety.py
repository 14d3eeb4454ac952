"""Obstacles and the safety filter's activity in plots of a run.

:func:`draw_obstacles` draws circle and polygon obstacles (objects of
:mod:`formationlab.safety`, or their scenario form ``{"circle": {...}}`` /
``{"polygon": [...]}`` as stored in ``trajectory.nc``), :func:`draw_solids` the spheres
and boxes of a run in space on 3-D axes; :func:`plot_filter_activity`
is the figure of when each robot had an active constraint, with the least pair
distance against the filter's ``D_s`` and the least obstacle clearance.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.patches import Circle, Polygon
from numpy.typing import NDArray

from .colors import robot_colors

__all__ = [
    "ACTIVE_COLOR",
    "draw_obstacles",
    "draw_safety",
    "draw_solids",
    "obstacle_shapes",
    "plot_filter_activity",
    "solid_bounds",
]

#: Colour of active constraints (robot rings, pair lines, activity raster).
ACTIVE_COLOR = "crimson"


def obstacle_shapes(obstacles: Iterable[Any]) -> list[tuple[str, Any]]:
    """``("circle", (center, radius))`` / ``("polygon", vertices)`` in the plane,
    ``("sphere", (center, radius))`` / ``("box", (center, size))`` in space, of objects or
    of their scenario form (mappings)."""
    out: list[tuple[str, Any]] = []
    for ob in obstacles:
        spec = ob if isinstance(ob, dict) else ob.scenario()
        kind = next(iter(spec))
        if kind == "polygon":
            out.append(("polygon", np.asarray(spec["polygon"], float)))
            continue
        table = spec[kind]
        second = float(table["radius"]) if "radius" in table else np.asarray(table["size"], float)
        out.append((kind, (np.asarray(table["center"], float), second)))
    return out


def draw_solids(ax: Any, obstacles: Iterable[Any], *, label: bool = True) -> list[Any]:
    """Draw obstacles in space on the 3-D axes ``ax``: spheres as grey surfaces, boxes as
    grey faces, numbered from 1; returns the artists."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # (3-D axes only)

    artists: list[Any] = []
    for k, (kind, (center, second)) in enumerate(obstacle_shapes(obstacles)):
        if kind == "sphere":
            u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 25), np.linspace(0, np.pi, 13))
            unit = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)])
            surface = center[:, None, None] + second * unit
            artists.append(ax.plot_surface(*surface, color="0.6", alpha=0.35, linewidth=0.0))
        else:
            lo, hi = center - 0.5 * second, center + 0.5 * second
            corner = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)])
            pts = lo + corner * (hi - lo)
            faces = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4],
                     [1, 3, 7, 5]]  # fmt: skip
            box = Poly3DCollection([pts[f] for f in faces], facecolor="0.6", edgecolor="0.3",
                                   alpha=0.35, linewidth=0.5)  # fmt: skip
            artists.append(ax.add_collection3d(box))
        if label:
            artists.append(ax.text(*center, f"O{k + 1}", ha="center", va="center"))
    return artists


def solid_bounds(obstacles: Iterable[Any]) -> NDArray[np.float64]:
    """The corners ``(2 O, 3)`` of boxes holding the obstacles in space (axes' limits)."""
    out = [np.zeros((0, 3))]
    for kind, (center, second) in obstacle_shapes(obstacles):
        half = second if kind == "sphere" else 0.5 * second
        out.append(np.stack([center - half, center + half]))
    return np.concatenate(out)


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
