"""Reading scenario files (TOML); validation lives in :mod:`formationlab.scenario`."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import ScenarioError
from ..scenario.parse import Scenario, parse_scenario

__all__ = ["load_scenario"]


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
