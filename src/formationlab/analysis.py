"""Reading a state: distance errors, orientation, and the outcome of a run.

One classification is shared by every command (``run``, ``paper``, ``study``,
``equilibria``), so an outcome means the same thing everywhere:

``collision``
    some pair at ``r_ij <= a_ij`` (or a step was rejected for reaching contact);
``desired``
    every specified distance within ``Tolerances.distance`` of ``d_ij`` and every
    restricted triple with the desired orientation (any orientation when the
    formation's orientation is free);
``mirror``
    distances met and *every* restricted triple reversed: the mirror image;
``incorrect``
    stopped (largest ``|u_i|`` below ``Tolerances.speed``) with distances not
    met, or distances met with only *some* triples reversed (a flip that a
    non-rigid graph allows);
``not-converged``
    still moving at the end with distances not met.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import ParameterError
from .potentials import triple_products
from .spec import Formation

__all__ = [
    "OUTCOMES",
    "Outcome",
    "Tolerances",
    "classify",
    "converged_time",
    "distance_errors",
    "edge_labels",
    "orientation_agreement",
    "triangle_orientation",
]

Outcome = Literal["desired", "mirror", "incorrect", "collision", "not-converged"]
OUTCOMES: tuple[Outcome, ...] = ("desired", "mirror", "incorrect", "collision", "not-converged")


@dataclass(frozen=True, kw_only=True)
class Tolerances:
    """Tolerances of the outcome classification.

    Parameters
    ----------
    distance : float
        Largest ``|r_ij - d_ij|`` over the edges for the distances to count as met.
    speed : float
        Largest ``|u_i|`` for the robots to count as stopped.
    """

    distance: float = 1e-2
    speed: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("distance", "speed"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v > 0):
                raise ParameterError(f"tolerance {name} must be a finite number > 0, got {v!r}")


def distance_errors(formation: Formation, q: ArrayLike) -> NDArray[np.float64]:
    """``r_ij - d_ij`` per edge, shape ``(..., m)`` in the order of ``formation.edges``."""
    q = np.asarray(q, dtype=float)
    e = formation.edges
    r = np.linalg.norm(q[..., e[:, 1], :] - q[..., e[:, 0], :], axis=-1)
    return r - formation.distances


def edge_labels(formation: Formation) -> list[str]:
    """1-based labels ``"1-2"`` of the edges, in order."""
    return [f"{i + 1}-{j + 1}" for i, j in formation.edges]


def triangle_orientation(q: ArrayLike, i: int = 0, j: int = 1, k: int = 2) -> str:
    """``"ccw"`` or ``"cw"``: the turn of robots ``i, j, k`` (0-based), from ``c_ijk``."""
    q = np.asarray(q, dtype=float)
    rij, rik = q[j] - q[i], q[k] - q[i]
    c = rij[0] * rik[1] - rij[1] * rik[0]
    return "ccw" if c > 0 else "cw" if c < 0 else "collinear"


def orientation_agreement(formation: Formation, q: ArrayLike) -> tuple[int, int]:
    """Restricted triples whose ``sign(c_ijk)`` agrees / disagrees with the desired one.

    Counts ordered triples ``(i, j, k)``; a state with no restriction returns ``(0, 0)``.
    """
    if formation.alpha is None:
        return 0, 0
    s = np.sign(triple_products(q)) * formation.desired_sign
    mask = formation.restricted
    return int(np.sum((s > 0) & mask)), int(np.sum((s <= 0) & mask))


def classify(
    formation: Formation,
    q: ArrayLike,
    u: ArrayLike,
    tolerances: Tolerances | None = None,
    *,
    contact: bool = False,
) -> Outcome:
    """The outcome of a final state ``q`` with controls ``u`` (both ``(n, 2)``).

    ``contact`` marks a run stopped at a rejected step (contact reached).
    """
    tol = tolerances or Tolerances()
    q = np.asarray(q, dtype=float)
    iu, ju = np.triu_indices(formation.n, k=1)
    r = np.linalg.norm(q[ju] - q[iu], axis=-1)
    if contact or np.any(r <= formation.contact_matrix[iu, ju]):
        return "collision"
    met = np.max(np.abs(distance_errors(formation, q))) <= tol.distance
    if met:
        agree, disagree = orientation_agreement(formation, q)
        if disagree == 0:
            return "desired"
        if agree == 0:
            return "mirror"
        return "incorrect"
    speed = np.max(np.linalg.norm(np.asarray(u, dtype=float), axis=-1))
    return "incorrect" if speed <= tol.speed else "not-converged"


def converged_time(t: NDArray[np.float64], u: NDArray[np.float64], speed: float) -> float | None:
    """First saved time after which every ``|u_i|`` stays below ``speed``; None if never.

    ``t`` has shape ``(T,)`` and ``u`` shape ``(T, n, 2)``.
    """
    moving = np.max(np.linalg.norm(u, axis=-1), axis=-1) > speed
    if moving[-1]:
        return None
    idx = np.flatnonzero(moving)
    return float(t[0] if idx.size == 0 else t[min(idx[-1] + 1, len(t) - 1)])
