"""Where the episodes of a vectorised environment's formations start: a study's trials.

Formation ``b``'s episode ``e`` starts where trial ``e`` of a study with the formation's
seed ``s_b`` starts (:func:`formationlab.studies.sampling.trial_initial_states` and
:func:`~formationlab.studies.sampling.model_initial_states`). A study draws its trials a
seed block (:data:`~formationlab.studies.sampling.SEED_BLOCK` trials) at a time from one
generator; :class:`EpisodeStarts` keeps each formation's current block, so that a new
episode's start is a row of it and a formation draws again once every ``SEED_BLOCK``
episodes (an automatic reset without a draw per formation).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..formation.spec import Formation
from ..models import RobotModel
from ..studies.config import BoxInitial, GaussianInitial
from ..studies.sampling import SEED_BLOCK, model_initial_states, trial_initial_states

__all__ = ["EpisodeStarts"]


class EpisodeStarts:
    """The first states of ``B`` formations' episodes (module docstring).

    Parameters
    ----------
    formation, model
        The formation and its robots' model.
    initial : BoxInitial or GaussianInitial
        The scenario's ``[study] initial`` distribution; ``center`` ``(n, 2)`` its centre
        (Gaussian starts).
    B : int
        The formations.

    Attributes
    ----------
    block : ndarray of int, shape (B,)
        The seed block each formation holds (-1: none).
    """

    def __init__(
        self,
        formation: Formation,
        model: RobotModel,
        initial: BoxInitial | GaussianInitial,
        center: NDArray[np.float64] | None,
        B: int,
    ) -> None:
        self.formation, self.model, self.initial, self.center = formation, model, initial, center
        n = formation.n
        self._states = np.zeros((B, SEED_BLOCK, n, model.state_size()))
        self.block = np.full(B, -1, dtype=np.int64)

    def forget(self) -> None:
        """Drop the blocks held (the formations' seeds change)."""
        self.block[:] = -1

    def states(
        self, seeds: NDArray[np.int64], episodes: NDArray[np.int64], which: NDArray[np.intp]
    ) -> NDArray[np.float64]:
        """The first states ``(L, n, k)`` of episodes ``episodes[which]`` of formations
        ``which`` whose seeds are ``seeds[which]``."""
        f, model = self.formation, self.model
        e = episodes[which]
        block = e // SEED_BLOCK
        stale = self.block[which] != block
        for b, c in zip(which[stale], block[stale], strict=True):  # once per SEED_BLOCK episodes
            s, trials = int(seeds[b]), np.arange(c * SEED_BLOCK, (c + 1) * SEED_BLOCK)
            q0 = trial_initial_states(f, self.initial, s, trials, center=self.center)
            self._states[b] = model_initial_states(f, model, q0, s, trials)
            self.block[b] = c
        return self._states[which, e % SEED_BLOCK]
