"""The live simulation behind the viewer: a run that a person steers.

:class:`LiveSession` owns the state of one closed loop and steps it with the
package's public stepping API (``System``, ``integrator.step``, ``law.control``,
``law.potential``, ``law.switching``); every call into the package that the
viewer makes is in this module, so that new robot models (states with more
than positions) are adapted here only. :class:`ReplaySession` plays back the
stored trajectory of ``formationlab run`` (``trajectory.nc``, read by
:func:`formationlab.io.netcdf.load_trajectory`).

Both speak the same small interface, used by :mod:`formationlab.viewer.controller`:
``info()`` (what does not change from frame to frame), ``frame()`` (the state
now: header and positions), ``advance(wall_dt)`` and the commands. Robot
numbers that cross this interface are 1-based, as everywhere a person reads
them; the arrays inside are 0-based.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from typing import Any

import numpy as np
import tomli_w
from numpy.typing import NDArray

from ..controllers import LAWS, Law, get_law
from ..dynamics import System
from ..errors import UserInputError
from ..integrators import FixedStepIntegrator, Integrator, get_integrator
from ..scenario import Scenario, parse_scenario
from ..spec import Formation

__all__ = ["Frame", "LiveSession", "SessionError", "law_parameters"]

#: Integrators the live view can step; the event-driven ``filippov`` is shown as implicit Euler.
LIVE_INTEGRATORS = ("euler", "rk4", "implicit-euler")
#: Edges whose errors go into each frame one by one (beyond: their maximum and RMS only).
EDGE_ERRORS_MAX = 24
#: Surfaces whose on/off state goes into each frame (beyond: none, no switching lines drawn).
SURFACES_MAX = 400
#: Least wall time between two evaluations of V when one costs more than 4 ms.
V_EVERY_S = 0.1
#: Most replay samples of V and the errors sent for the plots.
SERIES_MAX = 2000


class SessionError(UserInputError):
    """A command the session cannot carry out (the message says why and what to do)."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class Frame:
    """One state as the page draws it.

    Attributes
    ----------
    header : dict
        JSON-ready: ``t``, ``V``, error summary, active surfaces, status, ...
    positions : ndarray of float32, shape (n, 2)
    heading : ndarray of float32, shape (n,), optional
        Robot headings in radians, for models whose state has them.
    """

    header: dict[str, Any]
    positions: NDArray[np.float32]
    heading: NDArray[np.float32] | None = None


def law_parameters(law: Law) -> dict[str, float]:
    """The law's scalar gains by name (nested settings such as ``repulsion`` left out)."""
    return {
        f.name: float(getattr(law, f.name))
        for f in dataclasses.fields(law)
        if isinstance(getattr(law, f.name), int | float)
        and not isinstance(getattr(law, f.name), bool)
    }


def _law_catalogue() -> dict[str, dict[str, float]]:
    """Every registered law with the defaults of its scalar gains."""
    return {name: law_parameters(cls()) for name, cls in sorted(LAWS.items())}


def _split_state(state: NDArray[np.float64]) -> tuple[NDArray, NDArray | None]:
    """Positions ``(n, 2)`` and headings ``(n,)`` (or None) of a state.

    The single integrator's state is the positions; a model whose state carries
    headings (a unicycle: ``(n, 3)``, x, y, heading) is split here.
    """
    if state.shape[-1] == 3:
        return state[..., :2], state[..., 2]
    return state, None


def _distance_errors(formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """``r_ij - d_ij`` per edge, shape ``(m,)``."""
    e = formation.edges
    r = np.linalg.norm(q[e[:, 1]] - q[e[:, 0]], axis=-1)
    return r - formation.distances


def _error_fields(err: NDArray[np.float64]) -> dict[str, Any]:
    out: dict[str, Any] = {
        "err_max": float(np.max(np.abs(err))) if err.size else 0.0,
        "err_rms": float(np.sqrt(np.mean(err * err))) if err.size else 0.0,
    }
    if err.size <= EDGE_ERRORS_MAX:
        out["errors"] = [float(x) for x in err]
    return out


def _finite_or_none(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _static_info(formation: Formation, name: str) -> dict[str, Any]:
    """What the page draws besides the positions: diameters, graph, switching surfaces."""
    tris, beta, _ = formation.surfaces
    surfaces = None
    if len(tris) <= SURFACES_MAX:
        surfaces = {"triangles": (tris + 1).tolist(), "beta": [float(b) for b in beta]}
    return {
        "name": name,
        "n": formation.n,
        "diameters": [float(d) for d in formation.diameters],
        "edges": (formation.edges + 1).tolist(),
        "distances": [float(d) for d in formation.distances],
        "surfaces": surfaces,
        "edge_errors": len(formation.edges) <= EDGE_ERRORS_MAX,
    }


class LiveSession:
    """A live run of a scenario that the page steers.

    Parameters
    ----------
    scenario : Scenario
        What to run; its law, integrator and initial positions are the start.
    seed : int, optional
        Seed of the random perturbations (``numpy.random.default_rng``).
    step_budget_s : float
        Wall time one :meth:`advance` may spend stepping (at least one step is
        taken), so that the page keeps its frame rate when steps are slow.
    """

    mode = "live"

    def __init__(
        self, scenario: Scenario, *, seed: int | None = None, step_budget_s: float = 0.015
    ) -> None:
        self.scenario = scenario
        self.formation = scenario.formation
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.step_budget_s = step_budget_s
        self.notices: list[str] = []
        self.law: Law = scenario.law
        self.integrator: FixedStepIntegrator = self._live_integrator(scenario.integrator)
        self.system = System(formation=self.formation, law=self.law)
        self.speed = 1.0
        self.paused = False
        self.q = np.array(scenario.q0, dtype=float)
        self.t = 0.0
        self.steps = 0
        self.status = "running"
        self.message = ""
        self.pinned: int | None = None
        self._pin_at: NDArray[np.float64] | None = None
        self._debt = 0.0
        self._V: tuple[Any, float, float, float] | None = None

    # ------------------------------------------------------------------ package calls

    def _live_integrator(self, integrator: Integrator) -> FixedStepIntegrator:
        if isinstance(integrator, FixedStepIntegrator):
            return integrator
        dt = float(getattr(integrator, "dt", 1e-3))
        self.notices.append(
            f"the live view steps with a fixed step: integrator {integrator.name!r} is shown "
            f"as implicit-euler (dt = {dt:g} s), which slides on the surfaces like it"
        )
        out = get_integrator("implicit-euler", dt=dt)
        assert isinstance(out, FixedStepIntegrator)  # registry invariant, not user input
        return out

    def _one_step(self) -> bool:
        """Take one step; False (and paused, with a message) if the step is refused."""
        dt = self.integrator.dt
        q_new = np.asarray(self.integrator.step(self.system, self.q, dt), dtype=float)
        if self.pinned is not None and self._pin_at is not None:
            q_new[self.pinned] = self._pin_at
        if not np.all(np.isfinite(q_new)):
            return self._stop(
                "non-finite",
                f"the step from t = {self.t:g} s produced NaN "
                f"positions; reduce dt (now {dt:g} s) and reset",
            )
        if self.system.swept_clearance(self.q, q_new) <= 0:
            return self._stop(
                "step-collision",
                f"the step from t = {self.t:g} s would bring "
                f"two robots into contact; reduce dt (now {dt:g} s), or drag "
                "them apart, and run on",
            )
        self.q = q_new
        self.t += dt
        self.steps += 1
        return True

    def _stop(self, status: str, message: str) -> bool:
        self.status, self.message, self.paused = status, message, True
        return False

    def frame(self) -> Frame:
        """The state now."""
        q = self.q
        pos, heading = _split_state(q)
        V = self._lyapunov(q)
        sigma = np.asarray(self.law.switching(self.formation, q))
        header: dict[str, Any] = {
            "t": self.t,
            "V": _finite_or_none(V),
            **_error_fields(_distance_errors(self.formation, pos)),
            "active": (np.flatnonzero(sigma >= 0) + 1).tolist()
            if sigma.size <= SURFACES_MAX
            else None,
            "steps": self.steps,
            "paused": self.paused,
            "status": self.status,
            "message": self.message,
            "speed": self.speed,
            "pinned": None if self.pinned is None else self.pinned + 1,
            "law": self.law.name,
        }
        return Frame(
            header=header,
            positions=pos.astype(np.float32),
            heading=None if heading is None else heading.astype(np.float32),
        )

    def _lyapunov(self, q: NDArray[np.float64]) -> float:
        """``V`` now; for large formations (where it costs more than a few milliseconds)
        recomputed at most every :data:`V_EVERY_S` seconds of wall time, so that it does not
        halve the frame rate (the plot then gets ~10 values a second)."""
        key = (self.steps, self.t, self.law, q[0, 0], q[-1, -1])
        now = time.perf_counter()
        cached = self._V
        fresh = cached is not None and cached[0] == key
        if fresh or (cached is not None and cached[2] > 0.004 and now - cached[3] < V_EVERY_S):
            assert cached is not None
            return cached[1]
        V = float(np.asarray(self.law.potential(self.formation, q)))
        self._V = (key, V, time.perf_counter() - now, now)
        return V

    def info(self) -> dict[str, Any]:
        """What the page needs once: the formation, the choices of laws and integrators."""
        return {
            "mode": self.mode,
            **_static_info(self.formation, self.scenario.name),
            "law": {"name": self.law.name, "params": law_parameters(self.law)},
            "laws": _law_catalogue(),
            "integrator": {"name": self.integrator.name, "dt": self.integrator.dt},
            "integrators": list(LIVE_INTEGRATORS),
            "models": ["single-integrator"],
            "model": self.system.model.name,
            "notices": list(self.notices),
        }

    # ------------------------------------------------------------------ time

    def advance(self, wall_dt: float) -> int:
        """Run ``speed * wall_dt`` simulated seconds (less if the step budget runs out).

        Returns the number of steps taken. Time the budget could not cover is
        dropped, not owed: a slow formation plays in slow motion.
        """
        if self.paused:
            return 0
        dt = self.integrator.dt
        self._debt = min(self._debt + self.speed * max(wall_dt, 0.0), 50 * dt + self.speed * 0.1)
        want = int(self._debt / dt)
        done = 0
        start = time.perf_counter()
        while done < want:
            if not self._one_step():
                break
            done += 1
            if time.perf_counter() - start > self.step_budget_s:
                break
        self._debt = self._debt - done * dt if done == want else 0.0
        return done

    def step(self, count: int = 1) -> int:
        """Take ``count`` steps now (paused or not); returns how many were taken."""
        if self.status != "running":
            self.status, self.message = "running", ""
        done = 0
        while done < count and self._one_step():
            done += 1
        return done

    def set_paused(self, paused: bool) -> None:
        self.paused = paused
        if not paused and self.status != "running":
            self.status, self.message = "running", ""

    def set_speed(self, speed: float) -> None:
        self.speed = float(speed)

    def reset(self) -> None:
        """Back to the scenario's initial positions at t = 0 (law and integrator as chosen)."""
        self.q = np.array(self.scenario.q0, dtype=float)
        self.t, self.steps, self._debt = 0.0, 0, 0.0
        self.status, self.message = "running", ""
        self.pinned = self._pin_at = None

    # ------------------------------------------------------------------ interaction

    def _robot(self, robot: int) -> int:
        if not 1 <= robot <= self.formation.n:
            raise SessionError(f"robot {robot} does not exist; robots are 1..{self.formation.n}")
        return robot - 1

    def drag(self, robot: int, x: float, y: float) -> None:
        """Move robot ``robot`` (1-based) to ``(x, y)`` and hold it there until :meth:`release`."""
        i = self._robot(robot)
        q = self.q.copy()
        q[i] = (x, y)
        f = self.formation
        others = np.arange(f.n) != i
        gap = np.linalg.norm(q[others] - q[i], axis=-1) - f.contact_matrix[i, others]
        if np.min(gap) <= 0:
            j = int(np.arange(f.n)[others][np.argmin(gap)]) + 1
            raise SessionError(
                f"robot {robot} at ({x:.3g}, {y:.3g}) would overlap robot {j}; drop it elsewhere"
            )
        self.q = q
        self.pinned, self._pin_at = i, q[i].copy()
        if self.status != "running":
            self.status, self.message = "running", ""

    def release(self) -> None:
        """Let the dragged robot move under its control again."""
        self.pinned = self._pin_at = None

    def perturb(self, scale: float) -> None:
        """Add a Gaussian displacement of standard deviation ``scale`` to every robot."""
        f = self.formation
        iu, ju = np.triu_indices(f.n, k=1)
        for _ in range(50):
            q = self.q + self.rng.normal(0.0, scale, size=self.q.shape)
            gap = np.linalg.norm(q[ju] - q[iu], axis=-1) - f.contact_matrix[iu, ju]
            if gap.size == 0 or np.min(gap) > 0:
                self.q = q
                if self.status != "running":
                    self.status, self.message = "running", ""
                return
        raise SessionError(
            f"50 random perturbations of size {scale:g} all made robots overlap; use a smaller one"
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
        self.law = law
        self.system = System(formation=self.formation, law=law)

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
        self.integrator = integ
        self._debt = 0.0

    def export_scenario(self) -> tuple[str, str]:
        """The current state as a scenario file: ``(file name, TOML text)``, validated."""
        raw = _export_table(self.scenario, self.q, self.t)
        raw["controller"] = {
            "law": self.law.name,
            **{
                k: v
                for k, v in self.scenario.raw.get("controller", {}).items()
                if k == "alpha_values"
            },
            **_plain(dataclasses.asdict(self.law)),
        }
        raw["simulation"] = {
            "integrator": self.integrator.name,
            **_plain(dataclasses.asdict(self.integrator)),
            "duration": self.scenario.duration,
        }
        return _finish_export(self.scenario.name, raw, self.t)


def _plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _export_table(scenario: Scenario, q: NDArray[np.float64], t: float) -> dict[str, Any]:
    raw = copy.deepcopy(scenario.raw)
    raw.setdefault("robots", {})["positions"] = [[float(x), float(y)] for x, y in q]
    raw["name"] = f"{scenario.name}-t{t:.3f}".replace(".", "_")
    text = f"state of {scenario.name!r} at t = {t:.6g} s, exported from the viewer"
    raw["description"] = f"{scenario.description} ({text})" if scenario.description else text
    return raw


def _finish_export(name: str, raw: dict[str, Any], t: float) -> tuple[str, str]:
    text = tomli_w.dumps(raw)
    parse_scenario(text, source="<export>")  # never hand out a file that does not validate
    return f"{name}-t{t:.3f}.toml".replace(" ", "_"), text
