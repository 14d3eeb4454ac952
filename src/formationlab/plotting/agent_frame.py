"""Pictures of the robots as RGB arrays: the frames of the agents' environment.

:class:`AgentFrames` draws the robots (discs of their diameters, headings of unicycles)
and the formation's graph on one figure of its own (the Agg canvas, no ``pyplot`` state)
that it keeps: each frame moves the artists and draws only them over the axes kept from
the last time the view was fitted (blitting; the view is fitted again when a robot leaves
it or the robots shrink to a small part of it), instead of building a figure (ten times
faster), for
:meth:`formationlab.envs.pettingzoo.FormationEnv.render`. :func:`agent_frame` is one frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle
from numpy.typing import NDArray

from .colors import robot_colors

__all__ = ["AgentFrames", "agent_frame"]

#: the view's half-width over the robots' (a margin round them when the view is fitted)
_MARGIN = 1.15
#: the least share of the view's half-width the robots fill before the view is fitted again
_FILL = 0.4


class AgentFrames:
    """The frames of one formation's robots, drawn on one kept figure.

    Parameters
    ----------
    formation : Formation
        Its robots (diameters) and graph (edges).
    model : RobotModel, optional
        With headings (``model.has_heading``), a line from each centre shows the heading.
    size : (int, int)
        ``(W, H)`` of the frames in pixels.
    dpi : int
        Of the figure.
    """

    def __init__(
        self,
        formation: Any,
        *,
        model: Any = None,
        size: tuple[int, int] = (480, 480),
        dpi: int = 96,
    ) -> None:
        self.formation, self.model = formation, model
        self.figure = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.figure)
        ax = self.axes = self.figure.add_subplot()
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        self.radii = np.asarray(formation.diameters, dtype=float) / 2
        self._edges = np.asarray(formation.edges)
        self._graph = LineCollection([], colors="0.6", linewidths=1.0, zorder=1)
        ax.add_collection(self._graph)
        self._discs = [
            ax.add_patch(Circle((0.0, 0.0), r, color=c, zorder=2))
            for r, c in zip(self.radii, robot_colors(formation.n), strict=True)
        ]
        self._headings = None
        if model is not None and model.has_heading:
            self._headings = LineCollection([], colors="k", linewidths=1.0, zorder=3)
            ax.add_collection(self._headings)
        self._title = ax.set_title("")
        self._moving = [self._graph, *self._discs, self._title]
        self._moving += [] if self._headings is None else [self._headings]
        for artist in self._moving:  # drawn over the kept background (blitting)
            artist.set_animated(True)
        self._view: tuple[float, float, float] | None = None  # centre x, y, half-width
        self._background: Any = None

    def __call__(self, x: NDArray[np.float64], t: float | None = None) -> NDArray[np.uint8]:
        """The robots at state ``x`` ``(n, k)`` as an RGB image ``(H, W, 3)`` of ``uint8``;
        ``t`` (seconds) goes in the title."""
        x = np.asarray(x, dtype=float)
        q, radii = x[:, :2], self.radii
        self._graph.set_segments(np.stack([q[self._edges[:, 0]], q[self._edges[:, 1]]], axis=1))
        for disc, centre in zip(self._discs, q, strict=True):
            disc.set_center(tuple(centre))
        if self._headings is not None:
            h = self.model.heading(x)
            tip = q + 2 * radii[:, None] * np.stack([np.cos(h), np.sin(h)], axis=-1)
            self._headings.set_segments(np.stack([q, tip], axis=1))
        self._title.set_text("" if t is None else f"t = {t:.3f} s")
        self._fit(q)
        self.canvas.restore_region(self._background)
        for artist in self._moving:
            self.axes.draw_artist(artist)
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()

    def _fit(self, q: NDArray[np.float64]) -> None:
        """Keep the view (and the drawn axes behind the robots) while every robot is in it
        and they fill more than :data:`_FILL` of it; else fit it to them and draw it."""
        r = float(self.radii.max())
        lo, hi = q.min(axis=0) - r, q.max(axis=0) + r
        extent = max(float(np.max(hi - lo)) / 2, 0.5 / _MARGIN)
        if self._view is not None:
            cx, cy, half = self._view
            inside = np.all(lo >= (cx - half, cy - half)) and np.all(hi <= (cx + half, cy + half))
            if inside and extent >= _FILL * half:
                return
        mid, half = (lo + hi) / 2, extent * _MARGIN
        self._view = (float(mid[0]), float(mid[1]), half)
        self.axes.set_xlim(mid[0] - half, mid[0] + half)
        self.axes.set_ylim(mid[1] - half, mid[1] + half)
        self.canvas.draw()  # the axes without the (animated) robots
        self._background = self.canvas.copy_from_bbox(self.figure.bbox)


def agent_frame(
    formation: Any,
    x: NDArray[np.float64],
    *,
    model: Any = None,
    t: float | None = None,
    size: tuple[int, int] = (480, 480),
    dpi: int = 96,
) -> NDArray[np.uint8]:
    """The robots at state ``x`` ``(n, k)`` as an RGB image ``(H, W, 3)`` of ``uint8``
    (one frame of :class:`AgentFrames`; keep an :class:`AgentFrames` for many)."""
    return AgentFrames(formation, model=model, size=size, dpi=dpi)(x, t)
