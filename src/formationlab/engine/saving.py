"""The saving stage of the compiled loop: the states a run keeps along the way.

A run that keeps its path (``simulate``, the paper's scans) saves, trial by trial, every
``every``-th step's state with the rates it was left with, and the state each trial ends
at (the last step, or the last accepted state before a rejected step), in the robots' own
numbers (``perm``: the robot each number of the run is, or empty when they are the same).
The stepping driver (:func:`formationlab.integrators.drive`) saves the same rows.

A batch that keeps only how each trial ended (a study) has the saving :func:`no_saving`
(``every`` 0, no rows): the loop then writes each trial's last state and rates to its
outputs. Both are one type for the compiler, so a single run and a batch of the same
layout share one compiled loop (compiled once).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["Saving", "no_saving", "saved_rows", "saving"]


class Saving(NamedTuple):
    """Room for the saved rows of ``B`` trials (:func:`saving`)."""

    every: int  #: save every this many steps (0: none saved, :func:`no_saving`)
    k: NDArray[np.int64]  #: (B, rows) the step of each saved row
    x: NDArray[np.float64]  #: (B, rows, n, k) its state
    v: NDArray[np.float64]  #: (B, rows, n, k) the rates it was left with
    rows: NDArray[np.int64]  #: (B,) rows saved
    perm: NDArray[np.int32]  #: (n,) or (0,)


def saved_rows(n_steps: int, every: int) -> int:
    """States a run of ``n_steps`` keeps: every ``every``-th step and the last one.

    A run that ends early keeps its last accepted state in the room of the final one.
    """
    return n_steps // every + 1 + (1 if n_steps % every else 0)


def saving(B: int, n: int, k: int, n_steps: int, every: int, perm: NDArray | None = None) -> Saving:
    """Room for ``B`` trials of ``n`` robots with ``k`` numbers each, ``n_steps`` steps."""
    rows = saved_rows(n_steps, every)
    return Saving(
        every=int(every), k=np.zeros((B, rows), np.int64), x=np.zeros((B, rows, n, k)),
        v=np.zeros((B, rows, n, k)), rows=np.zeros(B, np.int64),
        perm=np.zeros(0, np.int32) if perm is None else np.ascontiguousarray(perm, np.int32),
    )  # fmt: skip


def no_saving() -> Saving:
    """The saving of a run that keeps only how each trial ended (module docstring)."""
    return Saving(
        every=0, k=np.zeros((0, 0), np.int64), x=np.zeros((0, 0, 0, 0)),
        v=np.zeros((0, 0, 0, 0)), rows=np.zeros(0, np.int64), perm=np.zeros(0, np.int32),
    )  # fmt: skip


@njit(cache=True, error_model="numpy", nogil=True)
def save(sv, x, f, b, g, k):
    """Save slot ``b``'s state of ``x`` ``(n, k, C)`` and its rates ``f`` at step ``k`` as the
    next row of trial ``g``."""
    row = sv.rows[g]
    sv.k[g, row] = k
    n, kk = x.shape[0], x.shape[1]
    for i in range(n):
        r = sv.perm[i] if sv.perm.size else i
        for d in range(kk):
            sv.x[g, row, r, d] = x[i, d, b]
            sv.v[g, row, r, d] = f[i, d, b]
    sv.rows[g] = row + 1
