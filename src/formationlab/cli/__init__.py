"""The ``formationlab`` command line (typer).

Each sub-module of this package registers its commands on :data:`app`; they
are discovered at start-up, so a new command is a new module. Errors a user
can cause (:class:`~formationlab.errors.UserInputError`, missing files) are
printed as one clear message on standard error with exit status 2, never as a
traceback. A command imports the modules that do its work when it runs, inside its function
(start-up time: ``formationlab --help`` and a refused file answer before numba, matplotlib
or xarray load); that is the one place where late imports are the rule.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys

from . import _signals
from ._app import app, fail

__all__ = ["app", "fail", "main"]


def _load_commands() -> None:
    for mod in pkgutil.iter_modules(__path__):
        if not mod.name.startswith("_"):
            importlib.import_module(f"{__name__}.{mod.name}")


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``formationlab`` console script (``argv``: the arguments, when
    called from Python; then the signal handlers in place before are restored at the end)."""
    _signals.install()
    try:
        try:  # (inside a command, its own handling says what was kept)
            _load_commands()
            app(args=argv if argv is not None else sys.argv[1:], prog_name="formationlab")
        except KeyboardInterrupt:  # loading the commands, reading the arguments, or after
            _signals.exit_interrupted()
        raise SystemExit(0)
    except SystemExit as exc:  # (a signal that came as the command ended is said too)
        raise SystemExit(_signals.ended(exc.code, process=argv is None)) from None
