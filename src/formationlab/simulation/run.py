"""One entry point, :func:`simulate`, and the result it returns.

``simulate(formation, law, q0, duration=..., integrator=..., model=..., marching=...)``
integrates the closed loop (``q_dot = u(q)``, eq. 1, for the paper's single
integrators; any robot model of :mod:`formationlab.models`) and returns a
:class:`SimulationResult` holding times, the full states ``(T, n, k)`` and the
positions ``(T, n, 2)``, velocities, the law's Lyapunov function ``(T,)``, which
angular restrictions were active, a status with a message, and the integrator's
diagnostics.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..controllers import LAWS, Law
from ..controllers.bearing import leader_target
from ..dynamics import System
from ..errors import FormationError, IgnoredKeyWarning, ParameterError
from ..formation.chunked import over_time
from ..formation.spec import Formation
from ..integrators import INTEGRATORS, Euler, Integrator, RawSolution
from ..integrators.compiled import compiled_terms, run_euler_compiled
from ..integrators.diagnostics import switching_diagnostics
from ..marching import March, Marching, centroid_velocity, heading_spread
from ..models import MODELS, RobotModel, SingleIntegrator
from ..models.registry import initial_keys
from ..outcomes.analysis import (
    Outcome,
    Tolerances,
    bearing_errors,
    classify,
    converged_time,
    distance_errors,
    edge_labels,
    error_statistics,
    final_motion,
    net_speed,
    triangle_orientation,
)
from ..outcomes.rigid_motion import RigidMotion
from ..registry import resolve
from ..resources import available_memory
from ..safety import SafetyFilter, SafetyRecord, check_obstacle_starts
from ..sensing import Faults, Sensing
from ..status import Status
from ..validation import whole

if TYPE_CHECKING:
    from ..safety import Obstacle, SafetyFilter, SafetyRecord

__all__ = ["LIST_LIMIT", "SimulationResult", "build_system", "run_system", "simulate"]

#: Most edges (robots, surfaces) whose values a run's summary lists one by one; beyond,
#: summary statistics and counts (the per-edge values go to a table file).
LIST_LIMIT = 100


@dataclass(frozen=True, kw_only=True, eq=False)
class SimulationResult:
    """A simulated run of a law on a formation.

    Attributes
    ----------
    formation, law, integrator
        What was simulated, and how.
    t : ndarray, shape (T,)
        Saved times, seconds.
    q : ndarray, shape (T, n, 2)
        Positions (robot centres) at those times.
    u : ndarray, shape (T, n, 2)
        The velocity of the positions each saved state was left with: the step
        the integrator took (for ``implicit-euler`` and ``filippov`` on a
        switching surface, the sliding motion, not the field of one side); equal
        to the control of the law for single integrators away from the surfaces.
    x : ndarray, shape (T, n, k)
        The full states, positions first (``model.state_names``); ``q`` for single integrators.
    xdot : ndarray, shape (T, n, k)
        The rate of the full state each saved state was left with (``u`` is its positions).
    model : RobotModel
        The robots' motion model.
    marching : Marching or MotionParameters or None
        How the formation was made to march, if it was.
    V : ndarray, shape (T,)
        The law's Lyapunov function: eq. (9) for the distance law, eq. (15) for
        the angle-restricted law.
    sigma : ndarray, shape (T, s)
        Switching functions of the law's distinct surfaces (``s = 0`` for a
        smooth law); a restriction is active where ``sigma >= 0``.
    status : Status
        How the run ended (:class:`formationlab.status.Status`, a string
        enumeration: ``"success"``, ``"step-collision"``, ``"step-too-large"``,
        ``"non-finite"``, ``"interrupted"``, ...).
    message : str
        Why, in words.
    stats : dict
        Integrator diagnostics (steps, cost, switches, ...).
    safety : SafetyRecord or None
        With obstacles or a safety filter: the obstacles, and which robots, pairs and
        obstacle constraints the filter held active at each saved state
        (:class:`formationlab.safety.SafetyRecord`); None otherwise.
    sensing : Sensing or None
        How the robots sensed each other (:mod:`formationlab.sensing`), if not as the paper.
    faults : Faults or None
        The robots that stopped, if any.
    own_distances : ndarray, shape (E, 2), or None
        Under ``sensing.mismatch``: the desired distance of each edge as its first and
        its second robot held it.
    min_robot_clearance, min_obstacle_clearance : float
        Least robot-robot clearance ``r_ij - a_ij`` and least robot-obstacle clearance
        (distance minus the robot's radius; inf without obstacles) over every accepted
        step, saved or not; NaN where the integrator does not measure them (``filippov``).
    """

    formation: Formation
    law: Law
    integrator: Integrator
    t: NDArray[np.float64]
    q: NDArray[np.float64]
    u: NDArray[np.float64]
    V: NDArray[np.float64]
    sigma: NDArray[np.float64]
    status: Status
    message: str
    stats: dict[str, Any] = field(default_factory=dict)
    x: NDArray[np.float64] = field(default=None)  # type: ignore[arg-type]
    xdot: NDArray[np.float64] = field(default=None)  # type: ignore[arg-type]
    model: RobotModel = field(default_factory=SingleIntegrator)
    marching: March | None = None
    sensing: Sensing | None = None
    faults: Faults | None = None
    own_distances: NDArray[np.float64] | None = None
    min_robot_clearance: float = math.nan
    min_obstacle_clearance: float = math.nan

    def __post_init__(self) -> None:
        if self.x is None:
            object.__setattr__(self, "x", self.q)
        if self.xdot is None:
            object.__setattr__(self, "xdot", self.u)

    @cached_property
    def points(self) -> NDArray[np.float64]:
        """Where the law acts, ``(T, n, 2)``: the hand points of near-identity unicycles.

        The formation's distances and orientation apply to them: the outcome,
        the distance errors and the net speed are measured on them.
        """
        return self.model.points(self.x)

    @cached_property
    def point_velocity(self) -> NDArray[np.float64]:
        """Velocities of :attr:`points`, ``(T, n, 2)`` (``u`` unless the points differ)."""
        return self.model.point_rates(self.x, self.xdot)

    @cached_property
    def _shape_frame(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The points and their velocities; with marching, relative to their centroid.

        A marching formation never stops: whether it has settled (the outcome, the
        convergence time, the net speed) is judged in the frame that moves with it.
        """
        p, w = self.points, self.point_velocity
        if self.marching is None:
            return p, w
        return p - p.mean(axis=-2, keepdims=True), w - w.mean(axis=-2, keepdims=True)

    @property
    def headings(self) -> NDArray[np.float64] | None:
        """Headings ``(T, n)`` in radians, for models that have them (else None)."""
        names = type(self.model).state_names
        return self.x[..., names.index("theta")] if "theta" in names else None

    @cached_property
    def shape_error(self) -> NDArray[np.float64]:
        """``max_ij |r_ij - d_ij|`` over the edges, ``(T,)``, at the law's points."""
        f = self.formation

        def largest(p: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.max(np.abs(distance_errors(f, p)), axis=-1)

        return over_time(largest, self.points, 8 * 8 * len(f.edges))

    def centroid_velocity(self) -> NDArray[np.float64]:
        """Velocity of the centroid of the law's points, ``(T, 2)`` (central differences)."""
        return centroid_velocity(self.t, self.points)

    @property
    def heading_spread(self) -> NDArray[np.float64] | None:
        """Largest angle between a heading and their circular mean, ``(T,)`` (unicycles)."""
        h = self.headings
        return None if h is None else heading_spread(h)

    safety: SafetyRecord | None = None

    @property
    def active(self) -> NDArray[np.bool_]:
        """Whether each surface's restriction is on, shape ``(T, s)``."""
        return self.sigma >= 0

    @property
    def restriction_labels(self) -> list[str]:
        """1-based label of each surface of the law, e.g. ``"alpha_123"`` (its first triple).

        Empty for a law without switching surfaces, whatever the formation's orientation.
        """
        if self.sigma.shape[-1] == 0:
            return []
        return self.formation.surface_labels

    @property
    def final(self) -> NDArray[np.float64]:
        """Final positions, shape ``(n, 2)``."""
        return self.q[-1]

    @cached_property
    def distance_errors(self) -> NDArray[np.float64]:
        """``r_ij - d_ij`` per edge over time (at the law's points), shape ``(T, m)``."""
        f = self.formation
        return over_time(lambda p: distance_errors(f, p), self.points, 8 * 8 * len(f.edges))

    @property
    def edge_labels(self) -> list[str]:
        return edge_labels(self.formation)

    def net_speed(self, tolerances: Tolerances | None = None) -> float | None:
        """Net speed over the last ``tolerances.window`` seconds of the run.

        ``max_i |q_i(t_end) - q_i(t_j)| / (t_end - t_j)`` with ``t_j`` the latest saved
        time at least ``window`` before the end (:func:`formationlab.outcomes.analysis.net_speed`):
        with ``save_every`` thinning the samples, over the shortest saved interval of at
        least ``window``; None when the saved run is shorter than ``window``.
        """
        tol = tolerances or Tolerances()
        v = float(net_speed(self.t, self._shape_frame[0], tol.window)[-1])
        return v if np.isfinite(v) else None

    def motion(self, tolerances: Tolerances | None = None) -> RigidMotion:
        """Rigid motion over the last ``drift_window`` seconds (:func:`~.analysis.final_motion`)."""
        return final_motion(self.t, self.q, tolerances)

    def outcome(self, tolerances: Tolerances | None = None) -> Outcome:
        """Outcome of the final state (:mod:`formationlab.outcomes.analysis`), at the law's points.

        With marching, the state is judged in the frame of the points' centroid.

        The robots count as stopped when the final ``max_i |u_i|`` or the net speed over
        the last ``window`` seconds (:meth:`net_speed`) is at most ``tolerances.speed``;
        a moving formation that kept its shape over the last ``drift_window`` seconds
        (:meth:`motion`) is ``drifting`` or ``rotating``.
        """
        p, w = self._shape_frame
        return classify(
            self.formation,
            p[-1],
            w[-1],
            tolerances,
            contact=Status(self.status).contact,
            net_speed=self.net_speed(tolerances),
            motion=self.motion(tolerances),
        )

    @property
    def below_safety_distance(self) -> bool:
        """Whether two robots came closer than the safety filter's ``D_s`` at some step
        (:attr:`formationlab.safety.SafetyRecord.below_safety_distance`): the filter's
        promise broken, whatever the status and outcome say; False without a filter."""
        return self.safety is not None and self.safety.below_safety_distance

    def converged_time(self, tolerances: Tolerances | None = None) -> float | None:
        """First saved time after which the robots stay stopped (instantaneous or net speed)."""
        tol = tolerances or Tolerances()
        p, w = self._shape_frame
        return converged_time(self.t, w, tol.speed, q=p, window=tol.window)

    def summary(self, tolerances: Tolerances | None = None) -> dict[str, Any]:
        """A JSON-ready summary of the run (the ``summary.json`` of ``run`` and ``paper``).

        Keys: ``model`` (name and parameters), ``state_names``, ``outcome``, ``status``,
        ``message``, ``n_robots``, ``n_edges``, ``final_positions`` (``[[x, y], ...]``,
        robot 1 first), ``distance_errors`` (final ``r_ij - d_ij`` keyed by edge label
        ``"i-j"``, 1-based), ``max_distance_error``, ``distance_error_stats``
        (:func:`~formationlab.outcomes.analysis.error_statistics` of the final errors: max, mean,
        rms, percentiles, how many within the tolerance), ``converged_time`` (or None),
        ``final_time``, ``orientation`` (``"ccw"``/``"cw"`` of robots 1, 2, 3),
        ``active_restrictions_final`` (labels) and ``active_restrictions_final_count``,
        ``diagnostics`` (integrator statistics),
        ``tolerances``; for a ``drifting`` or ``rotating`` outcome ``rigid_motion``:
        ``velocity`` (of the centroid, ``[vx, vy]``), ``speed``, ``angular_velocity``,
        ``centre`` (of the rotation; None for a drift), ``shape_rate`` and ``window``; in
        space also the screw's ``axis`` (the unit direction of the rotation, ``centre`` its
        point nearest the centroid), ``axial_velocity`` along it and ``pitch`` (m/rad);
        for models with more state ``final_state`` (rows of ``state_names``), for
        unicycles ``final_headings`` and ``heading_spread`` (radians), and with
        marching ``marching`` (final shape error, centroid velocity, its error against
        the reference); with marching ``final_speed``, ``converged_time`` and
        ``net_speed`` are measured relative to the centroid.
        With obstacles or a filter also ``safety``
        (:meth:`formationlab.safety.SafetyRecord.summary`), and always
        ``min_robot_clearance`` and ``min_obstacle_clearance`` (over every accepted step;
        None where not measured or without obstacles) and ``below_safety_distance``
        (:attr:`below_safety_distance`).

        **Many robots.** The lists stay readable: per-edge values (``distance_errors``,
        the sensing's ``own_distances``) only up to :data:`LIST_LIMIT` edges, per-robot
        values (``final_positions``, ``final_points``, ``final_state``,
        ``final_headings``) up to :data:`LIST_LIMIT` robots, ``active_restrictions_final``
        up to :data:`LIST_LIMIT` surfaces; beyond, the statistics and counts remain
        (:meth:`edge_table` holds every edge; ``formationlab run`` writes it to a file).
        A run that blew up has inf or NaN figures, without numpy's warnings.
        """
        with np.errstate(over="ignore", invalid="ignore"):
            return self._summary(tolerances)

    def _summary(self, tolerances: Tolerances | None) -> dict[str, Any]:
        tol = tolerances or Tolerances()
        n, m = self.formation.n, len(self.formation.edges)
        p_final = self.points[-1]
        err = distance_errors(self.formation, p_final)
        outcome = self.outcome(tol)
        moving = outcome in ("drifting", "rotating")
        on = self.active[-1]
        lists: dict[str, Any] = {}  # per robot, per edge, per surface: for few only
        if n <= LIST_LIMIT:
            lists["final_positions"] = self.q[-1].tolist()
        if m <= LIST_LIMIT:
            lists["distance_errors"] = dict(zip(self.edge_labels, err.tolist(), strict=True))
        if on.size <= LIST_LIMIT:
            lists["active_restrictions_final"] = [
                lab for lab, a in zip(self.restriction_labels, on, strict=True) if a
            ]
        extra: dict[str, Any] = {}
        if self.headings is not None:
            if n <= LIST_LIMIT:
                extra["final_headings"] = self.headings[-1].tolist()
            extra["heading_spread"] = float(self.heading_spread[-1])  # type: ignore[index]
        if len(self.model.names_in(self.formation.dim)) > self.formation.dim and n <= LIST_LIMIT:
            extra["final_state"] = self.x[-1].tolist()
        differ = self.points is not self.q and not np.array_equal(p_final, self.q[-1])
        if differ and n <= LIST_LIMIT:
            extra["final_points"] = p_final.tolist()
        if self.marching is not None and len(self.t) > 2:
            extra["marching"] = self._marching_summary()
        extra["min_robot_clearance"] = _finite(self.min_robot_clearance)
        extra["min_obstacle_clearance"] = _finite(self.min_obstacle_clearance)
        extra["below_safety_distance"] = self.below_safety_distance
        if self.safety is not None:
            extra["safety"] = self.safety.summary()
        if self.sensing is not None:
            extra["sensing"] = self.sensing.describe()
            if self.own_distances is not None and m <= LIST_LIMIT:
                extra["sensing"]["own_distances"] = dict(
                    zip(self.edge_labels, self.own_distances.tolist(), strict=True)
                )
        if self.faults is not None:
            extra["faults"] = self.faults.describe()
        if self.formation.bearings is not None:  # judged by its bearings: say how far
            berr = bearing_errors(self.formation, p_final)
            if m <= LIST_LIMIT:
                extra["bearing_errors"] = dict(zip(self.edge_labels, berr.tolist(), strict=True))
            extra["max_bearing_error"] = float(np.max(berr))
            extra["bearing_error_stats"] = error_statistics(berr, tol.bearing)
        return {
            "model": {"name": self.model.name, **dataclasses.asdict(self.model)},
            "state_names": list(self.model.names_in(self.formation.dim)),
            "outcome": outcome,
            "status": self.status,
            "message": self.message,
            "final_time": float(self.t[-1]),
            "n_robots": n,
            "n_edges": m,
            **{k: lists.pop(k) for k in ("final_positions", "distance_errors") if k in lists},
            "max_distance_error": float(np.max(np.abs(err))),
            "distance_error_stats": error_statistics(err, tol.distance),
            "converged_time": self.converged_time(tol),
            "final_speed": float(np.max(np.linalg.norm(self._shape_frame[1][-1], axis=-1))),
            "net_speed": self.net_speed(tol),
            "orientation": (triangle_orientation(p_final) if n >= 3 else None),
            **lists,
            "active_restrictions_final_count": int(np.count_nonzero(on)),
            "diagnostics": dict(self.stats),
            "tolerances": dataclasses.asdict(tol),
            **({"rigid_motion": _motion_dict(self.motion(tol), outcome)} if moving else {}),
            **extra,
        }

    def edge_table(self) -> dict[str, NDArray[Any]]:
        """Every edge at the end of the run, as columns of equal length ``m``.

        ``edge`` (label ``"i-j"``), ``i`` and ``j`` (1-based robots), ``desired_distance``
        ``d_ij``, ``distance`` ``r_ij`` and ``distance_error`` ``r_ij - d_ij`` (at the law's
        points). ``formationlab run`` writes it to ``distance_errors.parquet`` when the
        formation has more than :data:`LIST_LIMIT` edges.
        """
        f = self.formation
        p, e = self.points[-1], f.edges.astype(np.int64)  # the table's robots as int64
        r = np.linalg.norm(p[e[:, 1]] - p[e[:, 0]], axis=-1)
        return {
            "edge": np.array(self.edge_labels),
            "i": e[:, 0] + 1,
            "j": e[:, 1] + 1,
            "desired_distance": np.asarray(f.distances, dtype=float),
            "distance": r,
            "distance_error": r - f.distances,  # as analysis.distance_errors
        }

    def _marching_summary(self) -> dict[str, Any]:
        """Final shape error and centroid velocity (against the reference, when there is one)."""
        vc = self.centroid_velocity()[-1]
        out: dict[str, Any] = {
            "shape_error_final": float(self.shape_error[-1]),
            "centroid_velocity_final": vc.tolist(),
        }
        march = self.marching
        if isinstance(march, Marching):
            ref = march.reference(float(self.t[-1]))
            out["reference_velocity_final"] = ref.tolist()
            if not march.per_leader:  # (leaders with a velocity each: no one centroid velocity)
                out["centroid_velocity_error_final"] = float(np.linalg.norm(vc - ref))
            out["leader"] = march.leader
            f = self.formation
            if len(march.leaders) >= 2 and f.bearings is not None:  # where the leaders say
                p = self.points[-1]
                lead = np.array(march.leaders) - 1
                target = leader_target(f, march.leaders, p[lead])
                scale = float(np.max(np.linalg.norm(target - target.mean(axis=0), axis=-1)))
                gap = float(np.max(np.linalg.norm(p - target, axis=-1)))
                out["leader_target_error_final"] = gap
                out["leader_target_scale_final"] = scale
        return out

    def plot(self, kind: str = "trajectories", ax: Any = None, **kwargs: Any) -> Any:
        """Plot the run: ``"trajectories"``, ``"controls"``, ``"lyapunov"`` or ``"errors"``.

        Needs matplotlib (imported here, not at package import). Returns the artists.
        """
        from .. import plotting  # draws with matplotlib: imported when drawing (start-up time)

        return plotting.plot_result(self, kind, ax=ax, **kwargs)


def _motion_dict(m: RigidMotion, outcome: str) -> dict[str, Any]:
    v = np.asarray(m.velocity, dtype=float)
    screw = {}  # in space: the screw's axis, its advance along it and per radian
    if m.axis is not None:
        screw = {
            "axis": np.asarray(m.axis, dtype=float).tolist(),
            "axial_velocity": float(m.axial_velocity),
            "pitch": float(m.pitch),
        }
    return {
        "velocity": v.tolist(),
        "speed": float(np.hypot(*v) if v.size == 2 else np.linalg.norm(v)),
        "angular_velocity": float(m.omega),
        "centre": np.asarray(m.centre).tolist() if outcome == "rotating" else None,
        **screw,
        "shape_rate": float(m.shape_rate),
        "window": float(m.window),
    }


def simulate(
    formation: Formation,
    law: Law | str,
    q0: ArrayLike,
    *,
    duration: float,
    integrator: Integrator | str | None = None,
    model: RobotModel | str | None = None,
    marching: March | None = None,
    save_every: int = 1,
    progress: Callable[[float], None] | None = None,
    interruptible: bool = False,
    obstacles: Sequence[Obstacle] = (),
    safety: SafetyFilter | str | None = None,
    backend: Literal["auto", "numpy", "numba"] = "auto",
    sensing: Sensing | None = None,
    faults: Faults | None = None,
    **initial: Any,
) -> SimulationResult:
    """Simulate ``law`` on ``formation`` from ``q0`` (``q_dot_i = u_i``, eq. 1, by default).

    Parameters
    ----------
    formation : Formation
        Robots, graph, desired distances and orientation.
    law : Law or str
        The control law, e.g. :class:`~formationlab.AngleRestrictedLaw`, or its name
        (``"distance"``: built with its defaults).
    q0 : array_like, shape (n, 2) or (n, k)
        Initial positions (robot centres), validated (finite, no overlapping
        robots); or the model's full initial state (``k = model.state_size()``).
    duration : float
        Simulated time, seconds.
    integrator : Integrator or str, optional
        Default ``Euler(dt=1e-3)``; a name (``"rk4"``) gets the integrator's defaults.
    model : RobotModel or str, optional
        The robots (:mod:`formationlab.models`): default the paper's single
        integrators; a name (``"unicycle"``) gets the model's defaults.
    marching : Marching or MotionParameters, optional
        Make the formation march (:mod:`formationlab.marching`).
    save_every : int
        Keep every K-th step (thins what is stored, not what is computed).
    progress : callable, optional
        Called with the simulated time now and then.
    interruptible : bool
        On Ctrl-C, return the run so far with status ``"interrupted"`` instead of
        raising ``KeyboardInterrupt`` (fixed-step integrators).
    backend : {"auto", "numpy", "numba"}
        ``"numba"``: the compiled single-run path (:mod:`formationlab.integrators.compiled`:
        explicit Euler, single integrators, a law with kernel data; any size, no ``n x n``
        arrays); ``"numpy"``: the integrator's own ``run`` (the stepping driver);
        ``"auto"`` (default) takes the compiled path wherever it applies. The two agree
        to rounding (tested).
    **initial
        The model's extra initial state when ``q0`` holds positions only:
        ``headings`` (unicycle, radians), ``velocities`` (double integrator).
    obstacles : sequence of Circle or Polygon
        Static obstacles (:mod:`formationlab.safety`): the law gains Khatib's repulsion
        from them, and touching one is contact (status ``"step-collision"``).
    safety : SafetyFilter or str, optional
        A safety filter between the law and the robots (``"barrier"``,
        ``"barrier-decentralized"`` with their defaults, or a configured
        :class:`~formationlab.safety.SafetyFilter`); default none.
    sensing : Sensing, optional
        How the robots measure each other (:mod:`formationlab.sensing`: local frames,
        noise, range, delay, drops, mismatch; seeded by ``sensing.seed``); default the
        paper's exact, common-frame sensing. Needs ``euler`` or ``rk4``.
    faults : Faults, optional
        Robots that stop moving (:class:`~formationlab.sensing.Faults`).

    Returns
    -------
    SimulationResult

    Examples
    --------
    >>> import formationlab as fl
    >>> f = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
    >>> res = fl.simulate(f, fl.DistanceLaw(k_c=2.0), [[-3, -3], [3, -3], [0, 3]],
    ...                   duration=10.0)
    >>> res.outcome()
    'desired'
    >>> uni = fl.simulate(f, "distance", [[-3, -3], [3, -3], [0, 3]], duration=10.0,
    ...                   model="unicycle", headings=[0.0, 1.5, 3.0])
    >>> uni.x.shape[-1], uni.outcome()
    (3, 'desired')
    """
    save_every = whole(save_every, "save_every")
    law, integrator = resolve(LAWS, law), resolve(INTEGRATORS, integrator or Euler(dt=1e-3))
    robot = resolve(MODELS, model or SingleIntegrator())
    x0 = initial_state(formation, robot, q0, **initial)
    system = build_system(
        formation, law, robot, x0, marching=marching, obstacles=obstacles, safety=safety,
        sensing=sensing, faults=faults,
    )  # fmt: skip
    return run_system(
        system, integrator, x0, duration=duration, save_every=save_every, progress=progress,
        interruptible=interruptible, backend=backend,
    )  # fmt: skip


def run_system(
    system: System,
    integrator: Integrator,
    x0: NDArray[np.float64],
    *,
    duration: float,
    save_every: int = 1,
    progress: Callable[[float], None] | None = None,
    interruptible: bool = False,
    backend: Literal["auto", "numpy", "numba"] = "auto",
) -> SimulationResult:
    """Run a closed loop built by :func:`build_system` from its validated start ``x0``.

    The second half of :func:`simulate` (its arguments mean the same); a scenario's loop
    (:func:`formationlab.scenario.closed_loop`) runs through it too.
    """
    save_every = whole(save_every, "save_every")
    law, robot = system.law, system.model
    if backend not in ("auto", "numpy", "numba"):
        raise ParameterError(
            f"backend must be 'auto', 'numpy' or 'numba', got {backend!r}", key="backend"
        )
    _check_size(system, integrator, duration, save_every)
    terms = compiled_terms(system, integrator) if backend != "numpy" else None
    if backend == "numba" and terms is None:
        raise ParameterError(
            'backend="numba" runs explicit Euler on the package\'s robot models with a law '
            "that has kernel data; got "
            f"{integrator.name!r}, {robot.name!r} and {law.name!r}: use backend='auto'"
        )
    if terms is not None:
        raw = run_euler_compiled(
            terms, system, x0, dt=integrator.dt, duration=float(duration),  # type: ignore[attr-defined]
            save_every=int(save_every), progress=progress, interruptible=interruptible,
            diagnostics=False,
        )  # fmt: skip
        terms = None  # the run's lists are let go before the post-processing
    else:
        raw = integrator.run(
            system, x0, float(duration), save_every=int(save_every), progress=progress,
            interruptible=interruptible,
        )  # fmt: skip
    return _result(system, integrator, raw, interruptible=interruptible)


#: the most steps one run may take: more is a mistyped number (1e13 steps of the paper's
#: triangle take about four months at the compiled run's 1 us per step)
STEP_LIMIT = 1e13


def _check_size(system: System, integrator: Integrator, duration: float, save_every: int) -> None:
    """Refuse, before anything is allocated, a run of more than :data:`STEP_LIMIT` steps or
    whose saved states (a state, its rates and its time each) cannot be held in the memory
    available; the advice printed is accepted. (The commands plan more closely, figures and
    files included, and refuse earlier: ``formationlab.cli._plan``.)"""
    dt = getattr(integrator, "dt", None)
    if dt is None:  # an event-driven integrator: no step count known in advance
        return
    steps = float(duration) / float(dt)
    if not steps <= STEP_LIMIT:
        raise ParameterError(
            f"duration = {float(duration):g} s in steps of dt = {float(dt):g} s is "
            f"{steps:.3g} steps, more than {STEP_LIMIT:.0e}: shorten the duration or "
            f"lengthen dt (at most {STEP_LIMIT * float(dt):.3g} s at this dt)",
            key="duration",
        )
    k = len(system.model.names_in(system.formation.dim))
    per_state = 16.0 * system.formation.n * k + 8.0
    need = (steps / save_every + 2) * per_state
    memory = available_memory()
    if memory is None or need <= memory:  # (beyond, the allocation would fail)
        return
    states = 0.25 * memory / per_state  # (room for the result's post-processing too)
    every = max(save_every + 1, math.ceil(steps / max(states - 2, 1)))
    raise ParameterError(
        f"the run keeps {steps / save_every + 2:,.0f} states (save_every = {save_every}): "
        f"~{need / 2**30:,.3g} GiB, with {memory / 2**30:,.3g} GiB of memory available; keep "
        f"fewer (save_every = {every}), or shorten the duration or lengthen dt",
        key="save_every",
    )


def _result(
    system: System, integrator: Integrator, raw: RawSolution, *, interruptible: bool = False
) -> SimulationResult:
    """The :class:`SimulationResult` of ``raw``, a run of ``system`` under ``integrator``:
    the post-processing of :func:`simulate` (V, sigma, the switching diagnostics of a
    compiled run, the safety record), slice by slice along time."""
    system = system.at_step(getattr(integrator, "dt", None))  # (the filter the run stepped)
    formation, law, robot = system.formation, system.law, system.model
    marching, sensing, faults = system.marching, system.sensing, system.faults
    points = robot.points(raw.x)
    record = None
    if system.obstacles or system.filtered:
        clear = system.obstacle_clearances(raw.x)
        least = clear.min(axis=(-2, -1)) if clear.size else np.full(len(raw.t), np.inf)
        record = SafetyRecord.from_states(
            raw.q, filter=system.safety if system.filtered else None,
            obstacles=system.obstacles,
            result=system.filter_result(raw.x) if system.filtered else None,
            obstacle_clearance=least, least_distance=raw.min_pair_distance,
        )  # fmt: skip
    status, message = raw.status, raw.message
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # a diverged run: V is inf
            V, sigma = system.potential(raw.x), system.sigma(raw.x)
        if raw.stats.get("backend") == "numba":  # the compiled run's switching diagnostics
            raw.stats.update(switching_diagnostics(raw.t, sigma))
    except KeyboardInterrupt:  # while reading the run: keep the states, not V and sigma
        if not interruptible:
            raise
        V = np.full(len(raw.t), np.nan)
        sigma = np.full((len(raw.t), law.switching(formation, points[:1]).shape[-1]), np.nan)
        status = Status.INTERRUPTED
        message = f"interrupted by the user at t = {raw.t[-1]:g} s"
    return SimulationResult(
        formation=formation,
        law=law,
        integrator=integrator,
        t=raw.t,
        q=raw.q,
        u=raw.v[..., : formation.dim],
        V=V,
        sigma=sigma,
        status=status,
        message=message,
        stats=dict(raw.stats),
        x=raw.x,
        xdot=raw.v,
        model=robot,
        marching=marching,
        safety=record,
        sensing=sensing,
        faults=faults,
        own_distances=_own_distances(system, integrator),
        min_robot_clearance=raw.min_robot_clearance,
        min_obstacle_clearance=raw.min_obstacle_clearance,
    )


def _finite(value: float) -> float | None:
    """``value``, or None when it is not a finite number (not measured, no obstacles)."""
    return float(value) if math.isfinite(value) else None


def _own_distances(system: System, integrator: Integrator) -> NDArray[np.float64] | None:
    """The desired distances each robot of a mismatched run held (its channel's, trial 0)."""
    if not system.sensed or system.sensing is None or system.sensing.mismatch == 0:
        return None
    own = system.channel(None, float(getattr(integrator, "dt", 1.0))).own_distance
    return None if own is None else own[0]


def _own_initial(model: RobotModel, initial: dict[str, Any]) -> dict[str, Any]:
    """The keywords of ``initial`` that are ``model``'s initial state; another model's
    (``headings`` for a single integrator) is ignored with a warning, an unknown keyword
    refused by name (``simulate`` and ``run_async`` take the model's initial state as keywords)."""
    own = type(model).initial_keys
    kept = {k: v for k, v in initial.items() if k in own}
    for key in sorted(set(initial) - set(own)):
        owners = initial_keys().get(key, ())
        if not owners:
            raise ParameterError(
                f"unknown keyword {key!r}: beside the named arguments, a run takes the "
                f"robot model's initial state ({model.name!r}: "
                f"{', '.join(own) if own else 'none'}; "
                + ", ".join(
                    f"{k!r} for {' and '.join(map(repr, n))}" for k, n in initial_keys().items()
                )
                + ")",
                key=key,
            )
        warnings.warn(
            f"{key} is the initial state of the {' and '.join(map(repr, owners))} model"
            f"{'s' if len(owners) > 1 else ''}; the {model.name!r} model has none: ignored",
            IgnoredKeyWarning,
            stacklevel=4,
        )
    return kept


def initial_state(
    formation: Formation, model: RobotModel, q0: ArrayLike, **initial: Any
) -> NDArray[np.float64]:
    """The validated initial state ``(..., n, k)`` of ``model`` from positions or a full state.

    ``q0`` ``(..., n, 2)`` gets the model's extra state from ``initial``
    (:meth:`RobotModel.initial_state`); ``(..., n, k)`` is taken as it is. The
    centres must be clear of contact, and so must the law's points where they
    differ (near-identity hand points: the law's barrier acts on them).
    """
    arr = np.asarray(q0, dtype=float)
    model.check_space(formation.dim)
    k = len(model.names_in(formation.dim))
    if arr.ndim >= 2 and arr.shape[-1] == k and k > formation.dim:
        if initial:
            raise ParameterError(
                f"q0 is already a full {model.name} state (..., n, {k}); do not also give "
                + ", ".join(sorted(initial))
            )
        if not np.all(np.isfinite(arr)):
            raise FormationError("the initial state holds NaN or infinite numbers")
        x0 = arr.copy()
        formation.check_positions(model.positions(x0))
    else:
        q = formation.check_positions(arr)
        x0 = model.initial_state(q, **_own_initial(model, initial))
    if x0.ndim != 2:
        raise ParameterError(f"simulate takes one initial state of shape (n, k), got {x0.shape}")
    points = model.points(x0)
    if not np.array_equal(points, model.positions(x0)):
        try:
            formation.check_positions(points, what="initial hand points")
        except (FormationError, ParameterError) as exc:  # (overlap, or beyond the coordinates)
            # an offset wider than the formation is the cause, else the robots' headings
            q = model.positions(x0)
            across = float(np.max(np.ptp(q, axis=0))) if len(q) else 0.0
            offset = float(getattr(model, "offset", 0.0))
            if offset > across:
                raise FormationError(
                    f"{exc} (the law acts on points {offset:.3g} m ahead of the centres, "
                    f"and the robots stand within {across:.3g} m: use a smaller offset)",
                    key="offset",
                ) from None
            raise FormationError(
                f"{exc} (the law acts on points ahead of the centres: turn the robots or "
                "use a smaller offset)",
                key="headings",
            ) from None
    return x0


def build_system(
    formation: Formation,
    law: Law,
    model: RobotModel,
    x0: NDArray[np.float64],
    *,
    marching: March | None = None,
    obstacles: Sequence[Obstacle] = (),
    safety: SafetyFilter | str | None = None,
    sensing: Sensing | None = None,
    faults: Faults | None = None,
) -> System:
    """The closed loop of every part, with obstacles and filter validated against ``x0``.

    The one builder of a :class:`System` from its parts: :func:`simulate`, a scenario's
    :func:`~formationlab.scenario.closed_loop` and the asynchronous runner call it.

    Parameters
    ----------
    formation, law, model
        Robots and graph, control law, robot model.
    x0 : ndarray, shape (n, k)
        The validated start (:func:`initial_state`); the obstacles must be clear of it.
    marching, obstacles, safety, sensing, faults
        As for :func:`simulate`; ``safety`` may be a filter's name.
    """
    if not obstacles and (safety is None or safety == "none"):
        return System(
            formation=formation, law=law, model=model, marching=marching, sensing=sensing,
            faults=faults,
        )  # fmt: skip
    if isinstance(safety, str):
        safety = SafetyFilter(filter=safety)  # type: ignore[arg-type]
    elif safety is not None and not isinstance(safety, SafetyFilter):
        raise ParameterError(
            f"safety must be a SafetyFilter or a filter's name ('barrier', "
            f"'barrier-decentralized', 'none'), got {safety!r}",
            key="safety",
        )
    system = System(
        formation=formation, law=law, model=model, marching=marching,
        obstacles=tuple(obstacles), safety=safety, sensing=sensing, faults=faults,
    )  # fmt: skip
    check_obstacle_starts(model.positions(x0), formation.diameters / 2, system.obstacles)
    return system
