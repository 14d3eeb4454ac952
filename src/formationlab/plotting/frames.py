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


def frame_indices(t: ArrayLike, max_frames: int) -> NDArray[np.int64]:
    """Indices into ``t`` (shape ``(T,)``) of at most ``max_frames`` frames evenly spaced in time.

    The first and the last saved states are always included.
    """
    if max_frames < 2:
        raise ValueError(f"an animation needs at least 2 frames, got max_frames={max_frames}")
    return even_indices(t, max_frames)


def path_indices(t: ArrayLike, max_frames: int, n: int) -> NDArray[np.int64]:
    """Indices of the saved states the trails are drawn through: evenly spaced, at least the
    frames, at most 2000, and for many robots at most :data:`TRAIL_VERTICES` ``/ n``."""
    most = max(2000, max_frames) if n <= LABEL_LIMIT else max(TRAIL_VERTICES // n, 2)
    return even_indices(t, most)


def used_indices(t: ArrayLike, max_frames: int, n: int) -> NDArray[np.int64]:
    """The saved states an animation of ``n`` robots reads: its frames and its trails' states.

    An animation of ``t[rows]``, ``q[rows]`` draws what it draws of ``t``, ``q`` (the
    frames and the trails pick the same states), so a reader loads only these.
    """
    return np.union1d(frame_indices(t, max_frames), path_indices(t, max_frames, n))


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
    max_frames: int,
    n: int,
    trail: float | None,
    clock: Text,
    title: str,
    fps: int,
) -> FuncAnimation:
    """The animation of ``scene`` over the frames of the saved times ``t`` ``(T,)``.

    Each frame picks its saved state (:func:`frame_indices`) and the states of the trails
    behind it (:func:`path_indices`, the last ``trail`` seconds, or all when None), lets
    ``scene`` draw them and writes the time into ``clock``. The figure is laid out once,
    at the first frame (the limits are fixed): the constrained layout measures every tick
    label each time, about half the cost of a frame.
    """
    frames = frame_indices(t, max_frames)
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
