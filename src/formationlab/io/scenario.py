"""Reading scenario files (TOML); validation lives in :mod:`formationlab.scenario`."""

from __future__ import annotations

import os
import re
import tomllib
from pathlib import Path

from ..controllers import file_keys
from ..errors import ScenarioError
from ..scenario.parse import Scenario, parse_scenario
from ..validation import line_of
from .files import atomic_write_bytes, atomic_write_text

__all__ = ["load_scenario", "resolve_scenario", "write_scenario"]


def load_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Read and validate the scenario file at ``path``.

    Parameters
    ----------
    path : path-like
        A TOML file; see ``docs/scenarios.md`` for its keys.

    Returns
    -------
    Scenario
        With ``text`` the file's text as read, ``source`` the path, and ``name``
        the file's stem unless the file sets ``name``.

    Raises
    ------
    ScenarioError
        The file is missing, unreadable, not UTF-8, not valid TOML (the message
        gives the line), or does not validate (the message names the key).
    """
    p = Path(path)
    if not p.exists():
        raise ScenarioError(f"scenario file {p} does not exist; check the path")
    if p.is_dir():
        raise ScenarioError(f"{p} is a folder, not a scenario file; give a .toml file")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise ScenarioError(f"cannot read scenario file {p}: {exc.strerror}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ScenarioError(
            f"{p}: not a UTF-8 text file (byte {exc.start}); scenario files are TOML text"
        ) from None
    return parse_scenario(text, source=str(p))


def resolve_scenario(scenario: Scenario | str | os.PathLike[str]) -> Scenario:
    """A scenario from what a person gives: a :class:`Scenario`, a path or TOML text.

    The one reading of a scenario argument, for ``formationlab.envs.parallel_env`` and
    ``formationlab.Viewer`` alike.

    Parameters
    ----------
    scenario : Scenario, path-like or str
        A scenario (returned as it is); a ``pathlib.Path`` (or other path-like), read with
        :func:`load_scenario`; a ``str`` naming a file, read the same way; any other
        ``str``, taken as the TOML text of a scenario (``parse_scenario``).

    Raises
    ------
    ScenarioError
        The file cannot be read or does not validate; a ``str`` that names no file and is
        not TOML (the message says both were tried); any other type.
    """
    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, os.PathLike):
        return load_scenario(scenario)
    if not isinstance(scenario, str):
        raise ScenarioError(
            "a scenario is a Scenario, the path of a scenario file (str or pathlib.Path) or a "
            f"scenario's TOML text, got {type(scenario).__name__}"
        )
    if _names_file(scenario):
        return load_scenario(scenario)
    try:
        tomllib.loads(scenario)
    except tomllib.TOMLDecodeError as exc:
        shown = scenario if len(scenario) <= 60 else scenario[:57] + "..."
        raise ScenarioError(
            f"{shown!r} is neither a scenario file (no file has that path) nor a scenario's "
            f"TOML text ({exc}); give the path of an existing .toml file, or TOML text"
        ) from None
    except RecursionError:  # nested thousands deep: parse_scenario says where
        pass
    return parse_scenario(scenario)


def _names_file(text: str) -> bool:
    """Whether ``text`` is the path of an existing file (False for text no path can be)."""
    if "\n" in text or "\0" in text:
        return False
    try:
        return Path(text).is_file()
    except (OSError, ValueError):  # a name too long for the file system
        return False


def write_scenario(folder: str | os.PathLike[str], sc: Scenario) -> list[str]:
    """Write ``sc`` as ``folder/scenario.toml`` so that the folder runs again as it is.

    Each file the law reads (:func:`~formationlab.controllers.base.file_keys`: the learned
    law's ``parameters``) is copied beside it, and its key in the copy of the scenario names
    the copy (a path relative to the scenario file would not be found from the output
    folder). The rest of the text is the scenario's own, comments included. Returns the
    names written, ``scenario.toml`` last.
    """
    folder = Path(folder)
    text, written = sc.text, []
    for key in file_keys(sc.law):
        source = Path(getattr(sc.law, key))
        if not source.is_file():  # (a law built from memory names no file)
            continue
        atomic_write_bytes(folder / source.name, source.read_bytes())
        text = _with_string(text, f"controller.{key}", source.name)
        written.append(source.name)
    atomic_write_text(folder / "scenario.toml", text)
    return [*written, "scenario.toml"]


def _with_string(text: str, key: str, value: str) -> str:
    """``text`` with the string value of the dotted ``key`` (on its own line) set to
    ``value``; unchanged where the key is not written as ``name = "..."`` on one line."""
    line = line_of(text, key)
    lines = text.splitlines(keepends=True)
    if line is None:
        return text
    name = re.escape(key.rsplit(".", 1)[-1])
    pattern = re.compile(rf"""^(\s*{name}\s*=\s*)("[^"]*"|'[^']*')""")
    new, count = pattern.subn(lambda m: m.group(1) + _toml_string(value), lines[line - 1])
    if count:
        lines[line - 1] = new
    return "".join(lines)


def _toml_string(value: str) -> str:
    """``value`` as a TOML basic string."""
    return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
