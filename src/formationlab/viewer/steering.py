"""What a person does to a live run: drag, release and perturb robots, change the law, its
gains or the integrator, and export the state as a scenario.

:class:`Steering` holds these commands of :class:`~formationlab.viewer.session.LiveSession`
(which steps the run and draws its frames); each refuses what the live view cannot honour
by name (:class:`~formationlab.viewer.export.SessionError`). Robot numbers are 1-based,
as everywhere a person reads them.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..controllers import LAWS, Law, get_law, laws_in
from ..errors import UserInputError
from ..integrators import FixedStepIntegrator, get_integrator
from .export import SessionError, export_table, finish_export, plain

if TYPE_CHECKING:
    from ..dynamics import System
    from ..formation import Formation
    from ..scenario import Scenario

__all__ = ["LIVE_INTEGRATORS", "Steering", "law_parameters"]

#: Integrators the live view can step; the event-driven ``filippov`` is shown as implicit Euler.
LIVE_INTEGRATORS = ("euler", "rk4", "implicit-euler")


def law_parameters(law: Law) -> dict[str, float]:
    """The law's scalar gains by name (nested settings such as ``repulsion`` left out)."""
    return {
        f.name: float(getattr(law, f.name))
        for f in dataclasses.fields(law)
        if isinstance(getattr(law, f.name), int | float)
        and not isinstance(getattr(law, f.name), bool)
    }


def _law_catalogue(dim: int) -> dict[str, dict[str, float]]:
    """Every registered law that works in ``dim`` dimensions, with the defaults of its
    scalar gains."""
    return {name: law_parameters(LAWS[name]()) for name in laws_in(dim)}


class Steering:
    """The person's commands on a live run (mixed into
    :class:`~formationlab.viewer.session.LiveSession`, which provides the state, the closed
    loop and :meth:`_moved`, :meth:`_start`)."""

    scenario: Scenario
    formation: Formation
    system: System
    integrator: FixedStepIntegrator
    rng: np.random.Generator
    notices: list[str]
    pinned: int | None
    _pin_at: NDArray[np.float64] | None
    _debt: float

    @property
    def law(self) -> Law:
        """The law in force."""
        return self.system.law

    if TYPE_CHECKING:  # (LiveSession's)

        @property
        def state(self) -> NDArray[np.float64]: ...

        @property
        def t(self) -> float: ...

        def _moved(self, x: NDArray[np.float64]) -> None: ...

        def _start(self, x: NDArray[np.float64], t: float, *, record: bool = True) -> None: ...

    def _robot(self, robot: int) -> int:
        if not 1 <= robot <= self.formation.n:
            raise SessionError(f"robot {robot} does not exist; robots are 1..{self.formation.n}")
        return robot - 1

    def _check_clear(self, x: NDArray[np.float64], what: str) -> None:
        """Refuse a state with robots in contact, or a robot touching an obstacle."""
        system = self.system
        if system.obstacles:
            clear = system.obstacle_clearances(x)
            if clear.size and clear.min() <= 0:
                i, o = (int(v) for v in np.unravel_index(int(np.argmin(clear)), clear.shape))
                raise SessionError(
                    f"{what} would put robot {i + 1} on obstacle {o + 1} "
                    f"({system.obstacles[o].describe()}); drop it elsewhere"
                )

    def drag(self, robot: int, x: float, y: float, z: float | None = None) -> None:
        """Move robot ``robot`` (1-based) to ``(x, y)`` in the plane, or ``(x, y, z)`` in
        space, and hold it there until :meth:`release`.

        In space a drag without ``z`` keeps the robot's height; a ``z`` for a formation in
        the plane is refused. The robot's other state (heading) is kept; a double
        integrator's (or a quadrotor's) velocity is set to zero while it is held.
        """
        i = self._robot(robot)
        f = self.formation
        if z is not None and f.dim == 2:
            raise SessionError(
                f"robot {robot}: a drag to (x, y, z) = ({x:.3g}, {y:.3g}, {z:.3g}) in a formation "
                "in the plane; send x and y only"
            )
        state = self.state.copy()
        names = self.system.model.names_in(f.dim)
        where = (x, y) if f.dim == 2 else (x, y, state[i, 2] if z is None else z)
        state[i, : f.dim] = where
        for c, name in enumerate(names):
            if name in ("vx", "vy", "vz"):
                state[i, c] = 0.0
        at = f"({', '.join(f'{v:.3g}' for v in where)})"
        q = self.system.positions(state)
        others = np.arange(f.n) != i
        gap = np.linalg.norm(q[others] - q[i], axis=-1) - f.contact_matrix[i, others]
        if np.min(gap) <= 0:
            j = int(np.arange(f.n)[others][np.argmin(gap)]) + 1
            raise SessionError(f"robot {robot} at {at} would overlap robot {j}; drop it elsewhere")
        self._check_clear(state, f"robot {robot} at {at}")
        self.pinned, self._pin_at = i, state[i].copy()
        self._moved(state)

    def release(self) -> None:
        """Let the dragged robot move under its control again."""
        self.pinned = self._pin_at = None

    def perturb(self, scale: float) -> None:
        """Add a Gaussian displacement of standard deviation ``scale`` to every robot's position."""
        for _ in range(50):
            state = self.state.copy()
            dim = self.formation.dim
            state[:, :dim] += self.rng.normal(0.0, scale, size=(self.formation.n, dim))
            if self.system.clearance(state) > 0:
                self._moved(state)
                return
        raise SessionError(
            f"50 random perturbations of size {scale:g} all made robots overlap or touch an "
            "obstacle; use a smaller one"
        )

    def set_law(self, name: str, params: dict[str, float] | None = None) -> None:
        """Switch to the law ``name``; gains it shares with the current law carry over."""
        if name not in LAWS:
            raise SessionError(f"unknown law {name!r}; choose one of {', '.join(sorted(LAWS))}")
        fields = {f.name for f in dataclasses.fields(LAWS[name])}
        keep = {k: v for k, v in law_parameters(self.law).items() if k in fields}
        if "repulsion" in fields and hasattr(self.law, "repulsion"):
            keep["repulsion"] = self.law.repulsion
        self._install(get_law(name, **keep), params or {})

    def set_params(self, params: dict[str, float]) -> None:
        """Change some gains of the current law (e.g. ``k_c``, ``k_a``, ``theta``)."""
        self._install(self.law, params)

    def _install(self, law: Law, params: dict[str, float]) -> None:
        known = law_parameters(law)
        unknown = sorted(set(params) - set(known))
        if unknown:
            raise SessionError(
                f"law {law.name!r} has no parameter {unknown[0]!r}; its parameters are "
                f"{', '.join(known)}"
            )
        law = law.with_params(**params) if params else law
        try:  # the closed loop's own checks (a law without obstacle repulsion, ...)
            system = dataclasses.replace(self.system, law=law)
        except UserInputError as exc:
            raise SessionError(f"law {law.name!r} cannot run this scenario: {exc}") from None
        self._restart(system, self.integrator)

    def _restart(self, system: System, integrator: FixedStepIntegrator) -> None:
        """Step on from the state now with another law or integrator (a new driver pass:
        a sensing channel starts afresh)."""
        old = (self.system, self.integrator)
        x, t = self.state.copy(), self.t
        self.system, self.integrator = system, integrator
        try:
            self._start(x, t, record=False)  # (the same state, already recorded)
        except SessionError:
            self.system, self.integrator = old
            raise
        self._debt = 0.0

    def set_integrator(self, name: str, dt: float) -> None:
        """Step with ``name`` (``euler``, ``rk4``, ``implicit-euler``) and step ``dt``."""
        if name == "filippov":
            name = "implicit-euler"
            self.notices.append("filippov is event-driven; the live view uses implicit-euler")
        if name not in LIVE_INTEGRATORS:
            raise SessionError(
                f"integrator {name!r} cannot step live; choose one of {', '.join(LIVE_INTEGRATORS)}"
            )
        integ = get_integrator(name, dt=dt)
        assert isinstance(integ, FixedStepIntegrator)  # the three live ones are fixed-step
        self._restart(self.system, integ)

    def export_scenario(self) -> tuple[str, str]:
        """The current state as a scenario file: ``(file name, TOML text)``, validated.

        Every table of the scenario is kept (:mod:`formationlab.viewer.export`); the law
        and the integrator are those in force.
        """
        raw = export_table(self.scenario, self.state, self.t)
        raw["controller"] = {
            "law": self.law.name,
            **{
                k: v
                for k, v in self.scenario.raw.get("controller", {}).items()
                if k == "alpha_values"
            },
            **plain(dataclasses.asdict(self.law)),
        }
        raw["simulation"] = {
            "integrator": self.integrator.name,
            **plain(dataclasses.asdict(self.integrator)),
            "duration": self.scenario.duration,
        }
        return finish_export(self.scenario.name, raw, self.t)
