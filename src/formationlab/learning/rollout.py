"""Batched rollouts: ``B`` formations stepped at once with explicit Euler under any field.

The field is a function of positions ``(..., n, 2) -> (..., n, 2)``: for training, the
learned law's own command (:func:`formationlab.controllers.policy.policy_control`, one
formula for the law and its training) for a whole generation of candidates at once; for
the comparison of docs/learning.md, any law's ``control``. The step is the one of the
study's Euler (``q <- q + dt u``). A rollout records the final positions, whether two
robots ever came closer than their contact distance ``a_ij`` (a study stops such a trial as
a collision; here the formation is frozen there), the control effort ``int sum_i |u_i|^2
dt`` and the peak speed ``max_t max_i |u_i|``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..formation.geometry import row_norms
from ..formation.spec import Formation
from ..validation import positive, whole

__all__ = ["Field", "Rollout", "rollout"]

#: a closed loop's velocity field: positions ``(..., n, 2)`` to velocities of that shape
Field = Callable[[NDArray[np.float64]], NDArray[np.float64]]


class Rollout(NamedTuple):
    """How ``B`` formations ended.

    Attributes
    ----------
    q : ndarray, shape (..., B, n, 2)
        Final positions.
    collided : ndarray of bool, shape (..., B)
        Two robots came closer than ``a_ij`` at some step (or a state was not finite).
    effort : ndarray, shape (..., B)
        ``int sum_i |u_i|^2 dt`` (Euler sum) until the end or the collision.
    peak_speed : ndarray, shape (..., B)
        ``max_t max_i |u_i|``.
    """

    q: NDArray[np.float64]
    collided: NDArray[np.bool_]
    effort: NDArray[np.float64]
    peak_speed: NDArray[np.float64]


def rollout(
    field: Field, formation: Formation, q0: NDArray[np.float64], *, dt: float, steps: int
) -> Rollout:
    """Step ``q0`` ``(..., B, n, 2)`` for ``steps`` Euler steps of ``dt`` under ``field``.

    A formation that collides is frozen where it collided (as a study stops it).
    """
    dt = positive(dt, "dt")
    steps = whole(steps, "steps")
    q = np.array(q0, dtype=float)
    a, b = np.triu_indices(formation.n, 1)
    contact = formation.contact_matrix[a, b]
    collided = np.zeros(q.shape[:-2], dtype=bool)
    effort = np.zeros(q.shape[:-2])
    peak = np.zeros(q.shape[:-2])
    for _ in range(steps):
        u = field(q)
        u[collided] = 0.0
        speed = row_norms(u)
        effort += dt * np.sum(speed * speed, axis=-1)
        peak = np.maximum(peak, speed.max(axis=-1))
        q += dt * u
        gap = row_norms(q[..., b, :] - q[..., a, :]) - contact
        collided |= (gap <= 0.0).any(axis=-1) | ~np.isfinite(q).all(axis=(-2, -1))
    return Rollout(q=q, collided=collided, effort=effort, peak_speed=peak)
