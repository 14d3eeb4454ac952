"""The safety filter's configuration: which filter, its distance, gain and limits.

Scenario-file form (the ``[safety]`` table)::

    [safety]
    filter = "barrier"        # "none" (default) | "barrier" | "barrier-decentralized"
    distance = 0.25           # D_s (m), at least the contact distance
    gamma = 100.0
    max_speed = 0.5           # optional speed limit in the filter
    condition = "discrete"    # "discrete" (default) | "continuous"
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import FormationlabWarning, ParameterError
from ..validation import number, whole
from .condition import CONDITIONS, Condition
from .pairs import sensed_pairs
from .result import unchanged

if TYPE_CHECKING:
    from ..models import RobotModel
    from .obstacles import Obstacle
    from .result import FilterResult

__all__ = ["BELOW_TOLERANCE", "FILTERS", "FilterKind", "SafetyFilter", "register_filter"]

FilterKind = Literal["none", "barrier", "barrier-decentralized"]
FILTERS: tuple[str, ...] = ("none", "barrier", "barrier-decentralized")
#: the most sides of the polygon that stands for the filter's speed limit
SIDES_LIMIT = 256
#: a pair counts as below ``D_s`` when closer than ``D_s (1 - BELOW_TOLERANCE)``: the
#: discrete condition keeps ``h >= 0`` exactly in real arithmetic, and rounding of the
#: filter's solves (Clarabel's tolerance) may leave a pair this much (relative) inside
BELOW_TOLERANCE = 1e-6


class _Filter(NamedTuple):
    apply: Callable[..., Any]  #: (config, q, u_hat, obstacles) -> FilterResult
    commands: Callable[..., Any] | None  #: the commands alone, or None: apply's u


#: each filter's functions by name, registered by its module (``barrier.py``,
#: ``decentralized.py``, both imported with the package): the configuration below them
#: names a filter, and the filter imports its configuration, not the other way round
_FILTERS: dict[str, _Filter] = {}


def register_filter(
    name: str, apply: Callable[..., Any], commands: Callable[..., Any] | None = None
) -> None:
    """Make ``SafetyFilter(filter=name)`` run ``apply`` (and ``commands`` for the commands
    alone)."""
    _FILTERS[name] = _Filter(apply, commands)


@dataclass(frozen=True, kw_only=True)
class SafetyFilter:
    """A safety filter that minimally changes every robot's command (Wang, Ames, Egerstedt 2017).

    The barrier certificate of Wang, Ames and Egerstedt ("Safety barrier certificates
    for collisions-free multirobot systems", IEEE Transactions on Robotics 33(3),
    2017), as the Robotarium runs it: minimise ``sum_i |u_i - u_hat_i|^2`` subject to
    ``h_dot_ij >= -gamma h_ij^3`` for every pair within the sensing radius, with
    ``h_ij = |q_i - q_j|^2 - D_s^2``, plus obstacle barriers and speed limits.

    Parameters
    ----------
    filter : {"none", "barrier", "barrier-decentralized"}
        ``"none"`` returns the command unchanged; ``"barrier"`` solves one centralized QP
        per trial and step (:func:`~formationlab.safety.barrier.barrier_filter`);
        ``"barrier-decentralized"`` lets every robot solve its own constraints with half
        the responsibility per pair
        (:func:`~formationlab.safety.decentralized.decentralized_filter`).
    distance : float
        ``D_s`` (m): the centre-to-centre distance the filter keeps between robots. It
        must be at least every pair's contact distance ``a_ij``
        (:meth:`check_contact`). Default 0.25.
    gamma : float
        Barrier gain ``gamma >= 0`` (larger: robots may approach faster). Default 100.
    max_speed : float or None
        Speed limit ``|u_i| <= max_speed`` (m/s), imposed as the regular polygon with
        ``speed_sides`` sides inscribed in that disc (so the limit always holds, and
        the polygon loses at most ``1 - cos(pi / speed_sides)`` of it). ``None``: no limit.
    speed_sides : int
        Sides of that polygon (``>= 4``; 4 is the square inscribed in the disc). Default 8.
    sensing_radius : float
        Pairs farther apart than this pose no constraint (m). Default ``inf`` (every pair,
        the formulation of the paper); large swarms should set it.
    obstacle_distance : float or None
        ``D_o`` (m): the centre-to-obstacle distance kept; ``None`` means ``distance / 2``
        (half the pair distance, as each robot keeps half of ``D_s`` to a neighbour).
    condition : {"discrete", "continuous"}
        The rows' bound (:func:`~formationlab.safety.condition.barrier_bound`):
        ``"discrete"`` (default) ``h_dot >= -min(gamma h^3, h / dt)`` where ``h > 0``, which
        keeps every pair and obstacle clearance at every explicit Euler step of length
        ``dt`` (single integrators); ``"continuous"`` the paper's ``h_dot >= -gamma h^3``,
        which keeps it along the flow only (a step with ``dt gamma h^2 > 1`` can jump past).
        Both are the same row wherever ``dt gamma h^2 <= 1``.
    step : float or None
        The step ``dt`` the discrete condition guards. The closed loop sets it from its
        integrator (:meth:`at_step`); ``None`` (a filter used outside a fixed-step loop:
        Filippov's integrator, equilibria) gives the continuous rows.
    """

    filter: FilterKind = "none"
    distance: float = 0.25
    gamma: float = 100.0
    max_speed: float | None = None
    speed_sides: int = 8
    sensing_radius: float = math.inf
    obstacle_distance: float | None = None
    condition: Condition = "discrete"
    step: float | None = None

    def __post_init__(self) -> None:
        if self.filter not in FILTERS:
            known = ", ".join(f'"{f}"' for f in FILTERS)
            raise ParameterError(
                f"safety.filter must be one of {known}, got {self.filter!r}", key="filter"
            )
        number(self.distance, "distance", low=0.0, strict=True, owner="safety")
        if not (isinstance(self.gamma, int | float) and self.gamma >= 0):  # also NaN
            raise ParameterError(
                f"safety.gamma must be >= 0 (the barrier gain: 0 lets no pair approach at "
                f"all, larger values let pairs approach faster; default 100), got "
                f"{self.gamma!r}", key="gamma",
            )  # fmt: skip
        number(self.gamma, "gamma", low=0.0, strict=False, owner="safety")
        if self.max_speed is not None:
            number(self.max_speed, "max_speed", low=0.0, strict=True, owner="safety")
        whole(self.speed_sides, "speed_sides", minimum=4, owner="safety")
        if self.speed_sides > SIDES_LIMIT:  # (each side is a row of every robot's QP)
            raise ParameterError(
                f"safety.speed_sides must be at most {SIDES_LIMIT}, got {self.speed_sides:,}: "
                f"a polygon of {SIDES_LIMIT} sides is within "
                f"{100 * (1 - math.cos(math.pi / SIDES_LIMIT)):.2g} % of the speed limit's disc",
                key="speed_sides",
            )
        number(self.sensing_radius, "sensing_radius", low=0.0, strict=True, allow_inf=True,
               owner="safety")  # fmt: skip
        if self.sensing_radius <= self.distance:
            raise ParameterError(
                f"safety.sensing_radius ({self.sensing_radius:g}) must exceed the distance "
                f"D_s ({self.distance:g}), or robots inside D_s would not see each other",
                key="sensing_radius",
            )
        if self.obstacle_distance is not None:
            number(self.obstacle_distance, "obstacle_distance", low=0.0, strict=True,
                   owner="safety")  # fmt: skip
        if self.condition not in CONDITIONS:
            known = ", ".join(f'"{c}"' for c in CONDITIONS)
            raise ParameterError(
                f"safety.condition must be one of {known} (the barrier's discrete-time "
                f"condition, default, or the paper's continuous one), got {self.condition!r}",
                key="condition",
            )
        if self.step is not None:
            number(self.step, "step", low=0.0, strict=True, owner="safety")

    def at_step(self, dt: float | None) -> SafetyFilter:
        """This filter guarding explicit Euler steps of length ``dt`` (None: no step known)."""
        dt = None if dt is None else float(dt)
        return self if dt == self.step else replace(self, step=dt)

    @property
    def rows_step(self) -> float:
        """The step the rows guard: :attr:`step` under the discrete condition, else 0 (the
        continuous rows)."""
        return float(self.step) if self.condition == "discrete" and self.step else 0.0

    def least_distance(self, p: ArrayLike) -> NDArray[np.float64]:
        """Least distance ``|p_i - p_j|`` of the pairs this filter keeps ``D_s`` apart (those
        within the sensing radius) at points ``p`` ``(..., n, 2)``; ``(...)``, ``inf`` where
        no pair is within the radius. The compiled loop measures the same pairs as it
        filters (:func:`formationlab.safety.stage.filter_command`)."""
        p = np.asarray(p, dtype=float)
        batch = p.shape[:-2]
        out = np.full(int(np.prod(batch, dtype=np.int64)), np.inf)
        pairs = sensed_pairs(p, float(self.sensing_radius))
        if pairs.size:
            flat = p.reshape(-1, *p.shape[-2:])
            d = flat[pairs[:, 0], pairs[:, 2]] - flat[pairs[:, 0], pairs[:, 1]]
            np.minimum.at(out, pairs[:, 0], np.sum(d * d, axis=-1))
        return np.sqrt(out).reshape(batch)

    def below(self, least: ArrayLike) -> NDArray[np.bool_]:
        """Whether a run whose least pair distance (:meth:`least_distance` over its steps)
        is ``least`` came below ``D_s``: the filter's promise broken (the continuous
        condition with a coarse step or a huge ``gamma``, a start inside ``D_s``, a model
        whose points do not follow the command). The one place this is decided; a margin
        of :data:`BELOW_TOLERANCE` (relative) leaves out rounding. NaN (not measured) is not
        below."""
        least = np.asarray(least, dtype=float)
        with np.errstate(invalid="ignore"):
            return least < self.distance * (1.0 - BELOW_TOLERANCE)

    @property
    def below_advice(self) -> str:
        """What keeps the pairs ``D_s`` apart at every step, for a run or study that came
        below it (:meth:`below`)."""
        if self.condition == "continuous":
            return (
                'condition = "discrete" (the default) keeps them apart at every Euler step, '
                "or use a smaller dt or gamma"
            )
        return (
            "check that the robots start at least D_s apart and that the model follows the command"
        )

    @property
    def enabled(self) -> bool:
        """Whether the filter changes anything (``filter != "none"``)."""
        return self.filter != "none"

    @property
    def d_obstacle(self) -> float:
        """``D_o``: the given ``obstacle_distance``, or ``distance / 2``."""
        return self.distance / 2 if self.obstacle_distance is None else self.obstacle_distance

    def speed_polygon(self, dim: int = 2) -> tuple[NDArray[np.float64], float]:
        """Outward normals ``(S, dim)`` and bound ``c`` of the speed limit ``n_k . u <= c``.

        Empty when there is no limit. The polygon is inscribed in the disc of radius
        ``max_speed`` (vertices on the circle), so ``c = max_speed cos(pi / S)``. In space
        (``dim = 3``) there is no polygon: :meth:`check_space` refuses a ``max_speed``.
        """
        if self.max_speed is None:
            return np.zeros((0, dim)), 0.0
        self.check_space(dim)
        s = self.speed_sides
        angle = 2.0 * np.pi * np.arange(s) / s
        normals = np.column_stack([np.cos(angle), np.sin(angle)])
        return normals, self.max_speed * math.cos(math.pi / s)

    def check_space(self, dim: int) -> None:
        """Refuse what the filter does in the plane only, for robots in ``dim`` dimensions:
        the speed limit (a polygon in the plane of velocities)."""
        if dim != 2 and self.enabled and self.max_speed is not None:
            raise ParameterError(
                f"safety.max_speed limits the speed by a polygon of velocities in the plane; "
                f"a formation in space ({dim}-D) has none: remove max_speed (a drone's speed "
                'limit is the quadrotor model\'s max_speed, [robots] model = "quadrotor")',
                key="max_speed",
            )

    def check_model(self, model: RobotModel) -> None:
        """Whether the filter's certificate holds for ``model``.

        The filter certifies the law's command as the velocity of each robot's point
        (:meth:`~formationlab.models.RobotModel.points`). A model whose command is a force
        (``command_is_velocity`` False: the velocity lags it) is refused with a
        :class:`~formationlab.errors.ParameterError`; a model whose points do not follow
        the command (``points_follow_command`` False: heading-mapped unicycles turn first)
        gets a :class:`~formationlab.errors.FormationlabWarning`, since robots may still
        touch (docs/safety.md, Robot models).
        """
        if not self.enabled:
            return
        if model.command_is_velocity and not model.points_follow_command:
            warnings.warn(
                f"the safety filter {self.filter!r} certifies the law's command as the "
                f"velocity of each robot, which this {model.name} does not follow (it turns "
                "towards the command first), so robots may still touch: use mapping = "
                '"near-identity" with distance = D_s + 2 offset (docs/safety.md)',
                FormationlabWarning,
                stacklevel=3,
            )
        if not model.command_is_velocity:
            raise ParameterError(
                f"the safety filter {self.filter!r} certifies the law's command as the "
                f"velocity of each robot, and a {model.name}'s command is a force (its "
                "velocity lags it), so the filter would not keep the robots apart: set "
                'safety.filter = "none", or use the single-integrator or unicycle model (a '
                "second-order barrier certificate is not implemented)",
                key="filter",
            )

    def check_contact(self, contact: ArrayLike) -> None:
        """Raise :class:`~formationlab.errors.ParameterError` if ``D_s`` or ``D_o`` is too small.

        Parameters
        ----------
        contact : array_like, shape (n, n)
            The formation's contact distances ``a_ij = (rho_i + rho_j) / 2``
            (``Formation.contact_matrix``); the diagonal ``a_ii = rho_i`` is the robot's
            diameter, so ``D_o >= rho_i / 2`` keeps its body off the obstacles.
        """
        a = np.asarray(contact, dtype=float)
        if a.ndim != 2 or a.shape[0] != a.shape[1]:
            raise ParameterError(f"contact distances must be an (n, n) matrix, got {a.shape}")
        self.check_diameters(np.diag(a))

    def check_diameters(self, diameters: ArrayLike) -> None:
        """:meth:`check_contact` from the robots' diameters ``(n,)`` alone, in ``O(n)``: the
        largest contact distance is that of the two largest robots (a swarm's ``n x n``
        contact matrix is never built)."""
        rho = np.asarray(diameters, dtype=float).ravel()
        n = rho.size
        if n > 1:
            first = int(np.argmax(rho))  # the largest robot, and the largest of the others
            rest = np.where(np.arange(n) == first, -np.inf, rho)
            second = int(np.argmax(rest))
            lo, hi = sorted((first, second))
            a = 0.5 * (rho[lo] + rho[hi])
            if self.distance < a:
                raise ParameterError(
                    f"safety distance D_s = {self.distance:g} is below the contact distance "
                    f"a_{lo + 1}{hi + 1} = {a:g} of robots {lo + 1} and {hi + 1}; "
                    f"use distance >= {a:g}",
                    key="distance",
                )
        radius = 0.5 * rho
        k = int(np.argmax(radius)) if n else 0
        if n and self.d_obstacle < radius[k]:
            raise ParameterError(
                f"safety obstacle_distance D_o = {self.d_obstacle:g} is below the radius "
                f"{radius[k]:g} of robot {k + 1}; use obstacle_distance >= {radius[k]:g}",
                key="obstacle_distance",
            )

    def command(
        self, q: ArrayLike, u_hat: ArrayLike, *, obstacles: Sequence[Obstacle] = ()
    ) -> NDArray[np.float64]:
        """The filtered command alone, ``(..., n, d)``: :meth:`apply`'s ``u``.

        What the closed loop needs at every step; the decentralized filter then skips its
        statuses and active set.
        """
        if self.filter == "barrier-decentralized":
            q_arr = np.asarray(q, dtype=float)
            u_arr = np.asarray(u_hat, dtype=float)
            if q_arr.shape == u_arr.shape and q_arr.ndim >= 2 and q_arr.shape[-1] in (2, 3):
                return _FILTERS[self.filter].commands(self, q_arr, u_arr, obstacles)  # type: ignore[misc]
        return self.apply(q, u_hat, obstacles=obstacles).u

    def apply(
        self,
        q: ArrayLike,
        u_hat: ArrayLike,
        *,
        obstacles: Sequence[Obstacle] = (),
        contact: ArrayLike | None = None,
    ) -> FilterResult:
        """Filter the commands ``u_hat`` at positions ``q``.

        Parameters
        ----------
        q, u_hat : array_like, shape (n, d) or (..., n, d)
            Positions and the law's commands, batch axes leading; ``d`` = 2 (the plane) or 3
            (space).
        obstacles : sequence of Circle or Polygon (plane), Sphere or Box (space)
            Static obstacles.
        contact : array_like, shape (n, n), optional
            The formation's contact distances; when given, :meth:`check_contact` runs first.

        Returns
        -------
        FilterResult
            The filtered command (``(..., n, d)``), a status per trial and the active set.
        """
        if contact is not None:
            self.check_contact(contact)
        q_arr = np.asarray(q, dtype=float)
        u_arr = np.asarray(u_hat, dtype=float)
        if q_arr.shape != u_arr.shape or q_arr.ndim < 2 or q_arr.shape[-1] not in (2, 3):
            raise ParameterError(
                f"q and u_hat must both have shape (..., n, d) with d = 2 or 3, got "
                f"{q_arr.shape} and {u_arr.shape}"
            )
        self.check_space(q_arr.shape[-1])
        if self.filter == "none":
            return unchanged(u_arr)
        return _FILTERS[self.filter].apply(self, q_arr, u_arr, obstacles)
