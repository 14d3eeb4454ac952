"""A distance-plus-signed-area gradient law, for comparison with the angular term.

After B. D. O. Anderson, Z. Sun, T. Sugie, S. Azuma and K. Sakurama,
"Distance-based rigid formation control with signed area constraints", IEEE
Conference on Decision and Control (CDC), 2017, doi:10.1109/CDC.2017.8264071:
the squared-distance potential of Krick et al. plus a penalty on the signed
areas of triangles, which tells a triangle from its mirror image:

``V = 1/4 sum_{(i,j) in E} (r_ij^2 - d_ij^2)^2 + k_s/2 sum_{abc} (A_abc - A*_abc)^2``,

with ``A_abc = c_abc / 2`` the signed area of the sorted triangle ``a < b < c``
(positive counter-clockwise) and the sum over the formation's *restricted*
triangles (those with a non-zero ``alpha_ijk`` on any ordering). The desired
signed area ``A*`` takes its sign from the formation's desired orientation
(``Formation.desired_sign = -sign(alpha)``, so it follows the same convention
as the angle-restricted law) and its magnitude from the template when there is
one, otherwise from the three desired distances (Heron's formula) or, for
angle-valued alpha, from ``1/2 d_ij d_ik |sin alpha_ijk|``.

``grad_a c_abc = k x r_bc`` (the paper's eq. 23), so
``grad_a A_abc = 1/2 k x r_bc`` and cyclically. Khatib's repulsion between
non-neighbours is added as in :class:`SquaredDistanceLaw`.

Anderson et al. analyse how the equilibria depend on the area weight. With a
weak weight the mirror image survives as a shrunken local minimum: for three
robots with unit sides, the wrong-orientation equilateral triangle of side
``s`` with ``s^2 = (8 - k_s) / (8 + k_s)`` is stationary (``W = 1/3`` at
``k_s = 1``; see ``tests/test_comparison_laws.py``), so this law's failures are
classified ``incorrect`` rather than ``mirror``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from ..errors import FormationError
from ..formation.geometry import cross, parity, perp
from ..formation.spec import Formation
from ..validation import check_fields
from .base import Law, ObstacleRepulsion, Repulsion, register
from .kinds.signed_area import signed_area
from .squared_distance import (
    grad_repulsion,
    grad_squared_distance,
    repulsion_sum,
    squared_distance_sum,
)
from .terms import SQUARED, KernelTerms, build_terms

__all__ = ["SignedAreaLaw", "desired_areas", "grad_area_penalty", "signed_areas"]


def desired_areas(formation: Formation) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The restricted triangles and their desired signed areas ``A*``.

    Returns
    -------
    triangles : ndarray of int, shape (t, 3)
        Sorted 0-based robots ``a < b < c`` of each restricted triangle.
    target : ndarray, shape (t,)
        Desired signed area of ``(a, b, c)``; positive when counter-clockwise.

    Raises
    ------
    FormationError
        When the triples of one triangle ask for opposite orientations, or when
        the area's size cannot be known (no template, an edge missing, sign-valued alpha).
    """
    return _desired_areas_cached(formation)


@lru_cache(maxsize=64)
def _desired_areas_cached(formation: Formation) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    signs: dict[tuple[int, int, int], float] = {}
    first: dict[tuple[int, int, int], tuple[int, int, int]] = {}
    for (i, j, k), sign in zip(
        formation.restricted_triples, formation.restricted_sign, strict=True
    ):
        tri = (int(i), int(j), int(k))
        lo, mid, hi = sorted(tri)
        srt = (lo, mid, hi)
        s = float(sign) * float(parity(*tri))  # desired sign of c_abc
        if srt in signs and signs[srt] != s:
            a, b, c = (x + 1 for x in first[srt])
            x, y, z = (v + 1 for v in tri)
            raise FormationError(
                f"the alpha values of triples ({a},{b},{c}) and ({x},{y},{z}) ask for opposite "
                "orientations of the same triangle; fix the signs in the alpha table"
            )
        signs.setdefault(srt, s)
        first.setdefault(srt, tri)
    tris = np.array(sorted(signs), dtype=np.int64).reshape(-1, 3)
    target = np.array([signs[srt] * _area_size(formation, list(srt)) for srt in sorted(signs)])
    for arr in (tris, target):
        arr.setflags(write=False)
    return tris, target


def _area_size(formation: Formation, tri: list[int]) -> float:
    a, b, c = tri
    if formation.template is not None:
        p = formation.template
        return 0.5 * abs(float(cross(p[b] - p[a], p[c] - p[a])))
    dm, adj = formation.distance_matrix, formation.adjacency
    if adj[a, b] and adj[b, c] and adj[a, c]:
        x, y, z = dm[a, b], dm[b, c], dm[a, c]
        s = 0.5 * (x + y + z)
        return float(np.sqrt(max(s * (s - x) * (s - y) * (s - z), 0.0)))  # Heron
    if formation.alpha_values == "angle" and formation.has_orientation:
        alpha = dict(zip(map(tuple, formation.restricted_triples.tolist()),
                         formation.restricted_alpha, strict=True))  # fmt: skip
        for i, j, k in ((a, b, c), (b, c, a), (c, a, b)):
            if adj[i, j] and adj[i, k] and (i, j, k) in alpha:
                return 0.5 * dm[i, j] * dm[i, k] * abs(np.sin(alpha[i, j, k]))
    raise FormationError(
        f"the desired area of triangle ({a + 1},{b + 1},{c + 1}) is unknown: give a template, "
        "all three of its distances, or angle-valued alpha"
    )


def signed_areas(triangles: NDArray[np.int64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Signed areas ``A_abc = c_abc / 2`` of ``triangles`` (t, 3); ``(..., n, 2) -> (..., t)``."""
    q = np.asarray(q, dtype=float)
    a, b, c = (q[..., triangles[:, m], :] for m in range(3))
    return signed_area(a[..., 0], a[..., 1], b[..., 0], b[..., 1], c[..., 0], c[..., 1])


def grad_area_penalty(formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Gradient of ``1/2 sum (A_abc - A*_abc)^2``; ``(..., n, 2) -> (..., n, 2)``.

    ``grad_a A_abc = 1/2 k x r_bc``, ``grad_b = 1/2 k x r_ca``, ``grad_c = 1/2 k x r_ab``
    (the paper's eq. 23 for ``c_abc = 2 A_abc``).
    """
    q = np.asarray(q, dtype=float)
    tris, target = desired_areas(formation)
    out = np.zeros(q.shape)
    if len(tris) == 0:
        return out
    err = signed_areas(tris, q) - target  # (..., t)
    corner = np.eye(formation.n)[tris]  # (t, 3, n): one-hot robot of each corner
    for m in range(3):
        nxt, prv = tris[:, (m + 1) % 3], tris[:, (m + 2) % 3]
        g = 0.5 * perp(q[..., prv, :] - q[..., nxt, :])  # eq. (23), halved; (..., t, 2)
        out = out + np.einsum("...td,tn->...nd", err[..., None] * g, corner[:, m, :])
    return out


@register
@dataclass(frozen=True, kw_only=True)
class SignedAreaLaw(Law):
    """Distance and signed-area law ``u = -k grad (V_d + k_s V_A) - k_r grad Gamma``.

    ``V_d = 1/4 sum_E (r_ij^2 - d_ij^2)^2``, ``V_A = 1/2 sum (A_abc - A*_abc)^2``
    over the restricted triangles (module docstring), ``Gamma`` Khatib's
    repulsion between non-neighbours. A gradient flow of
    ``W = V_d + k_s V_A + (k_r / k) Gamma``.

    Reference: B. D. O. Anderson, Z. Sun, T. Sugie, S. Azuma and K. Sakurama,
    "Distance-based rigid formation control with signed area constraints",
    IEEE CDC 2017, doi:10.1109/CDC.2017.8264071.

    Parameters
    ----------
    k : float
        Overall gain. Default 1.
    k_s : float
        Weight of the signed-area penalty. Default 1.
    k_r : float
        Gain of the repulsion between non-neighbours. Default 2 (the paper's ``k_c``).
    repulsion : Repulsion
        Khatib's repulsion ``gamma_ij``.
    """

    name = "signed-area"
    dims = (2,)
    elsewhere = 'in space the chirality of tetrahedra takes its place: law = "chirality-restricted"'
    k: float = 1.0
    k_s: float = 1.0
    k_r: float = 2.0
    repulsion: Repulsion = field(default_factory=Repulsion)

    def __post_init__(self) -> None:
        check_fields(self, positive=("k",), nonnegative=("k_s", "k_r"))

    def control(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        u = -self.k * grad_squared_distance(formation, q)
        if self.k_s > 0:
            u = u - self.k * self.k_s * grad_area_penalty(formation, q)
        if self.k_r > 0:
            u = u - self.k_r * grad_repulsion(formation, q, self.repulsion)
        return u

    def potential(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``W = V_d + k_s V_A + (k_r / k) Gamma``, of which ``u = -k grad W``; shape ``(...)``."""
        v = squared_distance_sum(formation, q)
        tris, target = desired_areas(formation)
        if len(tris):
            err = signed_areas(tris, q) - target
            v = v + 0.5 * self.k_s * np.sum(err * err, axis=-1)
        if self.k_r > 0:
            v = v + (self.k_r / self.k) * repulsion_sum(formation, q, self.repulsion)
        return v

    def obstacle_repulsion(self) -> ObstacleRepulsion:
        """``-k_r grad Gamma_o``; ``u = -k grad W``, so ``W`` gains ``(k_r / k) Gamma_o``."""
        return ObstacleRepulsion(gain=self.k_r, weight=self.k_r / self.k, repulsion=self.repulsion)

    def kernel_terms(self, formation: Formation, *, pairs: bool = True) -> KernelTerms:
        rep = self.repulsion
        areas = desired_areas(formation) if self.k_s > 0 else None
        return build_terms(
            formation, pairs=pairs, kind=SQUARED, edge_gain=self.k, repulsion_gain=self.k_r,
            eta=rep.eta, influence=rep.influence, areas=areas, area_gain=self.k * self.k_s,
        )  # fmt: skip
