"""The stepping driver: the one time loop of every fixed-step run, trial and settling.

:func:`drive` steps a batch of states ``x`` of shape ``(B, n, k)`` (positions
first, then what the robot model adds) with any fixed-step scheme
(:class:`~formationlab.integrators.base.FixedStepIntegrator`), each trial on
its own:

* at step ``k`` (time ``t_k = k dt``, passed to the scheme for a field that
  depends on time) the scheme gives the next state ``x_{k+1}`` and the velocity
  ``v_k`` it followed (``x_{k+1} = x_k + dt v_k`` for explicit Euler; the
  Filippov velocity of a sliding step for implicit Euler);
* **stopped** (only with a :class:`StopRule`; with sensing, only while every robot
  sees all its neighbours, :meth:`~formationlab.sensing.Channel.informed`): at a check,
  a step ``k`` with ``k % check_every == 0`` (or the last step), the instantaneous speed
  ``max_i`` of the robot model's speed (:meth:`RobotModel.speed`; ``|v_i|`` of
  the positions for single integrators) or the net speed since the previous check,
  ``max_i |q_i(k) - q_i(k')| / ((k - k') dt)``, is at most ``speed``: the trial
  ends at ``x_k`` with :attr:`Status.CONVERGED`. The net speed recognises a
  trial at rest on a switching surface across which explicit Euler chatters;
* **rejected**: :meth:`System.step_verdict` refuses the step (not finite,
  contact at its end, or robots passing through each other along it): the
  trial ends at ``x_k``, its last accepted state, with that status;
* **end**: ``k`` reached ``n_steps`` (:attr:`Status.SUCCESS`).

With ``window`` the positions of the live trials at step ``n_steps - window`` (if
it is not negative) are kept (``Stepped.q_window``): the start of the drift window over which the
rigid motion of a formation that never stops is fitted
(:mod:`formationlab.outcomes.rigid_motion`).

With sensing (:attr:`System.sensed`) the driver makes the measurement channel of its
trials (:meth:`System.channel`, one seed per trial) and binds it to the system at each
step: with noise, delay or drops the robots measure once, at the start of the step, and
hold their commands over it (a digital controller); otherwise their sensed commands are
evaluated at every stage of the scheme. Only explicit schemes (``explicit = True``) step
a sensed system.

The loop's body is :class:`Stepping` (one call of :meth:`Stepping.step` per step, holding
the channel, the step ``k``, the stop rule's last check and what was saved): ``drive`` loops
over it, and the live viewer pulls it one step at a time.

Saving every ``save_every`` steps keeps ``(t, x, v)`` of every live trial, and
always a trial's last state. Counts in ``stats`` are integers.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from contextlib import nullcontext
from typing import Any, Concatenate, ParamSpec, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..dynamics import SensedView, System
from ..errors import ParameterError
from ..formation.geometry import row_norms
from ..outcomes.tolerances import NET_STEPS
from ..status import Status
from .diagnostics import SwitchMonitor
from .stepped import Stepped, StopRule

__all__ = ["Stepped", "Stepping", "StopRule", "drive", "position_dim"]

P = ParamSpec("P")
R = TypeVar("R")

Progress = Callable[[float], None]


def position_dim(system: Any) -> int:
    """The position columns of ``system``'s states: its formation's ``dim`` (2 in the plane,
    3 in space); 2 for the duck-typed systems of tests, which have no formation."""
    return int(getattr(getattr(system, "formation", None), "dim", 2))


class Scheme(Protocol):
    """What the driver needs of a fixed-step scheme (the contract of
    :class:`formationlab.integrators.base.FixedStepIntegrator`, which the schemes subclass)."""

    name: str
    dt: float
    explicit: bool  #: may step a sensed system (commands held over a step)
    evaluations_per_step: int

    def advance(
        self, system: System, x: NDArray[np.float64], dt: float, counters: dict[str, float],
        t: float = 0.0,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...  # fmt: skip


#: the progress callback is called at least this often (seconds of wall time)
PROGRESS_EVERY_S = 0.5


def _holding_formation(
    fn: Callable[Concatenate[System, P], R],
) -> Callable[Concatenate[System, P], R]:
    """``fn`` with the lists the system's formation derives from its restricted triples
    kept while it runs (``Formation.holding``): a field evaluated at every step reads them."""

    @functools.wraps(fn)
    def run(system: System, *args: P.args, **kw: P.kwargs) -> R:
        formation = getattr(system, "formation", None)  # (duck-typed systems of the tests)
        with formation.holding() if formation is not None else nullcontext():
            return fn(system, *args, **kw)

    return run


class Stepping:
    """The body of :func:`drive`, one step at a time: a closed loop that can be pulled.

    Holds what a run carries from step to step: the live trials and their states, the
    step ``k`` (time ``t0 + k dt``, the marching reference's time), the measurement
    channel of a sensed system, the stop rule's last check, the saved blocks. Each call
    of :meth:`step` is one pass of the loop described in the module docstring;
    :func:`drive` loops over it, and the live viewer calls it once per step.

    Parameters
    ----------
    system, stepper, x0, n_steps, save_every, stop, window, diagnostics, seeds
        As for :func:`drive`.
    t0 : float
        Time of ``x0`` (default 0: ``t_k = k dt`` exactly, as :func:`drive`).

    Attributes
    ----------
    k : int
        The step of the states of the live trials (their time is ``t0 + k dt``).
    live : ndarray of intp, shape (L,)
        The trials still running; ``x`` their states ``(L, n, k)``.
    """

    def __init__(
        self,
        system: System,
        stepper: Scheme,
        x0: NDArray[np.float64],
        *,
        n_steps: int,
        save_every: int | None = None,
        stop: StopRule | None = None,
        window: int | None = None,
        diagnostics: bool = False,
        seeds: Any = None,
        t0: float = 0.0,
    ) -> None:
        dt = float(stepper.dt)
        if hasattr(system, "at_step"):  # (duck-typed systems of the tests have no filter)
            system = system.at_step(dt)  # the safety filter guards steps of dt
        self.system, self.stepper, self.n_steps = system, stepper, int(n_steps)
        self.save_every, self.stop, self.t0 = save_every, stop, float(t0)
        self.dt = dt
        x = np.array(x0, dtype=float)
        B = x.shape[0]
        self.channel = None
        if getattr(system, "sensed", False):  # (duck-typed systems of the tests have none)
            if not getattr(stepper, "explicit", False):
                raise ParameterError(
                    f"[sensing] needs an explicit fixed-step integrator (euler or rk4): a robot "
                    f"measures once per step and holds its command; {stepper.name!r} is not one",
                    key="simulation.integrator",
                )
            self.channel = system.channel(seeds, dt, B)
            if self.channel.B != B:
                raise ParameterError(f"drive: {self.channel.B} seeds for {B} trials")
        self.sampled = self.channel is not None and self.channel.sensing.sampled
        self.x_out, self.v_out = np.empty_like(x), np.full_like(x, np.nan)
        self.steps = np.zeros(B, dtype=np.int64)
        self.status = np.full(B, Status.SUCCESS.code, dtype=np.int8)
        self.message = [""] * B
        self.min_clear, self.min_obs = system.clearances(x)
        # the least distance of the filter's pairs (System.filtered; duck-typed systems of
        # the tests have no filter), measured at every accepted state in `step`
        self.filter = system.safety if getattr(system, "filtered", False) else None
        self.min_pair = np.full(B, np.inf if self.filter is not None else np.nan)
        self.net = np.full(B, np.nan)
        self.dim = d = position_dim(system)  # the position columns
        self.q_window = np.full((B, *x.shape[1:-1], d), np.nan)
        self.window_step = -1 if window is None else self.n_steps - int(window)
        self.saved: list[
            tuple[int, NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]
        ] = []
        self.live, self.x = np.arange(B), x
        self.xc, self.kc = x[..., :d].copy(), -1  # positions at the previous check, its step
        self.seen_c = np.ones(B, dtype=bool)  # whether each trial's robots saw everyone then
        self.monitor = SwitchMonitor(sigma0=system.sigma(x[0]), t0=self.t0) if diagnostics else None
        self.counters: dict[str, float] = {}
        self.evaluations = 0
        self.k = 0  # the step of the states x of the live trials
        self.v: NDArray[np.float64] | None = None  # the velocity of the last step taken

    @property
    def done(self) -> bool:
        """Whether every trial has ended."""
        return self.live.size == 0

    def time(self, k: int) -> float:
        """``t0 + k dt`` (``k dt`` exactly for ``t0 = 0``)."""
        return self.t0 + k * self.dt

    def _finish(
        self, which: NDArray[np.bool_], code: Status, k: int, xk: NDArray, vk: NDArray
    ) -> None:
        ids = self.live[which]
        self.x_out[ids], self.v_out[ids] = xk[which], vk[which]
        self.steps[ids], self.status[ids] = k, code.code

    def step(self, hold: dict[int, NDArray[np.float64]] | None = None) -> bool:
        """One pass of the loop: step ``k`` of the live trials; False once every trial ended.

        ``hold`` maps 0-based robots to the state rows they are held at (a person
        dragging them in the viewer): the step's new states get these rows before the
        step is judged. ``drive`` holds none.
        """
        system, stepper, dt, k, x, live = (
            self.system,
            self.stepper,
            self.dt,
            self.k,
            self.x,
            self.live,
        )
        channel, stop, n_steps = self.channel, self.stop, self.n_steps
        if self.filter is not None:  # (x is accepted: the pairs the filter keeps apart)
            least = self.filter.least_distance(system.model.points(x))
            self.min_pair[live] = np.minimum(self.min_pair[live], least)
        here = system
        if channel is not None:
            u_local = channel.local(*channel.observe(x, live, k), live) if self.sampled else None
            here = system.bound(SensedView(channel, live, u_local))
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            x_new, v = stepper.advance(here, x, dt, self.counters, self.time(k))  # step_verdict
        for i, row in (hold or {}).items():
            x_new[:, i] = row
        self.evaluations += live.size
        self.v = v
        if k == self.window_step:
            self.q_window[live] = x[..., : self.dim]
        ending = np.zeros(live.size, dtype=bool)
        clear = None
        if stop is not None and (k % stop.check_every == 0 or k == n_steps):
            q = x[..., : self.dim]
            still = system.speed(x, v) <= stop.speed
            if self.kc >= 0:
                d = q - self.xc
                net = self.net
                net[live] = np.max(row_norms(d), -1)
                net[live] /= (k - self.kc) * dt
                if k - self.kc >= NET_STEPS:  # (over one step: the instantaneous speed's job)
                    still |= net[live] <= stop.speed
            if channel is not None:  # robots that wait for a measurement are not at rest
                informed = channel.informed(x, live)
                still &= informed & self.seen_c
                self.seen_c = informed
            self.xc, self.kc = q.copy(), k
            self._finish(still, Status.CONVERGED, k, x, v)
            ending |= still
        if k == n_steps:
            self._finish(~ending, Status.SUCCESS, k, x, v)
            ending[:] = True
        else:
            verdict, clear, clear_obs = system.judge(x, x_new)
            verdict[ending] = 0
            for code in np.unique(verdict[verdict > 0]) if verdict.any() else ():
                bad = verdict == code
                self._finish(bad, Status.from_code(code), k, x, v)
                for r in np.flatnonzero(bad):
                    self.message[live[r]] = system.step_message(
                        x[r], x_new[r], Status.from_code(code), self.time(k + 1), dt
                    )
            ending |= verdict > 0
        if self.save_every is not None:
            sel = np.ones(live.size, bool) if k % self.save_every == 0 else ending
            if sel.any():
                self.saved.append((k, live[sel], x[sel].copy(), v[sel].copy()))
        keep = ~ending
        if not keep.any():
            self.live = live[keep]
            return False
        self.live, self.x, self.xc, self.k = live[keep], x_new[keep], self.xc[keep], k + 1
        self.seen_c = self.seen_c[keep]
        assert clear is not None  # a trial that goes on had its step judged
        self.min_clear[self.live] = np.minimum(self.min_clear[self.live], clear[keep])
        self.min_obs[self.live] = np.minimum(self.min_obs[self.live], clear_obs[keep])
        if self.monitor is not None and self.live.size and self.live[0] == 0:
            self.monitor.record(self.time(k + 1), system.sigma(self.x[0]))
        return True

    def move(self, x: NDArray[np.float64]) -> None:
        """Replace the states ``(L, n, k)`` of the live trials between two steps.

        A person moving robots (the viewer's drag and perturbation); the stop rule's last
        check and the channel's history are kept.
        """
        self.x = np.array(x, dtype=float).reshape(self.x.shape)

    def interrupt(self) -> None:
        """Stop every live trial with :attr:`Status.INTERRUPTED` at its current state."""
        ids, x, system = self.live, self.x, self.system
        if not ids.size:
            return
        t = self.time(self.k)
        if self.channel is None:
            v_now = system.rhs(x, t)
        else:  # what the robots would do with exact measurements: the step was not taken
            v_now = system.bound(SensedView(self.channel, ids)).rhs(x, t)
        self.x_out[ids], self.v_out[ids], self.status[ids] = x, v_now, Status.INTERRUPTED.code
        self.steps[ids] = self.k
        if self.save_every is not None and (not self.saved or self.saved[-1][0] != self.k):
            self.saved.append((self.k, ids, x.copy(), v_now))
        self.live = ids[:0]

    def result(self, wall: float) -> Stepped:
        """The :class:`Stepped` of the trials so far (``wall``: seconds of wall time taken)."""
        dt, steps, status, message = self.dt, self.steps, self.status, self.message
        done = int(steps.sum())
        for b in range(len(message)):
            if not message[b]:
                message[b] = _message(Status.from_code(status[b]), int(steps[b]), dt)
        counters = self.counters
        stats: dict[str, Any] = {
            "steps": done,
            "rhs_evaluations": int(self.evaluations * self.stepper.evaluations_per_step)
            + int(counters.pop("extra_rhs_evaluations", 0)),
            "wall_time_s": wall,
            "step_cost_s": wall / max(done, 1),
            **(self.monitor.stats() if self.monitor is not None else {}),
            **{key: int(value) for key, value in counters.items()},
        }
        return Stepped(
            x=self.x_out, v=self.v_out, steps=steps, status=status, message=message,
            min_clearance=self.min_clear, net_speed=self.net, q_window=self.q_window,
            window_step=self.window_step, saved=self.saved, stats=stats, dt=dt,
            min_obstacle_clearance=self.min_obs, min_pair_distance=self.min_pair,
        )  # fmt: skip


@_holding_formation
def drive(
    system: System,
    stepper: Scheme,
    x0: NDArray[np.float64],
    *,
    n_steps: int,
    save_every: int | None = None,
    stop: StopRule | None = None,
    window: int | None = None,
    diagnostics: bool = False,
    progress: Progress | None = None,
    interruptible: bool = False,
    seeds: Any = None,
) -> Stepped:
    """Step the trials ``x0`` ``(B, n, k)`` for up to ``n_steps`` steps of ``stepper.dt``.

    The loop over :meth:`Stepping.step` (the body, one step at a time).

    Parameters
    ----------
    system : System
        The closed loop.
    stepper : FixedStepIntegrator
        The scheme; its :meth:`~FixedStepIntegrator.advance` takes the live batch.
    x0 : ndarray, shape (B, n, k)
        Initial states, already validated.
    n_steps : int
        Steps in the full duration.
    save_every : int, optional
        Keep ``(t, x, v)`` every this many steps (and each trial's last state);
        nothing is kept when None.
    stop : StopRule, optional
        Stop each trial once it has stopped moving; without one, trials run to the end.
    window : int, optional
        Keep the positions ``window`` steps before ``n_steps`` (module docstring).
    diagnostics : bool
        Record the switching diagnostics of trial 0 (for single runs).
    progress : callable, optional
        Called with the simulated time now and then (at least every half second).
    interruptible : bool
        On Ctrl-C, stop every live trial with :attr:`Status.INTERRUPTED` and return
        what was stepped so far (instead of raising ``KeyboardInterrupt``).
    seeds : sequence of int or tuple of int, optional
        With sensing, the seed of each trial's channel (default: the sensing's ``seed``).
    """
    run = Stepping(
        system, stepper, x0, n_steps=n_steps, save_every=save_every, stop=stop,
        window=window, diagnostics=diagnostics, seeds=seeds,
    )  # fmt: skip
    start = last_report = time.perf_counter()
    report = max(1, n_steps // 100)
    try:
        while run.step():
            if progress is not None and (
                run.k % report == 0 or time.perf_counter() - last_report > PROGRESS_EVERY_S
            ):
                progress(run.time(run.k))
                last_report = time.perf_counter()
    except KeyboardInterrupt:
        if not interruptible:
            raise
        run.interrupt()
    return run.result(time.perf_counter() - start)


def _message(status: Status, steps: int, dt: float) -> str:
    if status is Status.SUCCESS:
        return f"integrated {steps} steps of dt = {dt:g} s"
    if status is Status.CONVERGED:
        return f"the robots stopped moving after {steps} steps (t = {steps * dt:g} s)"
    if status is Status.INTERRUPTED:
        return f"interrupted by the user at t = {steps * dt:g} s"
    return f"{status.explanation} at t = {steps * dt:g} s"
