"""Saving matplotlib figures atomically."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

from .files import atomic_path

__all__ = ["save_figure"]


def save_figure(fig: Any, target: str | os.PathLike[str], *, dpi: int = 120) -> Path:
    """Save ``fig`` to ``target`` (format from the suffix) atomically and close it.

    Cropped to what is drawn (``bbox_inches="tight"``) unless the figure has a layout
    engine, which has fitted it to its size already.

    Closing concerns only figures that pyplot manages; pyplot is not imported for it
    (formationlab's figures are plain :class:`~matplotlib.figure.Figure` objects, and
    importing pyplot costs a good part of a second).
    """
    target = Path(target)
    # a figure with a layout engine (formationlab's are "constrained") is laid out already;
    # bbox_inches="tight" would draw it once more to measure it (a third of the time)
    tight = None if fig.get_layout_engine() is not None else "tight"
    with atomic_path(target) as tmp:
        fig.savefig(tmp, dpi=dpi, format=target.suffix.lstrip(".") or "png", bbox_inches=tight)
    plt = sys.modules.get("matplotlib.pyplot")
    if plt is not None:  # a figure of pyplot's is closed; no other can be its
        plt.close(fig)
    return target
