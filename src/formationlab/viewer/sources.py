"""Open what the viewer shows: a scenario (a file or a :class:`~formationlab.scenario.Scenario`)
for a live run, or the output folder of ``formationlab run`` for a replay.

Files are read through :mod:`formationlab.io` only.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import UserInputError
from ..io.netcdf import load_trajectory
from ..io.scenario import resolve_scenario
from ..scenario.parse import Scenario
from .replay import ReplaySession
from .session import LiveSession

__all__ = ["open_session"]


def open_session(
    target: Scenario | str | os.PathLike[str],
    *,
    replay: bool = False,
    seed: int | None = None,
) -> LiveSession | ReplaySession:
    """A live session of a scenario, or a replay of a run folder.

    Parameters
    ----------
    target : Scenario, path or str
        A scenario, a scenario file or its TOML text
        (:func:`formationlab.io.scenario.resolve_scenario`), or a folder written by
        ``formationlab run`` (holding ``trajectory.nc``), which is replayed.
    replay : bool
        Insist on a replay (``target`` must then be a run folder).
    seed : int, optional
        Seed of the live session's random perturbations.

    Raises
    ------
    UserInputError
        The file or folder cannot be read or is not a scenario / run.
    """
    if isinstance(target, Scenario):
        if replay:
            raise UserInputError("a replay needs the folder of `formationlab run`, not a scenario")
        return LiveSession(target, seed=seed)
    path = Path(target)
    if not (replay or os.path.isdir(path)):  # False for TOML text, not an OSError
        return LiveSession(resolve_scenario(target), seed=seed)
    nc = path / "trajectory.nc"
    if not nc.is_file():
        raise UserInputError(
            f"{path} holds no trajectory.nc; give a scenario file, or the --out folder of "
            "`formationlab run`"
        )
    try:
        ds = load_trajectory(nc)
    except (OSError, ValueError) as exc:
        raise UserInputError(f"cannot read {nc} as netCDF: {exc}") from None
    return ReplaySession(ds, name=path.name)
