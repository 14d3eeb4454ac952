"""Batched rollouts of the learned law: ``B`` formations stepped at once with explicit Euler.

The command is the law's own (:func:`formationlab.controllers.policy.policy_control`, one
formula for the law and its training); the step is the one of the study's Euler
(``q <- q + dt u``), at a coarser ``dt`` for speed. A rollout records the final positions
and whether two robots ever came closer than their contact distance ``a_ij`` (a study
stops such a trial as a collision).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..controllers.network import Network
from ..controllers.policy import Neighbourhoods, policy_control
from ..formation.geometry import row_norms
from ..formation.spec import Formation
from ..validation import positive, whole

__all__ = ["Rollout", "rollout"]


class Rollout(NamedTuple):
    """How ``B`` formations ended.

    Attributes
    ----------
    q : ndarray, shape (..., B, n, 2)
        Final positions.
    collided : ndarray of bool, shape (..., B)
        Two robots came closer than ``a_ij`` at some step.
    """

    q: NDArray[np.float64]
    collided: NDArray[np.bool_]


def rollout(
    network: Network,
    formation: Formation,
    hoods: Neighbourhoods,
    q0: NDArray[np.float64],
    *,
    dt: float,
    steps: int,
) -> Rollout:
    """Step ``q0`` ``(B, n, 2)`` for ``steps`` Euler steps of ``dt`` under the learned law.

    A formation that collides is frozen where it collided (as a study stops it). With a
    stack of ``P`` networks (:class:`~formationlab.controllers.network.Network`), ``q0``
    is ``(P, B, n, 2)``: each candidate steps its own copy of the starts.
    """
    dt = positive(dt, "dt")
    steps = whole(steps, "steps")
    q = np.array(q0, dtype=float)
    a, b = np.triu_indices(formation.n, 1)
    contact = formation.contact_matrix[a, b]
    collided = np.zeros(q.shape[:-2], dtype=bool)
    for _ in range(steps):
        u = policy_control(network, hoods, q)
        u[collided] = 0.0
        q += dt * u
        gap = row_norms(q[..., b, :] - q[..., a, :]) - contact
        collided |= (gap <= 0.0).any(axis=-1) | ~np.isfinite(q).all(axis=(-2, -1))
    return Rollout(q=q, collided=collided)
