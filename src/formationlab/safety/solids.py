"""Obstacles in space: spheres and axis-aligned boxes, and the geometry they share with the plane.

A robot's clearance to an obstacle is ``s = delta - rho_i / 2`` with ``delta`` the signed
distance of its centre to the obstacle (negative inside), in any dimension
(:mod:`.obstacles` for the plane's circles and polygons):

* a **ball** (a circle in the plane, a sphere in space; centre ``c``, radius ``R``):
  ``delta = |q - c| - R``, ``grad delta = (q - c) / |q - c|`` (:func:`ball_distance`, the
  one formula of both);
* an **axis-aligned box** (centre ``c``, half sizes ``e``): with ``w = q - c`` and
  ``d = |w| - e`` per axis, ``delta = |max(d, 0)|`` outside and ``max_k d_k`` inside; its
  gradient is ``sign(w) max(d, 0) / delta`` outside and ``sign(w_k) e_k`` on the axis ``k``
  of the largest ``d_k`` inside (:func:`box_distance`).

Barrier pieces (:meth:`Sphere.pieces`, :meth:`Box.pieces`): a sphere is one piece, its
centre with radius ``R + D_o``, as a circle; a box, being convex, is one piece too: its
nearest point ``p* = clip(q, c - e, c + e)`` with radius ``D_o``. Either way
``h = |q - p*|^2 - rho^2`` is the squared distance to a convex set minus a constant, convex
in ``q`` with gradient ``2 (q - p*)``: the pair barrier's form, so the discrete-time
argument of :mod:`.condition` holds for it in any dimension.

Contact along a straight step (:func:`segment_box_distance`): the squared distance of
``q0 + s (q1 - q0)`` to a box is a convex piecewise quadratic in ``s`` whose pieces change
where a coordinate crosses a face's plane; its least value on ``[0, 1]`` is at one of
those breakpoints, an end, or the vertex of one piece's quadratic, all of which are
evaluated: the distance is exact, not sampled.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ObstacleError
from ..validation import COORDINATE_LIMIT

__all__ = [
    "Ball",
    "Box",
    "Sphere",
    "ball_distance",
    "ball_radius",
    "box_distance",
    "finite_point",
    "segment_box_distance",
    "within_limit",
]

_NAMES = {2: "[x, y]", 3: "[x, y, z]"}


def finite_point(value: ArrayLike, what: str, dim: int = 2) -> NDArray[np.float64]:
    """``value`` as ``dim`` finite numbers, or an :class:`~formationlab.errors.ObstacleError`."""
    count = "two" if dim == 2 else "three"
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        arr = np.full(0, np.nan)
    if arr.shape != (dim,) or not np.all(np.isfinite(arr)):
        raise ObstacleError(f"{what} must be {count} finite numbers {_NAMES[dim]}, got {value!r}")
    return arr


def within_limit(numbers: NDArray[np.float64], what: str) -> None:
    """Refuse an obstacle whose coordinates (or radius) exceed ``COORDINATE_LIMIT``."""
    largest = float(np.max(np.abs(numbers)))
    if largest > COORDINATE_LIMIT:
        raise ObstacleError(
            f"{what} coordinates reach {largest:.3g}, beyond {COORDINATE_LIMIT:g}: squared "
            "distances to it overflow double precision; give the obstacle in metres"
        )


def ball_radius(r: object, what: str) -> float:
    """A ball's radius: a finite number ``> 0``."""
    if not (isinstance(r, int | float) and not isinstance(r, bool) and np.isfinite(r) and r > 0):
        raise ObstacleError(f"{what} radius must be a finite number > 0, got {r!r}")
    return float(r)


def ball_distance(
    q: ArrayLike, center: NDArray[np.float64], radius: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``delta = |q - c| - R`` and its gradient ``(q - c) / |q - c|``; ``(..., d) -> (...)``.

    The circle's formula in the plane and the sphere's in space (0 gradient at the centre).
    """
    w = np.asarray(q, dtype=float) - center
    dist = np.sqrt(np.sum(w * w, axis=-1))
    grad = w / np.where(dist > 0, dist, 1.0)[..., None]
    return dist - radius, grad


def box_distance(
    q: ArrayLike, center: NDArray[np.float64], half: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Signed distance to an axis-aligned box (negative inside) and its gradient.

    Parameters
    ----------
    q : array_like, shape (..., d)
    center, half : ndarray, shape (d,)
        The box's centre and half sizes ``e > 0``.

    Returns
    -------
    delta : ndarray, shape (...)
    grad : ndarray, shape (..., d)
        A unit vector pointing away from the box (module docstring).
    """
    w = np.asarray(q, dtype=float) - center
    side = np.where(w >= 0.0, 1.0, -1.0)
    d = np.abs(w) - half
    out = np.maximum(d, 0.0)
    outside = np.sqrt(np.sum(out * out, axis=-1))
    k = np.argmax(d, axis=-1)
    inside = np.take_along_axis(d, k[..., None], axis=-1)[..., 0]
    face = side * (np.arange(w.shape[-1]) == k[..., None])
    grad_out = side * out / np.where(outside > 0, outside, 1.0)[..., None]
    is_out = outside > 0
    return np.where(is_out, outside, inside), np.where(is_out[..., None], grad_out, face)


def segment_box_distance(
    q0: ArrayLike, q1: ArrayLike, lower: NDArray[np.float64], upper: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Least distance of the segments ``[q0, q1]`` to the box ``[lower, upper]``; ``(..., d)
    -> (...)``, 0 where a segment meets the box (module docstring: exact)."""
    q0 = np.asarray(q0, dtype=float)
    e = np.asarray(q1, dtype=float) - q0
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = np.concatenate([(lower - q0) / e, (upper - q0) / e], axis=-1)
    cross = np.where(np.isfinite(cross), np.clip(cross, 0.0, 1.0), 0.0)
    knots = np.sort(np.concatenate([cross, np.zeros_like(q0[..., :1]),
                                    np.ones_like(q0[..., :1])], axis=-1), axis=-1)  # fmt: skip
    mid = 0.5 * (knots[..., 1:] + knots[..., :-1])  # (..., K - 1): one point in each piece
    x = q0[..., None, :] + mid[..., None] * e[..., None, :]
    # on each piece, each coordinate is below its face, above it, or between (then 0)
    face = np.where(x < lower, lower, np.where(x > upper, upper, np.nan))
    act = ~np.isnan(face)
    off = np.where(act, q0[..., None, :] - np.nan_to_num(face), 0.0)
    de = np.where(act, e[..., None, :], 0.0)
    dd = np.sum(de * de, axis=-1)
    vertex = np.where(dd > 0, -np.sum(off * de, axis=-1) / np.where(dd > 0, dd, 1.0), 0.0)
    s = np.concatenate([knots, np.clip(vertex, knots[..., :-1], knots[..., 1:])], axis=-1)
    p = q0[..., None, :] + s[..., None] * e[..., None, :]
    gap = p - np.clip(p, lower, upper)
    return np.sqrt(np.min(np.sum(gap * gap, axis=-1), axis=-1))


@dataclass(frozen=True, kw_only=True, eq=False)
class Ball:
    """A ball obstacle in ``dim`` dimensions: :class:`~formationlab.safety.Circle` in the
    plane, :class:`Sphere` in space (one formula, module docstring).

    Parameters
    ----------
    center : array_like, shape (dim,)
        Centre ``c`` (m).
    radius : float
        Radius ``R > 0`` (m).
    """

    center: NDArray[np.float64]
    radius: float

    dim: ClassVar[int] = 3
    kind: ClassVar[str] = "ball"

    def __post_init__(self) -> None:
        c = finite_point(self.center, f"{self.kind} center", self.dim)
        r = ball_radius(self.radius, self.kind)
        within_limit(np.append(c, r), self.kind)
        c.setflags(write=False)
        object.__setattr__(self, "center", c)
        object.__setattr__(self, "radius", r)

    def describe(self) -> str:
        """``"sphere at (0, 0, 1) of radius 0.5"``, ``"circle at (0, 0) of radius 0.5"``."""
        at = ", ".join(f"{x:g}" for x in self.center)
        return f"{self.kind} at ({at}) of radius {self.radius:g}"

    def scenario(self) -> dict[str, object]:
        """The scenario-file form ``{kind: {"center": [...], "radius": R}}``."""
        return {self.kind: {"center": self.center.tolist(), "radius": float(self.radius)}}

    def signed_distance(self, q: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:func:`ball_distance`; ``(..., dim) -> (...)``, gradient ``(..., dim)``."""
        return ball_distance(q, self.center, self.radius)

    def pieces(
        self, q: NDArray[np.float64], distance: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Barrier pieces: the centre ``(..., 1, dim)`` for every point of ``q``, with radius
        ``R + D_o`` ``(1,)`` (``D_o = distance``)."""
        return np.broadcast_to(self.center, q.shape)[..., None, :], np.array(
            [self.radius + distance]
        )


@dataclass(frozen=True, kw_only=True, eq=False)
class Sphere(Ball):
    """A ball obstacle in space.

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre ``c`` (m).
    radius : float
        Radius ``R > 0`` (m).
    """

    dim: ClassVar[int] = 3
    kind: ClassVar[str] = "sphere"


@dataclass(frozen=True, kw_only=True, eq=False)
class Box:
    """An axis-aligned box obstacle in space.

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre ``c`` (m).
    size : array_like, shape (3,)
        Edge lengths along x, y and z (m), each ``> 0``.
    """

    center: NDArray[np.float64]
    size: NDArray[np.float64]

    dim: ClassVar[int] = 3

    def __post_init__(self) -> None:
        c = finite_point(self.center, "box center", 3)
        s = finite_point(self.size, "box size", 3)
        if np.any(s <= 0):
            raise ObstacleError(f"box size must be three lengths > 0, got {s.tolist()}")
        within_limit(np.concatenate([c, s]), "box")
        for arr in (c, s):
            arr.setflags(write=False)
        object.__setattr__(self, "center", c)
        object.__setattr__(self, "size", s)

    @property
    def half(self) -> NDArray[np.float64]:
        """Half sizes ``e``, ``(3,)``."""
        return 0.5 * self.size

    @property
    def corners(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Lowest and highest corner, each ``(3,)``."""
        return self.center - self.half, self.center + self.half

    def describe(self) -> str:
        """``"box at (0, 0, 1) of size 1 x 2 x 0.5"``."""
        x, y, z = self.center
        sx, sy, sz = self.size
        return f"box at ({x:g}, {y:g}, {z:g}) of size {sx:g} x {sy:g} x {sz:g}"

    def scenario(self) -> dict[str, object]:
        """The scenario-file form ``{"box": {"center": [...], "size": [...]}}``."""
        return {"box": {"center": self.center.tolist(), "size": self.size.tolist()}}

    def signed_distance(self, q: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:func:`box_distance`; ``(..., 3) -> (...)``, gradient ``(..., 3)``."""
        return box_distance(q, self.center, self.half)

    def pieces(
        self, q: NDArray[np.float64], distance: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Barrier pieces: the nearest point of the box ``(..., 1, 3)``, radius ``D_o`` ``(1,)``."""
        lo, hi = self.corners
        return np.clip(q, lo, hi)[..., None, :], np.array([distance])
