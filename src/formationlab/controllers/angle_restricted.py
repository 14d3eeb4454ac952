"""The paper's angle-restricted law, eqs. (11)-(14), and its Lyapunov function (15).

Reference: section 3.2 of "Formation Control of Multiple Robots Avoiding Local
Minima". ``u_i = -k_c grad_i phi_i - k_a grad_i psi_i`` with
``psi_i = sum_{j, k in N_i, j != k} psi_ijk`` over *ordered* pairs (eq. 13, as
printed: ``psi_ikj = psi_ijk``, so every unordered pair counts twice) and
``psi_ijk = alpha_ijk c_ijk Upsilon(alpha_ijk c_ijk + theta)`` (eq. 14).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..errors import ParameterError
from ..formation.geometry import cross, perp, scatter_rows
from ..formation.spec import DENSE_LIMIT, Formation
from ..validation import check_fields
from .base import Law, ObstacleRepulsion, Repulsion, register
from .distance import grad_phi, pair_geometry, phi_sum
from .kinds.restriction import switching, triangle_products, upsilon
from .terms import LOG_BARRIER, KernelTerms, build_terms

__all__ = [
    "AngleRestrictedLaw",
    "RestrictedLaw",
    "active_restrictions",
    "grad_psi",
    "psi_sum",
    "switching_functions",
    "switching_lines",
    "triple_steps",
]


#: surfaces or restricted triples evaluated at once by :func:`switching_functions` and
#: :func:`psi_sum` (more are taken in parts of this many, so that their scratch memory does
#: not grow with the formation)
PSI_PART = 1 << 16


def switching_functions(
    formation: Formation, q: NDArray[np.float64], theta: float
) -> NDArray[np.float64]:
    """``sigma_s = beta_s c_abc + theta`` of each distinct surface; ``(..., n, 2) -> (..., s)``.

    ``alpha_ijk c_ijk = beta_s c_abc`` for every triple of surface ``s``
    (``Formation.surfaces``), so the step ``Upsilon(alpha_ijk c_ijk + theta)``
    of eq. (14) is ``Upsilon(sigma_s)``. This is the one place where a
    restriction is decided on or off: the control, ``psi``, the integrators'
    switching diagnostics and the compiled kernels all use these numbers.
    """
    tris, beta, _ = formation.held_surfaces  # (beta as int8 signs or float64: the same products)
    if len(tris) <= PSI_PART:
        return switching(beta, triangle_products(q, tris), theta)  # eq. (14)
    q = np.asarray(q, dtype=float)
    out = np.empty((*q.shape[:-2], len(tris)))
    for a in range(0, len(tris), PSI_PART):  # in parts (the same numbers: element by element)
        part = slice(a, a + PSI_PART)
        out[..., part] = switching(beta[part], triangle_products(q, tris[part]), theta)  # eq. (14)
    return out


def switching_lines(
    q: NDArray[np.float64],
    triangles: NDArray[np.integer],
    beta: NDArray[np.float64],
    theta: float,
    *,
    extend: float = 0.6,
) -> NDArray[np.float64]:
    """Line ``s`` of eq. (26) for each vertex of each surface, as segments;
    ``(..., n, 2), (s, 3), (s,) -> (..., s, 3, 2, 2)``.

    For the vertex ``a`` of the surface ``beta c_abc + theta = 0`` (``b``, ``c`` the next
    two in cyclic order), the positions of ``a`` where the surface is met with ``b`` and
    ``c`` held: ``c_abc = r_bc x (a - b)``, so a line parallel to ``r_bc`` at the signed
    distance ``h = -theta / (beta |r_bc|)`` from the line through ``b`` and ``c`` (along
    ``k x r_bc``; eq. 26: ``theta / |r_bc|`` for ``|beta| = 1``). The segment runs from
    ``extend |r_bc|`` before ``b`` to as far past ``c``: the lines the live viewer draws for
    the active restrictions. Vertices ``m = 0, 1, 2`` of a surface are ``a``, ``b``, ``c``
    of its sorted triangle; a segment of coinciding ``b``, ``c`` or ``beta = 0`` is NaN.
    """
    q = np.asarray(q, dtype=float)
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    turn = np.stack([tri, np.roll(tri, -1, axis=1), np.roll(tri, -2, axis=1)], axis=-1)
    b, c = q[..., turn[..., 1], :], q[..., turn[..., 2], :]  # (..., s, 3, 2)
    d = c - b
    length = np.sqrt(np.sum(d * d, axis=-1, keepdims=True))
    with np.errstate(divide="ignore", invalid="ignore"):
        h = -theta / (np.asarray(beta, dtype=float)[:, None, None] * length)  # eq. (26)
        base = b + h * perp(d) / length
    return np.stack([base - extend * d, base + (1.0 + extend) * d], axis=-2)


def triple_steps(formation: Formation, weights: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per-surface weights ``(..., s)`` spread to the restricted triples, ``(..., t)``."""
    surface = formation.triple_surface
    w = np.asarray(weights, dtype=float)
    if w.shape[-1] == 0:
        return np.zeros((*w.shape[:-1], len(surface)))
    return np.take(w, surface, axis=-1)


def _steps(formation: Formation, q: NDArray[np.float64], theta: float) -> NDArray[np.float64]:
    """``Upsilon(sigma_s(q))`` of each restricted triple, ``(..., t)`` (Upsilon(0) = 1)."""
    return triple_steps(formation, upsilon(switching_functions(formation, q, theta)))


def _dense(formation: Formation, per_triple: NDArray) -> NDArray:
    """Values ``(..., t)`` of the restricted triples as an ``(..., n, n, n)`` array."""
    out = np.zeros((*per_triple.shape[:-1], *(formation.n,) * 3), dtype=per_triple.dtype)
    i, j, k = formation.restricted_triples.T
    out[..., i, j, k] = per_triple
    return out


def active_restrictions(
    formation: Formation, q: NDArray[np.float64], theta: float
) -> NDArray[np.bool_]:
    """Restricted triples whose step is on, ``alpha_ijk c_ijk + theta >= 0``; ``(..., n, n, n)``.

    For formations of at most ``DENSE_LIMIT`` robots; :func:`switching_functions` tells
    the same per surface for any size.
    """
    formation._dense("active_restrictions")
    return _dense(formation, _steps(formation, q, theta) > 0)


def grad_psi(
    formation: Formation,
    q: NDArray[np.float64],
    theta: float,
    steps: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """``grad_i psi_i`` for every robot, shape ``(..., n, 2)`` (eqs. 13, 23).

    ``grad_i psi_ijk = alpha_ijk Upsilon(.) k x r_jk`` (eq. 23); the step's own
    derivative is zero away from the switching surface and is left out, as in
    the paper. ``steps`` (``(..., t)``, one per restricted triple, values in
    [0, 1]) replaces ``Upsilon(alpha_ijk c_ijk + theta)``, for Filippov
    combinations. Up to ``DENSE_LIMIT`` robots the sum runs over dense
    ``(n, n, n)`` arrays (the arithmetic the paper's figures were made with);
    beyond, over the list of triples.
    """
    q = np.asarray(q, dtype=float)
    if steps is None:
        steps = _steps(formation, q, theta)
    w = formation.restricted_alpha * steps  # (..., t)
    if formation.n <= DENSE_LIMIT:
        r, _, _ = pair_geometry(q)
        return np.einsum("...ijk,...jkd->...id", _dense(formation, w), perp(r))  # eq. (23)
    i, j, k = formation.restricted_triples.T
    terms = w[..., None] * perp(q[..., k, :] - q[..., j, :])  # eq. (23), summed as eq. (13)
    return scatter_rows(terms, i, formation.n)


def psi_sum(formation: Formation, q: NDArray[np.float64], theta: float) -> NDArray[np.float64]:
    """``sum_i psi_i`` over ordered pairs (eq. 13); shape ``(...)``.

    Beyond :data:`PSI_PART` restricted triples, summed part by part over the halves
    ``j < k`` the formation holds, twice (``alpha_ikj c_ikj = alpha_ijk c_ijk`` and both
    switch on one surface: the same terms; the sum's rounding may differ in the last bits).
    """
    q = np.asarray(q, dtype=float)
    if 2 * len(formation.restricted_halves) <= PSI_PART:
        i, j, k = formation.restricted_triples.T
        c = cross(q[..., j, :] - q[..., i, :], q[..., k, :] - q[..., i, :])  # c_ijk
        ac = formation.restricted_alpha * c
        return np.sum(ac * _steps(formation, q, theta), axis=-1)  # eq. (14): alpha c Upsilon(.)
    on = upsilon(switching_functions(formation, q, theta))  # (..., s)
    halves, surface = formation.restricted_halves, formation.half_surface
    total = np.zeros(q.shape[:-2])
    for a in range(0, len(halves), PSI_PART):
        i, j, k = halves[a : a + PSI_PART].T
        c = cross(q[..., j, :] - q[..., i, :], q[..., k, :] - q[..., i, :])  # c_ijk
        steps = np.take(on, surface[a : a + PSI_PART], axis=-1)
        alpha = formation.half_alpha(slice(a, a + PSI_PART))  # (int8 signs or float64)
        total = total + np.sum(alpha * c * steps, axis=-1)  # eq. (14)
    return 2.0 * total  # eq. (13): the ordered pairs (j, k) and (k, j)


@dataclass(frozen=True, kw_only=True)
class RestrictedLaw(Law):
    """What the paper's law and its lift to space share: the gains of eq. (11), the
    threshold ``theta``, Khatib's repulsion, ``lambda`` of eq. (25) and the obstacles'
    repulsion. The restriction itself (triangles in the plane, tetrahedra in space) is the
    subclass's.

    Parameters
    ----------
    k_c : float
        Gain of the distance term (paper: 2).
    k_a : float
        Gain of the restriction's term (paper: 3).
    theta : float
        Threshold of the restrictions, > 0 (paper: 0.5).
    repulsion : Repulsion
        Khatib's repulsion between non-neighbours.
    """

    barrier_at_contact = True
    smooth = False
    k_c: float = 2.0
    k_a: float = 3.0
    theta: float = 0.5
    repulsion: Repulsion = field(default_factory=Repulsion)

    def __post_init__(self) -> None:
        check_fields(self, positive=("k_c",), nonnegative=("k_a", "theta"))
        if not np.isfinite(2.0 * self.k_a / (3.0 * self.k_c)):  # lambda of eq. (25), kappa >= 3
            raise ParameterError(
                f"k_c = {self.k_c:g} is so small beside k_a = {self.k_a:g} that lambda = "
                "2 k_a / (kappa k_c) of eq. (25) overflows; use gains of moderate size",
                key="k_c",
            )

    def lam(self, formation: Formation) -> float:
        """``lambda`` of eq. (25): ``lambda kappa k_c = 2 k_a`` (kappa = pi or 3 in the
        plane, 4 in space: ``Formation.kappa``)."""
        return 2.0 * self.k_a / (formation.kappa * self.k_c)  # eq. (25)

    def obstacle_repulsion(self) -> ObstacleRepulsion:
        """``-k_c grad Gamma_o``; ``u = -(k_c / 2) grad V``, so ``V`` gains ``2 Gamma_o``."""
        return ObstacleRepulsion(gain=self.k_c, weight=2.0, repulsion=self.repulsion)


@register
@dataclass(frozen=True, kw_only=True)
class AngleRestrictedLaw(RestrictedLaw):
    """The paper's law ``u_i = -k_c grad_i phi_i - k_a grad_i psi_i`` (eq. 11).

    The step function in ``psi_ijk`` (eq. 14) makes the closed loop
    discontinuous: trajectories may slide along the surfaces
    ``alpha_ijk c_ijk + theta = 0`` (line ``s`` of eq. 26). Parameters: those of
    :class:`RestrictedLaw`.
    """

    name = "angle-restricted"
    dims = (2,)
    elsewhere = 'in space the orientation is a chirality: use law = "chirality-restricted"'

    def control(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``u`` of eq. (11): :meth:`control_with` the steps ``Upsilon(sigma(q))``."""
        return self.control_with(formation, q, upsilon(self.switching(formation, q)))

    def _control(self, formation: Formation, q: NDArray, steps: NDArray) -> NDArray:
        u = -self.k_c * grad_phi(formation, q, self.repulsion)
        if formation.has_orientation and self.k_a > 0:
            u = u - self.k_a * grad_psi(formation, q, self.theta, steps)  # eq. (11)
        return u

    def potential(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``V_n = sum_i phi_i + lambda sum_i psi_i`` (eq. 15), lambda from (25)."""
        v = phi_sum(formation, q, self.repulsion)
        return v + self.lam(formation) * psi_sum(formation, q, self.theta)  # eq. (15)

    def active(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Restricted triples whose step is on, ``(..., n, n, n)``."""
        return active_restrictions(formation, q, self.theta)

    def switching(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``sigma_s = beta_s c_abc + theta`` per distinct surface (:func:`switching_functions`)."""
        return switching_functions(formation, q, self.theta)

    def control_with(
        self, formation: Formation, q: NDArray[np.float64], weights: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        return self._control(formation, q, triple_steps(formation, weights))

    def kernel_terms(self, formation: Formation, *, pairs: bool = True) -> KernelTerms:
        rep = self.repulsion
        return build_terms(
            formation, pairs=pairs, kind=LOG_BARRIER, edge_gain=self.k_c, repulsion_gain=self.k_c,
            eta=rep.eta, influence=rep.influence, k_a=self.k_a, theta=self.theta,
        )  # fmt: skip
