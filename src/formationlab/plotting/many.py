"""Drawing many robots: one collection per kind of mark, distributions instead of lines.

A figure of a swarm cannot show a line, a legend entry and a number per robot:
200 robots make a legend taller than the plot, 10,000 make the figure take
minutes. Beyond a few robots the run's figures draw

* every path, start, disc and edge as **one collection** each (a
  :class:`~matplotlib.collections.LineCollection` of the paths, thinned evenly
  in time to at most :data:`PATH_VERTICES` vertices together; an
  :class:`~matplotlib.collections.EllipseCollection` of discs of the robots'
  true diameters), coloured by robot number with a colour bar instead of a legend;
* quantities over time (controls, distance errors) as **bands** of their
  distribution over the robots or edges: the range (min to max), the 10-90 %
  band and the median, evaluated at most at :data:`BAND_TIMES` times.

The thresholds: :data:`LABEL_LIMIT` robots (or edges) get a legend entry and a
number each, :data:`LINE_LIMIT` get a line each.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import EllipseCollection, LineCollection
from numpy.typing import ArrayLike, NDArray

from ..formation.chunked import time_slices

__all__ = [
    "BAND_TIMES",
    "COLLECTION_LIMIT",
    "LABEL_LIMIT",
    "LINE_LIMIT",
    "PATH_VERTICES",
    "broken_line",
    "draw_bands",
    "draw_discs",
    "draw_lines",
    "draw_paths",
    "even_indices",
    "quantile_bands",
    "segments",
]

#: most robots (edges) with a legend entry or a number label each
LABEL_LIMIT = 12
#: most robots (edges) drawn as one line each in a plot over time; beyond, bands
LINE_LIMIT = 50
#: most lines drawn as a collection (each its own colour); beyond, one broken line
COLLECTION_LIMIT = 2000
#: most vertices of all the paths of a trajectory plot together
PATH_VERTICES = 1_000_000
#: most times at which the bands of a plot over time are evaluated
BAND_TIMES = 2000
#: the quantiles of the bands: range, 10-90 %, median
QUANTILES = (0.0, 10.0, 50.0, 90.0, 100.0)


def even_indices(t: ArrayLike, most: int) -> NDArray[np.int64]:
    """Indices into ``t`` (shape ``(T,)``) of at most ``most`` times evenly spaced in time.

    The first and the last saved states are always included.
    """
    t = np.asarray(t, dtype=float)
    if most < 2:
        raise ValueError(f"need at least 2 times, got most={most}")
    if len(t) <= most:
        return np.arange(len(t))
    targets = np.linspace(t[0], t[-1], most)
    idx = np.searchsorted(t, targets, side="left").clip(0, len(t) - 1)
    return np.unique(idx)


def segments(lines: NDArray[np.float64]) -> Any:
    """Lines ``(k, points, 2)`` as a :class:`LineCollection` takes them: the array itself (its
    type stubs ask for a sequence; a list of 300,000 arrays would cost more than the draw)."""
    return lines


def broken_line(lines: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
    """Lines ``(k, points, d)`` as the coordinates (``x``, ``y`` and, in space, ``z``) of one
    line broken by NaN between them.

    matplotlib makes one path object per line of a collection (tens of microseconds each),
    so beyond :data:`COLLECTION_LIMIT` lines one broken line of one colour draws instead.
    """
    k, p, d = lines.shape
    xy = np.full((k, p + 1, d), np.nan)
    xy[:, :p] = lines
    xy = xy.reshape(-1, d)
    return tuple(xy[:, a] for a in range(d))


def draw_lines(ax: Axes, lines: NDArray[np.float64], colors: Any, **style: Any) -> Any:
    """Lines ``(k, points, 2)``: a collection in ``colors`` up to :data:`COLLECTION_LIMIT`
    lines, one broken line in the first colour beyond (:func:`broken_line`)."""
    if len(lines) <= COLLECTION_LIMIT:
        lc = LineCollection(segments(lines), colors=colors, **style)
        ax.add_collection(lc)
        return lc
    color = colors if isinstance(colors, str) else np.asarray(colors).reshape(-1, 4)[0]
    style = {k.removesuffix("s"): v for k, v in style.items()}  # linewidths -> linewidth
    (line,) = ax.plot(*broken_line(lines), color=color, **style)
    return line


def draw_paths(ax: Axes, t: ArrayLike, q: NDArray[np.float64], colors: Any, **style: Any) -> Any:
    """Every robot's path ``q`` ``(T, n, 2)`` (:func:`draw_lines`), each thinned evenly in
    time so that all of them together have at most :data:`PATH_VERTICES` vertices."""
    n = q.shape[1]
    rows = even_indices(t, max(2, PATH_VERTICES // max(n, 1)))
    lines = np.swapaxes(q[rows], 0, 1)  # (n, rows, 2)
    if n > COLLECTION_LIMIT:
        colors = "0.5"
    return draw_lines(ax, lines, colors, **style)


def draw_discs(
    ax: Axes, centres: NDArray[np.float64], diameters: ArrayLike, colors: Any, **style: Any
) -> EllipseCollection:
    """Discs of the robots' true diameters (in the units of the axes) at ``centres`` ``(n, 2)``."""
    d = np.asarray(diameters, dtype=float)
    discs = EllipseCollection(
        d, d, np.zeros_like(d), units="xy", offsets=np.asarray(centres, dtype=float),
        offset_transform=ax.transData, facecolors=colors, **style,
    )  # fmt: skip
    ax.add_collection(discs)
    return discs


def quantile_bands(
    t: ArrayLike, values: Callable[[NDArray[np.int64]], NDArray[np.float64]], width: int
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The :data:`QUANTILES` of ``values(rows)`` ``(len(rows), width)`` over its last axis.

    Evaluated at most at :data:`BAND_TIMES` times evenly spaced in ``t``, in slices of
    them whose values and scratch fit :data:`formationlab.formation.chunked.BUDGET` (the values of
    all of them are never held at once). Returns the rows and the quantiles
    ``(len(QUANTILES), len(rows))``.
    """
    rows = even_indices(t, BAND_TIMES)
    out = np.empty((len(QUANTILES), len(rows)))
    for part in time_slices(len(rows), _SCRATCH * max(width, 1)):
        out[:, part] = np.percentile(values(rows[part]), QUANTILES, axis=-1)
    return rows, out


#: scratch bytes per value of a band (the values, their differences and the sort's copy)
_SCRATCH = 8 * 8


def draw_bands(
    ax: Axes,
    t: ArrayLike,
    values: Callable[[NDArray[np.int64]], NDArray[np.float64]],
    *,
    width: int,
    of: str,
    color: Any = "C0",
) -> list[Any]:
    """The range, the 10-90 % band and the median of ``values(rows)`` (``width`` values per
    time) over ``of`` (robots, edges) at each time (:func:`quantile_bands`); labelled for
    a legend of three entries."""
    t = np.asarray(t, dtype=float)
    rows, qs = quantile_bands(t, values, width)
    x = t[rows]
    return [
        ax.fill_between(x, qs[0], qs[4], color=color, alpha=0.2, lw=0, label=f"range over {of}"),
        ax.fill_between(x, qs[1], qs[3], color=color, alpha=0.45, lw=0, label="10-90 %"),
        *ax.plot(x, qs[2], color=color, lw=1.2, label="median"),
    ]
