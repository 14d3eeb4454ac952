"""Animation of a run: robots as discs of their diameters, the graph's edges, fading trails.

:func:`animate_run` builds a :class:`matplotlib.animation.FuncAnimation` from
positions ``(T, n, 2)``; the frames are a thinned, evenly spaced subset of the
saved times (at most ``max_frames``), so the cost and size of the GIF, MP4 and
HTML player stay bounded whatever the run's length. Saving is done by
:mod:`formationlab.io.animation`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.animation import FuncAnimation
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle
from numpy.typing import ArrayLike, NDArray

from .fonts import displayable, font_context
from .runs import robot_colors
from .safety import ACTIVE_COLOR, draw_obstacles

__all__ = ["animate_run", "frame_indices"]


def frame_indices(t: ArrayLike, max_frames: int) -> NDArray[np.int64]:
    """Indices into ``t`` (shape ``(T,)``) of at most ``max_frames`` frames evenly spaced in time.

    The first and the last saved states are always included.
    """
    t = np.asarray(t, dtype=float)
    if max_frames < 2:
        raise ValueError(f"an animation needs at least 2 frames, got max_frames={max_frames}")
    if len(t) <= max_frames:
        return np.arange(len(t))
    targets = np.linspace(t[0], t[-1], max_frames)
    idx = np.searchsorted(t, targets, side="left").clip(0, len(t) - 1)
    return np.unique(idx)


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
    q : array_like, shape (T, n, 2)
        Positions at those times.
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
    if q.ndim != 3 or q.shape[-1] != 2 or q.shape[0] != t.shape[0]:
        raise ValueError(f"q must have shape (T, n, 2) with T = len(t), got {q.shape}")
    n = q.shape[1]
    frames = frame_indices(t, max_frames)
    # trails are drawn through at most ~2000 states, so long runs stay cheap to render
    path = frame_indices(t, max(2000, max_frames))
    colors = robot_colors(n)

    title = displayable(title)  # the user's scenario name: any script
    with font_context():
        fig = Figure(figsize=(size, size), dpi=dpi, layout="constrained")
        ax = fig.add_subplot()
    lo = q.reshape(-1, 2).min(axis=0) - diameters.max()
    hi = q.reshape(-1, 2).max(axis=0) + diameters.max()
    pad = 0.05 * max(float(np.max(hi - lo)), 1e-9)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    if len(obstacles):
        draw_obstacles(ax, obstacles)
    on = np.zeros((len(t), n), bool) if active is None else np.asarray(active, bool)
    pairs = np.zeros((0, 3), np.int64) if active_pairs is None else np.asarray(active_pairs)
    pairs = pairs.reshape(-1, 3).astype(np.int64)
    red = ACTIVE_COLOR
    constrained = LineCollection([], colors=red, linewidths=2.0, zorder=2.5)
    ax.add_collection(constrained)

    theta = None if headings is None else np.asarray(headings, dtype=float)
    hand = None if points is None else np.asarray(points, dtype=float)
    ends = hand if hand is not None else q  # what the edges join
    noses = LineCollection(list(np.zeros((n, 2, 2))), colors="k", linewidths=1.5, zorder=5)
    if theta is not None:
        ax.add_collection(noses)
    marks = ax.plot([], [], "k+", ms=6, zorder=5)[0] if hand is not None else None
    graph = LineCollection(
        list(np.zeros((len(edges), 2, 2))), colors="0.3", linewidths=1.0, zorder=2
    )
    ax.add_collection(graph)
    trails = [ax.plot([], [], color=colors[i], lw=1.0, alpha=0.6, zorder=1)[0] for i in range(n)]
    discs = [
        Circle((0.0, 0.0), diameters[i] / 2, color=colors[i], alpha=0.9, zorder=3) for i in range(n)
    ]
    for disc in discs:
        ax.add_patch(disc)
    labels = [
        ax.annotate(
            str(i + 1), (0.0, 0.0), xytext=(4, 4), textcoords="offset points", fontsize=8, zorder=4
        )
        for i in range(n)
    ]
    clock = ax.set_title("")
    stop_at = np.full(n, np.inf)
    for robot, at in stops:
        stop_at[int(robot)] = float(at)

    def draw(k: int) -> list[Any]:
        idx = frames[k]
        now = q[idx]
        joined = ends[idx]
        graph.set_segments(list(np.stack([joined[edges[:, 0]], joined[edges[:, 1]]], axis=1)))
        extra: list[Any] = []
        if theta is not None:
            rim = now + (diameters / 2)[:, None] * np.stack(
                [np.cos(theta[idx]), np.sin(theta[idx])], axis=-1
            )
            noses.set_segments(list(np.stack([now, rim], axis=1)))
            extra.append(noses)
        if marks is not None and hand is not None:
            marks.set_data(hand[idx, :, 0], hand[idx, :, 1])
            extra.append(marks)
        since = -np.inf if trail is None else t[idx] - trail
        sel = path[(path < idx) & (t[path] >= since)]
        sel = np.append(sel, idx)
        hit = pairs[pairs[:, 0] == idx]
        constrained.set_segments(list(np.stack([now[hit[:, 1]], now[hit[:, 2]]], axis=1)))
        for i in range(n):
            trails[i].set_data(q[sel, i, 0], q[sel, i, 1])
            discs[i].center = (now[i, 0], now[i, 1])
            dead = t[idx] >= stop_at[i]
            discs[i].set_facecolor("0.55" if dead else colors[i])
            discs[i].set_edgecolor(red if on[idx, i] else "k" if dead else colors[i])
            discs[i].set_linewidth(2.0 if on[idx, i] or dead else 1.0)
            labels[i].xy = (now[i, 0], now[i, 1])
        clock.set_text(f"{title + ': ' if title else ''}t = {t[idx]:.2f} s")
        return [graph, constrained, *trails, *discs, *labels, clock, *extra]

    draw(0)
    return FuncAnimation(fig, draw, frames=len(frames), interval=1000 / fps, blit=False)
