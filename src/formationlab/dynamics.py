"""Robot motion models: how a control becomes a velocity.

The paper's robots are omnidirectional single integrators, ``q_dot_i = u_i``
(eq. 1). The model is kept separate from the laws so that other models (the
paper's "future work": robot dynamics) plug in without touching them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from .controllers import Law
from .spec import Formation

__all__ = ["SingleIntegrator", "System"]


@dataclass(frozen=True, kw_only=True)
class SingleIntegrator:
    """``q_dot_i = u_i`` (eq. 1): the state is the positions, shape ``(..., n, 2)``."""

    name: ClassVar[str] = "single-integrator"

    def velocity(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        return u  # eq. (1)


@dataclass(frozen=True, kw_only=True)
class System:
    """A closed loop: a formation, a law and a motion model.

    ``rhs(q)`` is the vector field the integrators step; ``rhs_with(q, w)`` the
    same with the law's steps replaced by Filippov weights ``w`` (shape of
    ``law.switching``); ``sigma(q)`` the switching functions.
    """

    formation: Formation
    law: Law
    model: SingleIntegrator = SingleIntegrator()

    def rhs(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.model.velocity(self.law.control(self.formation, q))

    def rhs_with(self, q: NDArray[np.float64], weights: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.model.velocity(self.law.control_with(self.formation, q, weights))

    def sigma(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.law.switching(self.formation, q)

    def clearance(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Least ``r_ij - a_ij`` over all pairs; shape ``(...)``."""
        q = np.asarray(q, dtype=float)
        iu, ju = np.triu_indices(self.formation.n, k=1)
        r = np.linalg.norm(q[..., ju, :] - q[..., iu, :], axis=-1)
        return np.min(r - self.formation.contact_matrix[iu, ju], axis=-1)

    def swept_clearance(
        self, q0: NDArray[np.float64], q1: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Least ``r_ij - a_ij`` over the straight step from ``q0`` to ``q1``; shape ``(...)``.

        Catches a step that carries two robots through each other, which the
        clearance at the end of the step alone would miss.
        """
        q0, q1 = np.asarray(q0, dtype=float), np.asarray(q1, dtype=float)
        iu, ju = np.triu_indices(self.formation.n, k=1)
        r0 = q0[..., ju, :] - q0[..., iu, :]
        dr = (q1[..., ju, :] - q1[..., iu, :]) - r0
        dd = np.sum(dr * dr, axis=-1)
        s = np.clip(-np.sum(r0 * dr, axis=-1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
        r = np.linalg.norm(r0 + s[..., None] * dr, axis=-1)
        return np.min(r - self.formation.contact_matrix[iu, ju], axis=-1)
