"""The paper's restriction lifted to space: the chirality-restricted law for 3-D formations.

In the plane, "Formation Control of Multiple Robots Avoiding Local Minima" (section 3.2)
adds to the distance law (eq. 8) a term per restricted triple,
``psi_ijk = alpha_ijk c_ijk Upsilon(alpha_ijk c_ijk + theta)`` (eq. 14), that pushes a
triangle out of its mirror image. In space the mirror image of a rigid shape has the
opposite chirality, the sign of the signed volume ``v_ijkl = r_ij . (r_ik x r_il)`` of its
tetrahedra (:mod:`formationlab.formation.chirality`, after Anderson, Sun, Sugie, Azuma and
Sakurama, IFAC J. Systems and Control 2017, and Liu and de Queiroz, Automatica 2022). This
law is eq. (11) with that volume in the place of ``c_ijk``:

``u_i = -k_c grad_i phi_i - k_a grad_i psi_i``,
``psi_i = sum_{j<k<l in N_i} psi_ijkl``,
``psi_ijkl = beta_ijkl v_ijkl Upsilon(beta_ijkl v_ijkl + theta)``,
``grad_i psi_ijkl = beta_ijkl Upsilon(.) r_jl x r_jk`` (the analogue of eq. 23).

Each set of three neighbours counts once (the paper's eq. 13 counts ordered pairs, twice;
here the six orderings of a set would only scale ``k_a``). ``V = sum_i phi_i +
lambda sum_i psi_i`` with ``lambda kappa k_c = 2 k_a`` and ``kappa = 4`` (eq. 25's
condition, with the four robots of a tetrahedron in the place of the three of a triangle)
gives ``dV/dt = -(2/k_c) sum_i |u_i|^2`` between switches when every restricted quadruple
is a tetrahedron of the graph (its four robots neighbours of one another); docs/three-d.md
derives it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..formation.chirality import signed_volumes, volume_gradients
from ..formation.geometry import scatter_rows
from ..formation.spec import Formation
from .angle_restricted import RestrictedLaw
from .base import register
from .distance import grad_phi, phi_sum
from .kinds.restriction import switching, upsilon

__all__ = ["ChiralityRestrictedLaw", "chi_sum", "chirality_switching", "grad_chi"]


def chirality_switching(
    formation: Formation, q: NDArray[np.float64], theta: float
) -> NDArray[np.float64]:
    """``sigma_s = beta_s v_abcd + theta`` of each distinct surface; ``(..., n, 3) -> (..., s)``.

    The one place a chirality restriction is decided on or off (the control, ``psi`` and
    the integrators' switching diagnostics use these numbers), as
    :func:`~formationlab.controllers.angle_restricted.switching_functions` in the plane.
    """
    tets, beta, _ = formation.chiral_surfaces
    return switching(beta, signed_volumes(q, tets), theta)  # eq. (14) with v for c


def grad_chi(
    formation: Formation, q: NDArray[np.float64], steps: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``grad_i psi_i`` for every robot, ``(..., n, 3)``: ``sum beta Upsilon r_jl x r_jk``.

    ``steps`` (``(..., Q)``, one per restricted quadruple, in [0, 1]) are the values of
    ``Upsilon(beta v + theta)``, or Filippov's weights on a surface.
    """
    quads = formation.chiral_quads
    w = formation.chiral_signs * steps  # (..., Q)
    grads = volume_gradients(q, quads)[..., 0, :]  # grad_i v_ijkl = r_jl x r_jk
    return scatter_rows(w[..., None] * grads, quads[:, 0], formation.n)  # type: ignore[index]


def chi_sum(formation: Formation, q: NDArray[np.float64], theta: float) -> NDArray[np.float64]:
    """``sum_i psi_i`` over every robot's restricted quadruples; shape ``(...)``."""
    if not formation.has_chirality:
        return np.zeros(np.shape(q)[:-2])
    bv = formation.chiral_signs * signed_volumes(q, formation.chiral_quads)
    return np.sum(bv * upsilon(switching(1.0, bv, theta)), axis=-1)  # eq. (14) with v for c


@register
@dataclass(frozen=True, kw_only=True)
class ChiralityRestrictedLaw(RestrictedLaw):
    """The paper's angle-restricted law (eq. 11) in space: chirality instead of angles.

    ``u_i = -k_c grad_i phi_i - k_a grad_i psi_i`` with ``psi_ijkl = beta_ijkl v_ijkl
    Upsilon(beta_ijkl v_ijkl + theta)`` (module docstring). Needs a formation in space
    (``dim = 3``) whose chirality is restricted (a 3-D template, ``orientation =
    "template"``); the planar formations have :class:`AngleRestrictedLaw`. Parameters:
    those of :class:`~.angle_restricted.RestrictedLaw` (defaults as the paper's, ``k_c =
    2``, ``k_a = 3``, ``theta = 0.5``); ``theta`` is a volume here, six times the
    tetrahedron's (a regular tetrahedron of edge 1 has ``|v| = 0.71``), and must stay below
    the flattest restricted tetrahedron of the template (docs/three-d.md). ``lambda`` of
    eq. (25) has ``kappa = 4``.
    """

    name = "chirality-restricted"
    dims = (3,)
    elsewhere = 'use law = "angle-restricted" (the paper\'s) in the plane'

    def switching(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``sigma_s = beta_s v_abcd + theta`` per surface (:func:`chirality_switching`)."""
        return chirality_switching(formation, q, self.theta)

    def control(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``u`` of eq. (11) in space: :meth:`control_with` the steps ``Upsilon(sigma(q))``."""
        return self.control_with(formation, q, upsilon(self.switching(formation, q)))

    def control_with(
        self, formation: Formation, q: NDArray[np.float64], weights: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        q = np.asarray(q, dtype=float)
        u = -self.k_c * grad_phi(formation, q, self.repulsion)
        if formation.has_chirality and self.k_a > 0:
            steps = np.take(np.asarray(weights, dtype=float), formation.chiral_surfaces[2], -1)
            u = u - self.k_a * grad_chi(formation, q, steps)  # eq. (11)
        return u

    def potential(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``V = sum_i phi_i + lambda sum_i psi_i`` (eq. 15), lambda from (25) with kappa 4."""
        v = phi_sum(formation, q, self.repulsion)
        return v + self.lam(formation) * chi_sum(formation, q, self.theta)  # eq. (15)
