"""The closed loop: a formation, a law and a robot model; and the one rule for a step.

:class:`System` is what every integrator steps. Its state ``x`` has shape
``(..., n, k)`` with the robot model's ``k`` numbers per robot, positions
first (:mod:`formationlab.models.base`); for the paper's single integrators
``x`` is the positions ``q`` themselves. The law sees ``model.points(x)``; a
:mod:`~formationlab.marching` term, if any, adds to the law's control
(:meth:`System.command`) before the model turns it into motion. The field may
depend on the time through the marching reference only: ``rhs(x, t)`` takes
``t`` (default 0) and the schemes pass each stage's time.

:meth:`System.step_verdict` is the contact rule of the package, used by the
stepping driver, the settling of equilibria and (in compiled form) the batch
kernel: a step from ``x0`` to ``x1`` is rejected when it is not finite (a coordinate
NaN or infinite, or a position coordinate beyond about 1.3e154, whose square overflows:
squared distances, and so the law's forces, are meaningless there), when it
ends with two robots in contact (``r_ij <= a_ij``: :attr:`Status.COLLISION`)
or when the straight path of the step passes through contact while both ends
are clear (:attr:`Status.STEP_TOO_LARGE`: robots jumped through each other).

Obstacles and a safety filter (:mod:`formationlab.safety`) belong to the closed
loop too: the command of robot ``i`` is the law's ``u_i`` plus Khatib's repulsion
``-k grad_i Gamma_o`` from the obstacles (``k`` the law's repulsion gain,
:meth:`~formationlab.controllers.Law.obstacle_repulsion`), then minimally changed by
the filter (:meth:`~formationlab.safety.SafetyFilter.apply` on the law's points), then
turned into motion by the robot model. A robot touching an obstacle (clearance
``delta - rho_i / 2 <= 0``) is contact like two robots touching, at the end of a step
and along it (:func:`formationlab.safety.swept_clearances`). Without obstacles and
with no filter every method computes exactly what it did before they existed.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from itertools import pairwise
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .controllers import Law
from .errors import ParameterError
from .formation.chunked import over_time, row_bytes
from .formation.geometry import row_norms
from .formation.spec import DENSE_LIMIT, Formation
from .marching import March
from .models import RobotModel, SingleIntegrator
from .neighbours.kdtree import close_pairs
from .safety import clearances, grad_obstacle_potential, obstacle_potential, swept_clearances
from .sensing import SENSING_LIMIT, Channel, Faults, Seed, Sensing
from .status import Status
from .validation import COORDINATE_LIMIT

if TYPE_CHECKING:  # the safety package needs the optional "safety" extra at run time
    from .safety import FilterResult, Obstacle, SafetyFilter

__all__ = ["SensedView", "System"]


class SensedView(NamedTuple):
    """A channel bound to the live trials of a step (:meth:`System.bound`).

    ``u_local`` holds the robots' commands in their own frames for the whole step
    (a channel with noise, delay or drops); None: computed from the state at each stage.
    """

    channel: Channel
    live: NDArray[np.intp]
    u_local: NDArray[np.float64] | None = None


@dataclass(frozen=True, kw_only=True)
class System:
    """A closed loop: a formation, a law, a robot model, obstacles and a safety filter.

    ``rhs(x, t)`` is the vector field the integrators step; ``rhs_with(x, w, t)``
    the same with the law's steps replaced by Filippov weights ``w`` (shape of
    ``law.switching``); ``sigma(x)`` the switching functions. ``marching``
    (:class:`~formationlab.marching.Marching` or
    :class:`~formationlab.marching.MotionParameters`) adds to the law's control.

    ``obstacles`` are static :class:`~formationlab.safety.Circle` and
    :class:`~formationlab.safety.Polygon` obstacles in the plane,
    :class:`~formationlab.safety.Sphere` and :class:`~formationlab.safety.Box` in space;
    ``safety`` a
    :class:`~formationlab.safety.SafetyFilter` (None or ``filter = "none"``: commands
    unchanged). The filter's ``D_s`` and ``D_o`` are checked against the contact
    distances when the system is built.
    """

    formation: Formation
    law: Law
    model: RobotModel = field(default_factory=SingleIntegrator)
    marching: March | None = None
    obstacles: Sequence[Obstacle] = ()
    safety: SafetyFilter | None = None
    sensing: Sensing | None = None
    faults: Faults | None = None
    view: SensedView | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "obstacles", tuple(self.obstacles))
        # the formation as the law is judged on it (desired bearings kept or dropped)
        object.__setattr__(self, "formation", self.law.formation_for(self.formation))
        if self.formation.dim != 2:
            self._check_space()
        if self.faults is not None:
            self.faults.check(self.formation.n)
        if self.sensed:
            if self.formation.n > SENSING_LIMIT:
                assert self.sensing is not None
                Channel(self.sensing, self.formation, self.law, self.model, [], 1.0)  # says why
            self.law.sensed_terms(self.formation)  # a law without its own-frame terms says so now
        if self.marching is not None:
            self.marching.check(self.formation)
        if self.filtered:
            assert self.safety is not None
            self.safety.check_model(self.model)
            self.safety.check_diameters(self.formation.diameters)
        if self.obstacles:
            self._check_obstacles()
            self.law.obstacle_repulsion()  # a law without one refuses obstacles now

    def _check_space(self) -> None:
        """Refuse, by name, what the closed loop cannot do yet for a formation in space.

        Sensing (local frames as rotations of SO(3), noise on each coordinate, range, delay,
        losses, mismatch), faults, marching, obstacles in space (spheres, boxes) and the
        safety filters run in space; a frame error, an angle in the plane, does not, nor do
        the plane's obstacles (circles, polygons) or the filter's speed polygon.
        """
        dim = self.formation.dim
        self.model.check_space(dim)
        if self.sensing is not None and self.sensing.frame_error > 0:
            raise ParameterError(
                f"sensing.frame_error turns the common frame by an angle in the plane; a "
                f"formation in space ({dim}-D) has no such angle: remove sensing.frame_error "
                '(frames = "local" gives every robot a random rotation in space)',
                key="sensing.frame_error",
            )
        if self.filtered:
            assert self.safety is not None
            self.safety.check_space(dim)

    def _check_obstacles(self) -> None:
        """Every obstacle lives in the formation's dimension (circles and polygons in the
        plane, spheres and boxes in space)."""
        dim = self.formation.dim
        for k, ob in enumerate(self.obstacles):
            if ob.dim != dim:
                where = {2: "the plane", 3: "space (3-D)"}
                instead = "a sphere or a box" if dim == 3 else "a circle or a polygon"
                raise ParameterError(
                    f"obstacle {k + 1} ({ob.describe()}) is an obstacle in {where[ob.dim]}, and "
                    f"the formation is in {where[dim]}: use {instead}",
                    key="obstacles",
                )

    @property
    def time_dependent(self) -> bool:
        """Whether the field depends on the time (a marching reference that is a function,
        a robot that stops at some finite ``t > 0``; ``at = inf`` never comes)."""
        stops = self.faults is not None and bool(self.faults.later())
        return stops or (self.marching is not None and self.marching.time_dependent)

    @property
    def sensed(self) -> bool:
        """Whether the robots sense other than the paper says (:attr:`Sensing.ideal`)."""
        return self.sensing is not None and not self.sensing.ideal

    def channel(self, seeds: Sequence[Seed] | None, dt: float, trials: int = 1) -> Channel:
        """The measurement channel of ``trials`` trials (``seeds``: default the sensing's seed)."""
        assert self.sensing is not None
        if seeds is None:
            seeds = [self.sensing.seed] * trials
        return Channel(self.sensing, self.formation, self.law, self.model, seeds, dt)

    def bound(self, view: SensedView) -> System:
        """This system reading its robots' measurements from ``view`` (the driver, per step)."""
        out = copy.copy(self)
        object.__setattr__(out, "view", view)
        return out

    def _law_control(self, x: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64]:
        """The law's part of the command: the law, or every robot's own sensed command."""
        if not self.sensed:
            return self.law.control(self.formation, p)
        view = self.view
        if view is None:
            assert self.sensing is not None
            if self.sensing.sampled:
                raise RuntimeError(
                    "a system whose sensing has noise, delay or drops is stepped through the "
                    "stepping driver, which owns its measurement channel"
                )
            batch = int(np.prod(x.shape[:-2], dtype=np.int64))
            flat = x.reshape(batch, *x.shape[-2:])
            view = SensedView(self.channel(None, 1.0, batch), np.arange(batch))
            return view.channel.world(self._sensed_local(view, flat), flat, view.live).reshape(
                p.shape
            )
        return view.channel.world(self._sensed_local(view, x), x, view.live)

    @staticmethod
    def _sensed_local(view: SensedView, x: NDArray[np.float64]) -> NDArray[np.float64]:
        if view.u_local is not None:
            return view.u_local
        z, seen = view.channel.field(x, view.live)
        return view.channel.local(z, seen, view.live)

    def _faulty(self, xdot: NDArray[np.float64], t: float) -> NDArray[np.float64]:
        """``xdot`` with the rows of the robots that have stopped by ``t`` set to zero."""
        if self.faults is None or not self.faults.any:
            return xdot
        stopped = self.faults.stopped(self.formation.n, t)
        if stopped.any():
            xdot = np.array(xdot, copy=True)
            xdot[..., stopped, :] = 0.0
        return xdot

    def at_step(self, dt: float | None) -> System:
        """This system with its safety filter guarding steps of length ``dt``
        (:meth:`SafetyFilter.at_step <formationlab.safety.SafetyFilter.at_step>`; None: no
        step known, the continuous rows). Every loop that steps a system calls it with its
        step: the stepping driver, the compiled runs and batches, the record of a run."""
        if not self.filtered:
            return self
        assert self.safety is not None
        safety = self.safety.at_step(dt)
        if safety is self.safety:
            return self
        out = copy.copy(self)  # (the checks of __post_init__ were made for this filter)
        object.__setattr__(out, "safety", safety)
        return out

    @property
    def filtered(self) -> bool:
        """Whether a safety filter changes the commands (``safety.filter != "none"``)."""
        return self.safety is not None and self.safety.enabled

    def command(
        self, p: NDArray[np.float64], u: NDArray[np.float64], t: float = 0.0
    ) -> NDArray[np.float64]:
        """The command ``(..., n, 2)``: the law's control ``u`` at points ``p``, with marching,
        obstacle repulsion and then the safety filter."""
        if self.marching is not None:
            u = self.marching.command(self.formation, p, u, t, self.model.velocity_gain)
        if self.obstacles:
            u = self._repelled(p, u)
        if self.filtered:
            assert self.safety is not None
            u = self.safety.command(p, u, obstacles=self.obstacles)
        return u

    def rhs(self, x: NDArray[np.float64], t: float = 0.0) -> NDArray[np.float64]:
        p = self.model.points(x)
        u = self.command(p, self._law_control(x, p), t)
        return self._faulty(self.model.derivative(x, u), t)

    def rhs_with(
        self, x: NDArray[np.float64], weights: NDArray[np.float64], t: float = 0.0
    ) -> NDArray[np.float64]:
        p = self.model.points(x)
        u = self.command(p, self.law.control_with(self.formation, p, weights), t)
        return self._faulty(self.model.derivative(x, u), t)

    def rhs_commanded(
        self, x: NDArray[np.float64], u: NDArray[np.float64], t: float = 0.0
    ) -> NDArray[np.float64]:
        """``x_dot`` when the law's part of the command is ``u`` ``(..., n, 2)``, given.

        ``u`` is in the common frame, at the law's points, as :meth:`command` takes it:
        robots whose commands come from elsewhere (the agents of
        :mod:`formationlab.agents`). Marching, obstacle repulsion, the safety filter, the
        robot model and the faults then act as in :meth:`rhs`.
        """
        p = self.model.points(x)
        return self._faulty(self.model.derivative(x, self.command(p, u, t)), t)

    def speed(self, x: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        """Largest robot speed (:meth:`RobotModel.speed`) of states and rates ``(..., n, k)``."""
        return np.max(self.model.speed(x, v), axis=-1)

    def filter_result(self, x: NDArray[np.float64], t: float | None = None) -> FilterResult:
        """What the safety filter does at states ``x`` ``(..., n, k)``: command, status, active set.

        Trials of the result are the flattened batch axes of ``x``. Needs a filter. The
        filter's input is the law's control with the obstacles' repulsion; with ``t``, also
        the marching term at ``t`` (the command the robots were given then, as in
        :meth:`command`).
        """
        if not self.filtered:
            raise ParameterError("this system has no safety filter (safety.filter is 'none')")
        assert self.safety is not None
        p = self.model.points(np.asarray(x, dtype=float))
        u = self.law.control(self.formation, p)
        if t is not None and self.marching is not None:
            u = self.marching.command(self.formation, p, u, t, self.model.velocity_gain)
        if self.obstacles:
            u = self._repelled(p, u)
        return self.safety.apply(p, u, obstacles=self.obstacles)

    def _repelled(self, p: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
        """``u - k grad Gamma_o``: Khatib's repulsion from the obstacles added to ``u``."""
        rep = self.law.obstacle_repulsion()
        return u - rep.gain * grad_obstacle_potential(
            p, self._radii, self.obstacles, eta=rep.repulsion.eta, influence=rep.repulsion.influence
        )

    def potential(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """The law's Lyapunov function at ``x``, with the obstacles' repulsion; shape ``(...)``.

        ``law.potential`` plus ``weight Gamma_o`` (:class:`~formationlab.controllers.base.
        ObstacleRepulsion`), so that the obstacle-repelled law still descends it. A safety
        filter only removes descent directions, so it is not part of ``V``. A long history
        ``(T, n, k)`` is evaluated slice by slice
        (:func:`formationlab.formation.chunked.over_time`).
        """
        return over_time(self._potential, np.asarray(x, dtype=float), self._row_bytes)

    def _potential(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        p = self.model.points(x)
        v = self.law.potential(self.formation, p)
        if self.obstacles:
            rep = self.law.obstacle_repulsion()
            v = v + rep.weight * obstacle_potential(
                p, self._radii, self.obstacles,
                eta=rep.repulsion.eta, influence=rep.repulsion.influence,
            )  # fmt: skip
        return v

    @cached_property
    def _radii(self) -> NDArray[np.float64]:
        return np.asarray(self.formation.diameters, dtype=float) / 2

    def obstacle_clearances(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Clearance ``delta - rho_i / 2`` of every robot to every obstacle; ``(..., n, O)``."""
        return clearances(self.positions(x), self._radii, self.obstacles)[0]

    def swept_obstacle_clearances(
        self, x0: NDArray[np.float64], x1: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Least robot-obstacle clearance along the straight step ``x0 -> x1``; ``(..., n, O)``."""
        return swept_clearances(self.positions(x0), self.positions(x1), self._radii, self.obstacles)

    def sigma(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """The law's switching functions at ``x``, ``(..., s)`` (slice by slice along a long
        leading axis: :func:`formationlab.formation.chunked.over_time`)."""
        return over_time(self._sigma, np.asarray(x, dtype=float), self._row_bytes)

    def _sigma(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.law.switching(self.formation, self.model.points(x))

    @cached_property
    def _row_bytes(self) -> int:
        return row_bytes(self.formation, len(self.model.names_in(self.formation.dim)))

    def positions(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Robot centres ``(..., n, dim)``."""
        return self.model.positions(np.asarray(x, dtype=float))

    @cached_property
    def _all_pairs(self) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
        iu, ju = np.triu_indices(self.formation.n, k=1)
        return iu, ju, self.formation.contact_matrix[iu, ju]

    def _pairs(self, *states: NDArray[np.float64]) -> tuple[NDArray, NDArray, NDArray, float]:
        """The pairs whose clearance can matter at ``states``, with ``a_ij`` and a floor.

        Every pair for small formations (floor ``inf``); beyond ``DENSE_LIMIT`` robots
        the pairs closer than ``max a + max(max a, 2 * largest move between the states)``
        in some state (a k-d tree query), and the floor below which no other pair's
        clearance can be.
        """
        f = self.formation
        if f.n <= DENSE_LIMIT:
            return (*self._all_pairs, np.inf)
        qs = [np.asarray(self.positions(x), dtype=float) for x in states]
        move = max((float(np.nanmax(np.abs(b - a))) for a, b in pairwise(qs)), default=0.0)
        top = float(f.diameters.max())
        # 1.5 > sqrt(2) turns the largest coordinate move into a bound on its norm; a step
        # moving robots more than some 16 diameters (a blow-up) is judged on the pairs
        # within that range
        cutoff = top + max(top, min(2.0 * 1.5 * move, 32.0 * top))
        p = close_pairs(np.stack(qs), cutoff)
        a = 0.5 * (f.diameters[p[:, 0]] + f.diameters[p[:, 1]])
        return p[:, 0], p[:, 1], a, cutoff - top

    def pair_clearances(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """``r_ij - a_ij`` of the pairs ``i < j`` (all, or the close ones: :meth:`_pairs`)."""
        return self._clearances(x, *self._pairs(x)[:3])

    def _clearances(self, x: NDArray, iu: NDArray, ju: NDArray, a: NDArray) -> NDArray:
        q = self.positions(x)
        d = q[..., ju, :] - q[..., iu, :]
        return row_norms(d) - a

    def clearance(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Least ``r_ij - a_ij`` over all pairs, and robot-obstacle clearance; shape ``(...)``.

        The lesser of :meth:`clearances`' two.
        """
        robots, obstacles = self.clearances(x)
        return np.minimum(robots, obstacles)

    def clearances(self, x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Least robot-robot clearance ``r_ij - a_ij`` and least robot-obstacle clearance
        (``inf`` without obstacles) of the states ``x`` ``(..., n, k)``; each ``(...)``.

        For large formations the pairs a k-d tree finds close; when none is, a floor
        (every clearance is at least that).
        """
        iu, ju, a, floor = self._pairs(x)
        robots = np.min(self._clearances(x, iu, ju, a), axis=-1, initial=floor)
        obstacles = np.full(np.shape(robots), np.inf)
        if self.obstacles:
            obstacles = np.min(self.obstacle_clearances(x), axis=(-2, -1))
        return robots, obstacles

    def pair_swept_clearances(
        self, x0: NDArray[np.float64], x1: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Least ``r_ij - a_ij`` of each pair along the straight step ``x0 -> x1``; ``(..., P)``."""
        iu, ju, a, _ = self._pairs(x0, x1)
        q0, q1 = self.positions(x0), self.positions(x1)
        r0 = q0[..., ju, :] - q0[..., iu, :]
        dr = (q1[..., ju, :] - q1[..., iu, :]) - r0
        dd = np.sum(dr * dr, axis=-1)
        s = np.clip(-np.sum(r0 * dr, axis=-1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
        m = r0 + s[..., None] * dr
        return row_norms(m) - a

    def swept_clearance(
        self, x0: NDArray[np.float64], x1: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Least ``r_ij - a_ij`` over the straight step from ``x0`` to ``x1``; shape ``(...)``.

        Catches a step that carries two robots through each other, which the
        clearance at the end of the step alone would miss. With obstacles, also the
        least robot-obstacle clearance along the step.
        """
        floor = self._pairs(x0, x1)[3]
        least = np.min(self.pair_swept_clearances(x0, x1), axis=-1, initial=floor)
        if self.obstacles:
            swept = self.swept_obstacle_clearances(x0, x1)
            least = np.minimum(least, np.min(swept, axis=(-2, -1)))
        return least

    def step_verdict(
        self, x0: NDArray[np.float64], x1: NDArray[np.float64]
    ) -> tuple[NDArray[np.int8], NDArray[np.float64]]:
        """Judge the steps ``x0 -> x1`` (``(..., n, k)``): the contact rule of the package.

        Returns the verdict, 0 for an acceptable step and otherwise the rejecting
        ``Status.code`` (module docstring), and the least clearance at ``x1``; both ``(...)``.
        """
        verdict, robots, obstacles = self.judge(x0, x1)
        return verdict, np.minimum(robots, obstacles)

    def judge(
        self, x0: NDArray[np.float64], x1: NDArray[np.float64]
    ) -> tuple[NDArray[np.int8], NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`step_verdict` with the least clearance at ``x1`` in its two parts
        (:meth:`clearances`: robot-robot, robot-obstacle); each ``(...)``."""
        with np.errstate(invalid="ignore", over="ignore"):
            q1 = self.positions(x1)
            finite = np.all(np.isfinite(x1), axis=(-2, -1)) & np.all(
                np.isfinite(q1 * q1), axis=(-2, -1)
            )  # (squares that overflow: module docstring)
            safe = np.where(finite[..., None, None], x1, x0)
            robots, obstacles = self.clearances(safe)
            end = np.minimum(robots, obstacles)
            swept = self.swept_clearance(x0, safe)
        verdict = np.select(
            [~finite, ~(end > 0), ~(swept > 0)],
            [Status.NON_FINITE.code, Status.COLLISION.code, Status.STEP_TOO_LARGE.code],
            default=0,
        ).astype(np.int8)
        return verdict, robots, obstacles

    def closest_pair(self, x: NDArray[np.float64]) -> tuple[int, int, float]:
        """The 1-based robots ``i < j`` of least clearance in one state ``(n, k)``, and ``a_ij``."""
        iu, ju, a, _ = self._pairs(x)
        p = int(np.argmin(self.pair_clearances(x)))
        return int(iu[p]) + 1, int(ju[p]) + 1, float(a[p])

    def step_message(
        self, x0: NDArray[np.float64], x1: NDArray[np.float64], status: Status, t: float, dt: float
    ) -> str:
        """Why the step from ``x0`` (one state ``(n, k)``) to ``x1``, ending at ``t``, failed."""
        with np.errstate(over="ignore", invalid="ignore"):  # a huge but finite step
            return self._step_message(x0, x1, status, t, dt)

    def _step_message(
        self, x0: NDArray[np.float64], x1: NDArray[np.float64], status: Status, t: float, dt: float
    ) -> str:
        if status is Status.NON_FINITE:
            head = (
                f"the step to t = {t:g} s produced NaN or infinite positions, or positions "
                "beyond about 1e154"
            )
            size = float(np.max(np.abs(self.positions(x0))))
            if self.sensed and self.sensing is not None and self.sensing.sampled:
                # the command came from measurements drawn for that step (the driver's
                # channel): the step itself says how far it went (NaN if not finite)
                move = float(np.max(np.abs(self.positions(x1) - self.positions(x0))))
            else:
                move = dt * float(np.max(np.abs(self.rhs(x0, t - dt))))  # NaN if not finite
            if size <= COORDINATE_LIMIT and move / 10 <= COORDINATE_LIMIT:
                return f"{head}; reduce dt (now {dt:g} s), e.g. to {dt / 10:g} s"
            # the velocity at the last accepted state is not finite, or its squared
            # distances overflow: no dt helps
            noisy = ""
            if self.sensed and self.sensing is not None and self.sensing.noise > 0:
                noisy = f", and the measurements' noise ([sensing] noise = {self.sensing.noise:g})"
            return (
                f"{head}: the velocity at t = {t - dt:g} s is not finite, whatever dt (the "
                f"largest coordinate is {size:.3g}; squared distances overflow beyond about "
                "1e154, and so do forces with huge gains): scale the positions, distances "
                f"and gains to moderate numbers{noisy}"
            )
        iu, ju, a, _ = self._pairs(x0, x1)
        q0, q1 = self.positions(x0), self.positions(x1)
        jump = float(np.max(np.linalg.norm(q1 - q0, axis=-1)))
        if self.obstacles:
            hit = self._obstacle_message(x0, x1, status, t, dt, jump)
            if hit:
                return hit
        if status is Status.COLLISION:
            i, j, a_ij = self.closest_pair(x1)
            r = self.clearance(x1) + a_ij
            head = f"the step to t = {t:g} s would bring robots {i} and {j} to r = {r:.4g} <= "
            if self.law.barrier_at_contact:
                return (
                    f"{head}a_{i}{j} = {a_ij:g}; the {self.law.name} law has a barrier at "
                    "contact (the paper's phi), so its exact flow cannot touch and the step is "
                    f"too large: reduce dt (now {dt:g} s), e.g. to {dt / 10:g} s"
                )
            return (
                f"{head}a_{i}{j} = {a_ij:g}; the {self.law.name} law has no barrier at "
                "contact, so its own flow can bring robots together (a smaller dt than "
                f"{dt:g} s tells whether it does); a safety filter ([safety]) keeps them apart"
            )
        p = int(np.argmin(self.pair_swept_clearances(x0, x1)))
        i, j = iu[p] + 1, ju[p] + 1
        return (
            f"robots {i} and {j} pass through each other during the step to t = {t:g} s "
            f"(the largest move in that step is {jump:.3g}, against a contact distance "
            f"a_{i}{j} = {a[p]:g}); the step is too large for the field: reduce dt "
            f"(now {dt:g} s), e.g. to {dt / 10:g} s"
        )

    def _obstacle_message(
        self, x0: NDArray[np.float64], x1: NDArray[np.float64], status: Status, t: float,
        dt: float, jump: float,
    ) -> str:  # fmt: skip
        """The message of a step rejected for an obstacle, or "" when a pair of robots did it."""
        if status is Status.COLLISION:
            s_obs, s_pair = self.obstacle_clearances(x1), self.pair_clearances(x1)
        else:
            s_obs = self.swept_obstacle_clearances(x0, x1)
            s_pair = self.pair_swept_clearances(x0, x1)
        if not s_obs.min() <= min(0.0, float(s_pair.min())):
            return ""
        i, o = (int(v) for v in np.unravel_index(int(np.argmin(s_obs)), s_obs.shape))
        what = f"obstacle {o + 1} ({self.obstacles[o].describe()})"
        fix = f"reduce dt (now {dt:g} s), e.g. to {dt / 10:g} s"
        if status is Status.COLLISION:
            return (
                f"the step to t = {t:g} s would bring robot {i + 1} into contact with {what}: "
                f"clearance {s_obs[i, o]:.4g} <= 0; Khatib's repulsion from the obstacles (a "
                f"positive repulsion gain) keeps the exact flow off them, so the step is too "
                f"large: {fix}"
            )
        return (
            f"robot {i + 1} passes through {what} during the step to t = {t:g} s (the largest "
            f"move in that step is {jump:.3g}); the step is too large for the field: {fix}"
        )
