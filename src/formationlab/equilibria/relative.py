"""Relative equilibria: the rigid motion of a shape, and the surfaces it slides on.

Helpers of :func:`formationlab.equilibria.refine` with ``moving=True``: the rigid
field ``v + omega k x (q_i - q_bar)`` (in space the screw ``v + w x (q_i - q_bar)``)
solved for beside the shape, its first guess,
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
    """The rigid field at ``q`` ``(..., n, d)``: ``v + omega k x (q_i - q_bar)`` in the plane
    for ``motion = (vx, vy, omega)``; in space the screw ``v + w x (q_i - q_bar)`` for
    ``motion = (vx, vy, vz, wx, wy, wz)`` (``w = omega a``, the angular velocity about the
    axis ``a``)."""
    p = q - q.mean(axis=-2, keepdims=True)
    d = q.shape[-1]
    v, w = motion[..., None, :d], motion[..., None, d:]
    if d == 3:
        return v + np.cross(w, p)
    return v + w * np.stack([-p[..., 1], p[..., 0]], axis=-1)


def rigid_guess(u: NDArray, q: NDArray) -> NDArray[np.float64]:
    """Least-squares rigid motion of the velocities ``u`` ``(n, d)`` at ``q``: ``(vx, vy,
    omega)`` in the plane, ``(v, w)`` (six numbers) in space.

    ``v`` is the mean velocity (the centred positions sum to zero); in space ``w`` solves
    ``J w = sum_i p_i x u_i`` with ``J = sum_i (|p_i|^2 I - p_i p_i^T)`` (the normal
    equations of ``min sum_i |u_i - v - w x p_i|^2``; least squares where ``J`` is singular,
    robots on a line).
    """
    p = q - q.mean(axis=0)
    if q.shape[-1] == 3:
        inertia = np.sum(p * p) * np.eye(3) - p.T @ p
        moment = np.sum(np.cross(p, u), axis=0)
        w = np.linalg.lstsq(inertia, moment, rcond=None)[0]
        return np.concatenate([u.mean(axis=0), w])
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
