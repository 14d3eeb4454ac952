"""What a live session stepped: its states, thinned past a budget, and read back as
times, positions, V and the per-edge errors.

:class:`StateHistory` keeps each state with the closed loop in force when it was stepped,
so that ``V`` and the errors read back are that loop's own (a change of law mid-run
changes what V is). It keeps every state until :data:`HISTORY_MAX` samples or
:data:`HISTORY_BYTES`; then every other one is dropped, and every other state offered is
kept after, so that the history always spans the whole run at a coarser step.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..dynamics import System
from .frames import History, edge_errors

__all__ = ["HISTORY_BYTES", "HISTORY_MAX", "StateHistory"]

#: Most samples a history keeps before it thins.
HISTORY_MAX = 100_000
#: Most bytes of states a history keeps before it thins (a sample is a state ``(n, k)``).
HISTORY_BYTES = 256 * 1024**2


class StateHistory:
    """The states a live session stepped since its last reset (module docstring)."""

    def __init__(self) -> None:
        self.samples: list[tuple[float, NDArray[np.float64], System]] = []
        self.clear()

    def clear(self) -> None:
        self.samples.clear()
        self._thin = 1  # every _thin-th state offered is kept (doubles at each thinning)
        self._offered = 0

    def __len__(self) -> int:
        return len(self.samples)

    def record(self, t: float, x: NDArray[np.float64], system: System) -> None:
        """Offer the state ``x`` ``(n, k)`` at time ``t``, stepped by ``system``."""
        self._offered += 1
        if (self._offered - 1) % self._thin:
            return
        if len(self.samples) >= HISTORY_MAX or (len(self.samples) + 1) * x.nbytes > HISTORY_BYTES:
            del self.samples[1::2]
            self._thin *= 2
        self.samples.append((float(t), np.array(x, dtype=float), system))

    def read(self) -> History:
        """Times ``(T,)``, positions ``(T, n, d)`` (``d`` the formation's dimension), ``V``
        ``(T,)`` (eq. 15 for the paper's law, with the obstacles' repulsion) and the per-edge
        errors ``(T, m)`` of the states kept, each by the closed loop in force when it was
        stepped."""
        samples = self.samples
        t = np.array([s[0] for s in samples])
        if not samples:
            return History(t=t, positions=np.zeros((0, 0, 2)), V=t.copy(), errors=t[:, None])
        formation = samples[0][2].formation
        n, m = formation.n, len(formation.edges)
        q, V, err = np.zeros((len(t), n, formation.dim)), np.zeros(len(t)), np.zeros((len(t), m))
        start = 0
        while start < len(t):  # runs of states stepped under one closed loop
            system = samples[start][2]
            stop = start + 1
            while stop < len(t) and samples[stop][2] is system:
                stop += 1
            x = np.array([s[1] for s in samples[start:stop]])
            q[start:stop] = system.positions(x)
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                V[start:stop] = system.potential(x)
                err[start:stop] = edge_errors(formation, system.model.points(x))
            start = stop
        return History(t=t, positions=q, V=V, errors=err)
