"""The colours and line styles of robots and edges, the same in every figure, animation and
frame: robot ``i`` and edge ``e`` have one colour wherever they are drawn.

:func:`palette` is the one palette; :func:`robot_colors` and :func:`edge_colors` give it
per robot and per edge, and :func:`line_styles` the dash patterns that keep lines
visible where they coincide (in the paper's unperturbed simulation 2, ``r_13`` lies on
``r_23``): a dashed line drawn over a solid one shows both colours.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["ROBOT_MAP", "edge_colors", "line_styles", "palette", "robot_colors"]

#: the continuous map of more than ten robots or edges
ROBOT_MAP = "viridis"

#: line styles, repeated past the fourth line
_STYLES = ("-", "--", ":", "-.")


def palette(k: int) -> Any:
    """One colour for each of ``k`` things (tab10, then a continuous map beyond ten).

    A list of RGBA tuples up to ten, an ``(k, 4)`` array beyond (indexable the same way,
    and what collections take).
    """
    import matplotlib as mpl

    if k <= 10:
        cmap = mpl.colormaps["tab10"]
        return [cmap(i) for i in range(k)]
    return mpl.colormaps[ROBOT_MAP](np.linspace(0.0, 1.0, k))


def robot_colors(n: int) -> Any:
    """The colour of each of ``n`` robots (:func:`palette`)."""
    return palette(n)


def edge_colors(m: int) -> Any:
    """The colour of each of ``m`` edges (:func:`palette`, in the formation's edge order)."""
    return palette(m)


def line_styles(k: int) -> list[str]:
    """The dash pattern of each of ``k`` lines: solid, dashed, dotted, dash-dotted, again."""
    return [_STYLES[i % len(_STYLES)] for i in range(k)]
