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
(:mod:`formationlab.rigid_motion`).

With sensing (:attr:`System.sensed`) the driver makes the measurement channel of its
trials (:meth:`System.channel`, one seed per trial) and binds it to the system at each
step: with noise, delay or drops the robots measure once, at the start of the step, and
hold their commands over it (a digital controller); otherwise their sensed commands are
evaluated at every stage of the scheme. Only explicit schemes (``explicit = True``) step
a sensed system.

Saving every ``save_every`` steps keeps ``(t, x, v)`` of every live trial, and
always a trial's last state. Counts in ``stats`` are integers.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Concatenate, ParamSpec, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..dynamics import SensedView, System
from ..errors import ParameterError
from ..status import Status
from .diagnostics import SwitchMonitor

if TYPE_CHECKING:
    from .base import FixedStepIntegrator

__all__ = ["Stepped", "StopRule", "drive"]

P = ParamSpec("P")
R = TypeVar("R")

Progress = Callable[[float], None]
#: the progress callback is called at least this often (seconds of wall time)
PROGRESS_EVERY_S = 0.5


@dataclass(frozen=True, kw_only=True)
class StopRule:
    """When a trial counts as stopped (module docstring).

    Parameters
    ----------
    speed : float
        Stopped when the instantaneous or the net speed is at most this.
    check_every : int
        Test every this many steps (and at the last step).
    """

    speed: float
    check_every: int = 1


@dataclass(frozen=True, kw_only=True, eq=False)
class Stepped:
    """What :func:`drive` returns: final states, statuses and saved steps of ``B`` trials.

    Attributes
    ----------
    x, v : ndarray, shape (B, n, k)
        Last accepted state of each trial and the velocity of the step that
        left it (for a rejected step, the rejected step's velocity).
    steps : ndarray of int64, shape (B,)
        Accepted steps of each trial.
    status : ndarray of int8, shape (B,)
        :attr:`Status.code` of how each trial ended.
    message : list of str
        Why each trial ended, in words (says what to change when it failed).
    min_clearance : ndarray, shape (B,)
        Least ``r_ij - a_ij`` over every accepted state.
    net_speed : ndarray, shape (B,)
        Net speed over the last check interval (NaN before the second check
        or without a stop rule).
    q_window : ndarray, shape (B, n, 2)
        Positions at step ``window_step`` (NaN for trials that had ended by then,
        and for all without ``window``).
    window_step : int
        ``n_steps - window`` (-1 without ``window``; negative: no positions kept).
    saved : list
        Blocks ``(k, trials, x, v)`` saved at step ``k``; see :meth:`trajectory`.
    stats : dict
        ``steps``, ``rhs_evaluations``, ``wall_time_s``, ``step_cost_s``, the
        scheme's counters and, with ``diagnostics``, the switching diagnostics
        of the first trial.
    dt : float
        The step.
    """

    x: NDArray[np.float64]
    v: NDArray[np.float64]
    steps: NDArray[np.int64]
    status: NDArray[np.int8]
    message: list[str]
    min_clearance: NDArray[np.float64]
    net_speed: NDArray[np.float64]
    q_window: NDArray[np.float64]
    window_step: int
    saved: list[tuple[int, NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]]
    stats: dict[str, Any] = field(default_factory=dict)
    dt: float = 0.0

    def statuses(self) -> list[Status]:
        """The :class:`Status` of every trial."""
        return [Status.from_code(c) for c in self.status]

    def trajectory(self, b: int = 0) -> tuple[NDArray, NDArray, NDArray]:
        """Saved times ``(T,)``, states and velocities ``(T, n, k)`` of trial ``b``."""
        ks, xs, vs = [], [], []
        for k, ids, x, v in self.saved:
            hit = np.flatnonzero(ids == b)
            if hit.size:
                ks.append(k)
                xs.append(x[hit[0]])
                vs.append(v[hit[0]])
        return np.asarray(ks, dtype=float) * self.dt, np.asarray(xs), np.asarray(vs)


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


@_holding_formation
def drive(
    system: System,
    stepper: FixedStepIntegrator,
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
    dt = float(stepper.dt)
    x = np.array(x0, dtype=float)
    B = x.shape[0]
    channel = None
    if getattr(system, "sensed", False):  # (duck-typed systems of the tests have no sensing)
        if not getattr(stepper, "explicit", False):
            raise ParameterError(
                f"[sensing] needs an explicit fixed-step integrator (euler or rk4): a robot "
                f"measures once per step and holds its command; {stepper.name!r} is not one",
                key="simulation.integrator",
            )
        channel = system.channel(seeds, dt, B)
        if channel.B != B:
            raise ParameterError(f"drive: {channel.B} seeds for {B} trials")
    sampled = channel is not None and channel.sensing.sampled
    x_out, v_out = np.empty_like(x), np.full_like(x, np.nan)
    steps = np.zeros(B, dtype=np.int64)
    status = np.full(B, Status.SUCCESS.code, dtype=np.int8)
    message = [""] * B
    min_clear = system.clearance(x)
    net = np.full(B, np.nan)
    q_window = np.full((B, *x.shape[1:-1], 2), np.nan)
    window_step = -1 if window is None else n_steps - int(window)
    saved: list[tuple[int, NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]] = []
    live = np.arange(B)
    xc, kc = x[..., :2].copy(), -1  # positions at the previous check, its step
    seen_c = np.ones(B, dtype=bool)  # whether each trial's robots saw everyone then
    monitor = SwitchMonitor(sigma0=system.sigma(x[0]), t0=0.0) if diagnostics else None
    counters: dict[str, float] = {}
    start = last_report = time.perf_counter()
    report = max(1, n_steps // 100)
    evaluations = 0

    def finish(which: NDArray[np.bool_], code: Status, k: int, xk: NDArray, vk: NDArray) -> None:
        ids = live[which]
        x_out[ids], v_out[ids], steps[ids], status[ids] = xk[which], vk[which], k, code.code

    now = 0  # the step of the states x of the live trials
    try:
        for k in range(n_steps + 1):
            here = system
            if channel is not None:
                u_local = channel.local(*channel.observe(x, live, k), live) if sampled else None
                here = system.bound(SensedView(channel, live, u_local))
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                x_new, v = stepper.advance(here, x, dt, counters, k * dt)  # judged by step_verdict
            evaluations += live.size
            if k == window_step:
                q_window[live] = x[..., :2]
            ending = np.zeros(live.size, dtype=bool)
            if stop is not None and (k % stop.check_every == 0 or k == n_steps):
                q = x[..., :2]
                still = system.speed(x, v) <= stop.speed
                if kc >= 0:
                    d = q - xc
                    net[live] = np.sqrt(np.max(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1], -1))
                    net[live] /= (k - kc) * dt
                    still |= net[live] <= stop.speed
                if channel is not None:  # robots that wait for a measurement are not at rest
                    informed = channel.informed(x, live)
                    still &= informed & seen_c
                    seen_c = informed
                xc, kc = q.copy(), k
                finish(still, Status.CONVERGED, k, x, v)
                ending |= still
            if k == n_steps:
                finish(~ending, Status.SUCCESS, k, x, v)
                ending[:] = True
            else:
                verdict, clear = system.step_verdict(x, x_new)
                verdict[ending] = 0
                for code in np.unique(verdict[verdict > 0]) if verdict.any() else ():
                    bad = verdict == code
                    finish(bad, Status.from_code(code), k, x, v)
                    for r in np.flatnonzero(bad):
                        message[live[r]] = system.step_message(
                            x[r], x_new[r], Status.from_code(code), (k + 1) * dt, dt
                        )
                ending |= verdict > 0
            if save_every is not None:
                sel = np.ones(live.size, bool) if k % save_every == 0 else ending
                if sel.any():
                    saved.append((k, live[sel], x[sel].copy(), v[sel].copy()))
            keep = ~ending
            if not keep.any():
                break
            live, x, xc, now = live[keep], x_new[keep], xc[keep], k + 1
            seen_c = seen_c[keep]
            min_clear[live] = np.minimum(min_clear[live], clear[keep])
            if monitor is not None and live.size and live[0] == 0:
                monitor.record((k + 1) * dt, system.sigma(x[0]))
            if progress is not None and (
                (k + 1) % report == 0 or time.perf_counter() - last_report > PROGRESS_EVERY_S
            ):
                progress((k + 1) * dt)
                last_report = time.perf_counter()
    except KeyboardInterrupt:
        if not interruptible:
            raise
        ids = live
        if ids.size:
            if channel is None:
                v_now = system.rhs(x, now * dt)
            else:  # what the robots would do with exact measurements: the step was not taken
                v_now = system.bound(SensedView(channel, ids)).rhs(x, now * dt)
            x_out[ids], v_out[ids], status[ids] = x, v_now, Status.INTERRUPTED.code
            steps[ids] = now
            if save_every is not None and (not saved or saved[-1][0] != now):
                saved.append((now, ids, x.copy(), v_now))
    wall = time.perf_counter() - start
    done = int(steps.sum())
    for b in range(B):
        if not message[b]:
            message[b] = _message(Status.from_code(status[b]), int(steps[b]), dt)
    stats: dict[str, Any] = {
        "steps": done,
        "rhs_evaluations": int(evaluations * stepper.evaluations_per_step)
        + int(counters.pop("extra_rhs_evaluations", 0)),
        "wall_time_s": wall,
        "step_cost_s": wall / max(done, 1),
        **(monitor.stats() if monitor is not None else {}),
        **{key: int(value) for key, value in counters.items()},
    }
    return Stepped(
        x=x_out, v=v_out, steps=steps, status=status, message=message,
        min_clearance=min_clear, net_speed=net, q_window=q_window,
        window_step=window_step, saved=saved, stats=stats, dt=dt,
    )  # fmt: skip


def _message(status: Status, steps: int, dt: float) -> str:
    if status is Status.SUCCESS:
        return f"integrated {steps} steps of dt = {dt:g} s"
    if status is Status.CONVERGED:
        return f"the robots stopped moving after {steps} steps (t = {steps * dt:g} s)"
    if status is Status.INTERRUPTED:
        return f"interrupted by the user at t = {steps * dt:g} s"
    return f"{status.explanation} at t = {steps * dt:g} s"
