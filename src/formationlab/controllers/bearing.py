"""The bearing-only law of Zhao and Zelazo (2016): the other family of formation control.

Reference: S. Zhao and D. Zelazo, "Bearing Rigidity and Almost Global Bearing-Only Formation
Stabilization", IEEE Transactions on Automatic Control 61(5):1255-1268, 2016 (survey: S. Zhao
and D. Zelazo, "Bearing rigidity theory and its applications for control and estimation of
network systems", IEEE Control Systems Magazine 39(2):66-83, April 2019).

Their notation: positions ``p_i``, ``e_ij = p_j - p_i``, bearings ``g_ij = e_ij / ||e_ij||``,
desired bearings ``g*_ij`` (:attr:`formationlab.Formation.bearings`), the projection
``P_x = I_d - x x^T / ||x||^2``. The law (their eq. 11) is

    p_i' = -k sum_{j in N_i} P_{g_ij} g*_ij,

each robot steering by the part of each desired bearing that is orthogonal to the bearing it
measures. It needs no distances and has no mirror problem: bearings fix the shape up to a
translation and a scale (for an infinitesimally bearing-rigid formation,
:mod:`formationlab.formation.bearing_rigidity`), and the orientation too, so the robots need
a common sense of direction (a robot whose frame is turned feeds turned bearings:
:mod:`formationlab.sensing`).

Properties the tests check (their Lemma 2 and Theorem 5): the centroid ``p_bar`` and the
scale ``s = sqrt(1/n sum_i ||p_i - p_bar||^2)`` are constant along the flow (``e_ij^T P_{g_ij}
= 0``, and robot ``j`` gets the opposite of robot ``i``'s term); the Lyapunov function is
``V = 1/2 ||p - p*||^2``, with ``p*`` the target formation of the same centroid and scale as
``p`` (so ``V`` is a function of ``p`` alone), and ``V' = -k sum_E ||e*_ij|| g*_ij^T P_{g_ij}
g*_ij <= 0``; from almost every start the robots reach ``p*``; the one other equilibrium,
every bearing reversed (``p*`` turned by pi in the plane), is unstable.

All of it holds in any dimension (their setting is ``R^d``). In space the reversed
equilibrium ``-p*`` is the point reflection of the target, the mirror image of the other
chirality: the bearing law reaches the template's chirality from almost every start,
where the distance law reaches each chirality about half the time (docs/three-d.md).

The law has no barrier at contact: two robots may meet, where their bearing is undefined. To
compare collision counts with the distance laws, Khatib's repulsion between robots that are
not neighbours may be added with ``k_r > 0`` (default 0, the law as published; with it the
scale is no longer constant).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import FormationError
from ..formation.bearing_rigidity import bearing_laplacian, bearing_realisation
from ..formation.geometry import scatter_rows
from ..formation.spec import Formation
from ..validation import check_fields
from .base import Law, ObstacleRepulsion, Repulsion, register
from .kinds.bearing import (
    bearing_force,
    bearing_force_in_space,
    bearing_misalignment,
    bearing_misalignment_in_space,
)
from .squared_distance import grad_repulsion
from .terms import BEARING, KernelTerms, build_terms

__all__ = [
    "BearingLaw",
    "bearing_controls",
    "bearing_lyapunov",
    "bearing_lyapunov_rate",
    "leader_target",
    "target",
]


def _bearings(formation: Formation) -> NDArray[np.float64]:
    if formation.bearings is None:
        raise FormationError(
            "the bearing law needs desired bearings: Formation.with_bearings() (from the "
            "template, or given per edge), or [formation] template = [...] in a scenario",
            key="bearings",
        )
    return formation.bearings


def bearing_controls(formation: Formation, q: NDArray[np.float64], k: float = 1.0) -> NDArray:
    """``p_i' = -k sum_{j in N_i} P_{g_ij} g*_ij`` (Zhao and Zelazo 2016, eq. 11); ``(..., n,
    d)``, in the plane or in space."""
    q = np.asarray(q, dtype=float)
    b = _bearings(formation)
    i, j = formation.edges[:, 0], formation.edges[:, 1]
    r = q[..., j, :] - q[..., i, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        if q.shape[-1] == 3:
            rx, ry, rz = r[..., 0], r[..., 1], r[..., 2]
            f = bearing_force_in_space(rx, ry, rz, b[:, 0], b[:, 1], b[:, 2], k)  # eq. (11)
        else:
            f = bearing_force(r[..., 0], r[..., 1], b[:, 0], b[:, 1], k)  # eq. (11)
    f = np.stack(f, axis=-1)
    return scatter_rows(f, i, formation.n) - scatter_rows(f, j, formation.n)


def target(formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """``p*``: the formation of the desired bearings with the centroid and the scale of ``q``
    (Zhao and Zelazo 2016, Theorem 5); ``(..., n, 2)``. Constant along the law's flow."""
    q = np.asarray(q, dtype=float)
    t = bearing_realisation(formation)  # centred, scale 1
    c = q.mean(axis=-2, keepdims=True)
    s = np.sqrt(np.mean(np.sum((q - c) ** 2, axis=-1), axis=-1))  # s(p), their eq. (13)
    return c + s[..., None, None] * t


def bearing_lyapunov(formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """``V = 1/2 ||p - p*||^2`` with ``p*`` of :func:`target`; shape ``(...)``."""
    q = np.asarray(q, dtype=float)
    d = q - target(formation, q)
    return 0.5 * np.sum(d * d, axis=(-2, -1))


def bearing_lyapunov_rate(
    formation: Formation, q: NDArray[np.float64], k: float = 1.0
) -> NDArray[np.float64]:
    """``V' = -k sum_E ||e*_ij|| g*_ij^T P_{g_ij} g*_ij`` along the law (proof of Theorem 5),
    with ``e*`` of the target :func:`target`; shape ``(...)``, never positive."""
    q = np.asarray(q, dtype=float)
    b = _bearings(formation)
    i, j = formation.edges[:, 0], formation.edges[:, 1]
    p = target(formation, q)
    length = np.linalg.norm(p[..., j, :] - p[..., i, :], axis=-1)  # ||e*_ij||
    r = q[..., j, :] - q[..., i, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        if q.shape[-1] == 3:
            rx, ry, rz = r[..., 0], r[..., 1], r[..., 2]
            m = bearing_misalignment_in_space(rx, ry, rz, b[:, 0], b[:, 1], b[:, 2])
        else:
            m = bearing_misalignment(r[..., 0], r[..., 1], b[:, 0], b[:, 1])
    return -k * np.sum(length * m, axis=-1)


def leader_target(
    formation: Formation, leaders: ArrayLike, p_leaders: ArrayLike
) -> NDArray[np.float64]:
    """Where the followers belong when the ``leaders`` (robot numbers, 1-based) stand at
    ``p_leaders`` ``(l, d)``: the formation of the desired bearings through them, ``(n, d)``.

    Zhao and Zelazo, "Translational and scaling formation maneuver control via a
    bearing-based approach", IEEE Transactions on Control of Network Systems 4(3):429-438,
    2017, Theorem 1: with the bearing Laplacian ``L_B`` partitioned into leaders ``l`` and
    followers ``f``, the target is unique if and only if ``L_ff`` is non-singular, and then
    ``p*_f = -L_ff^{-1} L_fl p_l``. Two leaders fix the position and the scale (and, with
    the bearings, the whole formation); the leaders keep their places. Refused when the
    leaders do not fix the target.
    """
    b = _bearings(formation)
    n = formation.n
    lead = np.unique(np.asarray(leaders, dtype=np.int64).reshape(-1)) - 1
    if lead.size < 2 or lead.min() < 0 or lead.max() >= n:
        raise FormationError(
            f"a bearing formation needs at least two leaders among robots 1..{n} to fix its "
            f"position and scale, got {np.asarray(leaders).tolist()}", key="leaders",
        )  # fmt: skip
    pl = np.asarray(p_leaders, dtype=float).reshape(lead.size, formation.dim)
    follow = np.setdiff1d(np.arange(n), lead)
    lap = bearing_laplacian(b, formation.edges, n).toarray()
    d = formation.dim
    cols_f = (d * follow[:, None] + np.arange(d)).ravel()
    cols_l = (d * lead[:, None] + np.arange(d)).ravel()
    l_ff, l_fl = lap[np.ix_(cols_f, cols_f)], lap[np.ix_(cols_f, cols_l)]
    if np.linalg.matrix_rank(l_ff) < l_ff.shape[0]:
        raise FormationError(
            "these leaders do not fix the followers' places (L_ff is singular, Zhao and "
            "Zelazo 2017, Theorem 1): choose leaders whose bearings pin every follower",
            key="leaders",
        )
    out = np.empty((n, d))
    out[lead] = pl
    out[follow] = np.linalg.solve(l_ff, -l_fl @ pl.ravel()).reshape(-1, d)  # Theorem 1
    return out


@register
@dataclass(frozen=True, kw_only=True)
class BearingLaw(Law):
    """Bearing-only law ``u_i = -k sum_{j in N_i} P_{g_ij} g*_ij`` (Zhao and Zelazo 2016).

    Reference: S. Zhao and D. Zelazo, "Bearing Rigidity and Almost Global Bearing-Only
    Formation Stabilization", IEEE Transactions on Automatic Control 61(5):1255-1268, 2016.

    The formation's desired bearings (:meth:`Formation.with_bearings`, from its template
    when it has none) define the target; the outcome of a run is judged by them.

    Parameters
    ----------
    k : float
        Gain. Default 1.
    k_r : float
        Gain of Khatib's repulsion between robots that are not neighbours, and from
        obstacles. Default 0: the law as published (the scale of the formation constant).
    repulsion : Repulsion
        Khatib's repulsion ``gamma_ij``.
    """

    name = "bearing"
    invariance = "scale"  # u(s q) = u(q): bearings fix the shape up to translation and scale
    k: float = 1.0
    k_r: float = 0.0
    repulsion: Repulsion = field(default_factory=Repulsion)

    def __post_init__(self) -> None:
        check_fields(self, positive=("k",), nonnegative=("k_r",))

    def formation_for(self, formation: Formation) -> Formation:
        """The formation judged by its bearings: its own, or its template's; refused, with
        how to give them, when it has neither, and when they do not fix the shape (not
        infinitesimally bearing rigid: :func:`bearing_realisation`)."""
        self.check_dim(formation)
        if formation.bearings is None:
            if formation.template is None:
                _bearings(formation)  # says how to give them
            formation = formation.with_bearings()
        bearing_realisation(formation)  # (computed once per formation)
        return formation

    def control(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        formation = self.formation_for(formation)  # (itself inside a closed loop)
        u = bearing_controls(formation, q, self.k)
        if self.k_r > 0:
            u = u - self.k_r * grad_repulsion(formation, q, self.repulsion)
        return u

    def potential(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``V = 1/2 ||p - p*||^2`` (module docstring): non-increasing along the law with
        ``k_r = 0``; with the repulsion it measures the distance to the target only."""
        return bearing_lyapunov(self.formation_for(formation), q)

    def obstacle_repulsion(self) -> ObstacleRepulsion:
        """``-k_r grad Gamma_o`` (weight 0 in ``V``: the law is not a gradient flow)."""
        return ObstacleRepulsion(gain=self.k_r, weight=0.0, repulsion=self.repulsion)

    def kernel_terms(self, formation: Formation, *, pairs: bool = True) -> KernelTerms:
        formation = self.formation_for(formation)
        rep = self.repulsion
        return build_terms(
            formation, pairs=pairs, kind=BEARING, edge_gain=self.k, repulsion_gain=self.k_r,
            eta=rep.eta, influence=rep.influence,
        )  # fmt: skip
