"""The rewards of the environments' robots: their terms, batched, and their weights.

Robot ``i``'s reward after a step is

``r_i = -(w_d e_i + w_o o_i + w_u |u_i|^2) - w_c [the step was rejected]``

with its terms:

``e_i`` (:func:`robot_errors`)
    its local formation error ``sum_{j in N_i} |r_ij - d_ij|`` at the law's points (for a
    formation judged by its bearings ``sum_{j in N_i} ||g_ij - g*_ij||``, docs/bearing.md);
``o_i`` (:func:`orientation_errors`)
    the number of its restricted triples ``(i, j, k)`` (``Formation.restricted_halves``)
    whose orientation ``sign(c_ijk)`` is not the desired one (eq. 3; a collinear triple
    counts as wrong): the mirror image of the formation has every one wrong;
``|u_i|^2``
    its command's squared size (the common frame's command at the law's point, before the
    model's limits: ``v^2 + l^2 omega^2`` for a unicycle's ``(v, omega)``): control effort;
``[the step was rejected]``
    by the package's contact rule (contact at the end of the step, robots passing through
    each other, a state not finite), for every robot of the formation.

:class:`Rewards` holds the weights; its default is the PettingZoo environment's reward
(``w_d = 1``, ``w_c`` = :data:`CONTACT_PENALTY`, the others 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..formation.spec import Formation
from ..outcomes.analysis import bearing_errors, distance_errors, turned_wrong
from ..validation import nonnegative

__all__ = ["CONTACT_PENALTY", "Rewards", "edge_errors", "orientation_errors", "robot_errors"]

#: the reward lost by every robot at a step rejected by the contact rule
CONTACT_PENALTY = 100.0


def _per_robot(formation: Formation, rows: NDArray[np.intp], values: NDArray) -> NDArray:
    """``out[..., i]``: the sum of ``values[..., t]`` over the items ``t`` with ``rows[t] =
    i``, item after item in order (the same sums whatever the batch); ``(..., n)``."""
    v = np.moveaxis(np.asarray(values, dtype=float), -1, 0)
    out = np.zeros((formation.n, *v.shape[1:]))
    np.add.at(out, rows, v)
    return np.moveaxis(out, 0, -1)


def edge_errors(formation: Formation, p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each edge's error at the law's points ``p`` ``(..., n, 2)``: ``|r_ij - d_ij|``, or
    ``||g_ij - g*_ij||`` for a formation judged by its bearings; ``(..., E)``."""
    if formation.bearings is not None:
        return bearing_errors(formation, p)
    return np.abs(distance_errors(formation, p))


def robot_errors(
    formation: Formation, p: NDArray[np.float64], edges: NDArray[np.float64] | None = None
) -> NDArray[np.float64]:
    """Each robot's local formation error ``e_i`` (module docstring) at the law's points
    ``p`` ``(..., n, 2)``, from the edges' errors (:func:`edge_errors`, computed when not
    given); ``(..., n)``."""
    e = edge_errors(formation, p) if edges is None else edges
    edges = formation.edges
    both = np.concatenate([edges[:, 0], edges[:, 1]])
    return _per_robot(formation, both, np.concatenate([e, e], axis=-1))


def orientation_errors(formation: Formation, p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each robot's count ``o_i`` of its restricted triples with the wrong orientation
    (module docstring) at the law's points ``p`` ``(..., n, 2)``; ``(..., n)``."""
    halves = formation.restricted_halves
    if halves.shape[0] == 0:
        return np.zeros(p.shape[:-1])
    wrong = turned_wrong(formation, p)
    return _per_robot(formation, halves[:, 0], wrong)


@dataclass(frozen=True, kw_only=True)
class Rewards:
    """The weights of a robot's reward (module docstring); each >= 0.

    Attributes
    ----------
    distance : float
        ``w_d``, of the local formation error (default 1).
    orientation : float
        ``w_o``, of the restricted triples with the wrong orientation (default 0).
    effort : float
        ``w_u``, of the command's squared size (default 0).
    collision : float
        ``w_c``, lost by every robot at a rejected step (default :data:`CONTACT_PENALTY`).
    """

    distance: float = 1.0
    orientation: float = 0.0
    effort: float = 0.0
    collision: float = CONTACT_PENALTY

    def __post_init__(self) -> None:
        for name in ("distance", "orientation", "effort", "collision"):
            object.__setattr__(self, name, nonnegative(getattr(self, name), f"rewards.{name}"))

    def of(
        self,
        formation: Formation,
        p: NDArray[np.float64] | None,
        u: NDArray[np.float64],
        rejected: NDArray[np.bool_],
        errors: NDArray[np.float64] | None = None,
        wrong: NDArray[np.float64] | None = None,
    ) -> NDArray[np.float64]:
        """Every robot's reward ``(B, n)`` at the law's points ``p`` ``(B, n, 2)`` (the state
        after the step, or before it where the step was ``rejected`` ``(B,)``), under the
        commands ``u`` ``(B, n, 2)``; ``errors``: :func:`robot_errors` of ``p`` and ``wrong``:
        :func:`orientation_errors` of ``p``, if known (then ``p`` may be None)."""
        e = robot_errors(formation, p) if errors is None else errors
        r = -self.distance * e
        if self.orientation:
            o = orientation_errors(formation, p) if wrong is None else wrong
            r = r - self.orientation * o
        if self.effort:
            r = r - self.effort * np.sum(u * u, axis=-1)
        return r - np.where(rejected, self.collision, 0.0)[:, None]
