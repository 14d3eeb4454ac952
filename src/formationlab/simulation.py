"""One entry point, :func:`simulate`, and the result it returns.

``simulate(formation, law, q0, duration=..., integrator=...)`` integrates the
closed loop ``q_dot = u(q)`` (eq. 1) and returns a :class:`SimulationResult`
holding times, positions ``(T, n, 2)``, controls ``(T, n, 2)``, the law's
Lyapunov function ``(T,)``, which angular restrictions were active, a status
with a message, and the integrator's diagnostics.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .analysis import (
    Outcome,
    Tolerances,
    classify,
    converged_time,
    distance_errors,
    edge_labels,
    final_motion,
    net_speed,
)
from .controllers import LAWS, Law
from .dynamics import System
from .errors import ParameterError
from .integrators import INTEGRATORS, Euler, Integrator
from .integrators.compiled import compiled_terms, run_euler_compiled
from .registry import resolve
from .rigid_motion import RigidMotion
from .spec import Formation
from .status import Status
from .validation import whole

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

    def motion(self, tolerances: Tolerances | None = None) -> RigidMotion:
        """Rigid motion over the last ``drift_window`` seconds (:func:`~.analysis.final_motion`)."""
        return final_motion(self.t, self.q, tolerances)

    def outcome(self, tolerances: Tolerances | None = None) -> Outcome:
        """Outcome of the final state (see :mod:`formationlab.analysis`).

        The robots count as stopped when the final ``max_i |u_i|`` or the net speed over
        the last ``window`` seconds (:meth:`net_speed`) is at most ``tolerances.speed``;
        a moving formation that kept its shape over the last ``drift_window`` seconds
        (:meth:`motion`) is ``drifting`` or ``rotating``.
        """
        return classify(
            self.formation,
            self.q[-1],
            self.u[-1],
            tolerances,
            contact=Status(self.status).contact,
            net_speed=self.net_speed(tolerances),
            motion=self.motion(tolerances),
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
        ``tolerances`` and, for a ``drifting`` or ``rotating`` outcome, ``rigid_motion``:
        ``velocity`` (of the centroid, ``[vx, vy]``), ``speed``, ``angular_velocity``,
        ``centre`` (of the rotation; None for a drift), ``shape_rate`` and ``window``.
        """
        from .analysis import triangle_orientation

        tol = tolerances or Tolerances()
        err = self.distance_errors[-1]
        outcome = self.outcome(tol)
        moving = outcome in ("drifting", "rotating")
        active = [
            lab for lab, on in zip(self.restriction_labels, self.active[-1], strict=True) if on
        ]
        return {
            "outcome": outcome,
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
            "tolerances": dataclasses.asdict(tol),
            **({"rigid_motion": _motion_dict(self.motion(tol), outcome)} if moving else {}),
        }

    def plot(self, kind: str = "trajectories", ax: Any = None, **kwargs: Any) -> Any:
        """Plot the run: ``"trajectories"``, ``"controls"``, ``"lyapunov"`` or ``"errors"``.

        Needs matplotlib (imported here, not at package import). Returns the artists.
        """
        from . import plotting

        return plotting.plot_result(self, kind, ax=ax, **kwargs)


def _motion_dict(m: RigidMotion, outcome: str) -> dict[str, Any]:
    v = np.asarray(m.velocity, dtype=float)
    return {
        "velocity": v.tolist(),
        "speed": float(np.hypot(*v)),
        "angular_velocity": float(m.omega),
        "centre": np.asarray(m.centre).tolist() if outcome == "rotating" else None,
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
    save_every: int = 1,
    progress: Callable[[float], None] | None = None,
    interruptible: bool = False,
    backend: Literal["auto", "numpy", "numba"] = "auto",
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
    backend : {"auto", "numpy", "numba"}
        ``"numba"``: the compiled single-run path (:mod:`formationlab.integrators.compiled`:
        explicit Euler, single integrators, a law with kernel data; any size, no ``n x n``
        arrays); ``"numpy"``: the integrator's own ``run`` (the stepping driver);
        ``"auto"`` (default) takes the compiled path wherever it applies. The two agree
        to rounding (tested).

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
    system = System(formation=formation, law=law)
    terms = compiled_terms(system, integrator) if backend != "numpy" else None
    if backend == "numba" and terms is None:
        raise ParameterError(
            'backend="numba" runs explicit Euler on single integrators with a law that has '
            f'kernel data; got {integrator.name!r} and {law.name!r}: use backend="auto"'
        )
    if terms is not None:
        raw = run_euler_compiled(
            terms, system, q0, dt=integrator.dt, duration=float(duration),  # type: ignore[attr-defined]
            save_every=int(save_every), progress=progress, interruptible=interruptible,
        )  # fmt: skip
    else:
        raw = integrator.run(
            system, q0, float(duration), save_every=int(save_every), progress=progress,
            interruptible=interruptible,
        )  # fmt: skip
    points = system.model.points(raw.x)
    status, message = raw.status, raw.message
    try:
        V, sigma = law.potential(formation, points), law.switching(formation, points)
    except KeyboardInterrupt:  # while reading the run: keep the states, not V and sigma
        if not interruptible:
            raise
        V = np.full(len(raw.t), np.nan)
        sigma = np.full((len(raw.t), len(formation.surfaces[0])), np.nan)
        status = Status.INTERRUPTED
        message = f"interrupted by the user at t = {raw.t[-1]:g} s"
    return SimulationResult(
        formation=formation,
        law=law,
        integrator=integrator,
        t=raw.t,
        q=raw.q,
        u=raw.v[..., :2],
        V=V,
        sigma=sigma if law.switching(formation, points[:1]).shape[-1] else sigma[..., :0],
        status=status,
        message=message,
        stats=dict(raw.stats),
    )
