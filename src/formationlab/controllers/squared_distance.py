"""The squared-distance gradient law of Krick, Broucke and Francis (2009), for comparison.

Reference: L. Krick, M. E. Broucke and B. A. Francis, "Stabilisation of
infinitesimally rigid formations of multi-robot networks", International Journal
of Control 82(3):423-439, 2009. Each robot descends

``V = 1/4 sum_{(i, j) in E} (r_ij^2 - d_ij^2)^2``,

the sum running over the edges **once** (unordered pairs, as in Krick et al.),
so that ``grad_i V = -sum_{j in N_i} (r_ij^2 - d_ij^2) r_ij`` with
``r_ij = q_j - q_i`` and the law ``u = -k grad V`` is an exact gradient flow.
It has no barrier at contact and no notion of orientation: mirror images and
(for rigid graphs with cycles) incorrect equilibria are all stationary.

To make collision counts comparable with the paper's laws, the same Khatib
repulsion ``gamma_ij`` acts between robots that are *not* neighbours, with its
own gain ``k_r`` (default 2, the paper's ``k_c``, so that the repulsive force is
exactly the one in :class:`~formationlab.controllers.DistanceLaw` and
:class:`~formationlab.controllers.AngleRestrictedLaw` with their defaults).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..formation.spec import DENSE_LIMIT, Formation
from ..validation import check_fields
from .base import Law, ObstacleRepulsion, Repulsion, register
from .distance import _grad_listed, pair_geometry, repulsion_pairs
from .kinds.khatib import dkhatib_ds, khatib
from .kinds.squared_distance import squared_gain, squared_value
from .terms import SQUARED, KernelTerms, build_terms

__all__ = [
    "SquaredDistanceLaw",
    "grad_repulsion",
    "grad_squared_distance",
    "repulsion_sum",
    "squared_distance_sum",
]


def grad_squared_distance(formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """``grad_i V`` of ``V = 1/4 sum_edges (r_ij^2 - d_ij^2)^2``; ``(..., n, 2) -> (..., n, 2)``.

    ``grad_i V = -sum_{j in N_i} (r_ij^2 - d_ij^2) r_ij`` (Krick et al. 2009).
    """
    if formation.n > DENSE_LIMIT:
        return _grad_listed(formation, q, None, edge_slope=_squared_slope)
    r, dist, _ = pair_geometry(q)
    adj = formation.adjacency
    d = np.where(adj, formation.distance_matrix, 0.0)
    weight = np.where(adj, squared_gain(dist * dist, d), 0.0)  # (..., n, n)
    return -np.einsum("...ij,...ijd->...id", weight, r)


def grad_repulsion(
    formation: Formation, q: NDArray[np.float64], repulsion: Repulsion
) -> NDArray[np.float64]:
    """``grad_i`` of Khatib's ``Gamma = sum_{non-neighbour pairs, once} gamma_ij``; ``(..., n, 2)``.

    ``grad_i gamma_ij = -gamma'(s_ij) r_ij / r_ij`` with the clearance ``s_ij = r_ij - a_ij``.
    """
    if formation.n > DENSE_LIMIT:
        return _grad_listed(formation, q, repulsion, edge_slope=_no_slope)
    _, dist, unit = pair_geometry(q)
    n = formation.n
    other = ~formation.adjacency & ~np.eye(n, dtype=bool)
    if not other.any():
        return np.zeros(np.shape(q))
    a = formation.contact_matrix
    s = np.where(other, dist - a, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(other, dkhatib_ds(s, repulsion.eta, repulsion.influence), 0.0)
    return -np.einsum("...ij,...ijd->...id", slope, unit)


def repulsion_sum(
    formation: Formation, q: NDArray[np.float64], repulsion: Repulsion
) -> NDArray[np.float64]:
    """``Gamma = sum_{i < j, j not in N_i} gamma_ij``, each pair once; shape ``(...)``."""
    q = np.asarray(q, dtype=float)
    i, j = repulsion_pairs(formation, q, repulsion)
    if not i.size:
        return np.zeros(q.shape[:-2])
    a_ij = 0.5 * (formation.diameters[i] + formation.diameters[j])
    s = np.linalg.norm(q[..., j, :] - q[..., i, :], axis=-1) - a_ij
    return khatib(s, repulsion.eta, repulsion.influence).sum(axis=-1)


def _squared_slope(r: NDArray, formation: Formation, a: NDArray) -> NDArray:
    """``d/dr`` of ``1/4 (r^2 - d^2)^2``: ``(r^2 - d^2) r`` (Krick et al. 2009)."""
    return squared_gain(r * r, formation.distances) * r


def _no_slope(r: NDArray, formation: Formation, a: NDArray) -> NDArray:
    return np.zeros_like(r)


def squared_distance_sum(formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """``V = 1/4 sum_edges (r_ij^2 - d_ij^2)^2``, each edge once; shape ``(...)``."""
    q = np.asarray(q, dtype=float)
    e = formation.edges
    diff = q[..., e[:, 1], :] - q[..., e[:, 0], :]
    r2 = np.sum(diff * diff, axis=-1)
    return np.sum(squared_value(r2, formation.distances), axis=-1)


@register
@dataclass(frozen=True, kw_only=True)
class SquaredDistanceLaw(Law):
    """Squared-distance gradient law ``u = -k grad V - k_r grad Gamma`` (Krick et al. 2009).

    ``V = 1/4 sum_{(i,j) in E} (r_ij^2 - d_ij^2)^2`` over the edges once, and
    ``Gamma`` Khatib's repulsion between non-neighbours (module docstring).
    The closed loop is the gradient flow of ``W = V + (k_r / k) Gamma``:
    ``dW/dt = -|u|^2 / k``.

    Reference: L. Krick, M. E. Broucke and B. A. Francis, "Stabilisation of
    infinitesimally rigid formations of multi-robot networks", Int. J. Control
    82(3):423-439, 2009.

    Parameters
    ----------
    k : float
        Gain of the distance term. Default 1.
    k_r : float
        Gain of the repulsion between non-neighbours. Default 2 (the paper's
        ``k_c``, so the repulsive force equals that of the paper's laws).
    repulsion : Repulsion
        Khatib's repulsion ``gamma_ij``.
    """

    name = "squared-distance"
    sensed_dims = (2, 3)  # edges and pairs only: lengths, any space
    compiled_dims = (2, 3)  # (the same reason: the compiled loop's field in space)
    k: float = 1.0
    k_r: float = 2.0
    repulsion: Repulsion = field(default_factory=Repulsion)

    def __post_init__(self) -> None:
        check_fields(self, positive=("k",), nonnegative=("k_r",))

    def control(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        u = -self.k * grad_squared_distance(formation, q)
        if self.k_r > 0:
            u = u - self.k_r * grad_repulsion(formation, q, self.repulsion)
        return u

    def potential(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``W = V + (k_r / k) Gamma``, of which ``u = -k grad W``; shape ``(...)``."""
        v = squared_distance_sum(formation, q)
        if self.k_r > 0:
            v = v + (self.k_r / self.k) * repulsion_sum(formation, q, self.repulsion)
        return v

    def obstacle_repulsion(self) -> ObstacleRepulsion:
        """``-k_r grad Gamma_o``; ``u = -k grad W``, so ``W`` gains ``(k_r / k) Gamma_o``."""
        return ObstacleRepulsion(gain=self.k_r, weight=self.k_r / self.k, repulsion=self.repulsion)

    def kernel_terms(self, formation: Formation, *, pairs: bool = True) -> KernelTerms:
        rep = self.repulsion
        return build_terms(
            formation, pairs=pairs, kind=SQUARED, edge_gain=self.k, repulsion_gain=self.k_r,
            eta=rep.eta, influence=rep.influence,
        )  # fmt: skip
