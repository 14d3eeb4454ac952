"""Saving matplotlib figures atomically."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from .files import atomic_path

__all__ = ["save_figure"]


def save_figure(fig: Any, target: str | os.PathLike[str], *, dpi: int = 120) -> Path:
    """Save ``fig`` to ``target`` (format from the suffix) atomically and close it."""
    import matplotlib.pyplot as plt

    target = Path(target)
    with atomic_path(target) as tmp:
        fig.savefig(tmp, dpi=dpi, format=target.suffix.lstrip(".") or "png", bbox_inches="tight")
    plt.close(fig)
    return target
