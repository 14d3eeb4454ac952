"""Static obstacles: circles and simple polygons, their clearances, repulsion and barriers.

The same holds in space for spheres and axis-aligned boxes (:mod:`.solids`, which holds
the formulas both share: a circle and a sphere are one formula in ``d`` dimensions); the
functions below take any of the four, for robot centres of shape ``(..., n, d)``, ``d`` the
obstacles' dimension. Every obstacle offers, for robot centres ``q`` of shape ``(..., n, 2)``:

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
``grad h = 2 (q_i - p*)``, the same form as the pair barrier between robots (each
obstacle's ``pieces``; a sphere's and a box's in :mod:`.solids`). Keeping
every edge's ``h >= 0`` keeps the centre at least ``D_o`` from the polygon: the centre
cannot reach the polygon without coming within ``D_o`` of some edge.

The hot path is vectorised numpy (all edges at once); shapely is used to validate
polygons (valid, simple ring, non-zero area) and, in the tests, as the reference
for distances and containment.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..controllers.kinds.khatib import dkhatib_ds, khatib
from ..errors import ObstacleError, require_extra
from .condition import barrier_bounds
from .solids import Ball, Box, Sphere, within_limit

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


@dataclass(frozen=True, kw_only=True, eq=False)
class Circle(Ball):
    """A disc obstacle: the ball of :mod:`.solids` in the plane.

    Parameters
    ----------
    center : array_like, shape (2,)
        Centre ``c`` (m).
    radius : float
        Radius ``R > 0`` (m).
    """

    dim: ClassVar[int] = 2
    kind: ClassVar[str] = "circle"


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

    dim: ClassVar[int] = 2

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
        within_limit(v, "polygon")
        # a closing repeat of the first vertex is tolerated: equal to within the polygon's
        # size (not to within 1e-8: all the vertices of a tiny polygon were, and it lost one)
        if np.all(np.abs(v[0] - v[-1]) <= 1e-9 * float(np.max(np.ptp(v, axis=0)))):
            v = v[:-1]
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

    def scenario(self) -> dict[str, object]:
        """The scenario-file form ``{"polygon": [[x, y], ...]}``."""
        return {"polygon": self.vertices.tolist()}

    def pieces(
        self, q: NDArray[np.float64], distance: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Barrier pieces: the nearest point of every edge ``(..., k, 2)``, radius ``D_o``
        ``(k,)``."""
        return self.nearest_on_edges(q), np.full(len(self.vertices), distance)

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


#: an obstacle in the plane (circle, polygon) or in space (sphere, box)
Obstacle = Circle | Polygon | Sphere | Box
#: the obstacles of the scenario files by kind, and the dimension each lives in
KINDS: dict[str, int] = {"circle": 2, "polygon": 2, "sphere": 3, "box": 3}
_FORMS = {
    "circle": "circle = { center = [x, y], radius = R }",
    "polygon": "polygon = [[x, y], ...]",
    "sphere": "sphere = { center = [x, y, z], radius = R }",
    "box": "box = { center = [x, y, z], size = [sx, sy, sz] }",
}


def _table(spec: Mapping[str, object], kind: str, keys: tuple[str, ...]) -> Mapping[str, Any]:
    """The inline table of a ``circle``, ``sphere`` or ``box``, with exactly ``keys``."""
    table = spec[kind]
    if not isinstance(table, Mapping) or set(table) != set(keys):
        got = sorted(table) if isinstance(table, Mapping) else table
        raise ObstacleError(f"a {kind} is {_FORMS[kind]}, got {got!r}")
    return table


def obstacle_from_mapping(spec: Mapping[str, object], *, dim: int | None = None) -> Obstacle:
    """An obstacle from its scenario-file form.

    ``{"circle": {"center": [x, y], "radius": R}}`` or ``{"polygon": [[x, y], ...]}`` in the
    plane; ``{"sphere": {"center": [x, y, z], "radius": R}}`` or ``{"box": {"center":
    [x, y, z], "size": [sx, sy, sz]}}`` in space. With ``dim``, the formation's dimension, an
    obstacle of the other one is refused by name.
    """
    keys = set(spec)
    kind = next(iter(keys)) if len(keys) == 1 else ""
    if kind not in KINDS:
        forms = " or ".join(_FORMS[k] for k in KINDS if dim is None or KINDS[k] == dim)
        raise ObstacleError(f"an obstacle is either {forms}, got keys {sorted(keys)}")
    if dim is not None and KINDS[kind] != dim:
        other = [k for k in KINDS if KINDS[k] == dim]
        where = {2: "the plane", 3: "space (3-D)"}
        raise ObstacleError(
            f"a {kind} is an obstacle in {where[KINDS[kind]]}, and this formation is in "
            f"{where[dim]}: use {' or '.join(_FORMS[k] for k in other)}"
        )
    if kind == "polygon":
        return Polygon(vertices=spec["polygon"])  # type: ignore[arg-type]
    if kind == "box":
        box = _table(spec, "box", ("center", "size"))
        return Box(center=box["center"], size=box["size"])
    ball = _table(spec, kind, ("center", "radius"))
    return (Circle if kind == "circle" else Sphere)(center=ball["center"], radius=ball["radius"])


def clearances(
    q: ArrayLike, radii: ArrayLike, obstacles: Sequence[Obstacle]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Clearance ``s = delta - rho_i / 2`` of every robot to every obstacle, and its gradient.

    Parameters
    ----------
    q : array_like, shape (..., n, d)
        Robot centres.
    radii : array_like, shape (n,)
        Robot radii ``rho_i / 2``.
    obstacles : sequence of Circle, Polygon, Sphere or Box
        ``O`` obstacles.

    Returns
    -------
    s : ndarray, shape (..., n, O)
        Signed clearances (``<= 0``: the robot touches or overlaps the obstacle).
    grad : ndarray, shape (..., n, O, d)
        ``grad_{q_i} s``, a unit vector pointing away from the obstacle.
    """
    q = np.asarray(q, dtype=float)
    radii = np.asarray(radii, dtype=float)
    if not obstacles:
        return np.zeros((*q.shape[:-1], 0)), np.zeros((*q.shape[:-1], 0, q.shape[-1]))
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
    """``grad_i`` of :func:`obstacle_potential`, ``sum_o gamma'(s_io) grad s_io``; ``(..., n, d)``.

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
    q0 : array_like, shape (n, d) or (B, n, d)
        Initial positions (every trial of a batch is checked).
    radii : array_like, shape (n,)
        Robot radii ``rho_i / 2``.
    obstacles : sequence of Circle, Polygon, Sphere or Box
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

    ``a`` has shape ``(..., n, K, d)``, ``b`` and ``h`` ``(..., n, K)``, ``owner`` ``(K,)``
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
    q : array_like, shape (..., n, d)
    obstacles : sequence of Circle, Polygon, Sphere or Box
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
        p, r = ob.pieces(q, distance)
        nearest.append(p)
        rho.append(r)
        owner.append(np.full(len(r), o))
    if not nearest:
        empty = np.zeros((*q.shape[:-1], 0))
        return ObstacleRows(
            np.zeros((*empty.shape, q.shape[-1])), empty, empty, np.zeros(0, np.int64)
        )
    p = np.concatenate(nearest, axis=-2)
    rho_all = np.concatenate(rho)
    w = q[..., None, :] - p
    h = np.sum(w * w, axis=-1) - rho_all**2
    b = barrier_bounds(h, gamma, step)
    return ObstacleRows(-2.0 * w, b, h, np.concatenate(owner).astype(np.int64))
