"""The distance-based law of eq. (8) and the pure functions it is built from.

Reference: section 3.1 of "Formation Control of Multiple Robots Avoiding Local
Minima": ``u_i = -k_c grad_i phi_i`` with
``phi_i = sum_{j in N_i} phi_ij + sum_{j not in N_i} gamma_ij`` (eqs. 8, 12).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..formation.geometry import pair_vectors, scatter_rows
from ..formation.spec import DENSE_LIMIT, Formation
from ..neighbours.kdtree import close_pairs, non_edges
from ..validation import check_fields
from .base import Law, ObstacleRepulsion, Repulsion, register
from .kinds.khatib import dkhatib_ds, khatib
from .kinds.log_barrier import dphi_dr, phi
from .terms import LOG_BARRIER, KernelTerms, build_terms

__all__ = ["DistanceLaw", "grad_phi", "pair_geometry", "phi_sum", "repulsion_pairs"]


def pair_geometry(q: NDArray[np.float64]) -> tuple[NDArray, NDArray, NDArray]:
    """``r_ij`` ``(..., n, n, 2)``, distances ``(..., n, n)`` and unit vectors ``r_ij / r_ij``.

    The diagonal of the unit vectors is zero.
    """
    r = pair_vectors(q)
    dist = np.sqrt(np.sum(r * r, axis=-1))
    n = r.shape[-2]
    eye = np.eye(n, dtype=bool)
    unit = r / np.where(eye, 1.0, dist)[..., None]
    return r, dist, unit


def _pair_slopes(
    formation: Formation, dist: NDArray[np.float64], repulsion: Repulsion | None
) -> NDArray[np.float64]:
    """``d phi_ij / d r`` on edges and ``d gamma_ij / d r`` on other pairs; ``(..., n, n)``."""
    adj = formation.adjacency
    a = formation.contact_matrix
    d = np.where(adj, formation.distance_matrix, a + 1.0)  # filler off the edges
    eye = np.eye(formation.n, dtype=bool)
    safe = np.where(eye, a + 1.0, dist)
    # Off the domain (r <= a, only reached by a rejected trial step) the
    # slopes are meaningless but must not raise; the integrators reject them.
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(adj, dphi_dr(safe, d, a), 0.0)  # eq. (7)
        if repulsion is not None:
            other = ~adj & ~eye
            if other.any():
                s = np.where(other, safe - a, np.inf)
                gamma = dkhatib_ds(s, repulsion.eta, repulsion.influence)
                slope = slope + np.where(other, gamma, 0.0)
    return slope


def grad_phi(
    formation: Formation, q: NDArray[np.float64], repulsion: Repulsion | None = None
) -> NDArray[np.float64]:
    """``grad_i phi_i`` for every robot (eq. 12), shape ``(..., n, 2)``.

    ``grad_i phi_ij = phi'(r_ij) grad_i r_ij = -phi'(r_ij) r_ij / r_ij``.
    """
    if formation.n > DENSE_LIMIT:  # over the edges and the close pairs only
        return _grad_listed(formation, q, repulsion, edge_slope=_phi_slope)
    _, dist, unit = pair_geometry(q)
    slope = _pair_slopes(formation, dist, repulsion)
    return -np.einsum("...ij,...ijd->...id", slope, unit)


def repulsion_pairs(
    formation: Formation, q: NDArray[np.float64], repulsion: Repulsion
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The non-neighbour pairs ``i < j`` that Khatib's repulsion can reach at ``q``.

    Every non-edge for small formations; beyond ``DENSE_LIMIT`` robots only those
    closer than ``max a_ij + s0`` in some state of ``q`` (``gamma_ij`` is zero farther).
    """
    n = formation.n
    if n <= DENSE_LIMIT:
        iu, ju = np.triu_indices(n, k=1)
        other = ~formation.adjacency[iu, ju]
        return iu[other], ju[other]
    reach = float(formation.diameters.max()) + repulsion.influence
    p = non_edges(close_pairs(q, reach), formation.edges, n)
    return p[:, 0], p[:, 1]


def _phi_slope(r: NDArray, formation: Formation, a: NDArray) -> NDArray:
    return dphi_dr(r, formation.distances, a)  # eq. (7)


def _grad_listed(formation: Formation, q: NDArray, repulsion: Repulsion | None, *, edge_slope):
    """``grad_i`` of the edge potentials and the repulsion, pair by listed pair; ``(..., n, 2)``.

    ``edge_slope(r, formation, a)`` is ``d V_ij / d r`` per edge; each pair ``(i, j)``
    adds ``-slope r_ij / r_ij`` to robot ``i`` and the opposite to robot ``j``.
    """
    q = np.asarray(q, dtype=float)
    e = formation.edges
    a = 0.5 * (formation.diameters[e[:, 0]] + formation.diameters[e[:, 1]])
    i, j = e[:, 0], e[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        vec = q[..., j, :] - q[..., i, :]
        r = np.sqrt(np.sum(vec * vec, axis=-1))
        force = (edge_slope(r, formation, a) / r)[..., None] * vec
        if repulsion is not None:
            pi, pj = repulsion_pairs(formation, q, repulsion)
            pv = q[..., pj, :] - q[..., pi, :]
            pr = np.sqrt(np.sum(pv * pv, axis=-1))
            s = pr - 0.5 * (formation.diameters[pi] + formation.diameters[pj])
            slope = dkhatib_ds(s, repulsion.eta, repulsion.influence)
            i, j = np.concatenate([i, pi]), np.concatenate([j, pj])
            force = np.concatenate([force, (slope / pr)[..., None] * pv], axis=-2)
    n = formation.n
    return scatter_rows(-force, i, n) + scatter_rows(force, j, n)


def phi_sum(
    formation: Formation, q: NDArray[np.float64], repulsion: Repulsion | None = None
) -> NDArray[np.float64]:
    """``sum_i phi_i`` (eq. 9): each edge's ``phi_ij`` and each other pair's ``gamma_ij`` twice.

    Shape ``(...)``; ``+inf`` when two robots touch.
    """
    q = np.asarray(q, dtype=float)
    e = formation.edges
    r = np.linalg.norm(q[..., e[:, 1], :] - q[..., e[:, 0], :], axis=-1)
    a = 0.5 * (formation.diameters[e[:, 0]] + formation.diameters[e[:, 1]])
    total = 2.0 * phi(r, formation.distances, a).sum(axis=-1)
    if repulsion is not None:
        i, j = repulsion_pairs(formation, q, repulsion)
        if i.size:
            a_ij = 0.5 * (formation.diameters[i] + formation.diameters[j])
            s = np.linalg.norm(q[..., j, :] - q[..., i, :], axis=-1) - a_ij
            total = total + 2.0 * khatib(s, repulsion.eta, repulsion.influence).sum(axis=-1)
    return total


@register
@dataclass(frozen=True, kw_only=True)
class DistanceLaw(Law):
    """Distance-based gradient law ``u_i = -k_c grad_i phi_i`` (eq. 8).

    Descends ``V = sum_i phi_i`` (eq. 9) with ``dV/dt = -(2/k_c) sum |u_i|^2``
    (eq. 10): the log-barrier ``phi_ij`` of eq. (5) on edges and Khatib's
    ``gamma_ij`` between other pairs.

    Parameters
    ----------
    k_c : float
        Gain of the distance term (the paper uses 2).
    repulsion : Repulsion
        Khatib's repulsion between non-neighbours.
    """

    name = "distance"
    sensed_dims = (2, 3)  # edges and pairs only: lengths, any space
    compiled_dims = (2, 3)  # (the same reason: the compiled loop's field in space)
    barrier_at_contact = True
    k_c: float = 2.0
    repulsion: Repulsion = field(default_factory=Repulsion)

    def __post_init__(self) -> None:
        check_fields(self, positive=("k_c",))

    def control(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        return -self.k_c * grad_phi(formation, q, self.repulsion)  # eq. (8)

    def potential(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        return phi_sum(formation, q, self.repulsion)  # eq. (9)

    def obstacle_repulsion(self) -> ObstacleRepulsion:
        """``-k_c grad Gamma_o``; ``u = -(k_c / 2) grad V``, so ``V`` gains ``2 Gamma_o``."""
        return ObstacleRepulsion(gain=self.k_c, weight=2.0, repulsion=self.repulsion)

    def kernel_terms(self, formation: Formation, *, pairs: bool = True) -> KernelTerms:
        rep = self.repulsion
        return build_terms(
            formation, pairs=pairs, kind=LOG_BARRIER, edge_gain=self.k_c, repulsion_gain=self.k_c,
            eta=rep.eta, influence=rep.influence,
        )  # fmt: skip
