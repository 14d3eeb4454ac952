"""What a safety filter returns: the filtered command, a status per trial and the active set.

A filter never hands back a silent zero command: every call reports, per trial,
whether the command passed unchanged, was solved, had to be relaxed (the state
was already inside an unsafe set) or fell back (the solver failed), together
with the constraints that hold with equality at the returned command.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

__all__ = ["FilterResult", "FilterStatus", "unchanged"]


class FilterStatus(IntEnum):
    """Outcome of one filter call for one trial (worst over its robots for the decentralized one).

    ``UNCHANGED``: no constraint was violated by the command; it is returned bit for bit.
    ``SOLVED``: the QP was solved; the command changed minimally.
    ``RELAXED``: the constraints were infeasible because some barrier ``h`` was already
    negative (the state is inside an unsafe set); those constraints were relaxed from
    ``h_dot >= -gamma h^3`` to ``h_dot >= 0`` ("do not get any closer"), which the zero
    command satisfies, and the relaxed QP was solved.
    ``FALLBACK``: the centralized solver failed on a problem the decentralized filter can
    solve; the decentralized solution is returned (it is feasible for the centralized
    constraints, see ``docs/safety.md``).
    ``FAILED``: no feasible command was found even for the relaxed problem (numerical
    trouble only: the zero command is feasible for it); the robots concerned get the zero
    command, flagged by this status.
    """

    UNCHANGED = 0
    SOLVED = 1
    RELAXED = 2
    FALLBACK = 3
    FAILED = 4


@dataclass(frozen=True, kw_only=True, eq=False)
class FilterResult:
    """The output of :meth:`formationlab.safety.SafetyFilter.apply` and of the filters.

    Parameters
    ----------
    u : ndarray, shape (..., n, 2)
        The filtered command.
    status : ndarray of int8, shape (...)
        A :class:`FilterStatus` per trial.
    active : ndarray of bool, shape (..., n)
        Robots with at least one constraint holding with equality at ``u`` (only robots
        whose command was changed are marked).
    active_pairs : ndarray of int, shape (k, 3)
        ``(trial, i, j)``, 0-based with ``i < j``, of the pair constraints that hold with
        equality; ``trial`` indexes the flattened batch axes (0 for an unbatched call).
    active_obstacles : ndarray of int, shape (k, 3)
        ``(trial, robot, obstacle)``, 0-based, of the obstacle constraints holding with
        equality.
    message : str
        A one-line summary for people.
    """

    u: NDArray[np.float64]
    status: NDArray[np.int8]
    active: NDArray[np.bool_]
    active_pairs: NDArray[np.int64]
    active_obstacles: NDArray[np.int64]
    message: str = ""

    @property
    def ok(self) -> bool:
        """Whether every trial's constraints held as posed (``UNCHANGED`` or ``SOLVED``)."""
        return bool(np.all(self.status <= FilterStatus.SOLVED))

    @property
    def worst(self) -> FilterStatus:
        """The worst status over all trials."""
        return FilterStatus(int(np.max(self.status)) if self.status.size else 0)


def summarise(status: NDArray[np.int8]) -> str:
    """``"2 solved, 1 relaxed"``-style count of the statuses of a batch."""
    values, counts = np.unique(np.asarray(status).ravel(), return_counts=True)
    pairs = zip(values, counts, strict=True)
    parts = [f"{c} {FilterStatus(int(v)).name.lower()}" for v, c in pairs]
    return ", ".join(parts) if parts else "no trials"


def unchanged(u_hat: NDArray[np.float64]) -> FilterResult:
    """The result of a filter that changes nothing: ``u_hat`` copied, status ``UNCHANGED``."""
    u_hat = np.asarray(u_hat, dtype=float)
    return FilterResult(
        u=u_hat.copy(),
        status=np.zeros(u_hat.shape[:-2], np.int8),
        active=np.zeros(u_hat.shape[:-1], bool),
        active_pairs=np.zeros((0, 3), np.int64),
        active_obstacles=np.zeros((0, 3), np.int64),
        message="no filter",
    )
