"""Neighbours that disagree about a distance: the distorted formation in steady rigid motion.

Mou, Belabbas, Morse, Sun and Anderson, "Undirected rigid formations are
problematic", IEEE Transactions on Automatic Control 61(10), 2016, show that when
the two robots of an edge hold slightly different desired distances
(``d_ij != d_ji``), the squared-distance gradient law of Krick et al. no longer
comes to rest: the formation converges exponentially to a distorted but rigid shape
that travels a circle at a constant angular speed. With ``sensing.mismatch`` the
package realises such disagreements (:class:`formationlab.sensing.Channel`:
``own_distance[e] = (d_ij + e_ij, d_ij + e_ji)``); this module finds the motion they
end in without simulating. Equations (M1) to (M4) below are derived here (they agree
with the paper's statement above; the tests hold them against simulated runs), not
copied from the paper.

**Why a rotation.** Every edge law of the package gives robot ``i`` the term
``g_ij(r) z_ij`` (``z_ij = q_j - q_i``, ``g_ij = k (r^2 - d_ij^2)`` for Krick et al.,
``k_c phi'(r) / r`` for the paper's eq. (8)), with robot ``i``'s own ``d_ij``. A shape
whose distances stay constant is one whose velocity field is rigid,
``u_i = v + omega k x (q_i - q_bar)``; a rigid field has angular momentum
``L = sum_i (q_i - q_bar) x u_i = omega I``, ``I = sum_i |q_i - q_bar|^2``, and the
edge terms give (the symmetric parts, and Khatib's repulsion, cancel)

``omega = sum_(i,j) in E (g_ij - g_ji) (q_i - q_bar) x (q_j - q_bar) / I``.   (M1)

With agreement ``g_ij = g_ji`` and ``omega = 0``: the gradient flow comes to rest.
With disagreement the weighted sum of the edges' signed areas vanishes only on a
set of measure zero of the errors, so "almost for certain" ``omega != 0``, and a
rigid motion with ``omega != 0`` is a rotation about the fixed centre
``c = q_bar + (k x v) / omega``: the centroid, like every robot, goes round a circle.
A pure translation (``omega = 0``, ``v != 0``) is the exceptional case.

**First order.** ``g_ij - g_ji`` is already of the order of the errors, so (M1) at
the desired shape ``p`` is ``omega`` to first order (the shape's distortion enters at
second order):

``omega_1 = sum_E kappa_ij (dhat_ji - dhat_ij) (p_i - p_bar) x (p_j - p_bar) / I(p)``,  (M2)

``kappa = -dg/d(dhat)`` at ``r = dhat = d``: ``2 k d`` for Krick et al.,
``k_c / ((d - a)^2 d)`` for the log barrier of eq. (7).

**The triangle.** For Krick et al.'s law ``g_ij - g_ji = k (dhat_ji^2 - dhat_ij^2)``
whatever the shape, the centroid cuts a triangle into three of equal area, so
``(q_i - q_bar) x (q_j - q_bar) = 2 A / 3`` for each counter-clockwise pair ``(i, j)``
(``A`` the signed area, robots 1, 2, 3 counter-clockwise), and
``I = (a^2 + b^2 + c^2) / 3`` for sides ``a, b, c``. (M1) is then, exactly,

``omega = 2 k A / (a^2 + b^2 + c^2) sum_ccw (dhat_ji^2 - dhat_ij^2)``,   (M3)

the sum over the three edges oriented counter-clockwise, ``i -> j``, and ``A``,
``a, b, c`` those of the distorted steady shape. The factor ``2 A / (a^2 + b^2 + c^2)``
is largest, ``sqrt(3) / 6``, for the equilateral triangle (Weitzenboeck's
inequality), so on the equilateral triangle of side ``d`` the first-order

``omega_1 = k / (2 sqrt 3) sum_ccw (dhat_ji^2 - dhat_ij^2)``   (M4)

is off only at third order in the errors (a first-order distortion leaves a
stationary factor unchanged). It is linear in the errors: with independent
``e ~ N(0, sigma^2)``, ``omega_1 ~ N(0, 2 k^2 d^2 sigma^2)`` and
``E |omega_1| = 2 k d sigma / sqrt(pi)``: the drift grows in proportion to the
mismatch. :func:`first_order_motion` evaluates (M2) (and the centroid velocity, the
mean of ``u`` at ``p``) from the package's own controls.

**The solver.** :func:`steady_motion` solves for the shape directly: unknowns the
positions ``q`` ``(n, 2)``, ``omega`` and the centroid velocity ``v`` (``2n + 3``);
equations the rigid field ``u_i(q) = v + omega k x (q_i - q_bar)`` (``2n``) and a
gauge that fixes the shape's position and turn (``3``): its centroid is the guess's,
and its Procrustes rotation from the guess is zero, ``sum_i (g_i - g_bar) x q_i = 0``.
``u`` is the mismatched per-robot control of :func:`formationlab.sensing.local_controls`
from the law's kernel terms. scipy's Levenberg-Marquardt solves the square system.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..controllers import Law
from ..errors import ParameterError
from ..formation.geometry import cross, perp
from ..formation.realisability import best_realisation
from ..formation.spec import Formation
from ..models import SingleIntegrator
from ..outcomes.analysis import distance_errors, orientation_agreement
from ..outcomes.rigid_motion import RigidMotion, field_motion
from ..sensing import Channel, Sensing, local_controls, measured

__all__ = [
    "DriftTable",
    "SteadyMotion",
    "first_order_motion",
    "measure_drift",
    "mismatched_controls",
    "own_distances",
    "rigid_omega",
    "steady_motion",
]

#: largest rigid-field residual (m/s) of a converged solution
TOL = 1e-9


def _own(formation: Formation, own_distance: ArrayLike | None) -> NDArray[np.float64]:
    """``own_distance`` validated, shape ``(E, 2)``; None: every robot holds ``d_ij``."""
    e = len(formation.edges)
    if own_distance is None:
        return np.repeat(np.asarray(formation.distances, float)[:, None], 2, axis=1)
    own = np.asarray(own_distance, dtype=float)
    if own.shape != (e, 2):
        raise ParameterError(
            f"own_distance must have shape (E, 2) = ({e}, 2), one row per edge in the order "
            f"of formation.edges (the distance as robots i and j hold it), got {own.shape}",
            key="own_distance",
        )
    if not np.all(np.isfinite(own)) or np.any(own <= 0):
        raise ParameterError("own_distance must hold finite positive distances", key="own_distance")
    return own


def mismatched_controls(
    formation: Formation, law: Law, q: ArrayLike, own_distance: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Every robot's control ``(..., n, 2)`` at positions ``q`` ``(..., n, 2)``.

    Robot ``i`` steers each edge to its own desired distance (``own_distance``
    ``(E, 2)``, column 0 held by ``formation.edges[e, 0]``); exact measurements in a
    common frame (:func:`formationlab.sensing.local_controls`).
    """
    own = _own(formation, own_distance)
    terms = law.compiled_terms(formation)
    return local_controls(terms, measured(np.asarray(q, dtype=float), None), own_distance=own)


def rigid_omega(q: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
    """``L / I``: the angular velocity of a rigid field ``u`` at ``q`` (eq. M1 of the module).

    ``q``, ``u`` ``(..., n, 2)``; returns ``(...)``. For a field that is not rigid this
    is the angular velocity of its least-squares rigid part.
    """
    q, u = np.asarray(q, dtype=float), np.asarray(u, dtype=float)
    b = q - q.mean(axis=-2, keepdims=True)
    return np.sum(cross(b, u), axis=-1) / np.sum(b * b, axis=(-2, -1))  # omega = L / I


def own_distances(
    formation: Formation, law: Law, mismatch: float, seeds: Sequence[int]
) -> NDArray[np.float64]:
    """The desired distances each robot holds, ``(len(seeds), E, 2)``, as a run draws them.

    Trial ``b`` is what ``simulate(..., sensing=Sensing(mismatch=mismatch,
    seed=seeds[b]))`` realises (:class:`formationlab.sensing.Channel`).
    """
    if mismatch == 0:
        return np.stack([_own(formation, None)] * len(seeds))
    channel = Channel(
        Sensing(mismatch=mismatch), formation, law, SingleIntegrator(), list(seeds), 1.0
    )
    assert channel.own_distance is not None
    return channel.own_distance


def desired_shape(formation: Formation) -> NDArray[np.float64]:
    """A shape ``(n, 2)`` meeting the distances, in the desired orientation where there is one.

    The template, else the best realisation of the distances; mirrored when most
    restricted triples turn the wrong way.
    """
    q = formation.template
    if q is None:
        q, _ = best_realisation(formation)
    q = np.array(q, dtype=float)
    if formation.has_orientation:
        agree, disagree = orientation_agreement(formation, q)
        if disagree > agree:
            q[:, 0] = -q[:, 0]
    return q


@dataclass(frozen=True, kw_only=True, eq=False)
class SteadyMotion:
    """The distorted shape whose closed-loop field is a rigid motion (:func:`steady_motion`).

    Attributes
    ----------
    q : ndarray, shape (n, 2)
        The shape, centred and turned as the guess (the gauge).
    omega : float
        Angular velocity, rad/s (counter-clockwise positive).
    velocity : ndarray, shape (2,)
        Velocity of the centroid, m/s.
    centre : ndarray, shape (2,)
        Centre of the rotation, ``q_bar + (k x v) / omega``; NaN when the rotation moves
        no robot faster than ``tol`` about the centroid (``kind`` is not ``"rotation"``).
    distance_error : ndarray, shape (E,)
        ``r_ij - d_ij`` of the shape, in the order of ``formation.edges``.
    residual : float
        ``max_i |u_i - v - omega k x (q_i - q_bar)|``, m/s.
    converged : bool
        Whether the solver stopped with ``residual <= tol``.
    message : str
        The solver's message.
    own_distance : ndarray, shape (E, 2)
        The distances the robots steered to.
    kind : {"rotation", "translation", "rest"}
        ``"rotation"`` when the rotation moves some robot about the centroid faster than
        ``tol``; otherwise ``"translation"`` when the centroid moves faster than ``tol``,
        else ``"rest"`` (an equilibrium: no mismatch, or one that cancels).
    """

    q: NDArray[np.float64]
    omega: float
    velocity: NDArray[np.float64]
    centre: NDArray[np.float64]
    distance_error: NDArray[np.float64]
    residual: float
    converged: bool
    message: str
    own_distance: NDArray[np.float64]
    kind: str

    @property
    def speed(self) -> float:
        """Speed of the centroid, ``|v| = |omega| |q_bar - c|``, m/s."""
        return float(np.linalg.norm(self.velocity))

    @property
    def motion(self) -> RigidMotion:
        """As the :class:`~formationlab.outcomes.rigid_motion.RigidMotion` of an exact rigid
        field."""
        return field_motion(self.q, self.velocity, self.omega)


def steady_motion(
    formation: Formation,
    law: Law,
    own_distance: ArrayLike | None,
    *,
    guess: ArrayLike | None = None,
    tol: float = TOL,
) -> SteadyMotion:
    """The shape whose mismatched closed-loop field is a rigid motion (module docstring).

    Solves ``u_i(q) = v + omega k x (q_i - q_bar)`` (Mou et al., IEEE TAC 61(10), 2016:
    the distorted formation's steady motion) for ``q``, ``omega`` and ``v`` with a gauge
    that pins the shape's centroid and turn to the guess's.

    Parameters
    ----------
    formation, law
        The formation and its law (any law with kernel terms).
    own_distance : array_like, shape (E, 2), or None
        Edge ``e``'s desired distance as robot ``formation.edges[e, 0]`` (column 0) and
        robot ``formation.edges[e, 1]`` (column 1) hold it; ``Channel.own_distance[b]``.
        None: no mismatch.
    guess : array_like, shape (n, 2), optional
        Start of the solver, and the gauge; default :func:`desired_shape`. The solution
        is the rigid motion near it: pass a late state of a run to find the one the
        run reached.
    tol : float
        Largest residual (m/s) accepted as converged.

    Returns
    -------
    SteadyMotion
    """
    from scipy.optimize import least_squares

    own = _own(formation, own_distance)
    g = desired_shape(formation) if guess is None else np.array(guess, dtype=float)
    n = formation.n
    if g.shape != (n, 2) or not np.all(np.isfinite(g)):
        raise ParameterError(
            f"guess must be finite positions of shape ({n}, 2), got {g.shape}", key="guess"
        )
    terms = law.compiled_terms(formation)
    gbar = g.mean(axis=0)
    gc = g - gbar
    scale = float(np.sqrt(np.sum(gc * gc) / n)) or 1.0

    def unpack(x: NDArray[np.float64]) -> tuple[NDArray, float, NDArray]:
        return x[: 2 * n].reshape(n, 2), float(x[2 * n]), x[2 * n + 1 :]

    def rigid_part(q: NDArray, omega: float, v: NDArray) -> NDArray:
        u = local_controls(terms, measured(q, None), own_distance=own)
        return u - v - omega * perp(q - q.mean(axis=0))  # u_i - v - omega k x (q_i - q_bar)

    def equations(x: NDArray[np.float64]) -> NDArray[np.float64]:
        q, omega, v = unpack(x)
        gauge = [*(q.mean(axis=0) - gbar), np.sum(cross(gc, q)) / scale]  # centroid, turn
        return np.concatenate([rigid_part(q, omega, v).ravel(), gauge])

    u0 = local_controls(terms, measured(g, None), own_distance=own)
    x0 = np.concatenate([g.ravel(), [rigid_omega(g, u0)], u0.mean(axis=0)])
    sol = least_squares(equations, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    q, omega, v = unpack(sol.x)
    residual = float(np.max(np.linalg.norm(rigid_part(q, omega, v), axis=-1)))
    spin = abs(omega) * float(np.max(np.linalg.norm(q - q.mean(axis=0), axis=-1)))
    kind = "rotation" if spin > tol else "translation" if np.linalg.norm(v) > tol else "rest"
    centre = q.mean(axis=0) + perp(v) / omega if kind == "rotation" else np.full(2, np.nan)
    return SteadyMotion(
        q=q, omega=omega, velocity=np.array(v), centre=centre,
        distance_error=distance_errors(formation, q), residual=residual,
        converged=bool(sol.status > 0 and residual <= tol), message=str(sol.message),
        own_distance=own, kind=kind,
    )  # fmt: skip


def first_order_motion(
    formation: Formation,
    law: Law,
    own_distance: ArrayLike | None,
    *,
    shape: ArrayLike | None = None,
) -> tuple[float, NDArray[np.float64]]:
    """``(omega_1, v_1)``: the steady motion to first order in the mismatch (eq. M2).

    ``omega_1 = L(p) / I(p)`` and ``v_1`` the mean of ``u(p)``, the mismatched field at
    the desired shape ``p`` (``shape``; default :func:`desired_shape`). First order
    when the law without mismatch is the gradient of a rotation-invariant potential
    near ``p`` (the squared-distance and distance laws; the angle-restricted law with
    its restrictions off), so that its own field has no angular momentum.
    """
    p = desired_shape(formation) if shape is None else np.asarray(shape, dtype=float)
    u = mismatched_controls(formation, law, p, own_distance)
    return float(rigid_omega(p, u)), u.mean(axis=0)  # eq. (M2); v_1 = mean_i u_i(p)


@dataclass(frozen=True, kw_only=True, eq=False)
class DriftTable:
    """Steady drift against mismatch (:func:`measure_drift`).

    Attributes
    ----------
    mismatch : ndarray, shape (S,)
        The standard deviations ``sigma`` (m) of the robots' errors.
    seeds : ndarray, shape (B,)
        The realisations' seeds (``Sensing.seed``).
    omega : ndarray, shape (S, B)
        Steady angular velocity, rad/s.
    speed : ndarray, shape (S, B)
        Steady speed of the centroid, m/s.
    distortion : ndarray, shape (S, B)
        ``max |r_ij - d_ij|`` of the steady shape, m.
    converged : ndarray of bool, shape (S, B)
        Whether the solver converged.
    """

    mismatch: NDArray[np.float64]
    seeds: NDArray[np.int64]
    omega: NDArray[np.float64]
    speed: NDArray[np.float64]
    distortion: NDArray[np.float64]
    converged: NDArray[np.bool_]

    def summary(self) -> dict[str, NDArray[np.float64]]:
        """Mean and standard deviation over the seeds of ``|omega|``, speed, distortion."""
        out = {}
        for name, a in (("omega", np.abs(self.omega)), ("speed", self.speed),
                        ("distortion", self.distortion)):  # fmt: skip
            out[f"{name}_mean"] = a.mean(axis=1)
            out[f"{name}_std"] = a.std(axis=1, ddof=1) if a.shape[1] > 1 else np.zeros(len(a))
        return out

    def slope(self) -> float:
        """Slope of ``log mean |omega|`` against ``log sigma`` over ``sigma > 0``: 1 if linear."""
        m = self.mismatch > 0
        w = np.abs(self.omega[m]).mean(axis=1)
        return float(np.polyfit(np.log(self.mismatch[m]), np.log(w), 1)[0])


def measure_drift(
    formation: Formation,
    law: Law,
    mismatch: Sequence[float],
    seeds: Sequence[int],
    *,
    guess: ArrayLike | None = None,
) -> DriftTable:
    """The steady rigid motion of every ``(sigma, seed)``, by :func:`steady_motion`.

    For each mismatch ``sigma`` and seed, the robots' desired distances are those a
    run with ``Sensing(mismatch=sigma, seed=seed)`` draws (:func:`own_distances`).
    """
    sig = np.asarray(mismatch, dtype=float)
    if sig.ndim != 1 or np.any(sig < 0) or not np.all(np.isfinite(sig)):
        raise ParameterError(f"mismatch must be a list of numbers >= 0, got {mismatch!r}")
    shape = (sig.size, len(seeds))
    omega, speed, dist = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    ok = np.zeros(shape, dtype=bool)
    for a, s in enumerate(sig):
        for b, own in enumerate(own_distances(formation, law, float(s), seeds)):
            m = steady_motion(formation, law, own, guess=guess)
            omega[a, b], speed[a, b], ok[a, b] = m.omega, m.speed, m.converged
            dist[a, b] = np.max(np.abs(m.distance_error))
    return DriftTable(
        mismatch=sig, seeds=np.asarray(seeds, dtype=np.int64), omega=omega, speed=speed,
        distortion=dist, converged=ok,
    )  # fmt: skip
