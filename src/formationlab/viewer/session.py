"""The live simulation behind the viewer: a run that a person steers.

:class:`LiveSession` owns one closed loop and steps it the way every run of the package
is stepped: the scenario's whole closed loop (:func:`formationlab.scenario.closed_loop`:
robot model, marching, obstacles, safety filter, sensing, faults) advanced one step at a
time by the stepping driver's body (:class:`formationlab.integrators.driver.Stepping`:
the time ``t_k = k dt``, the measurement channel, the contact rule
``System.step_verdict`` and its messages). From a reset, ``step(k)`` gives the states
``simulate(..., backend="numpy")`` saves, in the plane or in space (``Formation.dim``: a
drag then takes ``z`` too). A large formation (from
:data:`~formationlab.viewer.stepping.COMPILED_FROM` robots) that can run compiled steps in
segments on the engine's compiled single run instead (:mod:`.stepping`: the same states,
to rounding), so that "x1" is real time at a thousand robots; :attr:`LiveSession.reached`
says what speed the run reached. A state that is not finite (or beyond float32, which the
page receives) pauses the run with a message. A person may change the state between steps
(drag, perturb): a dragged robot is held where the pointer is, before the step is judged.
What the live view cannot honour is refused by name (:class:`SessionError`) or, for a
substitute it shows instead (a ``filippov`` integrator shown with ``implicit-euler``),
warned about (:class:`~formationlab.errors.ViewerWarning`).
:class:`ReplaySession` (:mod:`.replay`) plays back the stored trajectory of
``formationlab run``.

Both speak the same small interface, used by :mod:`formationlab.viewer.controller`:
``info()`` (what does not change from frame to frame), ``frame()`` (the state
now: header and positions), ``advance(wall_dt)`` and the commands. Robot
numbers that cross this interface are 1-based, as everywhere a person reads
them; the arrays inside are 0-based.
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import validation
from ..dynamics import System
from ..errors import UserInputError, ViewerWarning
from ..integrators import FixedStepIntegrator, Integrator, get_integrator
from ..integrators.driver import Stepping
from ..scenario import Scenario, closed_loop
from ..status import Status
from .export import SessionError
from .frames import (
    Frame,
    History,
    finite_or_none,
    live_header,
    scene_info,
    split_state,
    static_info,
)
from .history import StateHistory
from .steering import LIVE_INTEGRATORS, Steering, _law_catalogue, law_parameters
from .stepping import CompiledSteps

__all__ = ["Frame", "LiveSession", "SessionError", "law_parameters"]

#: Least wall time between two evaluations of V when one costs more than 4 ms.
V_EVERY_S = 0.1
#: the largest coordinate the page can draw (it receives float32 positions)
DRAWABLE = float(np.finfo(np.float32).max)
#: Most replay samples of V and the errors sent for the plots.
SERIES_MAX = 2000
#: Steps a live run may take (it has no end: a person stops it).
LIVE_STEPS = 2**62
#: Wall seconds over which the speed reached is measured.
REACHED_OVER_S = 0.5


class LiveSession(Steering):
    """A live run of a scenario that the page steers.

    Parameters
    ----------
    scenario : Scenario
        What to run: its whole closed loop, its integrator and its initial state.
    seed : int, optional
        Seed of the random perturbations (``numpy.random.default_rng``), a whole number in
        ``[0, 2**63)``.
    step_budget_s : float
        Wall time one :meth:`advance` may spend stepping (at least one step is
        taken), so that the page keeps its frame rate when steps are slow.

    Raises
    ------
    SessionError
        For a scenario with ``[asynchronous]`` (each robot its own task: not a loop of
        common steps), naming the table.
    """

    mode = "live"

    def __init__(
        self, scenario: Scenario, *, seed: int | None = None, step_budget_s: float = 0.015
    ) -> None:
        if scenario.asynchronous is not None:
            raise SessionError(
                "[asynchronous]: every robot updates on its own clock, which the live view "
                "cannot step frame by frame; remove [asynchronous] to watch the synchronous "
                "loop, or run it with `formationlab run`"
            )
        self.scenario = scenario
        self.formation = scenario.formation
        self.seed = None if seed is None else validation.seed(seed)
        self.rng = np.random.default_rng(seed)
        self.step_budget_s = step_budget_s
        self.notices: list[str] = []
        self.integrator: FixedStepIntegrator = self._live_integrator(scenario.integrator)
        self.system: System = closed_loop(scenario)
        self.speed = 1.0
        self.paused = False
        self.steps = 0
        self.status = "running"
        self.message = ""
        self.pinned: int | None = None
        self._pin_at: NDArray[np.float64] | None = None
        self._debt = 0.0
        self._V: tuple[Any, float, float, float] | None = None
        #: the states stepped since the last reset, with the closed loop of each
        self.history = StateHistory()
        self._compiled: CompiledSteps | bool | None = False  # False: not yet looked at
        self._step_cost = 0.0  # wall seconds per compiled step, as last measured
        #: simulated seconds per wall second over the last REACHED_OVER_S of running (None
        #: before it is measured, and while paused)
        self.reached: float | None = None
        self._window = [0.0, 0.0]  # wall seconds and simulated seconds of the window
        self._start(np.array(scenario.x0, dtype=float), 0.0)

    # ------------------------------------------------------------------ the loop

    @property
    def state(self) -> NDArray[np.float64]:
        """The state now, ``(n, k)`` (``model.state_names``: positions first)."""
        run = self._run
        return run.x[0] if run.live.size else run.x_out[0]

    @property
    def positions(self) -> NDArray[np.float64]:
        """Robot centres now, ``(n, d)`` (robot 1 is row 0; ``d = 3`` in space)."""
        return self.system.positions(self.state)

    q = positions

    @property
    def t(self) -> float:
        """Simulated time now, seconds."""
        return self._run.time(self._run.k)

    def _start(self, x: NDArray[np.float64], t: float, *, record: bool = True) -> None:
        """Step on from the state ``x`` ``(n, k)`` at time ``t`` (a new pass of the driver);
        ``record``: keep it in the history (it is not there yet)."""
        try:
            self._run = Stepping(
                self.system, self.integrator, x[None], n_steps=LIVE_STEPS, t0=t
            )  # the sensing's own seed, as simulate's run
        except UserInputError as exc:
            raise SessionError(str(exc), key=exc.key) from None
        if record:
            self._record()

    def trajectory(self) -> History:
        """What was stepped since the last reset: times ``(T,)``, positions ``(T, n, d)``,
        ``V`` ``(T,)`` and the per-edge errors ``(T, m)``, each state's by the law in force
        when it was stepped (:class:`~formationlab.viewer.history.StateHistory`: every
        state, thinned past its budget; a large formation on the compiled loop keeps every
        few steps of a long segment, :mod:`.stepping`)."""
        return self.history.read()

    def _record(self, x: NDArray[np.float64] | None = None, t: float | None = None) -> None:
        """Keep a state (default the state now) in :attr:`history`."""
        self.history.record(self.t if t is None else t, self.state if x is None else x, self.system)

    def _live_integrator(self, integrator: Integrator) -> FixedStepIntegrator:
        if isinstance(integrator, FixedStepIntegrator):
            return integrator
        dt = float(getattr(integrator, "dt", 1e-3))
        text = (
            f"[simulation] integrator = {integrator.name!r}: the live view steps with a fixed "
            f"step, so it shows implicit-euler (dt = {dt:g} s), which slides on the surfaces "
            "like it; `formationlab run` runs the scenario's own"
        )
        warnings.warn(text, ViewerWarning, stacklevel=4)
        self.notices.append(text)
        out = get_integrator("implicit-euler", dt=dt)
        assert isinstance(out, FixedStepIntegrator)  # registry invariant, not user input
        return out

    def _one_step(self) -> bool:
        """Take one step; False (and paused, with a message) if the step is refused."""
        run = self._run
        hold = None
        if self.pinned is not None and self._pin_at is not None:
            hold = {self.pinned: self._pin_at}
        if run.step(hold):
            self.steps += 1
            self._record()
            return self._drawable()
        # the contact rule refused the step (System.step_verdict): stay at the last
        # accepted state, ready to run on from it
        status, message = Status.from_code(run.status[0]), run.message[0]
        self._start(run.x_out[0].copy(), run.time(int(run.steps[0])), record=False)
        return self._stop(str(status), message)

    def _compiled_steps(self) -> CompiledSteps | None:
        """The compiled loop of the closed loop in force, for a large formation that no
        one holds (:mod:`.stepping`), else None."""
        if self._compiled is False or (
            isinstance(self._compiled, CompiledSteps)
            and (self._compiled.system is not self.system
                 or self._compiled.integrator != self.integrator)
        ):  # fmt: skip
            self._compiled = CompiledSteps.for_system(self.system, self.integrator)
        return self._compiled if self.pinned is None else None  # type: ignore[return-value]

    def _segment(self, compiled: CompiledSteps, count: int) -> int:
        """Take ``count`` steps on the compiled loop; returns how many were accepted."""
        run, t0 = self._run, self.t
        seg = compiled.run(self.state, t0, count)
        dt = self.integrator.dt
        for k, x in zip(seg.k[1:], seg.x[1:], strict=True):
            self._record(x, t0 + int(k) * dt)
        run.move(seg.x[-1][None])  # the driver's state and step, moved on
        run.k += seg.steps
        self.steps += seg.steps
        if seg.status is not Status.SUCCESS:
            self._stop(str(seg.status), seg.message)
            return seg.steps
        self._drawable()
        return seg.steps

    def _take(self, count: int, budget_s: float | None = None) -> int:
        """Take up to ``count`` steps (within ``budget_s`` wall seconds, at least one step);
        returns how many were taken. Stops at a refused step (paused, with its message)."""
        done, start = 0, time.perf_counter()
        compiled = self._compiled_steps()
        while done < count and self.status == "running":
            if compiled is None:
                if not self._one_step():
                    break
                done += 1
            else:  # segments sized to the budget by the last one's cost per step
                left = count - done
                if budget_s is not None and self._step_cost > 0:
                    spare = budget_s - (time.perf_counter() - start)
                    left = max(1, min(left, int(spare / self._step_cost)))
                began = time.perf_counter()
                took = self._segment(compiled, left)
                if took:
                    self._step_cost = (time.perf_counter() - began) / took
                done += took
            if budget_s is not None and time.perf_counter() - start > budget_s:
                break
        return done

    def _drawable(self) -> bool:
        """Whether the state now can be drawn; if not, pause with a message (a state that
        is not finite, or beyond float32, which the page receives)."""
        x = self.state
        if not np.all(np.isfinite(x)):
            bad = sorted({int(i) + 1 for i in np.flatnonzero(~np.all(np.isfinite(x), axis=-1))})
            robots = ", ".join(map(str, bad[:5])) + (" ..." if len(bad) > 5 else "")
            return self._stop(
                "non-finite",
                f"the state is not finite (robot {robots} at inf or NaN) at t = {self.t:.4g} s: "
                "the stream is paused; reset the robots, or lower the gains or dt",
            )
        if not np.all(np.abs(x) <= DRAWABLE):  # finite, but not drawable
            return self._stop(
                "out-of-range",
                f"a robot left the range the page can draw (|x| > {DRAWABLE:.1e} m) at t = "
                f"{self.t:.4g} s: reset the robots, or lower the gains",
            )
        return True

    def _stop(self, status: str, message: str) -> bool:
        self.status, self.message, self.paused = status, message, True
        return False

    def _moved(self, x: NDArray[np.float64]) -> None:
        """The state changed between steps (a drag or a perturbation)."""
        self._run.move(x[None])
        if self.status != "running":
            self.status, self.message = "running", ""

    def frame(self) -> Frame:
        """The state now."""
        x = self.state
        dim = self.formation.dim
        pos, heading = split_state(x, self.system.model.names_in(dim), dim)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # (not finite:
            numbers = live_header(self.system, x, self.t)  # the status says so)
        header: dict[str, Any] = {
            "t": self.t,
            "V": finite_or_none(self._lyapunov(x)),
            **numbers,
            "steps": self.steps,
            "paused": self.paused,
            "status": self.status,
            "message": self.message,
            "speed": self.speed,
            "reached": None if self.paused else self.reached,
            "compiled": isinstance(self._compiled, CompiledSteps),
            "pinned": None if self.pinned is None else self.pinned + 1,
            "law": self.law.name,
        }
        return Frame(
            header=header,
            # drawable numbers only (a robot at NaN drawn at 0, one at inf at the edge of
            # float32: the status says why the run paused)
            positions=np.nan_to_num(pos, nan=0.0, posinf=DRAWABLE, neginf=-DRAWABLE)
            .clip(-DRAWABLE, DRAWABLE)
            .astype(np.float32),
            heading=None if heading is None else heading.astype(np.float32),
        )

    def _lyapunov(self, x: NDArray[np.float64]) -> float:
        """``V`` now (the system's: with the obstacles' repulsion); for large formations
        (where it costs more than a few milliseconds) recomputed at most every
        :data:`V_EVERY_S` seconds of wall time, so that it does not halve the frame rate."""
        key = (self.steps, self.t, self.law, x[0, 0], x[-1, -1])
        now = time.perf_counter()
        cached = self._V
        fresh = cached is not None and cached[0] == key
        if fresh or (cached is not None and cached[2] > 0.004 and now - cached[3] < V_EVERY_S):
            assert cached is not None
            return cached[1]
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            V = float(np.asarray(self.system.potential(x)))
        self._V = (key, V, time.perf_counter() - now, now)
        return V

    def info(self) -> dict[str, Any]:
        """What the page needs once: the formation, the closed loop's parts, the choices."""
        return {
            "mode": self.mode,
            **static_info(self.formation, self.scenario.name),
            **scene_info(self.system),
            "law": {"name": self.law.name, "params": law_parameters(self.law)},
            "laws": _law_catalogue(self.formation.dim),
            "integrator": {"name": self.integrator.name, "dt": self.integrator.dt},
            "integrators": list(LIVE_INTEGRATORS),
            "models": [self.system.model.name],
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
        done = self._take(want, self.step_budget_s) if self._resume() else 0
        self._debt = self._debt - done * dt if done == want else 0.0
        window = self._window
        window[0] += max(wall_dt, 0.0)
        window[1] += done * dt
        if window[0] >= REACHED_OVER_S:
            self.reached = window[1] / window[0]
            window[:] = [0.0, 0.0]
        return done

    def step(self, count: int = 1) -> int:
        """Take ``count`` steps now (paused or not); returns how many were taken (fewer when
        a step is refused, or when the state cannot be drawn: :attr:`status` says why)."""
        return self._take(count) if self._resume() else 0

    def run_for(self, seconds: float) -> int:
        """Run ``seconds`` of simulated time now (the steps of dt that fit, at least one);
        returns the steps taken."""
        return self.step(max(1, round(seconds / self.integrator.dt)))

    def _resume(self) -> bool:
        """Whether the run may step from the state now: a refused step's status is cleared
        (the next step is judged again), a state that cannot be drawn keeps it paused."""
        if self.status != "running":
            self.status, self.message = "running", ""
        return self._drawable()

    def set_paused(self, paused: bool) -> None:
        self.paused = paused
        self._window[:] = [0.0, 0.0]
        self.reached = None
        if not paused:
            self._resume()

    def set_speed(self, speed: float) -> None:
        self.speed = float(speed)

    def reset(self) -> None:
        """Back to the scenario's initial state at t = 0 (law and integrator as chosen)."""
        self.steps, self._debt = 0, 0.0
        self.status, self.message = "running", ""
        self.pinned = self._pin_at = None
        self.history.clear()
        self._start(np.array(self.scenario.x0, dtype=float), 0.0)
