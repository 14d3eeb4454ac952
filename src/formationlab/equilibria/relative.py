"""Relative equilibria: the rigid motion of a shape, and the surfaces it slides on.

Helpers of :func:`formationlab.equilibria.refine` with ``moving=True``: the rigid
field ``v + omega k x (q_i - q_bar)`` solved for beside the shape, its first guess,
and which subsets of the surfaces near a moving end state to try (a drifting
formation stepped by explicit Euler chatters on several at once, and several
relative equilibria slide on subsets of them: ``docs/drifting.md``).
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
from numpy.typing import NDArray

from ..controllers import Law
from ..formation.spec import Formation

__all__ = ["MAX_NEAR", "all_subsets", "attracts", "rigid_field", "rigid_guess"]


def rigid_field(q: NDArray, motion: NDArray) -> NDArray:
    """``v + omega k x (q_i - q_bar)`` at ``q`` ``(..., n, 2)`` for ``motion = (vx, vy, omega)``."""
    p = q - q.mean(axis=-2, keepdims=True)
    v, omega = motion[..., None, :2], motion[..., None, 2:3]
    return v + omega * np.stack([-p[..., 1], p[..., 0]], axis=-1)


def rigid_guess(u: NDArray, q: NDArray) -> NDArray[np.float64]:
    """Least-squares ``(vx, vy, omega)`` of the velocities ``u`` ``(n, 2)`` at ``q``."""
    p = q - q.mean(axis=0)
    kp = np.stack([-p[:, 1], p[:, 0]], axis=-1)
    omega = float(np.sum(kp * u) / max(float(np.sum(p * p)), 1e-12))
    return np.array([*u.mean(axis=0), omega])


#: most near surfaces whose subsets are all tried for a relative equilibrium (2^k - 1 solves)
MAX_NEAR = 5


def all_subsets(near: tuple[int, ...]) -> list[tuple[int, ...]]:
    """Every non-empty subset of ``near``, largest first."""
    return [c for k in range(len(near), 0, -1) for c in combinations(near, k)]


def attracts(
    formation: Formation, law: Law, q: NDArray, weights: NDArray, surfaces: tuple[int, ...]
) -> bool:
    """Whether each surface ``s`` attracts at ``q``: ``grad sigma_s . u`` is positive with
    ``w_s = 0`` and negative with ``w_s = 1`` (the other weights at ``weights``)."""
    h = 1e-7 * max(1.0, float(np.max(np.abs(q))))
    for s in surfaces:
        for value, sign in ((0.0, 1.0), (1.0, -1.0)):
            w = weights.copy()
            w[s] = value
            u = law.control_with(formation, q, w)
            ds = law.switching(formation, q + h * u)[s] - law.switching(formation, q - h * u)[s]
            if not sign * ds > 0:
                return False
    return True
