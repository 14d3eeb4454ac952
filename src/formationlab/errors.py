"""Exceptions of formationlab.

Everything a user can get wrong raises a subclass of :class:`UserInputError`
(itself a ``ValueError``) whose message names the problem and the fix. The
command line prints such messages without a traceback and exits non-zero.
"""

from __future__ import annotations

__all__ = [
    "FormationError",
    "FormationlabError",
    "OutputError",
    "OutputExistsError",
    "ParameterError",
    "ScenarioError",
    "UserInputError",
]


class FormationlabError(Exception):
    """Base class of formationlab's exceptions."""


class UserInputError(FormationlabError, ValueError):
    """Bad input from the user; the message says what was expected and what was given."""


class FormationError(UserInputError):
    """A formation or an initial state is not valid."""


class ParameterError(UserInputError):
    """A law's, integrator's or study's parameter is out of range."""


class ScenarioError(UserInputError):
    """A scenario file cannot be read or does not validate."""


class OutputExistsError(UserInputError):
    """An output folder already holds results and overwriting was not asked for."""


class OutputError(UserInputError, OSError):
    """An output file or folder cannot be written (permission, disk full, a path under a file).

    Also an ``OSError``, so that code catching the writer's own errors still catches it;
    the message names the folder, the reason and what to do.
    """
