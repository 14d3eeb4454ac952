"""Animation of a run: robots as discs of their diameters, the graph's edges, fading trails.

:func:`animate_run` builds a :class:`matplotlib.animation.FuncAnimation` from
positions ``(T, n, 2)``; the frames are a thinned subset of the saved times (at most
``max_frames``), spaced half by time and half by the robots' motion so that the transient
is seen (:func:`.frames.frame_indices`), so the cost and size of the GIF, MP4 and
HTML player stay bounded whatever the run's length (:mod:`.frames`). Positions
``(T, n, 3)``, a run in space, are drawn on 3-D axes by :mod:`.animation_space`.
Saving is done by :mod:`formationlab.io.animation`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.animation import FuncAnimation
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.patches import Circle
from numpy.typing import ArrayLike, NDArray

from .animation_space import animate_space
from .colors import robot_colors
from .fonts import displayable, font_context
from .frames import (
    TRAIL_VERTICES,
    frame_indices,
    path_indices,
    play,
    stop_times,
    used_indices,
)
from .many import COLLECTION_LIMIT, LABEL_LIMIT, broken_line, draw_discs, segments
from .safety import ACTIVE_COLOR, draw_obstacles

__all__ = ["TRAIL_VERTICES", "animate_run", "frame_indices", "path_indices", "used_indices"]


def animate_run(
    t: ArrayLike,
    q: ArrayLike,
    *,
    edges: ArrayLike,
    diameters: ArrayLike,
    max_frames: int = 150,
    fps: int = 15,
    trail: float | None = None,
    title: str = "",
    size: float = 5.0,
    dpi: int = 90,
    headings: ArrayLike | None = None,
    points: ArrayLike | None = None,
    obstacles: Sequence[Any] = (),
    active: ArrayLike | None = None,
    active_pairs: ArrayLike | None = None,
    stops: Sequence[tuple[int, float]] = (),
) -> FuncAnimation:
    """An animation of a run.

    Parameters
    ----------
    t : array_like, shape (T,)
        Saved times, seconds.
    q : array_like, shape (T, n, 2) or (T, n, 3)
        Positions at those times. In space (``(T, n, 3)``) the animation is
        :func:`~formationlab.plotting.animation_space.animate_space`'s, and the arguments
        of the plane only (``headings``, ``points`` apart from ``q``, ``obstacles``,
        ``active``, ``active_pairs``) are refused.
    edges : array_like of int, shape (m, 2)
        0-based robot pairs of the graph, drawn as lines between the robots.
    diameters : array_like, shape (n,)
        Robot diameters ``rho_i``; each robot is drawn as a disc of that
        diameter, in the units of the axes (true size).
    max_frames : int
        Upper bound on the number of frames (see :func:`frame_indices`).
    fps : int
        Frames per second of the saved animation.
    trail : float, optional
        Length in seconds of the path drawn behind each robot; the whole path
        so far when omitted.
    title : str
        Title; the time is appended.
    size, dpi : float, int
        Figure side in inches and resolution.
    headings : array_like, shape (T, n), optional
        Headings in radians (unicycles): a line from each centre to its rim.
    points : array_like, shape (T, n, 2), optional
        Where the law acts when not the centres (near-identity hand points):
        drawn as small crosses; the graph's edges join them.
    obstacles : sequence
        Obstacles to draw (:mod:`formationlab.safety` objects or their scenario form).
    active : array_like of bool, shape (T, n), optional
        Robots with an active safety constraint at each saved time: drawn with a red ring.
    active_pairs : array_like of int, shape (k, 3), optional
        Active pair constraints ``(time index, i, j)``, 0-based: drawn as red lines.
    stops : sequence of (int, float)
        Robots that stop (``[faults] stop``): 0-based robot and stop time; from then on
        the robot is drawn grey with a black rim.

    Returns
    -------
    matplotlib.animation.FuncAnimation
        Not attached to pyplot; save it with :func:`formationlab.io.animation.save_animation`.
    """
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    diameters = np.asarray(diameters, dtype=float)
    if q.ndim == 3 and q.shape[-1] == 3 and q.shape[0] == t.shape[0]:
        _planar_only(q, headings, points)
        return animate_space(
            t, q, edges=edges, diameters=diameters, max_frames=max_frames, fps=fps,
            trail=trail, title=title, size=size, dpi=dpi, stops=stops, obstacles=obstacles,
            active=active,
        )  # fmt: skip
    if q.ndim != 3 or q.shape[-1] != 2 or q.shape[0] != t.shape[0]:
        raise ValueError(f"q must have shape (T, n, 2) or (T, n, 3) with T = len(t), got {q.shape}")
    n = q.shape[1]
    many = n > LABEL_LIMIT
    frame_indices(t, max_frames)  # checks max_frames before a figure is made
    colors = np.asarray(robot_colors(n)) if many else robot_colors(n)

    title = displayable(title)  # the user's scenario name: any script
    with font_context():
        fig = Figure(figsize=(size, size), dpi=dpi, layout="constrained")
        ax = fig.add_subplot()
    lo = np.nanmin(q, axis=(0, 1)) - diameters.max()
    hi = np.nanmax(q, axis=(0, 1)) + diameters.max()
    pad = 0.05 * max(float(np.max(hi - lo)), 1e-9)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if len(obstacles):
        draw_obstacles(ax, obstacles)
    on = None if active is None else np.asarray(active, bool)
    pairs = np.zeros((0, 3), np.int64) if active_pairs is None else np.asarray(active_pairs)
    pairs = pairs.reshape(-1, 3).astype(np.int64)
    red = ACTIVE_COLOR
    constrained = LineCollection([], colors=red, linewidths=2.0, zorder=2.5)
    ax.add_collection(constrained)

    theta = None if headings is None else np.asarray(headings, dtype=float)
    hand = None if points is None else np.asarray(points, dtype=float)
    ends = hand if hand is not None else q  # what the edges join
    noses = LineCollection(segments(np.zeros((n, 2, 2))), colors="k", linewidths=1.5, zorder=5)
    if theta is not None:
        ax.add_collection(noses)
    marks = ax.plot([], [], "k+", ms=3 if many else 6, zorder=5)[0] if hand is not None else None
    graph = _Lines(ax, len(edges), colors="0.3", linewidth=0.5 if many else 1.0, zorder=2)
    stop_at = stop_times(n, stops)
    if n > COLLECTION_LIMIT:
        span = max(float(np.max(hi - lo)) + 2 * pad, 1e-9)
        points_per_unit = _AXES_SHARE * size * 72.0 / span
        robots: _Robots = _Points(ax, float(np.mean(diameters)) * points_per_unit, n)
    elif many:
        robots = _Collections(ax, diameters, colors)
    else:
        robots = _Patches(ax, diameters, colors)
    clock = ax.set_title("")

    def draw(k: int, idx: int, sel: NDArray[np.int64]) -> list[Any]:
        now = q[idx]
        joined = ends[idx]
        graph.set(np.stack([joined[edges[:, 0]], joined[edges[:, 1]]], axis=1))
        extra: list[Any] = []
        if theta is not None:
            rim = now + (diameters / 2)[:, None] * np.stack(
                [np.cos(theta[idx]), np.sin(theta[idx])], axis=-1
            )
            noses.set_segments(segments(np.stack([now, rim], axis=1)))
            extra.append(noses)
        if marks is not None and hand is not None:
            marks.set_data(hand[idx, :, 0], hand[idx, :, 1])
            extra.append(marks)
        hit = pairs[pairs[:, 0] == idx]
        constrained.set_segments(segments(np.stack([now[hit[:, 1]], now[hit[:, 2]]], axis=1)))
        dead = t[idx] >= stop_at
        ring = np.zeros(n, bool) if on is None else on[idx]
        drawn = robots.draw(q[sel], dead, ring)
        return [graph.artist, constrained, *drawn, *extra]

    return play(
        fig, t, draw, q=q, max_frames=max_frames, n=n, trail=trail, clock=clock, title=title,
        fps=fps,
    )  # fmt: skip


def _planar_only(
    q: NDArray[np.float64], headings: ArrayLike | None, points: ArrayLike | None
) -> None:
    """Refuse, by name, what a run in space cannot have: headings (no robot model in space
    has one) and hand points apart from the centres."""
    planar = {
        "headings": headings is not None,
        "points": points is not None and not np.array_equal(np.asarray(points, float), q),
    }
    given = [name for name, on in planar.items() if on]
    if given:
        raise ValueError(
            f"{', '.join(given)} belong to runs in the plane; an animation in space (q of shape "
            "(T, n, 3)) draws robots, edges, trails, stops, obstacles and active constraints"
        )


class _Robots:
    """How the robots of a frame are drawn: trails, discs (grey once stopped, a red ring
    with an active safety constraint) and, for few robots, their numbers."""

    def draw(
        self, trail: NDArray[np.float64], dead: NDArray[np.bool_], ring: NDArray[np.bool_]
    ) -> list[Any]:
        """Draw the states ``trail`` ``(k, n, 2)`` (the last one now); returns the artists."""
        raise NotImplementedError


class _Patches(_Robots):
    """Few robots: a line, a disc patch and a number each."""

    def __init__(self, ax: Axes, diameters: NDArray[np.float64], colors: Any) -> None:
        n = len(diameters)
        self.colors = colors
        self.trails = [
            ax.plot([], [], color=colors[i], lw=1.0, alpha=0.6, zorder=1)[0] for i in range(n)
        ]
        self.discs = [
            Circle((0.0, 0.0), diameters[i] / 2, color=colors[i], alpha=0.9, zorder=3)
            for i in range(n)
        ]
        for disc in self.discs:
            ax.add_patch(disc)
        self.labels = [
            ax.annotate(
                str(i + 1), (0.0, 0.0), xytext=(4, 4), textcoords="offset points", fontsize=8,
                zorder=4,
            )
            for i in range(n)
        ]  # fmt: skip

    def draw(
        self, trail: NDArray[np.float64], dead: NDArray[np.bool_], ring: NDArray[np.bool_]
    ) -> list[Any]:
        now = trail[-1]
        for i, disc in enumerate(self.discs):
            self.trails[i].set_data(trail[:, i, 0], trail[:, i, 1])
            disc.center = (now[i, 0], now[i, 1])
            disc.set_facecolor("0.55" if dead[i] else self.colors[i])
            disc.set_edgecolor(ACTIVE_COLOR if ring[i] else "k" if dead[i] else self.colors[i])
            disc.set_linewidth(2.0 if ring[i] or dead[i] else 1.0)
            self.labels[i].xy = (now[i, 0], now[i, 1])
        return [*self.trails, *self.discs, *self.labels]


class _Collections(_Robots):
    """Many robots: one collection of trails, one of discs of their true diameters."""

    def __init__(self, ax: Axes, diameters: NDArray[np.float64], colors: Any) -> None:
        n = len(diameters)
        self.colors = np.asarray(colors, dtype=float)
        self.trails = _Lines(ax, n, colors=self.colors, linewidth=0.5, alpha=0.6, zorder=1)
        self.discs = draw_discs(
            ax, np.zeros((n, 2)), diameters, self.colors, alpha=0.9, zorder=3, linewidths=0.0
        )

    def draw(
        self, trail: NDArray[np.float64], dead: NDArray[np.bool_], ring: NDArray[np.bool_]
    ) -> list[Any]:
        self.trails.set(np.swapaxes(trail, 0, 1))
        self.discs.set_offsets(trail[-1])
        if dead.any() or ring.any():
            face: Any = self.colors.copy()  # (n, 4) RGBA; the stubs say sequence
            face[dead] = (0.55, 0.55, 0.55, 1.0)
            edge: Any = self.colors.copy()
            edge[dead] = (0.0, 0.0, 0.0, 1.0)
            edge[ring] = to_rgba(ACTIVE_COLOR)
            self.discs.set_facecolor(face)
            self.discs.set_edgecolor(edge)
            widths: Any = np.where(dead | ring, 1.5, 0.0)
            self.discs.set_linewidth(widths)
        return [self.trails.artist, self.discs]


class _Points(_Robots):
    """Very many robots: points (markers of about the robots' mean size, at least a point
    wide) and trails of one colour; stopped robots grey, active constraints red."""

    def __init__(self, ax: Axes, size: float, n: int) -> None:
        self.trails = _Lines(ax, n, colors=_SWARM, linewidth=0.3, alpha=0.5, zorder=1)
        style: dict[str, Any] = {"ls": "none", "marker": "o", "ms": max(size, 1.0), "mew": 0.0}
        style["zorder"] = 3
        (self.discs,) = ax.plot([], [], color=_SWARM, **style)
        (self.stopped,) = ax.plot([], [], color="0.55", **style)
        (self.ringed,) = ax.plot([], [], mfc="none", mec=ACTIVE_COLOR, **{**style, "mew": 1.0})

    def draw(
        self, trail: NDArray[np.float64], dead: NDArray[np.bool_], ring: NDArray[np.bool_]
    ) -> list[Any]:
        now = trail[-1]
        self.trails.set(np.swapaxes(trail, 0, 1))
        self.discs.set_data(now[~dead, 0], now[~dead, 1])
        self.stopped.set_data(now[dead, 0], now[dead, 1])
        self.ringed.set_data(now[ring, 0], now[ring, 1])
        return [self.trails.artist, self.discs, self.stopped, self.ringed]


#: colour of the robots beyond COLLECTION_LIMIT (one colour: markers draw ~4 times faster)
_SWARM = "C0"
#: share of the figure's side the axes take (to size the markers of very many robots)
_AXES_SHARE = 0.8


class _Lines:
    """``k`` lines updated every frame: a collection (a colour each) up to
    :data:`~formationlab.plotting.many.COLLECTION_LIMIT`, one broken line beyond."""

    def __init__(self, ax: Axes, k: int, *, colors: Any, **style: Any) -> None:
        self.broken = k > COLLECTION_LIMIT
        self.artist: Any
        if self.broken:
            first = colors if isinstance(colors, str) else np.asarray(colors).reshape(-1, 4)[0]
            (self.artist,) = ax.plot([], [], color=first, **style)
        else:
            widths = style.pop("linewidth")
            self.artist = LineCollection(
                segments(np.zeros((k, 2, 2))), colors=colors, linewidths=widths, **style
            )
            ax.add_collection(self.artist)

    def set(self, lines: NDArray[np.float64]) -> None:
        """Draw the lines ``(k, points, 2)``."""
        if self.broken:
            self.artist.set_data(*broken_line(lines))
        else:
            self.artist.set_segments(segments(lines))
