"""The reward of a training episode: how far from the desired formation it ended.

``reward = -(e_d + e_o + c)``, per formation, with

* ``e_d``: the mean over edges of ``|log(r_ij / d_ij)|`` at the end (0 when every distance
  is met; ``log`` so that a shrunken and a stretched edge count alike and a far start does
  not dominate),
* ``e_o``: the fraction of restricted triples turned the wrong way at the end
  (:func:`formationlab.outcomes.analysis.turned_wrong`: 1 for the mirror image, 0 for the
  desired orientation),
* ``c``: 1 if two robots touched (a study counts the trial as a collision), else 0.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..formation.spec import Formation
from ..outcomes.analysis import distance_errors, turned_wrong
from .rollout import Rollout

__all__ = ["episode_reward"]


def episode_reward(formation: Formation, ended: Rollout) -> NDArray[np.float64]:
    """``-(e_d + e_o + c)`` of every formation of a rollout (module docstring); ``(B,)``."""
    r = distance_errors(formation, ended.q) + formation.distances
    e_d = np.mean(np.abs(np.log(np.maximum(r, 1e-12) / formation.distances)), axis=-1)
    wrong = turned_wrong(formation, ended.q)
    e_o = wrong.mean(axis=-1) if wrong.shape[-1] else np.zeros(len(e_d))
    penalty = e_d + e_o + ended.collided
    return -np.where(np.isfinite(penalty), penalty, 10.0)
