"""Static obstacles: circles and simple polygons, their clearances, repulsion and barriers.

Every obstacle offers, for robot centres ``q`` of shape ``(..., n, 2)``:

* the **signed distance** ``delta`` of a centre to the obstacle (negative inside) and
  its gradient; the robot's **clearance** is ``s = delta - rho_i / 2`` and ``s <= 0`` is a
  collision (:func:`obstacle_contacts`), like ``r_ij <= a_ij`` between robots;
* **Khatib's repulsion** ``gamma = eta/2 (1/s - 1/s0)^2`` for ``s < s0`` (Khatib, "Real-time
  obstacle avoidance for manipulators and mobile robots", IJRR 5(1), 1986), the same
  :func:`~formationlab.controllers.potentials.khatib` the laws use between robots
  (:func:`obstacle_potential`, :func:`grad_obstacle_potential`);
* **barrier constraints** for the safety filter (:func:`obstacle_barrier_rows`).

Barrier pieces. An obstacle is split into convex pieces whose squared distance is
smooth off the piece and convex: a circle is one piece (its centre, with radius
``R + D_o``), a polygon one piece per edge (the segment, radius ``D_o``). Each piece
``p`` gives ``h = |q_i - p*(q_i)|^2 - rho^2`` with ``p*`` the nearest point of the piece,
``grad h = 2 (q_i - p*)``, the same form as the pair barrier between robots. Keeping
every edge's ``h >= 0`` keeps the centre at least ``D_o`` from the polygon: the centre
cannot reach the polygon without coming within ``D_o`` of some edge.

The hot path is vectorised numpy (all edges at once); shapely is used to validate
polygons (valid, simple ring, non-zero area) and, in the tests, as the reference
for distances and containment.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..controllers.kinds.khatib import dkhatib_ds, khatib
from ..errors import ObstacleError, require_extra
from ..validation import COORDINATE_LIMIT
from .condition import barrier_bounds

__all__ = [
    "Circle",
    "Obstacle",
    "ObstacleRows",
    "Polygon",
    "check_obstacle_starts",
    "clearances",
    "grad_obstacle_potential",
    "obstacle_barrier_rows",
    "obstacle_contacts",
    "obstacle_from_mapping",
    "obstacle_potential",
]


def _finite_point(value: ArrayLike, what: str) -> NDArray[np.float64]:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ObstacleError(f"{what} must be two numbers [x, y], got {value!r}") from None
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ObstacleError(f"{what} must be two finite numbers [x, y], got {value!r}")
    return arr


def _within_limit(numbers: NDArray[np.float64], what: str) -> None:
    """Refuse an obstacle whose coordinates (or radius) exceed ``COORDINATE_LIMIT``."""
    largest = float(np.max(np.abs(numbers)))
    if largest > COORDINATE_LIMIT:
        raise ObstacleError(
            f"{what} coordinates reach {largest:.3g}, beyond {COORDINATE_LIMIT:g}: squared "
            "distances to it overflow double precision; give the obstacle in metres"
        )


@dataclass(frozen=True, kw_only=True, eq=False)
class Circle:
    """A disc obstacle.

    Parameters
    ----------
    center : array_like, shape (2,)
        Centre ``c`` (m).
    radius : float
        Radius ``R > 0`` (m).
    """

    center: NDArray[np.float64]
    radius: float

    def __post_init__(self) -> None:
        c = _finite_point(self.center, "circle center")
        r = self.radius
        if not (isinstance(r, int | float) and np.isfinite(r) and r > 0):
            raise ObstacleError(f"circle radius must be a finite number > 0, got {r!r}")
        _within_limit(np.append(c, r), "circle")
        c.setflags(write=False)
        object.__setattr__(self, "center", c)
        object.__setattr__(self, "radius", float(r))

    def describe(self) -> str:
        """``"circle at (0, 0) of radius 0.5"``."""
        return f"circle at ({self.center[0]:g}, {self.center[1]:g}) of radius {self.radius:g}"

    def signed_distance(self, q: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``delta = |q - c| - R`` and its gradient ``(q - c) / |q - c|``; ``(..., 2) -> (...)``."""
        w = np.asarray(q, dtype=float) - self.center
        dist = np.sqrt(np.sum(w * w, axis=-1))
        grad = w / np.where(dist > 0, dist, 1.0)[..., None]
        return dist - self.radius, grad


@dataclass(frozen=True, kw_only=True, eq=False)
class Polygon:
    """A simple polygon obstacle (convex or not), given by its vertices in order.

    Parameters
    ----------
    vertices : array_like, shape (k, 2)
        ``k >= 3`` vertices in either orientation, without repeating the first; the
        boundary must not cross or touch itself and must enclose a non-zero area.
    """

    vertices: NDArray[np.float64]

    def __post_init__(self) -> None:
        try:
            v = np.array(self.vertices, dtype=float)
        except (TypeError, ValueError):
            raise ObstacleError(
                f"polygon vertices must be a list of [x, y] pairs, got {self.vertices!r}"
            ) from None
        if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3:
            raise ObstacleError(f"a polygon needs at least 3 vertices [x, y], got shape {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ObstacleError(f"polygon vertices must be finite, got {v.tolist()}")
        _within_limit(v, "polygon")
        if np.allclose(v[0], v[-1]):
            v = v[:-1]  # a closing repeat of the first vertex is tolerated
        shapely: Any = require_extra("safety", ("shapely",), "polygon obstacles")
        ring = shapely.LinearRing(v) if len(v) >= 3 else None
        if ring is None or not ring.is_simple:
            raise ObstacleError(
                f"polygon {v.tolist()} is not simple: its edges cross or touch; "
                "list the vertices in boundary order without self-intersections"
            )
        shape = shapely.Polygon(v)
        if not shape.is_valid or shape.area <= 0:
            reason = shapely.is_valid_reason(shape)
            raise ObstacleError(f"polygon {v.tolist()} is not valid ({reason}); fix its vertices")
        v.setflags(write=False)
        object.__setattr__(self, "vertices", v)

    def describe(self) -> str:
        """``"polygon with 3 vertices starting at (1, 1)"``."""
        v0 = self.vertices[0]
        return f"polygon with {len(self.vertices)} vertices starting at ({v0[0]:g}, {v0[1]:g})"

    @property
    def edges(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Edge start and end points, each of shape ``(k, 2)``."""
        return self.vertices, np.roll(self.vertices, -1, axis=0)

    def contains(self, q: ArrayLike) -> NDArray[np.bool_]:
        """Whether points ``(..., 2)`` lie strictly inside (crossing-number test); ``(...)``."""
        q = np.asarray(q, dtype=float)
        a, b = self.edges
        x, y = q[..., None, 0], q[..., None, 1]
        straddle = (a[:, 1] > y) != (b[:, 1] > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
        crossings = np.sum(straddle & (x < x_cross), axis=-1)
        return (crossings % 2) == 1

    def nearest_on_edges(self, q: ArrayLike) -> NDArray[np.float64]:
        """Nearest point of every edge to each point; ``(..., 2) -> (..., k, 2)``."""
        q = np.asarray(q, dtype=float)
        a, b = self.edges
        e = b - a
        w = q[..., None, :] - a
        t = np.clip(np.sum(w * e, axis=-1) / np.sum(e * e, axis=-1), 0.0, 1.0)
        return a + t[..., None] * e

    def signed_distance(self, q: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Signed distance to the boundary (negative inside) and its gradient; ``(..., 2)``.

        The gradient is ``(q - p*) / |q - p*|`` outside and its opposite inside, ``p*``
        the nearest boundary point (a unit vector pointing away from the polygon).
        """
        q = np.asarray(q, dtype=float)
        p = self.nearest_on_edges(q)
        d2 = np.sum((q[..., None, :] - p) ** 2, axis=-1)
        k = np.argmin(d2, axis=-1)
        nearest = np.take_along_axis(p, k[..., None, None], axis=-2)[..., 0, :]
        w = q - nearest
        dist = np.sqrt(np.sum(w * w, axis=-1))
        sign = np.where(self.contains(q), -1.0, 1.0)
        grad = sign[..., None] * w / np.where(dist > 0, dist, 1.0)[..., None]
        return sign * dist, grad


Obstacle = Circle | Polygon


def obstacle_from_mapping(spec: Mapping[str, object]) -> Obstacle:
    """An obstacle from its scenario-file form.

    ``{"circle": {"center": [x, y], "radius": R}}`` or ``{"polygon": [[x, y], ...]}``.
    """
    keys = set(spec)
    if keys == {"circle"} and isinstance(spec["circle"], Mapping):
        c = spec["circle"]
        extra = set(c) - {"center", "radius"}
        if extra or not {"center", "radius"} <= set(c):
            raise ObstacleError(
                f"a circle needs exactly center = [x, y] and radius = R, got keys {sorted(c)}"
            )
        return Circle(center=c["center"], radius=c["radius"])  # type: ignore[arg-type]
    if keys == {"polygon"}:
        return Polygon(vertices=spec["polygon"])  # type: ignore[arg-type]
    raise ObstacleError(
        "an obstacle is either circle = { center = [x, y], radius = R } or polygon = "
        f"[[x, y], ...], got keys {sorted(keys)}"
    )


def clearances(
    q: ArrayLike, radii: ArrayLike, obstacles: Sequence[Obstacle]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Clearance ``s = delta - rho_i / 2`` of every robot to every obstacle, and its gradient.

    Parameters
    ----------
    q : array_like, shape (..., n, 2)
        Robot centres.
    radii : array_like, shape (n,)
        Robot radii ``rho_i / 2``.
    obstacles : sequence of Circle or Polygon
        ``O`` obstacles.

    Returns
    -------
    s : ndarray, shape (..., n, O)
        Signed clearances (``<= 0``: the robot touches or overlaps the obstacle).
    grad : ndarray, shape (..., n, O, 2)
        ``grad_{q_i} s``, a unit vector pointing away from the obstacle.
    """
    q = np.asarray(q, dtype=float)
    radii = np.asarray(radii, dtype=float)
    if not obstacles:
        return np.zeros((*q.shape[:-1], 0)), np.zeros((*q.shape[:-1], 0, 2))
    parts = [ob.signed_distance(q) for ob in obstacles]
    s = np.stack([p[0] for p in parts], axis=-1) - radii[:, None]
    grad = np.stack([p[1] for p in parts], axis=-2)
    return s, grad


def obstacle_contacts(
    q: ArrayLike, radii: ArrayLike, obstacles: Sequence[Obstacle]
) -> NDArray[np.bool_]:
    """Robot-obstacle collisions, clearance ``s <= 0``; shape ``(..., n, O)``."""
    return clearances(q, radii, obstacles)[0] <= 0.0


def obstacle_potential(
    q: ArrayLike,
    radii: ArrayLike,
    obstacles: Sequence[Obstacle],
    *,
    eta: float,
    influence: float,
) -> NDArray[np.float64]:
    """``sum_i sum_o gamma(s_io)``, Khatib's repulsion on the clearances; shape ``(...)``.

    ``gamma = eta/2 (1/s - 1/s0)^2`` for ``s < s0 = influence``, 0 beyond, ``+inf`` at contact.
    """
    s, _ = clearances(q, radii, obstacles)
    return np.sum(khatib(s, eta, influence), axis=(-2, -1))


def grad_obstacle_potential(
    q: ArrayLike,
    radii: ArrayLike,
    obstacles: Sequence[Obstacle],
    *,
    eta: float,
    influence: float,
) -> NDArray[np.float64]:
    """``grad_i`` of :func:`obstacle_potential`, ``sum_o gamma'(s_io) grad s_io``; ``(..., n, 2)``.

    A law adds ``-k grad`` to its command (``k`` its own gain, ``k_c`` for the paper's laws).
    """
    s, grad = clearances(q, radii, obstacles)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = dkhatib_ds(s, eta, influence)
    return np.einsum("...io,...iod->...id", slope, grad)


def check_obstacle_starts(q0: ArrayLike, radii: ArrayLike, obstacles: Sequence[Obstacle]) -> None:
    """Raise :class:`~formationlab.errors.ObstacleError` if a robot starts on an obstacle.

    Parameters
    ----------
    q0 : array_like, shape (n, 2) or (B, n, 2)
        Initial positions (every trial of a batch is checked).
    radii : array_like, shape (n,)
        Robot radii ``rho_i / 2``.
    obstacles : sequence of Circle or Polygon
    """
    s, _ = clearances(q0, radii, obstacles)
    bad = np.argwhere(s <= 0.0)
    if bad.size:
        where = tuple(bad[0])
        i, o = where[-2], where[-1]
        trial = f" in trial {where[0] + 1}" if len(where) == 3 else ""
        raise ObstacleError(
            f"robot {i + 1} starts inside or touching obstacle {o + 1} "
            f"({obstacles[o].describe()}){trial}: clearance {s[where]:g} <= 0; "
            "move the robot's start or the obstacle"
        )


class ObstacleRows(NamedTuple):
    """Barrier constraints ``a . u_i <= b`` of every robot against every obstacle piece.

    ``a`` has shape ``(..., n, K, 2)``, ``b`` and ``h`` ``(..., n, K)``, ``owner`` ``(K,)``
    (the 0-based obstacle each piece belongs to).
    """

    a: NDArray[np.float64]
    b: NDArray[np.float64]
    h: NDArray[np.float64]
    owner: NDArray[np.int64]


def obstacle_barrier_rows(
    q: ArrayLike, obstacles: Sequence[Obstacle], *, distance: float, gamma: float,
    step: float = 0.0,
) -> ObstacleRows:  # fmt: skip
    """Barrier rows ``-2 (q_i - p*) . u_i <= b(h)`` for every robot and obstacle piece.

    ``h = |q_i - p*|^2 - rho^2`` (module docstring): ``p*`` the circle's centre and
    ``rho = R + D_o``, or the nearest point of a polygon edge and ``rho = D_o``, with
    ``D_o = distance`` the centre-to-obstacle safety distance. The rows are the
    condition ``h_dot >= -gamma h^3`` of Wang, Ames and Egerstedt (IEEE T-RO 2017) for a
    static obstacle, which only the robot itself can satisfy (it takes full responsibility).

    Parameters
    ----------
    q : array_like, shape (..., n, 2)
    obstacles : sequence of Circle or Polygon
    distance : float
        ``D_o`` (m).
    gamma : float
        Barrier gain.
    step : float
        The Euler step the rows guard (0: the continuous rows); ``b`` is
        :func:`~formationlab.safety.condition.barrier_bound`, ``gamma h^3`` capped at
        ``h / step``.
    """
    q = np.asarray(q, dtype=float)
    nearest, rho, owner = [], [], []
    for o, ob in enumerate(obstacles):
        if isinstance(ob, Circle):
            nearest.append(np.broadcast_to(ob.center, q.shape)[..., None, :])
            rho.append(np.array([ob.radius + distance]))
            owner.append(np.array([o]))
        else:
            k = len(ob.vertices)
            nearest.append(ob.nearest_on_edges(q))
            rho.append(np.full(k, distance))
            owner.append(np.full(k, o))
    if not nearest:
        empty = np.zeros((*q.shape[:-1], 0))
        return ObstacleRows(np.zeros((*empty.shape, 2)), empty, empty, np.zeros(0, np.int64))
    p = np.concatenate(nearest, axis=-2)
    rho_all = np.concatenate(rho)
    w = q[..., None, :] - p
    h = np.sum(w * w, axis=-1) - rho_all**2
    b = barrier_bounds(h, gamma, step)
    return ObstacleRows(-2.0 * w, b, h, np.concatenate(owner).astype(np.int64))
