"""The typer application and the error handling every command shares."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, NoReturn, TypeVar

import typer
from rich.console import Console
from rich.markup import escape

from ..errors import UserInputError

__all__ = ["app", "command", "err_console", "fail"]

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


def command(*args: Any, **kwargs: Any) -> Callable[[F], F]:
    """``app.command`` that turns user errors into a message and exit status 2."""

    def deco(fn: F) -> F:
        @functools.wraps(fn)
        def wrapper(*a: Any, **k: Any) -> Any:
            try:
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


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", help="Print the version and exit."),
) -> None:
    """Multi-robot formation control: reproduce the paper, run scenarios, study outcomes."""
    if version:
        from .. import __version__

        typer.echo(f"formationlab {__version__}")
        raise typer.Exit(0)
