"""Exceptions and warnings of formationlab.

Everything a user can get wrong raises a subclass of :class:`UserInputError`
(itself a ``ValueError``) whose message names the problem and the fix. The
command line prints such messages without a traceback and exits non-zero.

An error about one parameter or one scenario key carries it in ``key``
(``"k_c"`` for a law's gain, ``"controller.k_c"`` once it is placed in a
scenario file), so callers find the line of a file without reading the message.

Things that are allowed but have no effect (a key of another law left in a
scenario) are :class:`FormationlabWarning` warnings; the command line prints
them as one line each.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "FolderBusyError",
    "FormationError",
    "FormationlabError",
    "FormationlabWarning",
    "IgnoredKeyWarning",
    "MissingExtraError",
    "ObstacleError",
    "OutputError",
    "OutputExistsError",
    "ParameterError",
    "ScenarioError",
    "UnknownNameError",
    "UserInputError",
    "ViewerWarning",
    "require_extra",
]


class FormationlabError(Exception):
    """Base class of formationlab's exceptions."""


class UserInputError(FormationlabError, ValueError):
    """Bad input from the user; the message says what was expected and what was given.

    Parameters
    ----------
    message : str
        What is wrong and how to fix it.
    key : str, optional
        The parameter or scenario key the error is about (``"k_c"``,
        ``"study.sweep.kA"``), or ``None``.
    """

    def __init__(self, message: str, *, key: str | None = None) -> None:
        super().__init__(message)
        self.key = key


class FormationError(UserInputError):
    """A formation or an initial state is not valid."""


class ParameterError(UserInputError):
    """A law's, integrator's or study's parameter is out of range."""


class UnknownNameError(ParameterError, KeyError):
    """A name that no registry entry has (a ``KeyError`` too, so registries are mappings)."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class ObstacleError(UserInputError):
    """An obstacle is not valid, or it overlaps a robot's start."""


class MissingExtraError(UserInputError, ImportError):
    """An optional part of formationlab is needed but not installed; the message names the
    extra to install (``pip install "formationlab[safety]"``) and ``extra`` holds its name."""

    def __init__(self, message: str, *, extra: str, key: str | None = None) -> None:
        super().__init__(message, key=key)
        self.extra = extra


def require_extra(extra: str, modules: tuple[str, ...], what: str) -> Any:
    """Import ``modules`` and return the first, or raise :class:`MissingExtraError` naming
    the extra ``extra`` to install. The one place that checks an optional dependency.

    ``what`` names what needs it, as the subject of "need" ("safety filters and
    obstacles").
    """
    import importlib

    loaded = []
    for name in modules:
        try:
            loaded.append(importlib.import_module(name))
        except ImportError:
            raise MissingExtraError(
                f"{what} need the optional part {extra!r}, which is not installed (no module "
                f'{name!r}): pip install "formationlab[{extra}]"',
                extra=extra,
            ) from None
    return loaded[0] if loaded else None


class ScenarioError(UserInputError):
    """A scenario file cannot be read or does not validate; ``key`` is the scenario key."""


class OutputExistsError(UserInputError):
    """An output folder already holds results and overwriting was not asked for."""


class FormationlabWarning(UserWarning):
    """Base class of formationlab's warnings."""


class IgnoredKeyWarning(FormationlabWarning):
    """A parameter that belongs to another law, integrator or model, so it has no effect."""


class ViewerWarning(FormationlabWarning):
    """The live viewer shows a stand-in for something it cannot step (the message says what)."""


class OutputError(UserInputError, OSError):
    """An output file or folder cannot be written (permission, disk full, a path under a file).

    Also an ``OSError``, so that code catching the writer's own errors still catches it;
    the message names the folder, the reason and what to do.
    """


class FolderBusyError(OutputError):
    """Another process is writing into the output folder (it holds the folder's claim,
    :mod:`formationlab.io.claim`)."""
