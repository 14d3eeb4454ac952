"""Saving matplotlib figures atomically, in the formats asked for (PNG, and PDF or SVG for
vector output in LaTeX)."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from ..errors import ParameterError
from .files import atomic_path

__all__ = ["FIGURE_FORMATS", "figure_formats", "save_figure", "save_figures"]

#: the formats a command writes its figures in (``--format``)
FIGURE_FORMATS = ("png", "pdf", "svg")


def figure_formats(text: str) -> tuple[str, ...]:
    """The formats of a comma-separated list such as ``"png,pdf,svg"`` (in order, each once).

    Raises :class:`~formationlab.errors.ParameterError` naming an unknown format.
    """
    return chosen_formats([text], FIGURE_FORMATS, what="figure", example="png,pdf")


def chosen_formats(
    values: Iterable[str], known: Iterable[str], *, what: str, example: str
) -> tuple[str, ...]:
    """The formats named in ``values``, each a comma-separated list (``--format gif,html`` or
    ``--format gif --format html``), in order and each once, lower case.

    Raises :class:`~formationlab.errors.ParameterError` naming an unknown format, and when
    none is named; ``what`` names the kind of file (``"figure"``), ``example`` a list to try.
    """
    known = tuple(known)
    formats = tuple(
        dict.fromkeys(f.strip().lower() for v in values for f in v.split(",") if f.strip())
    )
    bad = [f for f in formats if f not in known]
    if bad or not formats:
        problem = f"unknown {what} format {', '.join(map(repr, bad))}" if bad else "no format"
        raise ParameterError(
            f"{problem}: choose from {', '.join(known)} "
            f"(a comma-separated list, e.g. --format {example})"
        )
    return formats


def save_figures(
    fig: Any, stem: str | os.PathLike[str], formats: tuple[str, ...] = ("png",), *, dpi: int = 120
) -> list[Path]:
    """Save ``fig`` as ``stem.<format>`` for each of ``formats`` (:func:`save_figure`);
    returns the paths written."""
    stem = Path(stem)
    return [save_figure(fig, stem.with_name(f"{stem.name}.{f}"), dpi=dpi) for f in formats]


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
