"""The timing of an animation: which saved states are its frames and its trails, and the
animation that plays them.

The plane (:mod:`formationlab.plotting.animation`) and space
(:mod:`formationlab.plotting.animation_space`) draw a frame differently; what a frame is,
which states its trails pass through, the clock in the title and the
:class:`~matplotlib.animation.FuncAnimation` are the same, and live here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from matplotlib.animation import FuncAnimation
from matplotlib.figure import Figure
from matplotlib.text import Text
from numpy.typing import ArrayLike, NDArray

from .many import LABEL_LIMIT, even_indices

__all__ = [
    "TRAIL_VERTICES",
    "Scene",
    "frame_indices",
    "motion_measure",
    "path_indices",
    "play",
    "stop_times",
    "used_indices",
]

#: most vertices of all the trails of a frame together, beyond LABEL_LIMIT robots
TRAIL_VERTICES = 200_000

#: ``scene(k, idx, trail)``: draw frame ``k``, the saved state ``idx``, with the trails
#: through the saved states ``trail`` (ending at ``idx``); returns the artists it changed
Scene = Callable[[int, int, NDArray[np.int64]], list[Any]]


def frame_indices(
    t: ArrayLike, max_frames: int, q: ArrayLike | None = None, n: int | None = None
) -> NDArray[np.int64]:
    """Indices into ``t`` (shape ``(T,)``) of at most ``max_frames`` frames.

    Without ``q``, evenly spaced in time. With the positions ``q`` ``(T, n, d)`` (an array,
    or anything that loads only the rows it is indexed with, such as a lazily opened
    :class:`xarray.DataArray`), spaced evenly in a measure that is half the time and half
    the motion (:func:`motion_measure`): a transient of 1 s in a run of 15 s gets about
    half the frames instead of one fifteenth, and the still end is not skipped. The first
    and the last saved states are always included.
    """
    if max_frames < 2:
        raise ValueError(f"an animation needs at least 2 frames, got max_frames={max_frames}")
    if q is None:
        return even_indices(t, max_frames)
    t = np.asarray(t, dtype=float)
    if len(t) <= max_frames:
        return np.arange(len(t))
    coarse = path_indices(t, max_frames, q.shape[1] if n is None else n)  # type: ignore[union-attr]
    at, level = t[coarse], motion_measure(t[coarse], np.asarray(q[coarse]))  # type: ignore[index]
    # the times where the measure reaches evenly spaced levels, then the nearest saved state
    # at or after each (as even_indices): the same frames from any rows that hold them
    times = np.interp(np.linspace(0.0, 1.0, max_frames), level, at)
    idx = np.searchsorted(t, times, side="left").clip(0, len(t) - 1)
    return np.unique(np.concatenate([[0], idx, [len(t) - 1]]))


def motion_measure(t: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Half the elapsed time plus half the motion, from 0 at ``t[0]`` to 1 at ``t[-1]``;
    ``(T,)`` for the times ``t`` ``(T,)`` and positions ``q`` ``(T, n, d)``.

    The motion is the path length of the robots together (the sum over robots of
    ``|q_i(t_k+1) - q_i(t_k)|``, accumulated); strictly increasing, since time is.
    """
    span = float(t[-1] - t[0])
    elapsed = (t - t[0]) / span if span > 0 else np.linspace(0.0, 1.0, len(t))
    steps = np.linalg.norm(np.diff(q, axis=0), axis=-1).sum(axis=-1)
    arc = np.concatenate([[0.0], np.cumsum(np.nan_to_num(steps))])
    moved = arc / arc[-1] if arc[-1] > 0 else elapsed
    return 0.5 * elapsed + 0.5 * moved


def path_indices(t: ArrayLike, max_frames: int, n: int) -> NDArray[np.int64]:
    """Indices of the saved states the trails are drawn through: evenly spaced, at least the
    frames, at most 2000, and for many robots at most :data:`TRAIL_VERTICES` ``/ n``."""
    most = max(2000, max_frames) if n <= LABEL_LIMIT else max(TRAIL_VERTICES // n, 2)
    return even_indices(t, most)


def used_indices(
    t: ArrayLike, max_frames: int, n: int, q: ArrayLike | None = None
) -> NDArray[np.int64]:
    """The saved states an animation of ``n`` robots reads: its frames and its trails' states.

    An animation of ``t[rows]``, ``q[rows]`` draws what it draws of ``t``, ``q`` (the
    frames and the trails pick the same states: the frames are spaced by the motion
    through the trails' states, :func:`frame_indices`), so a reader loads only these.
    ``q`` ``(T, n, d)`` spaces the frames by the motion, as :func:`frame_indices`.
    """
    return np.union1d(frame_indices(t, max_frames, q, n), path_indices(t, max_frames, n))


def stop_times(n: int, stops: Sequence[tuple[int, float]]) -> NDArray[np.float64]:
    """Each robot's stop time ``(n,)`` from ``(0-based robot, time)`` pairs; inf if it runs on.

    A robot stopped (``[faults] stop``) is drawn grey from its stop time on.
    """
    stop_at = np.full(n, np.inf)
    for robot, at in stops:
        stop_at[int(robot)] = float(at)
    return stop_at


def play(
    fig: Figure,
    t: NDArray[np.float64],
    scene: Scene,
    *,
    q: NDArray[np.float64] | None = None,
    max_frames: int,
    n: int,
    trail: float | None,
    clock: Text,
    title: str,
    fps: int,
) -> FuncAnimation:
    """The animation of ``scene`` over the frames of the saved times ``t`` ``(T,)``.

    Each frame picks its saved state (:func:`frame_indices`, spaced by the motion of the
    positions ``q`` ``(T, n, d)`` when given) and the states of the trails
    behind it (:func:`path_indices`, the last ``trail`` seconds, or all when None), lets
    ``scene`` draw them and writes the time into ``clock``. The figure is laid out once,
    at the first frame (the limits are fixed): the constrained layout measures every tick
    label each time, about half the cost of a frame.
    """
    frames = frame_indices(t, max_frames, q, n)
    # trails are drawn through at most ~2000 states (fewer for many robots: the cost of a
    # frame stays bounded), so long runs stay cheap to render
    path = path_indices(t, max_frames, n)

    def draw(k: int) -> list[Any]:
        idx = int(frames[k])
        since = -np.inf if trail is None else t[idx] - trail
        sel = path[(path < idx) & (t[path] >= since)]
        drawn = scene(k, idx, np.append(sel, idx))
        clock.set_text(f"{title + ': ' if title else ''}t = {t[idx]:.2f} s")
        return [*drawn, clock]

    draw(0)
    fig.draw_without_rendering()
    fig.set_layout_engine("none")
    return FuncAnimation(fig, draw, frames=len(frames), interval=1000 / fps, blit=False)
