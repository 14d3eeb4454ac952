"""One entry point, :func:`simulate`, and the result it returns.

``simulate(formation, law, q0, duration=..., integrator=...)`` integrates the
closed loop ``q_dot = u(q)`` (eq. 1) and returns a :class:`SimulationResult`
holding times, positions ``(T, n, 2)``, controls ``(T, n, 2)``, the law's
Lyapunov function ``(T,)``, which angular restrictions were active, a status
with a message, and the integrator's diagnostics.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .analysis import (
    Outcome,
    Tolerances,
    classify,
    converged_time,
    distance_errors,
    edge_labels,
    net_speed,
)
from .controllers import LAWS, Law
from .dynamics import System
from .errors import ParameterError
from .integrators import INTEGRATORS, Euler, Integrator, RawSolution
from .registry import resolve
from .spec import Formation
from .status import Status
from .validation import whole

if TYPE_CHECKING:
    from .safety import Obstacle, SafetyFilter, SafetyRecord

__all__ = ["SimulationResult", "simulate"]


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
        Positions at those times.
    u : ndarray, shape (T, n, 2)
        The velocity each saved state was left with: the step the integrator
        took (for ``implicit-euler`` and ``filippov`` on a switching surface, the
        sliding motion, not the field of one side); equal to the control of the
        law for single integrators away from the surfaces.
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
        tris, _, index = self.formation.surfaces
        labels = []
        for s in range(len(tris)):
            i, j, k = np.argwhere(index == s)[0] + 1
            labels.append(f"alpha_{i}{j}{k}")
        return labels

    @property
    def final(self) -> NDArray[np.float64]:
        """Final positions, shape ``(n, 2)``."""
        return self.q[-1]

    @cached_property
    def distance_errors(self) -> NDArray[np.float64]:
        """``r_ij - d_ij`` per edge over time, shape ``(T, m)``."""
        return distance_errors(self.formation, self.q)

    @property
    def edge_labels(self) -> list[str]:
        return edge_labels(self.formation)

    def net_speed(self, tolerances: Tolerances | None = None) -> float | None:
        """Net speed over the last ``tolerances.window`` seconds of the run.

        ``max_i |q_i(t_end) - q_i(t_j)| / (t_end - t_j)`` with ``t_j`` the latest saved
        time at least ``window`` before the end (:func:`formationlab.analysis.net_speed`):
        with ``save_every`` thinning the samples, over the shortest saved interval of at
        least ``window``; None when the saved run is shorter than ``window``.
        """
        tol = tolerances or Tolerances()
        v = float(net_speed(self.t, self.q, tol.window)[-1])
        return v if np.isfinite(v) else None

    def outcome(self, tolerances: Tolerances | None = None) -> Outcome:
        """Outcome of the final state (see :mod:`formationlab.analysis`).

        The robots count as stopped when the final ``max_i |u_i|`` or the net speed over
        the last ``window`` seconds (:meth:`net_speed`) is at most ``tolerances.speed``.
        """
        return classify(
            self.formation,
            self.q[-1],
            self.u[-1],
            tolerances,
            contact=Status(self.status).contact,
            net_speed=self.net_speed(tolerances),
        )

    def converged_time(self, tolerances: Tolerances | None = None) -> float | None:
        """First saved time after which the robots stay stopped (instantaneous or net speed)."""
        tol = tolerances or Tolerances()
        return converged_time(self.t, self.u, tol.speed, q=self.q, window=tol.window)

    def summary(self, tolerances: Tolerances | None = None) -> dict[str, Any]:
        """A JSON-ready summary of the run (the ``summary.json`` of ``run`` and ``paper``).

        Keys: ``outcome``, ``status``, ``message``, ``final_positions`` (``[[x, y], ...]``,
        robot 1 first), ``distance_errors`` (final ``r_ij - d_ij`` keyed by edge label
        ``"i-j"``, 1-based), ``max_distance_error``, ``converged_time`` (or None),
        ``final_time``, ``orientation`` (``"ccw"``/``"cw"`` of robots 1, 2, 3),
        ``active_restrictions_final`` (labels), ``diagnostics`` (integrator statistics),
        ``tolerances`` and, with obstacles or a filter, ``safety``
        (:meth:`formationlab.safety.SafetyRecord.summary`).
        """
        from .analysis import triangle_orientation

        tol = tolerances or Tolerances()
        err = self.distance_errors[-1]
        active = [
            lab for lab, on in zip(self.restriction_labels, self.active[-1], strict=True) if on
        ]
        extra = {} if self.safety is None else {"safety": self.safety.summary()}
        return {
            "outcome": self.outcome(tol),
            "status": self.status,
            "message": self.message,
            "final_time": float(self.t[-1]),
            "final_positions": self.q[-1].tolist(),
            "distance_errors": dict(zip(self.edge_labels, err.tolist(), strict=True)),
            "max_distance_error": float(np.max(np.abs(err))),
            "converged_time": self.converged_time(tol),
            "final_speed": float(np.max(np.linalg.norm(self.u[-1], axis=-1))),
            "net_speed": self.net_speed(tol),
            "orientation": triangle_orientation(self.q[-1]) if self.formation.n >= 3 else None,
            "active_restrictions_final": active,
            "diagnostics": dict(self.stats),
            "tolerances": {"distance": tol.distance, "speed": tol.speed, "window": tol.window},
            **extra,
        }

    def plot(self, kind: str = "trajectories", ax: Any = None, **kwargs: Any) -> Any:
        """Plot the run: ``"trajectories"``, ``"controls"``, ``"lyapunov"`` or ``"errors"``.

        Needs matplotlib (imported here, not at package import). Returns the artists.
        """
        from . import plotting

        return plotting.plot_result(self, kind, ax=ax, **kwargs)


def simulate(
    formation: Formation,
    law: Law | str,
    q0: ArrayLike,
    *,
    duration: float,
    integrator: Integrator | str | None = None,
    save_every: int = 1,
    progress: Callable[[float], None] | None = None,
    interruptible: bool = False,
    obstacles: Sequence[Obstacle] = (),
    safety: SafetyFilter | str | None = None,
) -> SimulationResult:
    """Simulate ``q_dot_i = u_i`` (eq. 1) under ``law`` from ``q0``.

    Parameters
    ----------
    formation : Formation
        Robots, graph, desired distances and orientation.
    law : Law or str
        The control law, e.g. :class:`~formationlab.AngleRestrictedLaw`, or its name
        (``"distance"``: built with its defaults).
    q0 : array_like, shape (n, 2)
        Initial positions; validated (finite, no overlapping robots).
    duration : float
        Simulated time, seconds.
    integrator : Integrator or str, optional
        Default ``Euler(dt=1e-3)``; a name (``"rk4"``) gets the integrator's defaults.
    save_every : int
        Keep every K-th step (thins what is stored, not what is computed).
    progress : callable, optional
        Called with the simulated time now and then.
    interruptible : bool
        On Ctrl-C, return the run so far with status ``"interrupted"`` instead of
        raising ``KeyboardInterrupt`` (fixed-step integrators).
    obstacles : sequence of Circle or Polygon
        Static obstacles (:mod:`formationlab.safety`): the law gains Khatib's repulsion
        from them, and touching one is contact (status ``"step-collision"``).
    safety : SafetyFilter or str, optional
        A safety filter between the law and the robots (``"barrier"``,
        ``"barrier-decentralized"`` with their defaults, or a configured
        :class:`~formationlab.safety.SafetyFilter`); default none.

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
    """
    q0 = formation.check_positions(q0)
    if q0.ndim != 2:
        raise ParameterError(f"simulate takes one initial state of shape (n, 2), got {q0.shape}")
    save_every = whole(save_every, "save_every")
    law, integrator = resolve(LAWS, law), resolve(INTEGRATORS, integrator or Euler(dt=1e-3))
    system = _system(formation, law, q0, obstacles, safety)
    raw: RawSolution = integrator.run(
        system, q0, float(duration), save_every=int(save_every), progress=progress,
        interruptible=interruptible,
    )  # fmt: skip
    points = system.model.points(raw.x)
    record = None
    if system.obstacles or system.filtered:
        from .safety import SafetyRecord

        clear = system.obstacle_clearances(raw.x)
        least = clear.min(axis=(-2, -1)) if clear.size else np.full(len(raw.t), np.inf)
        record = SafetyRecord.from_states(
            raw.q, filter=system.safety if system.filtered else None,
            obstacles=system.obstacles,
            result=system.filter_result(raw.x) if system.filtered else None,
            obstacle_clearance=least,
        )  # fmt: skip
    return SimulationResult(
        formation=formation,
        law=law,
        integrator=integrator,
        t=raw.t,
        q=raw.q,
        u=raw.v[..., :2],
        V=system.potential(raw.x),
        sigma=law.switching(formation, points),
        status=raw.status,
        message=raw.message,
        stats=dict(raw.stats),
        safety=record,
    )


def _system(
    formation: Formation,
    law: Law,
    q0: NDArray[np.float64],
    obstacles: Sequence[Obstacle],
    safety: SafetyFilter | str | None,
) -> System:
    """The closed loop, with obstacles and filter validated against ``q0``."""
    if not obstacles and (safety is None or safety == "none"):
        return System(formation=formation, law=law)
    from .safety import SafetyFilter, check_obstacle_starts

    if isinstance(safety, str):
        safety = SafetyFilter(filter=safety)  # type: ignore[arg-type]
    check_obstacle_starts(q0, formation.diameters / 2, tuple(obstacles))
    return System(formation=formation, law=law, obstacles=tuple(obstacles), safety=safety)
