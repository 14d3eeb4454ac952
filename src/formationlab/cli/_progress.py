"""Progress on standard error, the same for every command that takes more than a second.

A command shows progress when :func:`shows_progress` says so: not ``--quiet``, and
standard error is a terminal (a log or a pipe gets no redrawn bars, only the lines a
command prints itself). :func:`progress_bar` is a transient rich bar of counted work
(frames, trials, time); :func:`stage_bar` a bar over the named stages of a command
(``paper``: the three runs, the two scans, the figures).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from rich.console import Console
from rich.markup import escape

from ._app import err_console

__all__ = ["progress_bar", "shows_progress", "stage_bar"]


def shows_progress(quiet: bool, console: Console | None = None) -> bool:
    """Whether a command shows progress: not ``--quiet``, and ``console`` (standard error)
    is a terminal."""
    return not quiet and (console or err_console).is_terminal


@contextmanager
def progress_bar(
    label: str, *, quiet: bool = False, total: float | None = None, count: str | None = None
) -> Iterator[Callable[..., None]]:
    """A transient bar ``label ━━━━ done/total`` on standard error (nothing when
    :func:`shows_progress` is false); yields ``update(done, total=None)``.

    ``count`` formats the count from ``done`` and ``total`` (``None``: ``12/150``, for
    frames and trials); for the times of a run, ``"t = {done:.2f} / {total:g} s"``.
    """
    if not shows_progress(quiet):
        yield lambda done, total=None: None
        return
    # rich.progress only when a bar is drawn (its import is a tenth of a second)
    from rich import progress as rp

    shown: Any = rp.MofNCompleteColumn()
    if count is not None:
        shown = rp.TextColumn(
            count.replace("{done", "{task.completed").replace("{total", "{task.total")
        )
    columns = (rp.TextColumn(escape(label)), rp.BarColumn(), shown, rp.TimeRemainingColumn())
    with rp.Progress(*columns, console=err_console, transient=True) as bar:
        task = bar.add_task(label, total=total)

        def update(done: float, total: float | None = None) -> None:
            bar.update(task, completed=done, **({} if total is None else {"total": total}))

        yield update


@contextmanager
def stage_bar(label: str, stages: int, *, quiet: bool = False) -> Iterator[Callable[[str], None]]:
    """A bar over ``stages`` named stages: yields ``now(name)``, which counts the stage
    before as done and shows ``label: name``."""
    if not shows_progress(quiet):
        yield lambda name: None
        return
    # rich.progress only when a bar is drawn (its import is a tenth of a second)
    from rich import progress as rp

    columns = (
        rp.TextColumn("{task.description}"),
        rp.BarColumn(),
        rp.MofNCompleteColumn(),
        rp.TimeElapsedColumn(),
    )
    with rp.Progress(*columns, console=err_console, transient=True) as bar:
        task = bar.add_task(escape(label), total=stages)
        started: list[str] = []

        def now(name: str) -> None:
            bar.update(task, completed=len(started), description=escape(f"{label}: {name}"))
            started.append(name)

        yield now
