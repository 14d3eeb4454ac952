"""The random starts of an equilibria search settled block by block: kept, and resumable.

:func:`settle_in_blocks` settles the starts ``(B, n, d)`` in blocks of :data:`BLOCK` with
:func:`~formationlab.equilibria.search.settle` (each trial's run is its own: a block's end
states do not depend on the other blocks), hands every settled block to a store and takes
the blocks the store already holds instead of settling them again. A search interrupted
(Ctrl-C) keeps the blocks settled so far, and ``formationlab equilibria --resume`` settles
only the rest (the store on disk is :class:`formationlab.io.equilibria.SettledFolder`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..controllers import Law
from ..dynamics import System
from ..formation.spec import Formation
from ..integrators import FixedStepIntegrator
from .search import settle

__all__ = ["BLOCK", "SettledStore", "settle_in_blocks"]

#: starts settled per block (a block is the unit that an interrupted search keeps)
BLOCK = 32


class SettledStore(Protocol):
    """Where settled blocks are kept: ``load(k)`` gives block ``k``'s ``(q_final, outcome)``
    or None, ``save(k, q_final, outcome)`` keeps it."""

    def load(self, k: int) -> tuple[NDArray[np.float64], NDArray[np.str_]] | None: ...

    def save(self, k: int, q: NDArray[np.float64], outcome: NDArray[np.str_]) -> None: ...


def settle_in_blocks(
    formation: Formation,
    law: Law,
    q0: NDArray[np.float64],
    *,
    duration: float,
    integrator: FixedStepIntegrator,
    system: System | None = None,
    store: SettledStore | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.str_]]:
    """End states ``(B, n, d)`` and outcomes ``(B,)`` of the starts ``q0`` ``(B, n, d)``.

    Blocks of :data:`BLOCK` starts, in order; a block ``store`` holds is taken from it, the
    others are settled (:func:`~formationlab.equilibria.search.settle`) and saved to it.
    ``progress(settled, total)`` is called after each block (and once before the first).
    """
    B = len(q0)
    qs: list[NDArray[np.float64]] = []
    outs: list[NDArray[np.str_]] = []
    done = 0
    if progress is not None:
        progress(0, B)
    for k, lo in enumerate(range(0, B, BLOCK)):
        part = q0[lo : lo + BLOCK]
        kept = store.load(k) if store is not None else None
        if kept is None or len(kept[0]) != len(part):
            res = settle(
                formation, law, part, duration=duration, integrator=integrator, system=system
            )
            kept = (np.asarray(res.q_final, dtype=float), np.asarray(res.outcome))
            if store is not None:
                store.save(k, *kept)
        qs.append(kept[0])
        outs.append(kept[1])
        done += len(part)
        if progress is not None:
            progress(done, B)
    if not qs:
        return np.zeros((0, *q0.shape[1:])), np.zeros(0, dtype=str)
    return np.concatenate(qs), np.concatenate(outs)
