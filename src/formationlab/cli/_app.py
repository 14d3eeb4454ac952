"""The typer application and the error handling every command shares.

Every command is registered through :func:`command`, which turns what a user
can cause into one ``error:`` line on standard error and an exit status,
never a traceback; formationlab's own warnings
(:class:`~formationlab.errors.FormationlabWarning`, e.g. a scenario key that
has no effect) become one ``warning:`` line each, whatever the warning filters
of the caller say, and never stop the command:

============================================  ======  =========================================
cause                                         status  message
============================================  ======  =========================================
bad input (:class:`~formationlab.errors.      2       the problem and the fix
UserInputError`), a missing file
a file or folder that cannot be read or       2       the path and the reason ("permission
written (any ``OSError``: permission, disk            denied", "no space left on device",
full, a path under a regular file)                    "not a directory", ...)
an optional part that is not installed        2       the extra to install
Ctrl-C (SIGTERM)                              130     ``interrupted`` (and what was kept), not
                                              (143)   an ``error:``
============================================  ======  =========================================
"""

from __future__ import annotations

import functools
import os
import re
import subprocess
import sys
import unicodedata
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Annotated, Any, NoReturn, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from typer.core import TyperArgument, TyperCommand, TyperGroup, TyperOption

from ..errors import FormationlabWarning, UserInputError
from . import _signals
from ._options import number_message
from ._signals import interrupted_status

__all__ = [
    "FigureFormatOption",
    "app",
    "command",
    "describe_os_error",
    "err_console",
    "fail",
    "group",
    "printable",
    "warn",
]


class _Console(Console):
    """rich's console, which lets go of what it was writing when the write is interrupted
    (Ctrl-C, SIGTERM): rich keeps it in its buffer, and the next message (``interrupted
    ...``) printed it a second time."""

    def _check_buffer(self) -> None:
        try:
            super()._check_buffer()
        except BaseException:
            del self._buffer[:]
            raise


err_console = _Console(stderr=True)

F = TypeVar("F", bound=Callable[..., Any])

#: the ``--format`` option of the commands that write figures (read with
#: :func:`formationlab.io.figures.figure_formats`)
FigureFormatOption = Annotated[
    str,
    typer.Option(
        "--format",
        help="Figure formats, a comma-separated list of png, pdf and svg (pdf and svg: "
        "vector figures for LaTeX), e.g. png,pdf.",
    ),
]

#: exit status of a command stopped by Ctrl-C (128 + SIGINT, as shells report it); 143
#: (128 + SIGTERM) when a SIGTERM stopped it
INTERRUPTED = 130


def printable(message: str) -> str:
    """``message`` with its control characters (a NUL, an escape) written as escapes
    (``\\x00``): messages quote what a user gave, which must not reach a terminal raw."""
    return "".join(
        c if c in "\n\t" or unicodedata.category(c) != "Cc" else repr(c)[1:-1] for c in message
    )


def fail(message: str, code: int = 2) -> NoReturn:
    """Print ``error: message`` on standard error and exit with ``code`` (an interrupt's
    message alone, below).

    :data:`INTERRUPTED` becomes ``128 +`` the signal that stopped the command (143 for
    SIGTERM, :func:`._signals.interrupted_status`), and its message (``interrupted ...``,
    with what was kept) is printed as it is: a deliberate stop is not an error.
    """
    # escape: messages quote user input such as "[x, y]", which is not rich markup
    if code == INTERRUPTED:
        err_console.print(f"[bold yellow]{escape(message)}[/]", highlight=False, soft_wrap=True)
        raise typer.Exit(interrupted_status())
    err_console.print(
        f"[bold red]error:[/] {escape(printable(message))}", highlight=False, soft_wrap=True
    )
    raise typer.Exit(code)


def warn(message: str) -> None:
    """Print ``warning: message`` on standard error, once per command."""
    if message in _shown:
        return
    _shown.add(message)
    err_console.print(
        f"[bold yellow]warning:[/] {escape(printable(message))}", highlight=False, soft_wrap=True
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


def describe_os_error(exc: OSError) -> str:
    """One line naming the path of a failed read or write and the reason.

    ``"cannot write to runs/a: permission denied"``; the path is the folder
    of the file that failed when the file itself is a temporary one.
    """
    reason = (exc.strerror or str(exc) or type(exc).__name__).rstrip(".")
    reason = reason[:1].lower() + reason[1:]
    path = exc.filename
    if path is None:
        return f"input/output error: {reason}"
    path = os.fspath(path)
    name = os.path.basename(path)
    if name.startswith(".") and os.path.dirname(path):  # an atomic write's temporary file
        path = os.path.dirname(path)
    return f"cannot use {path}: {reason}"


def command(*args: Any, on: typer.Typer | None = None, **kwargs: Any) -> Callable[[F], F]:
    """``app.command`` that turns user errors into a message and an exit status (module doc).

    ``on``: the group to register on (a sub-group such as ``formationlab export``); default
    :data:`app`."""
    kwargs.setdefault("cls", _Command)

    def deco(fn: F) -> F:
        @functools.wraps(fn)
        def wrapper(*a: Any, **k: Any) -> Any:
            _signals.command_done(False)
            try:
                try:
                    with _warnings_as_lines():
                        out = fn(*a, **k)
                    _signals.command_done()
                    return out
                except UserInputError as exc:
                    fail(str(exc))
                except FileNotFoundError as exc:
                    fail(f"file not found: {exc.filename or exc}")
                except OSError as exc:
                    fail(describe_os_error(exc))
                except subprocess.CalledProcessError as exc:  # ffmpeg died (e.g. by Ctrl-C)
                    fail(f"{os.path.basename(str(exc.cmd[0]))} failed (exit status "
                         f"{exc.returncode})")  # fmt: skip
                except KeyboardInterrupt:
                    fail("interrupted", code=INTERRUPTED)
                finally:
                    _release_claims()
            except KeyboardInterrupt:  # as the claims were let go, or a message printed
                fail(_signals.AFTER_THE_WORK if _signals.is_done() else "interrupted", INTERRUPTED)

        (app if on is None else on).command(*args, **kwargs)(wrapper)
        return fn

    return deco


def _release_claims() -> None:
    """End the claims of the output folders the command wrote (:mod:`formationlab.io.claim`;
    loaded only by a command that claimed one)."""
    claim = sys.modules.get("formationlab.io.claim")
    if claim is not None:
        claim.release_claims()


class _Flag(TyperOption):
    """An on/off option: its help shows no value type (a flag takes no value)."""

    def display_type_rich(self, ctx: Any) -> str | None:
        return None


class _Argument(TyperArgument):
    """A positional argument: ``SCENARIO`` in the usage line (not ``{scenario}``)."""

    def _usage_display_name(self) -> str:
        name = (self.metavar or self.name or "").upper()
        if self.nargs != 1:
            name += "..."
        return name if self.required else f"[{name}]"


def _conventional(params: list[Any]) -> list[Any]:
    """Give typer's parameters the help display of :class:`_Flag` and :class:`_Argument`."""
    for p in params:
        if type(p) is TyperOption and p.is_flag:
            p.__class__ = _Flag
        elif type(p) is TyperArgument:
            p.__class__ = _Argument
    return params


#: a hyphen inside a word ("--from-study", "barrier-decentralized") and the character that
#: stands in for it while click wraps the help (U+2011, a hyphen that does not break)
_INNER_HYPHEN = re.compile(r"(?<=\w)-(?=\w)")
_KEPT_HYPHEN = "\u2011"


def _unbroken(text: str) -> str:
    return _INNER_HYPHEN.sub(_KEPT_HYPHEN, text)


#: the context and help formatter of typer's commands (click's own, or the copy of click
#: that recent typer versions carry)
_BaseContext: Any = TyperCommand.context_class


class _HelpFormatter(_BaseContext.formatter_class):  # type: ignore[name-defined]
    """click's help layout, wrapped at spaces only: a hyphenated word stays on one line."""

    def write_text(self, text: str) -> None:
        super().write_text(_unbroken(text))

    def write_dl(self, rows: Any, *args: Any, **kwargs: Any) -> None:
        super().write_dl([(term, _unbroken(text)) for term, text in rows], *args, **kwargs)

    def getvalue(self) -> str:
        return super().getvalue().replace(_KEPT_HYPHEN, "-")


class _Context(_BaseContext):  # type: ignore[misc,valid-type]
    formatter_class = _HelpFormatter


class _Command(TyperCommand):
    """typer's command with conventional help: ``SCENARIO`` in usage, no ``<bool>`` on flags.

    Its summary in the root help is its whole first line (wrapped, never cut off).
    """

    context_class = _Context

    def get_params(self, ctx: Any) -> list[Any]:
        return _conventional(super().get_params(ctx))

    def get_short_help_str(self, limit: int = 45) -> str:
        return (self.short_help or (self.help or "").strip().split("\n\n")[0]).replace("\n", " ")

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        try:
            return super().parse_args(ctx, list(args))  # type: ignore[no-any-return]
        except typer.BadParameter as exc:
            message = number_message(exc.param, args)
            if message is None:
                raise
            fail(message)


class _Group(TyperGroup):
    """The root command and its sub-groups, with the help display of :class:`_Command`."""

    context_class = _Context
    get_short_help_str = _Command.get_short_help_str  # (a sub-group listed in the root's help)

    def get_params(self, ctx: Any) -> list[Any]:
        return _conventional(super().get_params(ctx))


app = typer.Typer(
    name="formationlab",
    help="Multi-robot formation control: reproduce the paper, run scenarios, study outcomes.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # help as click writes it, not through rich: rich reads "[view]" in "formationlab[view]"
    # as markup and drops it, and cuts words in its narrow option tables ("barrier-decentral…");
    # click keeps the text as written and wraps it at whole words to the terminal's width
    rich_markup_mode=None,
    cls=_Group,
)


def group(name: str, help: str) -> typer.Typer:
    """A sub-group of commands (``formationlab NAME ...``) added to :data:`app`; register its
    commands with ``command(..., on=group)``."""
    sub = typer.Typer(name=name, help=help, no_args_is_help=True, cls=_Group)
    app.add_typer(sub, name=name)
    return sub


def _print_version(value: bool) -> None:
    if value:
        from ..resources import package_version

        typer.echo(f"formationlab {package_version()}")
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
