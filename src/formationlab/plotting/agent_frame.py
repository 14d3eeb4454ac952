"""One picture of the robots as an RGB array: the frames of the agents' environment.

:func:`agent_frame` draws the robots (discs of their diameters, headings of unicycles)
and the formation's graph at one state on a figure of its own (the Agg canvas, no
``pyplot`` state), for :meth:`formationlab.envs.pettingzoo.FormationEnv.render`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle
from numpy.typing import NDArray

from .colors import robot_colors
from .runs import _draw_graph

__all__ = ["agent_frame"]


def agent_frame(
    formation: Any,
    x: NDArray[np.float64],
    *,
    model: Any = None,
    t: float | None = None,
    size: tuple[int, int] = (480, 480),
    dpi: int = 96,
) -> NDArray[np.uint8]:
    """The robots at state ``x`` ``(n, k)`` as an RGB image ``(H, W, 3)`` of ``uint8``.

    ``size`` is ``(W, H)`` in pixels; ``t`` (seconds) goes in the title; with a
    ``model`` that has headings, a line from each centre shows the heading.
    """
    x = np.asarray(x, dtype=float)
    q = x[:, :2]
    fig = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    _draw_graph(ax, formation, q, colors="0.6", linewidths=1.0, zorder=1)
    radii = np.asarray(formation.diameters, dtype=float) / 2
    for i, c in enumerate(robot_colors(formation.n)):
        ax.add_patch(Circle(tuple(q[i]), radii[i], color=c, zorder=2))
    if model is not None and model.has_heading:
        h = model.heading(x)
        tip = q + 2 * radii[:, None] * np.stack([np.cos(h), np.sin(h)], axis=-1)
        for i in range(formation.n):
            ax.plot(*np.stack([q[i], tip[i]]).T, color="k", linewidth=1.0, zorder=3)
    lo, hi = q.min(axis=0) - radii.max(), q.max(axis=0) + radii.max()
    mid, half = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2 * 1.15, 0.5)
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_aspect("equal")
    if t is not None:
        ax.set_title(f"t = {t:.3f} s")
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
