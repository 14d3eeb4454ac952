"""The typer application, and the error and warning handling every command shares.

User errors become one ``error:`` line and exit status 2; formationlab's own
warnings (:class:`~formationlab.errors.FormationlabWarning`, e.g. a scenario key
that has no effect) become one ``warning:`` line each, whatever the warning
filters of the caller say, and never stop the command.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, NoReturn, TypeVar

import typer
from rich.console import Console
from rich.markup import escape

from ..errors import FormationlabWarning, UserInputError

__all__ = ["app", "command", "err_console", "fail", "warn"]

app = typer.Typer(
    name="formationlab",
    help="Multi-robot formation control: reproduce the paper, run scenarios, study outcomes.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
err_console = Console(stderr=True)

F = TypeVar("F", bound=Callable[..., Any])


def fail(message: str, code: int = 2) -> NoReturn:
    """Print ``error: message`` on standard error and exit with ``code``."""
    # escape: messages quote user input such as "[x, y]", which is not rich markup
    err_console.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)
    raise typer.Exit(code)


def warn(message: str) -> None:
    """Print ``warning: message`` on standard error, once per command."""
    if message in _shown:
        return
    _shown.add(message)
    err_console.print(
        f"[bold yellow]warning:[/] {escape(message)}", highlight=False, soft_wrap=True
    )


_shown: set[str] = set()


@contextmanager
def _warnings_as_lines() -> Iterator[None]:
    """Print formationlab's warnings as ``warning:`` lines; pass the others on."""
    _shown.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("always", FormationlabWarning)
        show = warnings.showwarning

        def showwarning(message: Any, category: type[Warning], *args: Any, **kw: Any) -> None:
            if issubclass(category, FormationlabWarning):
                warn(str(message))
            else:
                show(message, category, *args, **kw)

        warnings.showwarning = showwarning
        yield


def command(*args: Any, **kwargs: Any) -> Callable[[F], F]:
    """``app.command`` that turns user errors into a message and exit status 2."""

    def deco(fn: F) -> F:
        @functools.wraps(fn)
        def wrapper(*a: Any, **k: Any) -> Any:
            try:
                with _warnings_as_lines():
                    return fn(*a, **k)
            except UserInputError as exc:
                fail(str(exc))
            except FileNotFoundError as exc:
                fail(f"file not found: {exc.filename or exc}")
            except KeyboardInterrupt:
                fail("interrupted", code=130)

        app.command(*args, **kwargs)(wrapper)
        return fn

    return deco


def _print_version(value: bool) -> None:
    if value:
        from .. import __version__

        typer.echo(f"formationlab {__version__}")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: bool = typer.Option(
        False,
        "--version",
        help="Print the version and exit.",
        is_eager=True,
        callback=_print_version,
    ),
) -> None:
    """Multi-robot formation control: reproduce the paper, run scenarios, study outcomes."""
