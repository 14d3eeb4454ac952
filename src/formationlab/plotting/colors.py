"""The robots' colours, the same in every figure, animation and frame."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["ROBOT_MAP", "robot_colors"]

#: the continuous map of formations of more than ten robots
ROBOT_MAP = "viridis"


def robot_colors(n: int) -> Any:
    """One colour per robot (tab10, then a continuous map for larger formations).

    A list of RGBA tuples up to ten robots, an ``(n, 4)`` array beyond (indexable the same
    way, and what collections take).
    """
    import matplotlib as mpl

    if n <= 10:
        cmap = mpl.colormaps["tab10"]
        return [cmap(i) for i in range(n)]
    return mpl.colormaps[ROBOT_MAP](np.linspace(0.0, 1.0, n))
