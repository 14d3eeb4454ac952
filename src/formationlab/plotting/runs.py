"""Plots of one simulated run: trajectories, controls, Lyapunov function, distance errors.

These are the panels of the paper's figures 4-12 (trajectories: figs. 4, 8;
velocities in x and y: figs. 5-6, 10-11; Lyapunov function: figs. 7, 12;
distance errors: fig. 9), usable for any formation.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle
from numpy.typing import NDArray

from ..outcomes.analysis import bearing_errors, distance_errors
from .colors import ROBOT_MAP, edge_colors, line_styles, robot_colors
from .fonts import displayable, font_context
from .many import (
    COLLECTION_LIMIT,
    LABEL_LIMIT,
    LINE_LIMIT,
    draw_bands,
    draw_discs,
    draw_lines,
    draw_paths,
    segments,
)
from .safety import draw_safety, draw_solids, plot_filter_activity, solid_bounds

__all__ = [
    "plot_bearing_errors",
    "plot_controls",
    "plot_distance_errors",
    "plot_lyapunov",
    "plot_trajectories",
    "plot_trajectories_3d",
    "robot_colors",
    "run_figures",
]


#: colour map of robot numbers beyond ten robots


def _axes(ax: Axes | None, figsize: tuple[float, float] = (6.0, 4.0)) -> Axes:
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    _, ax = plt.subplots(figsize=figsize)
    return ax


def _draw_graph(ax: Axes, formation: Any, q: np.ndarray, *, colors: Any, **style: Any) -> Any:
    """The graph's edges between the points ``q`` ``(n, 2)`` (:func:`draw_lines`)."""
    segs = np.stack([q[formation.edges[:, 0]], q[formation.edges[:, 1]]], axis=1)
    return draw_lines(ax, segs, colors, **style)


def _legend(ax: Axes) -> None:
    """The legend: where it hides least of the data, unless the lines have more than
    :data:`_BEST_LIMIT` points (matplotlib's ``loc="best"`` tests every point: seconds for
    ten robots over 60,000 saved states), then in the upper right corner."""
    points = 0
    for line in ax.get_lines():
        points += int(np.size(line.get_xdata()))
    ax.legend(loc="best" if points <= _BEST_LIMIT else "upper right", fontsize="small")


#: most points of the lines of a plot for the legend to be placed by matplotlib's "best"
_BEST_LIMIT = 50_000


def _shade_active(ax: Axes, result: Any) -> list[Any]:
    """Shade the time intervals where some angular restriction is active.

    One span per interval up to :data:`_SPANS` intervals; beyond (a run chattering on a
    surface), one filled area over the samples where a restriction is on.
    """
    if result.sigma.shape[-1] == 0:
        return []
    on = np.any(result.active, axis=-1)
    t = result.t
    edges = np.flatnonzero(np.diff(on.astype(int)))
    starts = ([0] if on[0] else []) + [e + 1 for e in edges if not on[e]]
    stops = [e + 1 for e in edges if on[e]] + ([len(t) - 1] if on[-1] else [])
    if len(starts) > _SPANS:
        band = ax.fill_between(
            t, 0, 1, where=on, color="0.85", lw=0, zorder=0, step="post",
            transform=ax.get_xaxis_transform(), label="restriction active",
        )  # fmt: skip
        return [band]
    artists = []
    for k, (a, b) in enumerate(zip(starts, stops, strict=False)):
        label = "restriction active" if k == 0 else None
        artists.append(ax.axvspan(t[a], t[b], color="0.85", zorder=0, label=label))
    return artists


#: most intervals shaded one by one (see _shade_active)
_SPANS = 50


def plot_trajectories(
    result: Any, ax: Axes | None = None, *, show_graph: bool = True, title: str | None = None
) -> list[Any]:
    """Robot paths in the plane: start (hollow circle), end (disc of the robot's diameter).

    The graph's edges are drawn dashed at the start and solid at the end, between
    the law's points (the hand points of near-identity unicycles, drawn as
    crosses). Unicycles show their final heading as a line from the centre to the rim.
    Up to :data:`~formationlab.plotting.many.LABEL_LIMIT` robots each has a legend entry
    and its number; beyond, the robots are coloured by number with a colour bar, and
    every kind of mark is one collection (:mod:`formationlab.plotting.many`).
    """
    ax = _axes(ax, (5.5, 5.5))
    f = result.formation
    q = result.q
    p = getattr(result, "points", q)
    many = f.n > LABEL_LIMIT
    colors = robot_colors(f.n)
    thin = 0.3 if f.n > COLLECTION_LIMIT else 0.8
    artists: list[Any] = []
    if show_graph:
        artists.append(_draw_graph(ax, f, p[0], colors="0.6", linestyles="--", linewidths=thin))
        artists.append(_draw_graph(ax, f, p[-1], colors="0.2", linewidths=1.5 * thin))
    if p is not q and not np.array_equal(p[-1], q[-1]):
        artists.append(ax.plot(p[-1, :, 0], p[-1, :, 1], "k+", ms=3 if many else 7, zorder=5)[0])
    headings = getattr(result, "headings", None)
    if headings is not None:
        h = np.stack([np.cos(headings[-1]), np.sin(headings[-1])], axis=-1)
        rim = q[-1] + (f.diameters / 2)[:, None] * h
        artists.append(
            ax.add_collection(
                LineCollection(segments(np.stack([q[-1], rim], axis=1)), colors="k", zorder=5)
            )
        )
    if many:
        artists += _many_robots(ax, result, colors)
    else:
        for i in range(f.n):
            (line,) = ax.plot(
                q[:, i, 0], q[:, i, 1], color=colors[i], lw=1.4, label=f"robot {i + 1}"
            )
            artists.append(line)
            artists.append(ax.plot(q[0, i, 0], q[0, i, 1], "o", mfc="none", mec=colors[i], ms=8)[0])
            disc = Circle(tuple(q[-1, i]), f.diameters[i] / 2, color=colors[i], alpha=0.8, zorder=3)
            ax.add_patch(disc)
            artists.append(disc)
            artists.append(
                ax.annotate(str(i + 1), q[0, i], xytext=(5, 5), textcoords="offset points")
            )
    if getattr(result, "safety", None) is not None:
        artists += draw_safety(ax, result)
    faults = getattr(result, "faults", None)
    for stop in () if faults is None else faults.stop:
        k = int(np.searchsorted(result.t, stop.at))
        if k < len(result.t):  # the robot stopped during the run: an x where it did
            i = stop.robot - 1
            artists.append(ax.plot(*q[k, i], "kx", ms=9, mew=2, zorder=6)[0])
            artists.append(
                ax.annotate(f"{stop.robot} stops, t = {stop.at:g} s", q[k, i], xytext=(6, -12),
                            textcoords="offset points", fontsize="small")
            )  # fmt: skip
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    model = getattr(result, "model", None)
    on = "" if model is None or model.name == "single-integrator" else f", {model.name}"
    robots = f", {f.n:,} robots" if many else ""
    ax.set_title(title or f"trajectories ({result.law.name} law{on}{robots})")
    if not many or ax.get_legend_handles_labels()[0]:
        _legend(ax)
    ax.autoscale_view()
    return artists


def plot_trajectories_3d(
    result: Any, ax: Any = None, *, show_graph: bool = True, title: str | None = None
) -> list[Any]:
    """Robot paths in space (a formation with ``dim = 3``), on matplotlib's 3-D axes.

    As :func:`plot_trajectories`: the graph dashed at the start and solid at the end, each
    path in its robot's colour with a hollow circle at its start and a dot at its end;
    beyond :data:`~formationlab.plotting.many.LABEL_LIMIT` robots the starts and ends only,
    coloured by number. The axes share one scale (a cube of data is a cube on the page);
    a run's spheres and boxes are drawn grey (:func:`~formationlab.plotting.safety.draw_solids`).
    ``ax`` must be a 3-D axes (``fig.add_subplot(projection="3d")``); None makes one.
    """
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    if ax is None:
        ax = Figure(figsize=(6.0, 6.0), layout="constrained").add_subplot(projection="3d")
    f = result.formation
    q = result.q
    many = f.n > LABEL_LIMIT
    colors = robot_colors(f.n)
    artists: list[Any] = []
    if show_graph:
        for k, style in ((0, {"colors": "0.6", "linestyles": "--"}), (-1, {"colors": "0.2"})):
            segs = np.stack([q[k, f.edges[:, 0]], q[k, f.edges[:, 1]]], axis=1)
            artists.append(ax.add_collection3d(Line3DCollection(segs, linewidths=0.9, **style)))
    if many:
        number = np.arange(1, f.n + 1)
        artists.append(ax.scatter(*q[0].T, c=number, cmap=ROBOT_MAP, s=6, alpha=0.3))
        artists.append(ax.scatter(*q[-1].T, c=number, cmap=ROBOT_MAP, s=10))
    else:
        for i in range(f.n):
            artists += ax.plot(*q[:, i].T, color=colors[i], lw=1.4, label=f"robot {i + 1}")
            artists += ax.plot(*q[0, i, :, None], "o", mfc="none", mec=colors[i], ms=7)
            artists += ax.plot(*q[-1, i, :, None], "o", color=colors[i], ms=6)
            artists.append(ax.text(*q[0, i], f" {i + 1}"))
    held = q.reshape(-1, 3)
    rec = getattr(result, "safety", None)
    if rec is not None and rec.obstacles:  # the obstacles in space, within the axes
        artists += draw_solids(ax, rec.obstacles)
        held = np.concatenate([held, solid_bounds(rec.obstacles)])
    lo, hi = held.min(axis=0), held.max(axis=0)
    centre, half = 0.5 * (lo + hi), 0.5 * max(float(np.max(hi - lo)), 1e-9)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    robots = f", {f.n:,} robots" if many else ""
    ax.set_title(title or f"trajectories in space ({result.law.name} law{robots})")
    if not many:
        ax.legend(loc="upper left", fontsize="small")
    return artists


def _many_robots(ax: Axes, result: Any, colors: Any) -> list[Any]:
    """Paths, starts and final positions, one collection each.

    Up to :data:`~formationlab.plotting.many.COLLECTION_LIMIT` robots each has its colour
    (a colour bar of robot numbers) and its final disc at true size; beyond, paths in grey
    and the robots as points of one colour (a collection of 100,000 coloured discs takes
    seconds to draw, and would show no more at this size).
    """
    import matplotlib as mpl

    f, q = result.formation, result.q
    if f.n > COLLECTION_LIMIT:
        return [
            draw_paths(ax, result.t, q, "0.5", linewidths=0.3, alpha=0.8, zorder=1),
            *ax.plot(*q[0].T, ls="none", marker="o", ms=1.5, mfc="none", mec="0.5", mew=0.3,
                     zorder=2),
            *ax.plot(*q[-1].T, ls="none", marker="o", ms=1.5, mew=0.0, color="C0", zorder=3),
        ]  # fmt: skip
    artists: list[Any] = [
        draw_paths(ax, result.t, q, colors, linewidths=0.8, alpha=0.8, zorder=1),
        ax.scatter(q[0, :, 0], q[0, :, 1], s=8.0, facecolors="none", edgecolors=colors,
                   linewidths=0.5, zorder=2),
        draw_discs(ax, q[-1], f.diameters, colors, alpha=0.8, zorder=3),
    ]  # fmt: skip
    ax.update_datalim(np.concatenate([q[0], q[-1]]))
    norm = mpl.colors.Normalize(1, f.n)
    bar = ax.figure.colorbar(  # type: ignore[union-attr]
        mpl.cm.ScalarMappable(norm=norm, cmap=ROBOT_MAP), ax=ax, shrink=0.8, pad=0.02
    )
    bar.set_label("robot")
    return [*artists, bar]


def plot_controls(
    result: Any, ax: Axes | None = None, *, axis: int = 0, title: str | None = None
) -> list[Any]:
    """Control actions (robot velocities) along x (``axis=0``), y (1) or, in space, z (2).

    One line per robot up to :data:`~formationlab.plotting.many.LINE_LIMIT` robots (a
    legend up to ``LABEL_LIMIT``); beyond, bands of their distribution over the robots.
    """
    ax = _axes(ax)
    n = result.formation.n
    colors, styles = robot_colors(n), line_styles(n)
    name = "xyz"[axis]
    artists = _shade_active(ax, result)
    if n > LINE_LIMIT:
        u = result.u
        artists += draw_bands(ax, result.t, lambda rows: u[rows, :, axis], width=n, of="robots")
    else:
        for i in range(n):
            artists += ax.plot(
                result.t, result.u[:, i, axis], color=colors[i], ls=styles[i],
                label=f"$u_{{{i + 1}{name}}}$",
            )  # fmt: skip
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"velocity in {name} [m/s]")
    ax.set_title(title or f"control actions in {name}")
    if n <= LABEL_LIMIT or n > LINE_LIMIT:
        _legend(ax)
    return artists


def plot_lyapunov(
    result: Any, ax: Axes | None = None, *, log: bool = False, title: str | None = None
) -> list[Any]:
    """The law's Lyapunov function over time (eq. 9 or eq. 15), dimensionless (the
    potentials of eq. 5 are).

    ``log``: a log axis where V stays positive (down to :data:`_LOG_DEPTH` times its
    largest value: a converged V's round-off, 0 or -1e-16, is not a value to show); where
    it goes below zero beyond round-off (eq. 15's restriction term can be negative), a
    symmetric log axis, linear within 0.01 of 0, which the axis label says.
    """
    ax = _axes(ax)
    artists = _shade_active(ax, result)
    v = np.asarray(result.V, dtype=float)
    label = "$V_n$ (eq. 15)" if result.sigma.shape[-1] else "$V$ (eq. 9)"
    artists += ax.plot(result.t, v, color="k", label=label)
    ylabel = "V (dimensionless)"
    finite = v[np.isfinite(v)]
    top = float(np.max(np.abs(finite), initial=0.0))
    if log and top > 0 and finite.min() >= -_LOG_DEPTH * top:
        ax.set_yscale("log")
        shown = finite[finite > _LOG_DEPTH * top]
        ax.set_ylim(max(float(shown.min(initial=top)), _LOG_DEPTH * top) / 2, 2 * top)
        ylabel = "V (dimensionless, log scale)"
    elif log:
        ax.set_yscale("symlog", linthresh=1e-2)
        ylabel = "V (dimensionless);\nsymlog: linear within ±0.01"
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title or "Lyapunov function")
    _legend(ax)
    return artists


#: the smallest V, relative to its largest, that a log axis of V shows
_LOG_DEPTH = 1e-12


def plot_distance_errors(
    result: Any, ax: Axes | None = None, *, title: str | None = None
) -> list[Any]:
    """Inter-robot distance errors ``r_ij - d_ij`` per edge over time.

    One line per edge up to :data:`~formationlab.plotting.many.LINE_LIMIT` edges (a
    legend up to ``LABEL_LIMIT``); beyond, bands of their distribution over the edges,
    evaluated at the plotted times only.
    """
    f, p = result.formation, getattr(result, "points", result.q)
    return _per_edge(
        result, _axes(ax), lambda rows: distance_errors(f, p[rows]),
        lambda: result.distance_errors, lambda lab: f"$r_{{{lab}}} - d$",
        "distance error [m]", title or "inter-robot distance errors",
    )  # fmt: skip


def plot_bearing_errors(
    result: Any, ax: Axes | None = None, *, title: str | None = None
) -> list[Any]:
    """Bearing errors ``||g_ij - g*_ij||`` per edge over time, of a formation defined by
    bearings (Zhao and Zelazo 2016): 0 at the desired bearing, 2 at the reversed one.

    One line per edge up to :data:`~formationlab.plotting.many.LINE_LIMIT` edges (a
    legend up to ``LABEL_LIMIT``); beyond, bands of their distribution over the edges.
    """
    f, p = result.formation, getattr(result, "points", result.q)
    return _per_edge(
        result, _axes(ax), lambda rows: bearing_errors(f, p[rows]),
        lambda: bearing_errors(f, p), lambda lab: f"$|g_{{{lab}}} - g^*|$",
        "bearing error (dimensionless, about rad)", title or "bearing errors",
    )  # fmt: skip


def _per_edge(
    result: Any, ax: Axes, of_rows: Callable[[Any], NDArray], every: Callable[[], NDArray],
    label: Callable[[str], str], ylabel: str, title: str,
) -> list[Any]:  # fmt: skip
    """One line per edge of ``every()`` ``(T, m)`` labelled ``label("ij")``, or beyond
    ``LINE_LIMIT`` edges bands of ``of_rows(rows)`` over the edges; a zero line, the axes'
    words and a legend where it is readable."""
    artists = _shade_active(ax, result)
    m = len(result.formation.edges)
    if m > LINE_LIMIT:
        artists += draw_bands(ax, result.t, of_rows, width=m, of="edges", color="C3")
    else:
        err = every()
        colors, styles = edge_colors(m), line_styles(m)
        for e, lab in enumerate(result.edge_labels):
            artists += ax.plot(
                result.t, err[:, e], color=colors[e], ls=styles[e],
                label=label(lab.replace("-", "")),
            )  # fmt: skip
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    if m <= LABEL_LIMIT or m > LINE_LIMIT:
        _legend(ax)
    return artists


def _prefixed(prefix: str, title: str) -> str:
    """``"name: title"``, on two lines when longer than :data:`_TITLE_CHARACTERS` (the
    figures are saved at their size, so a longer line would be cut)."""
    one = f"{prefix}: {title}"
    return one if len(one) <= _TITLE_CHARACTERS else f"{prefix}:\n{title}"


#: most characters of a one-line title of a run's figure (about the width of 5.5 inches)
_TITLE_CHARACTERS = 55


def run_figures(result: Any, *, prefix: str = "") -> dict[str, Figure]:
    """The standard figures of a run, by name: ``trajectories``, ``controls_x``,
    ``controls_y`` (and ``controls_z`` in space), ``lyapunov``, ``distance_errors``
    (``bearing_errors`` for a formation judged by its bearings; and ``safety`` for a run
    with obstacles or a safety filter). Figures are not managed by pyplot (no GUI); save
    them with
    :func:`formationlab.io.save_figure`."""
    out: dict[str, Figure] = {}
    panels: tuple[
        tuple[str, Callable[..., list[Any]], dict[str, Any], tuple[float, float]], ...
    ] = (
        ("trajectories", plot_trajectories, {}, (5.5, 5.5)),
        ("controls_x", plot_controls, {"axis": 0}, (6.0, 3.6)),
        ("controls_y", plot_controls, {"axis": 1}, (6.0, 3.6)),
        ("lyapunov", plot_lyapunov, {}, (6.0, 3.6)),
        ("distance_errors", plot_distance_errors, {}, (6.0, 3.6)),
    )
    if result.formation.bearings is not None:  # judged by its bearings: their errors
        panels = (*panels[:-1], ("bearing_errors", plot_bearing_errors, {}, (6.0, 3.6)))
    space = result.formation.dim == 3
    if space:  # in space: the paths on 3-D axes, and the velocities in z
        panels = (
            ("trajectories", plot_trajectories_3d, {}, (6.0, 6.0)),
            *panels[1:3],
            ("controls_z", plot_controls, {"axis": 2}, (6.0, 3.6)),
            *panels[3:],
        )
    for name, fn, kw, size in panels:
        with font_context():  # ``prefix`` is the user's scenario name: any script
            fig = Figure(figsize=size, layout="constrained")
            ax = fig.add_subplot(projection="3d" if fn is plot_trajectories_3d else None)
            fn(result, ax=ax, **kw)
            if prefix:
                ax.set_title(_prefixed(displayable(prefix), ax.get_title()), wrap=True)
        out[name] = fig
    if getattr(result, "safety", None) is not None:
        fig = Figure(figsize=(6.0, 5.0), layout="constrained")
        top, bottom = fig.subplots(2, 1, sharex=True)
        plot_filter_activity(result, ax=top, ax_distance=bottom)
        if prefix:
            top.set_title(_prefixed(displayable(prefix), top.get_title()), wrap=True)
        out["safety"] = fig
    return out
