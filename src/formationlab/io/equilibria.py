"""Files of the ``equilibria`` command: ``equilibria.json`` out, a study's end states in.

``equilibria.json`` holds ``{"equilibria": [...], ...}`` with one entry per
distinct equilibrium (:meth:`formationlab.equilibria.Catalogue.to_dict`),
written atomically. :class:`SettledFolder` keeps the random starts' settled blocks in
``DIR/settled/<fingerprint>/`` while the search runs, for ``--resume``.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import ParameterError, ScenarioError
from .files import KeptFolder, atomic_path, atomic_write_json

__all__ = ["SettledFolder", "read_study_end_states", "write_equilibria"]


class SettledFolder(KeptFolder):
    """Settled blocks of one search's random starts under ``DIR/settled/<fingerprint>/``
    (a :class:`formationlab.equilibria.blocks.SettledStore`), each ``block-K.npz`` written
    atomically: a block is there whole or not at all.

    Parameters
    ----------
    out : path-like
        The search's output folder.
    identity : dict
        JSON-ready: what decides the starts and how they settle (the scenario's text, the
        ``[equilibria]`` settings); its fingerprint names the folder, so blocks of another
        search are never taken.
    """

    def __init__(self, out: str | os.PathLike[str], identity: dict[str, Any]) -> None:
        text = json.dumps(identity, sort_keys=True, default=str)
        super().__init__(out, "settled", identity, hashlib.sha256(text.encode()).hexdigest()[:16])

    def check_resumable(self) -> int:
        """How many settled starts are kept for this search.

        Raises
        ------
        ParameterError
            The folder holds no blocks of this search (none, or another search's).
        """
        if not (self.folder / "manifest.json").exists():
            other = any(self.root.glob("*/manifest.json"))
            raise ParameterError(
                f"nothing to resume in {self.root.parent}: it holds "
                + ("the settled starts of another search (another scenario or [equilibria] "
                   "settings); resume with the same ones, or start afresh with --force"
                   if other else "no settled starts; run without --resume")
            )  # fmt: skip
        return sum(len(self._read(p)[1]) for p in sorted(self.folder.glob("block-*.npz")))

    def _path(self, k: int) -> Path:
        return self.folder / f"block-{k:06d}.npz"

    def _read(self, path: Path) -> tuple[NDArray[np.float64], NDArray[np.str_]]:
        try:
            with np.load(path, allow_pickle=False) as f:
                return np.asarray(f["q"], dtype=float), np.asarray(f["outcome"])
        except (OSError, ValueError, KeyError) as exc:
            raise ParameterError(
                f"cannot read the settled starts {path} ({exc}): delete it and resume to "
                "settle them again"
            ) from None

    def load(self, k: int) -> tuple[NDArray[np.float64], NDArray[np.str_]] | None:
        """Block ``k``'s end states and outcomes, or None if it was not settled."""
        path = self._path(k)
        return self._read(path) if path.exists() else None

    def save(self, k: int, q: NDArray[np.float64], outcome: NDArray[np.str_]) -> None:
        """Keep block ``k``."""
        with atomic_path(self._path(k)) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, q=np.asarray(q, dtype=float), outcome=np.asarray(outcome, dtype=str))

    def settled(self) -> int:
        """How many starts the kept blocks hold."""
        if not self.folder.is_dir():
            return 0
        return sum(len(self._read(p)[1]) for p in self.folder.glob("block-*.npz"))


def write_equilibria(data: dict[str, Any], target: str | os.PathLike[str]) -> Path:
    """Write the catalogue ``data`` (a dict with key ``"equilibria"``) as JSON, atomically."""
    if "equilibria" not in data:
        raise ValueError("an equilibria file needs the key 'equilibria'")
    return atomic_write_json(target, data)


def read_study_end_states(
    study: str | os.PathLike[str],
    n: int,
    law: str,
    parameters: dict[str, float] | None = None,
    dim: int = 2,
) -> tuple[NDArray[np.float64], NDArray[np.str_]]:
    """Final positions and outcomes of a study's trials of ``law``.

    Parameters
    ----------
    study : path-like
        A study's output folder (holding ``trials.parquet``) or the file itself.
    n : int
        Number of robots: columns ``x1, y1, ..., xn, yn`` (1-based) must exist
        (and ``z1, ..., zn`` for a formation in space, ``dim = 3``).
    law : str
        Only rows whose ``law`` column equals this name are read.
    parameters : dict, optional
        The law's parameters (e.g. ``{"k_a": 3.0}``). A study that swept one of
        them has a column of that name; only rows at this value (or NaN, not
        applicable) are read, so that the end states belong to the law refined.
    dim : int
        The formation's space: 2 (the plane) or 3.

    Returns
    -------
    q : ndarray, shape (B, n, dim)
    outcome : ndarray of str, shape (B,)

    Raises
    ------
    ScenarioError
        The file is missing, lacks columns, or holds no trial of ``law``.
    """
    import pandas as pd

    path = Path(study)
    if path.is_dir():
        path = path / "trials.parquet"
    if not path.exists():
        raise ScenarioError(f"no study results at {path}; run `formationlab study` first")
    try:
        frame = pd.read_parquet(path)
    except (OSError, ValueError, ImportError) as exc:  # pyarrow's errors are ValueErrors
        reason = getattr(exc, "strerror", None) or str(exc).split("\n")[0]
        raise ScenarioError(f"cannot read {path} as a study's trials table: {reason}") from None
    axes = "xyz"[:dim]
    need = ["outcome", *(f"{c}{i}" for i in range(1, n + 1) for c in axes)]
    missing = [c for c in need if c not in frame.columns]
    if missing:
        raise ScenarioError(
            f"{path} lacks the columns {', '.join(missing[:4])}: is it a study of "
            f"{n} robots written by `formationlab study`?"
        )
    if "law" in frame.columns:
        frame = frame[frame["law"] == law]
    if frame.empty:
        raise ScenarioError(
            f"{path} holds no trial of the law {law!r}; use a study that ran it, "
            "or leave out --from-study to use random starts"
        )
    for key, value in (parameters or {}).items():
        if key in frame.columns and key not in ("law", "outcome"):
            column = frame[key].to_numpy(dtype=float)
            keep = np.isnan(column) | np.isclose(column, float(value), rtol=1e-12, atol=0.0)
            if not keep.any():
                swept = ", ".join(f"{v:g}" for v in np.unique(column[~np.isnan(column)]))
                raise ScenarioError(
                    f"{path}: the study ran {law!r} at {key} = {swept}, not at the "
                    f"scenario's {key} = {float(value):g}; set {key} to one of those"
                )
            frame = frame[keep]
    columns = [[f"{c}{i}" for c in axes] for i in range(1, n + 1)]
    q = np.stack([frame[c].to_numpy(dtype=float) for c in columns], axis=1)
    return q, frame["outcome"].to_numpy(dtype=str)
