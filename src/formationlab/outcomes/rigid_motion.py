"""Formations that move as a rigid body: the fit and the decision ``drifting`` / ``rotating``.

A relative equilibrium of the closed loop is a shape that the field moves
rigidly, ``u_i = v + omega k x (q_i - c)``: it never stops, yet its shape does
not change (the angle-restricted law has them on the hexagon: ``docs/drifting.md``).
Every path that classifies a final state (single runs, the batched kernel and
its numpy specification, settling) reads the motion the same way, here:

:func:`rigid_motion` fits the rigid motion that carries the positions
``P = q(t - T)`` onto ``Q = q(t)`` over the *drift window* ``T``: the rotation
``phi`` of the least-squares (Procrustes) fit of the centred shapes,
``phi = atan2(sum_i A_i x B_i, sum_i A_i . B_i)`` with ``A_i = P_i - P_bar``,
``B_i = Q_i - Q_bar``, and the motion of constant ``omega = phi / T`` along the
circular arc through both centroids. The *shape rate* is what the fit leaves,
``max_i |B_i - R(phi) A_i| / T``; it is zero exactly when the shape did not
change (every distance and angle kept).

:func:`rigid_outcome` decides: ``drifting`` (a translation) or ``rotating``
(an angular velocity ``omega`` about a centre ``c``) when the shape rate is at
most ``Tolerances.shape`` while the rigid motion moves some robot faster than
that; ``rotating`` when the rotation alone moves the robots about their
centroid faster than ``Tolerances.shape`` (``|omega| max_i |B_i|``).

In space (``(..., n, 3)``) the fit is Kabsch's, and the motion of constant velocity and
angular velocity is a screw (Chasles's theorem): a rotation by ``phi`` about a fixed axis
and a translation ``tau`` along it. Its axis, its rate ``omega = phi / T`` and the
centroid's velocity at the end of the window are fitted exactly as in the plane, the
plane's formulas applied across the axis (the centroid's chord across the axis turned by
``phi / 2`` and lengthened by ``(phi / 2) / sin(phi / 2)``) and ``tau / T`` along it; the
centre is the point of the screw axis nearest the centroid. Sun, Mou, Anderson and Morse,
"Rigid motions of 3-D undirected formations with mismatch between desired distances"
(IEEE Transactions on Automatic Control 62(8), 2017) show that mismatched distances drive a
formation in space into such a helical motion.

Why a window of seconds and not the check interval of the stopping rule:
explicit Euler on a switching surface chatters by about ``dt max_i |u_i|``
(``~1e-2`` m on the hexagon) at every step; over 10 ms that is a shape rate of
up to 1 m/s, over 2 s at most about 1e-2 m/s. A rotation by more than ``pi`` over the
window cannot be told from a slower one (``|omega| < pi / T``: 1.57 rad/s at
the default 2 s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..formation.geometry import cross, perp
from .tolerances import Tolerances

__all__ = ["RigidMotion", "field_motion", "kabsch", "rigid_motion", "rigid_outcome"]

#: codes of :func:`rigid_outcome`
NOT_RIGID, DRIFTING, ROTATING = 0, 1, 2


@dataclass(frozen=True, kw_only=True, eq=False)
class RigidMotion:
    """The rigid motion fitted over the drift window, for a batch of shape ``S``.

    Attributes
    ----------
    velocity : ndarray, shape S + (2,)
        Velocity of the centroid at the end of the window, m/s.
    omega : ndarray, shape S
        Angular velocity, rad/s (counter-clockwise positive).
    centre : ndarray, shape S + (2,)
        Centre of the rotation, ``c = Q_bar + (k x v) / omega`` (from
        ``v = omega k x (Q_bar - c)``); NaN where ``omega = 0``.
    speed : ndarray, shape S
        Largest speed of a robot in the rigid motion, ``max_i |v + omega k x B_i|``.
    spin : ndarray, shape S
        Largest speed of a robot about the centroid, ``|omega| max_i |B_i|``.
    shape_rate : ndarray, shape S
        ``max_i |B_i - R(phi) A_i| / T``: how fast the shape changed, m/s.
    window : ndarray, shape S
        The window ``T``, seconds (NaN: no positions that far back).
    axis : ndarray, shape S + (3,), or None
        In space, the unit direction of the rotation's axis (``omega >= 0`` about it, by
        the right hand); None in the plane, where the axis is ``k`` and ``omega`` signed.
    """

    velocity: NDArray[np.float64]
    omega: NDArray[np.float64]
    centre: NDArray[np.float64]
    speed: NDArray[np.float64]
    spin: NDArray[np.float64]
    shape_rate: NDArray[np.float64]
    window: NDArray[np.float64]
    axis: NDArray[np.float64] | None = None

    def __getitem__(self, index: int | slice | NDArray[np.intp]) -> RigidMotion:
        """The motions of some trials of a batch."""
        axis = None if self.axis is None else self.axis[index]
        return RigidMotion(**{k: getattr(self, k)[index] for k in _FIELDS}, axis=axis)

    @classmethod
    def unknown(cls, shape: tuple[int, ...] = (), dim: int = 2) -> RigidMotion:
        """No window (a run shorter than it, or a trial that stopped before it): all NaN."""
        nan, nan2 = np.full(shape, np.nan), np.full((*shape, dim), np.nan)
        return cls(
            velocity=nan2, omega=nan, centre=nan2.copy(), speed=nan.copy(), spin=nan.copy(),
            shape_rate=nan.copy(), window=nan.copy(), axis=nan2.copy() if dim == 3 else None,
        )  # fmt: skip

    @property
    def axial_velocity(self) -> NDArray[np.float64]:
        """In space, the translation's rate along the axis, ``velocity . axis`` (m/s): the
        screw's advance; zero for a rotation about a fixed axis or a motion in the plane."""
        if self.axis is None:
            return np.zeros(np.shape(self.omega))
        return np.sum(self.velocity * self.axis, axis=-1)

    @property
    def pitch(self) -> NDArray[np.float64]:
        """The screw's advance per radian, ``axial_velocity / omega`` (m/rad; inf for a
        translation along the axis, NaN for rest)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.axial_velocity / self.omega


_FIELDS = ("velocity", "omega", "centre", "speed", "spin", "shape_rate", "window")


def rigid_motion(before: ArrayLike, after: ArrayLike, window: ArrayLike) -> RigidMotion:
    """Fit the rigid motion carrying ``before`` onto ``after`` in ``window`` seconds.

    Parameters
    ----------
    before, after : array_like, shape (..., n, 2)
        Positions ``q(t - T)`` and ``q(t)``; NaN in ``before`` gives an unknown motion.
    window : array_like, shape (...)
        ``T``, seconds; not positive or NaN gives an unknown motion.

    Returns
    -------
    RigidMotion
        Of batch shape ``(...)``. The motion is the one of constant velocity and
        angular velocity: the centroid moves along the arc of angle ``phi`` whose
        chord is ``Q_bar - P_bar``, so its velocity at the end is the chord turned
        by ``phi / 2`` and lengthened by ``(phi / 2) / sin(phi / 2)``.
    """
    p = np.asarray(before, dtype=float)
    q = np.asarray(after, dtype=float)
    t = np.asarray(window, dtype=float)
    if p.shape[-1] == 3:
        return _rigid_motion_in_space(p, q, t)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(t > 0, t, np.nan)
        pc, qc = p.mean(axis=-2), q.mean(axis=-2)
        a, b = p - pc[..., None, :], q - qc[..., None, :]
        phi = np.arctan2(np.sum(cross(a, b), axis=-1), np.sum(a * b, axis=(-2, -1)))
        c, s = np.cos(phi)[..., None], np.sin(phi)[..., None]
        ra = c[..., None] * a + s[..., None] * perp(a)  # R(phi) A_i
        shape_rate = np.max(np.linalg.norm(b - ra, axis=-1), axis=-1) / t
        omega = phi / t
        half = 0.5 * phi[..., None]
        chord = qc - pc
        stretch = np.where(half == 0.0, 1.0, half / np.sin(np.where(half == 0.0, 1.0, half)))
        turned = np.cos(half) * chord + np.sin(half) * perp(chord)
        velocity = stretch * turned / t[..., None]
        centre = qc + perp(velocity) / np.where(omega == 0.0, np.nan, omega)[..., None]
        spin = np.abs(omega) * np.max(np.linalg.norm(b, axis=-1), axis=-1)
        move = velocity[..., None, :] + omega[..., None, None] * perp(b)
        speed = np.max(np.linalg.norm(move, axis=-1), axis=-1)
    return RigidMotion(
        velocity=velocity, omega=omega, centre=centre, speed=speed, spin=spin,
        shape_rate=shape_rate, window=t,
    )  # fmt: skip


def kabsch(a: NDArray, b: NDArray) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The rotation ``R`` (``det R = +1``) that best carries the centred points ``a`` onto
    ``b`` in space, least ``sum_i |B_i - R A_i|^2``; shapes ``(..., n, 3) -> (..., 3, 3)``.

    From the singular value decomposition of ``sum_i B_i A_i^T``, with the sign of its last
    singular direction chosen to keep a rotation, never a reflection (W. Kabsch, "A solution
    for the best rotation to relate two sets of vectors", Acta Crystallographica A32, 1976).
    Also returns where the sum is finite (elsewhere ``R`` is that of zero points).
    """
    h = np.einsum("...ni,...nj->...ij", b, a)  # sum_i B_i A_i^T
    ok = np.all(np.isfinite(h), axis=(-2, -1))
    u, _, vt = np.linalg.svd(np.where(ok[..., None, None], h, 0.0))
    flip = np.sign(np.linalg.det(u @ vt))
    u[..., :, 2] *= np.where(flip == 0, 1.0, flip)[..., None]
    return u @ vt, ok


def _rigid_motion_in_space(p: NDArray, q: NDArray, t: NDArray) -> RigidMotion:
    """:func:`rigid_motion` of positions in space ``(..., n, 3)``.

    The rotation ``R`` is the least-squares (Kabsch) fit of the centred shapes, from the
    singular value decomposition of ``sum_i B_i A_i^T`` with the sign that keeps ``det R =
    +1`` (a rotation, never a reflection) (W. Kabsch, "A solution for the best rotation to
    relate two sets of vectors", Acta Crystallographica A32, 1976); ``omega`` is its angle
    over ``T`` (>= 0: in space the axis carries the direction). The motion of constant
    velocity and angular velocity through both fits is a screw about a fixed axis (module
    docstring): the centroid's chord ``c = Q_bar - P_bar`` splits into ``tau a`` along the
    axis ``a`` and ``c_perp`` across it; the velocity at the end of the window is ``(tau a
    + s (cos(phi/2) c_perp + sin(phi/2) a x c_perp)) / T``, ``s = (phi/2) / sin(phi/2)``
    (the plane's arc across the axis), and the centre the axis's point nearest ``Q_bar``,
    ``Q_bar + (a x v) / omega`` (NaN where ``omega = 0``).
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(t > 0, t, np.nan)
        pc, qc = p.mean(axis=-2), q.mean(axis=-2)
        a, b = p - pc[..., None, :], q - qc[..., None, :]
        rot, ok = kabsch(a, b)  # the rotation carrying A onto B (det +1)
        ra = np.einsum("...ij,...nj->...ni", rot, a)
        shape_rate = np.max(np.linalg.norm(b - ra, axis=-1), axis=-1) / t
        cos = np.clip(0.5 * (np.trace(rot, axis1=-2, axis2=-1) - 1.0), -1.0, 1.0)
        angle = np.where(ok, np.arccos(cos), np.nan)
        omega = angle / t
        # the axis, from the rotation's antisymmetric part (omega_vec = omega axis)
        w = np.stack([rot[..., 2, 1] - rot[..., 1, 2], rot[..., 0, 2] - rot[..., 2, 0],
                      rot[..., 1, 0] - rot[..., 0, 1]], axis=-1)  # fmt: skip
        size = np.linalg.norm(w, axis=-1)
        axis = w / np.where(size > 0, size, 1.0)[..., None]
        chord = qc - pc
        tau = np.sum(chord * axis, axis=-1)[..., None]  # the translation along the axis
        across = chord - tau * axis
        half = 0.5 * angle[..., None]
        stretch = np.where(half == 0.0, 1.0, half / np.sin(np.where(half == 0.0, 1.0, half)))
        turned = np.cos(half) * across + np.sin(half) * np.cross(axis, across)
        velocity = (tau * axis + stretch * turned) / t[..., None]
        still = np.where(omega == 0.0, np.nan, omega)[..., None]
        centre = qc + np.cross(axis, velocity) / still
        move = velocity[..., None, :] + omega[..., None, None] * np.cross(axis[..., None, :], b)
        speed = np.max(np.linalg.norm(move, axis=-1), axis=-1)
        spin = np.abs(omega) * np.max(np.linalg.norm(b, axis=-1), axis=-1)
    return RigidMotion(
        velocity=velocity, omega=omega, centre=centre, speed=speed, spin=spin,
        shape_rate=shape_rate, window=t, axis=axis,
    )  # fmt: skip


def field_motion(
    q: ArrayLike, velocity: ArrayLike, omega: ArrayLike, axis: ArrayLike | None = None
) -> RigidMotion:
    """The :class:`RigidMotion` of the exact rigid field ``u_i = v + omega k x (q_i - q_bar)``.

    For a relative equilibrium found by solving for it (``formationlab.equilibria``):
    ``q`` ``(..., n, 2)``, ``velocity`` ``v`` ``(..., 2)`` of the centroid and
    ``omega`` ``(...)``; the shape rate is 0 and the window infinite. In space ``q`` is
    ``(..., n, 3)``, ``omega >= 0`` and ``axis`` ``(..., 3)`` the unit direction of the
    rotation: the screw ``u_i = v + omega a x (q_i - q_bar)``, its centre the axis's point
    nearest the centroid, ``q_bar + (a x v) / omega``.
    """
    q = np.asarray(q, dtype=float)
    v = np.asarray(velocity, dtype=float)
    w = np.asarray(omega, dtype=float)
    b = q - q.mean(axis=-2, keepdims=True)
    a = None if axis is None else np.asarray(axis, dtype=float)
    # the rotation's part of every robot's velocity, and what it turns the velocity into
    turned, across = (
        (perp(b), perp(v)) if a is None else (np.cross(a[..., None, :], b), np.cross(a, v))
    )
    move = v[..., None, :] + w[..., None, None] * turned
    with np.errstate(invalid="ignore", divide="ignore"):
        centre = q.mean(axis=-2) + across / np.where(w == 0.0, np.nan, w)[..., None]
    return RigidMotion(
        velocity=v, omega=w, centre=centre,
        speed=np.max(np.linalg.norm(move, axis=-1), axis=-1),
        spin=np.abs(w) * np.max(np.linalg.norm(b, axis=-1), axis=-1),
        shape_rate=np.zeros(w.shape), window=np.full(w.shape, np.inf), axis=a,
    )  # fmt: skip


def rigid_outcome(motion: RigidMotion, tolerances: Tolerances) -> NDArray[np.int8]:
    """``NOT_RIGID``, ``DRIFTING`` or ``ROTATING`` for every motion of a batch (module docstring).

    Rigid: ``shape_rate <= tolerances.shape < speed`` (the shape kept while some
    robot moves faster than that). Rotating: rigid and ``spin > tolerances.shape``.
    An unknown motion (NaN) is not rigid. Only states whose distances are not met
    and that have not stopped reach this decision (:func:`formationlab.outcomes.analysis.classify`).
    """
    with np.errstate(invalid="ignore"):
        rigid = (motion.shape_rate <= tolerances.shape) & (motion.speed > tolerances.shape)
        turning = motion.spin > tolerances.shape
    return np.where(rigid, np.where(turning, ROTATING, DRIFTING), NOT_RIGID).astype(np.int8)
