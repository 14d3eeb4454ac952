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

__all__ = [
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
    "require",
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


class MissingExtraError(ParameterError, ImportError):
    """A part of the package that needs an optional dependency that is not installed."""


def require(module: str, extra: str, what: str) -> object:
    """Import ``module`` or raise a :class:`MissingExtraError` that names the extra to install.

    ``what`` says what needs it (``"the safety filters' QP solver"``).
    """
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(
            f"{what} needs the optional package {module!r}: install it with "
            f'pip install "formationlab[{extra}]"'
        ) from None
