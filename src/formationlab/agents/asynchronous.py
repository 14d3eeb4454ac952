"""Robots as asyncio tasks with their own control periods: :func:`run_async`.

Each robot ``i`` is a task that wakes at its own times

    ``t_i^k = k T_i + e_i^k``,  ``e_i^k ~ U[0, jitter T_i)`` (a late wake-up, never early),

measures its neighbours, reads what the bus (:mod:`.bus`) has delivered, computes its
command from its own row of the law (:func:`formationlab.sensing.local_controls`: its own
measurements in its own frame, its own desired distances under ``Sensing.mismatch``) and
holds it until its next wake-up. Time is simulated, not wall-clock
(:mod:`.clock`): a run is reproducible and as fast as its arithmetic.

* **Measurement.** At ``t_i^k`` robot ``i``'s sensor takes ``z_ij = R(-a_i) (p_j - p_i)``
  of every robot ``j`` within ``Sensing.range`` (centres), plus ``Sensing.noise`` (robot
  ``i``'s own generator), and publishes one message per neighbour on the topic
  ``"relative-position"``, delivered ``Sensing.delay`` seconds later and lost with
  probability ``Sensing.drop``; a lost one leaves the last one received in place. A
  robot out of range is reported as unseen (never lost), so its terms are left out, as
  in the synchronous channel (:class:`formationlab.sensing.Channel`).
* **World.** Between events the world integrates every robot model with explicit Euler
  on the grid ``j dt``, with a shorter step to reach an event between two grid points;
  each robot's command is held (zero-order hold) in its own frame and turned into the
  common frame at each step, ``R(a_i) u_i``, with the heading of the step's start for
  unicycles. Robots that have stopped (``Faults.stop``) do not move. Robots due at the
  same time wake in robot order, all before the world moves on; until its first
  wake-up a robot's command is zero.
* **Contact** is the package's rule (:meth:`formationlab.System.step_verdict`): a
  rejected step ends the run at its start, with that status and message.

With every period equal to ``dt``, no jitter and no faults, this is the synchronous
closed loop stepped by :func:`formationlab.simulate` with ``Euler(dt=dt)`` (tested to
``1e-12``), with the same :class:`~formationlab.sensing.Sensing` frames, mismatch and a
delay of whole steps. Randomness comes from one seed: the frames and mismatch are the
synchronous channel's (children 0 and 1 of ``SeedSequence(seed)``); the jitter, noise
and losses of robot ``i`` are drawn from ``SeedSequence(seed)`` child 4, its child ``i``.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..controllers import LAWS, Law
from ..dynamics import System
from ..errors import ParameterError
from ..formation.spec import Formation
from ..integrators import Euler
from ..integrators.base import steps_for
from ..models import MODELS, RobotModel, SingleIntegrator
from ..registry import resolve
from ..sensing import Channel, Faults, Sensing, local_controls, rotate
from ..simulation.run import SimulationResult, build_system, initial_state
from ..status import Status
from ..validation import nonnegative, positive, whole
from ..validation import seed as check_seed
from .bus import TIE, Bus, Message
from .clock import VirtualClock

__all__ = ["MEASUREMENT", "AsyncResult", "arun", "check_schedule", "run_async"]

#: the bus topic of measured relative positions
MEASUREMENT = "relative-position"
#: an event closer than this fraction of dt to a grid point happens at the grid point
_SNAP = 1e-9


@dataclass(frozen=True, kw_only=True, eq=False)
class AsyncResult(SimulationResult):
    """An asynchronous run: a :class:`~formationlab.SimulationResult` (saved on the grid
    ``j dt``, plottable, with its outcome) and what each robot did.

    Attributes
    ----------
    periods : ndarray, shape (n,)
        Each robot's control period ``T_i``, seconds.
    jitter : float
        The jitter, a fraction of each period.
    seed : int
        The seed of every random draw of the run.
    update_times : tuple of ndarray
        Robot ``i``'s wake-up times ``(K_i,)``.
    commands : tuple of ndarray
        Robot ``i``'s commands ``(K_i, 2)``, in its own frame, one per wake-up.
    """

    periods: NDArray[np.float64] = dataclasses.field(default=None)  # type: ignore[arg-type]
    jitter: float = 0.0
    seed: int = 0
    update_times: tuple[NDArray[np.float64], ...] = ()
    commands: tuple[NDArray[np.float64], ...] = ()

    @property
    def updates(self) -> NDArray[np.int64]:
        """How many times each robot updated its command, ``(n,)``."""
        return np.array([len(t) for t in self.update_times], dtype=np.int64)

    def summary(self, tolerances: Any = None) -> dict[str, Any]:
        """:meth:`SimulationResult.summary` with ``asynchronous``: periods, jitter, seed and
        each robot's number of updates (robot 1 first)."""
        out = super().summary(tolerances)
        out["asynchronous"] = {
            "periods": np.asarray(self.periods, dtype=float).tolist(),
            "jitter": float(self.jitter),
            "seed": int(self.seed),
            "updates": self.updates.tolist(),
        }
        return out


def _wake_times(
    period: float, jitter: float, rng: np.random.Generator, dt: float, end: float
) -> Iterator[float]:
    """``k T + e_k`` up to ``end`` (module docstring); snapped to the grid when within ``_SNAP``."""
    k = 0
    while True:
        t = k * period + (jitter * period * rng.random() if jitter > 0 else 0.0)
        j = round(t / dt)
        if abs(t - j * dt) <= _SNAP * dt:
            t = j * dt
        if t > end + TIE:
            return
        yield t
        k += 1


class _World:
    """The physics, the sensors and the actuators of one asynchronous run."""

    def __init__(
        self, system: System, channel: Channel, x0: NDArray[np.float64], *, dt: float,
        bus: Bus, noise_rngs: Sequence[np.random.Generator], save_every: int,
        periods: NDArray[np.float64], held: bool,
    ) -> None:  # fmt: skip
        self.system, self.model, self.channel = system, system.model, channel
        self.sensing, self.terms = channel.sensing, channel.terms
        self.n = system.formation.n
        self.x, self.dt, self.bus, self._noise = x0.copy(), dt, bus, list(noise_rngs)
        self.own = None if channel.own_distance is None else channel.own_distance[0]
        self.u_local = np.zeros((self.n, 2))
        self.t, self.j, self.on_grid, self.save_every = 0.0, 0, True, save_every
        self.periods, self.held = periods, held  # held: a command outlives a step of dt
        self.saved_t: list[float] = []
        self.saved_x: list[NDArray[np.float64]] = []
        self.saved_v: list[NDArray[np.float64]] = []
        self.times: list[list[float]] = [[] for _ in range(self.n)]
        self.commands: list[list[NDArray[np.float64]]] = [[] for _ in range(self.n)]
        self.status, self.message = Status.SUCCESS, ""
        self.steps = 0
        self._eye = np.eye(self.n, dtype=bool)

    def _angles(self, x: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """Each robot's frame ``(1, n)`` at ``x`` (the channel's), or None for the common frame."""
        return self.channel.angles(x[None], np.zeros(1, dtype=np.intp))

    # ---------------------------------------------------------------- robots' side

    def sense(self, i: int, t: float) -> None:
        """Robot ``i``'s sensor at ``t``: one measurement message per other robot."""
        p = self.model.points(self.x)
        z = p - p[i]
        a = self._angles(self.x)
        if a is not None:
            z = rotate(z, -a[0, i])
        s = self.sensing
        if s.noise > 0:
            z = z + s.noise * self._noise[i].standard_normal((self.n, 2))
        if math.isinf(s.range):
            inside = np.ones(self.n, dtype=bool)
        else:
            q = self.model.positions(self.x)
            inside = np.sum((q - q[i]) ** 2, axis=-1) <= s.range**2
        for j in range(self.n):
            if j != i:
                seen = bool(inside[j])
                m = Message(topic=MEASUREMENT, sender=j, recipient=i, stamp=t,
                            payload=z[j].copy() if seen else None)  # fmt: skip
                self.bus.publish(m, lossy=seen)

    def control(self, i: int, t: float) -> NDArray[np.float64]:
        """Robot ``i``'s command in its own frame from the measurements delivered by ``t``."""
        z = np.zeros((self.n, self.n, 2))
        seen = np.zeros((self.n, self.n), dtype=bool)
        for j, m in self.bus.latest(i, MEASUREMENT, t).items():
            if m.payload is not None:
                z[i, j], seen[i, j] = m.payload, True
        u = local_controls(self.terms, z, seen=seen, own_distance=self.own)[i]
        self.u_local[i] = u
        self.times[i].append(t)
        self.commands[i].append(u)
        return u

    # ---------------------------------------------------------------- world's side

    def rate(self) -> NDArray[np.float64]:
        """``x_dot`` now: the held commands in the common frame, stopped robots at rest."""
        a = self._angles(self.x)
        u = self.u_local.copy() if a is None else rotate(self.u_local, a[0])
        v = self.model.derivative(self.x, u)
        faults = self.system.faults
        if faults is not None and faults.any:
            v = np.where(faults.stopped(self.n, self.t)[:, None], 0.0, v)
        return v

    def _save(self, v: NDArray[np.float64]) -> None:
        self.saved_t.append(self.j * self.dt if self.on_grid else self.t)
        self.saved_x.append(self.x.copy())
        self.saved_v.append(v)

    def advance_to(self, target: float) -> bool:
        """Integrate to ``target``; False when a step is rejected (the run ends at its start)."""
        dt = self.dt
        while self.t < target - TIE:
            grid = (self.j + 1) * dt
            full = grid <= target + TIE
            t_b = grid if full else target
            h = dt if full and self.on_grid else t_b - self.t
            v = self.rate()
            saving = self.on_grid and self.j % self.save_every == 0
            if saving:
                self._save(v)
            with np.errstate(over="ignore", invalid="ignore"):
                x_new = self.x + h * v
            verdict = int(self.system.step_verdict(self.x, x_new)[0])
            if verdict:
                self.status = Status.from_code(verdict)
                self.message = self.system.step_message(self.x, x_new, self.status, t_b, h)
                if self.held:
                    self.message += (
                        "; between its wake-ups each robot holds its command (periods "
                        + ", ".join(f"{T:g}" for T in self.periods)
                        + " s, robot 1 first): a long period can bring robots into contact too"
                    )
                if not saving:
                    self._save(v)
                return False
            self.x, self.t, self.steps = x_new, t_b, self.steps + 1
            if full:
                self.j, self.t, self.on_grid = self.j + 1, grid, True
            else:
                self.on_grid = False
        return True

    def finish(self) -> None:
        """Save the last state with the velocity the robots hold there."""
        self._save(self.rate())
        counts = ", ".join(f"{len(t)}" for t in self.times)
        self.message = (
            f"integrated to t = {self.t:g} s in {self.steps} steps of at most dt = {self.dt:g} s; "
            f"robot updates: {counts} (robots 1 to {self.n})"
        )


async def _robot(i: int, world: _World, clock: VirtualClock, times: Iterator[float]) -> None:
    """Robot ``i``: sleep, measure, read the bus, command; until its last wake-up."""
    for t in times:
        await clock.sleep_until(t, i)
        world.sense(i, t)
        world.control(i, t)


#: the most wake-ups of all robots one run may hold (each is a task's turn in Python: about
#: ten minutes for 1e7)
WAKE_LIMIT = 1e7


def check_schedule(
    periods: float | ArrayLike | None, jitter: float, n: int, dt: float,
    duration: float | None = None,
) -> tuple[NDArray[np.float64], float]:  # fmt: skip
    """Each robot's period ``(n,)`` (default ``dt``) and the jitter, validated as by the runner;
    with ``duration``, the wake-ups of the run (``sum_i duration / T_i``) at most
    :data:`WAKE_LIMIT`."""
    T = _periods(periods, n, dt)
    if duration is not None:
        wakes = float(np.sum(duration / T))
        if not wakes <= WAKE_LIMIT:
            raise ParameterError(
                f"periods as short as {T.min():g} s make {wakes:.3g} wake-ups in "
                f"{duration:g} s, more than {WAKE_LIMIT:.0e} for one run: lengthen the "
                "periods (a robot's period is usually dt or a few times it)",
                key="periods",
            )
    return T, _jitter(jitter)


def _jitter(jitter: float) -> float:
    jitter = nonnegative(jitter, "jitter")
    if not jitter < 1:
        raise ParameterError(
            f"jitter is a fraction of each period in [0, 1), got {jitter!r}: a wake-up is "
            "late by less than one period", key="jitter",
        )  # fmt: skip
    return jitter


def _periods(periods: float | ArrayLike | None, n: int, dt: float) -> NDArray[np.float64]:
    if periods is None:
        return np.full(n, dt)
    given: Any = [periods] * n if np.ndim(periods) == 0 else periods  # one for all
    values = list(np.asarray(given, dtype=object).ravel())
    if np.ndim(given) != 1 or len(values) != n:
        raise ParameterError(
            f"periods must be one number or one per robot ({n} robots, robot 1 first), got "
            f"{periods!r}", key="periods",
        )  # fmt: skip
    out = np.empty(n)
    for r, v in enumerate(values):
        try:
            out[r] = positive(v, "periods")
        except ParameterError:  # the key is the list's; the robot is named in the message
            raise ParameterError(
                f"periods, robot {r + 1}, must be a finite number > 0 (seconds), got {v!r}",
                key="periods",
            ) from None
    return out


async def arun(
    formation: Formation, law: Law | str, q0: ArrayLike, *, duration: float, dt: float,
    periods: float | ArrayLike | None = None, jitter: float = 0.0,
    sensing: Sensing | None = None, faults: Faults | None = None,
    model: RobotModel | str | None = None, seed: int | None = None, save_every: int = 1,
    **initial: Any,
) -> AsyncResult:  # fmt: skip
    """:func:`run_async` as a coroutine, for a caller that already runs an event loop."""
    duration = positive(duration, "duration")
    dt = positive(dt, "dt")
    save_every = whole(save_every, "save_every")
    jitter = _jitter(jitter)
    if sensing is not None and not isinstance(sensing, Sensing):
        raise ParameterError(f"sensing must be a Sensing, got {sensing!r}", key="sensing")
    if faults is not None and not isinstance(faults, Faults):
        raise ParameterError(f"faults must be a Faults, got {faults!r}", key="faults")
    sensing = sensing or Sensing()
    if seed is None:
        seed = int(sensing.seed)
    else:
        seed = check_seed(seed)
    law, robot = resolve(LAWS, law), resolve(MODELS, model or SingleIntegrator())
    n = formation.n
    T, _ = check_schedule(periods, 0.0, n, dt, duration)
    x0 = initial_state(formation, robot, q0, **initial)
    system = build_system(formation, law, robot, x0, faults=faults)
    # the synchronous channel's frames and mismatch; its delay is the bus's here
    channel = Channel(dataclasses.replace(sensing, delay=0.0, seed=int(seed)), formation, law,
                      robot, [int(seed)], dt)  # fmt: skip
    streams = [c.spawn(3) for c in np.random.SeedSequence(int(seed), spawn_key=(4,)).spawn(n)]
    gens = [[np.random.Generator(np.random.PCG64(s)) for s in c] for c in streams]
    bus = Bus(n, delay=sensing.delay, drop=sensing.drop, rngs=[g[2] for g in gens])
    world = _World(system, channel, x0, dt=dt, bus=bus, noise_rngs=[g[1] for g in gens],
                   save_every=save_every, periods=T,
                   held=jitter > 0 or bool(np.any(np.abs(T - dt) > _SNAP * dt)))  # fmt: skip
    end = steps_for(duration, dt) * dt  # as the synchronous run: whole steps of dt
    clock = VirtualClock()
    start = time.perf_counter()
    clock.start([
        _robot(i, world, clock, _wake_times(T[i], jitter, gens[i][0], dt, end))
        for i in range(n)
    ])  # fmt: skip
    try:
        await clock.idle()
        while True:
            due = clock.next_time()
            if not world.advance_to(end if due is None else min(due, end)):
                break
            if due is None:
                world.finish()
                break
            await clock.wake(due)
    finally:
        await clock.close()
    x = np.asarray(world.saved_x)
    v = np.asarray(world.saved_v)
    points = robot.points(x)
    with np.errstate(over="ignore", invalid="ignore"):
        V, sigma = system.potential(x), law.switching(formation, points)
    stats = {
        "steps": world.steps, "wall_time_s": time.perf_counter() - start,
        "updates": [len(t) for t in world.times],
        "messages_sent": bus.sent, "messages_lost": bus.lost, "seed": int(seed),
    }  # fmt: skip
    return AsyncResult(
        formation=formation, law=law, integrator=Euler(dt=dt), t=np.asarray(world.saved_t),
        q=x[..., :2], u=v[..., :2], V=V, sigma=sigma, status=world.status,
        message=world.message, stats=stats, x=x, xdot=v, model=robot, periods=T,
        jitter=jitter, seed=int(seed),
        update_times=tuple(np.asarray(t, dtype=float) for t in world.times),
        commands=tuple(np.asarray(c, dtype=float).reshape(-1, 2) for c in world.commands),
    )  # fmt: skip


def run_async(
    formation: Formation, law: Law | str, q0: ArrayLike, *, duration: float, dt: float,
    periods: float | ArrayLike | None = None, jitter: float = 0.0,
    sensing: Sensing | None = None, faults: Faults | None = None,
    model: RobotModel | str | None = None, seed: int | None = None, save_every: int = 1,
    **initial: Any,
) -> AsyncResult:  # fmt: skip
    """Run ``law`` on ``formation`` with every robot an asyncio task (module docstring).

    Parameters
    ----------
    formation, law, q0, model, **initial
        As for :func:`formationlab.simulate` (``headings=`` for unicycles); the law needs
        kernel terms (every law of the package has them).
    duration : float
        Simulated time, seconds (rounded up to whole steps of ``dt``, as in
        :func:`formationlab.simulate`).
    dt : float
        The physics step: the world integrates with explicit Euler on the grid ``j dt``
        (and saves there, every ``save_every``-th point).
    periods : float or sequence of float, optional
        Each robot's control period ``T_i`` (seconds, robot 1 first; one number for all);
        default ``dt``.
    jitter : float
        Each wake-up is late by ``U[0, jitter) T_i``; in ``[0, 1)``.
    sensing : Sensing, optional
        Frames, noise, range, delay (any number of seconds), drop and mismatch of the
        measurements; default the paper's exact sensing.
    faults : Faults, optional
        Robots that stop moving.
    seed : int, optional
        Of the frames, mismatch, jitter, noise and losses; default ``sensing.seed``.

    Returns
    -------
    AsyncResult
        A :class:`~formationlab.SimulationResult` with each robot's update times and
        commands; ``status`` ``"success"`` or the contact rule's status.

    Inside a running event loop (a notebook), ``await arun(...)`` instead.
    """
    return asyncio.run(
        arun(formation, law, q0, duration=duration, dt=dt, periods=periods, jitter=jitter,
             sensing=sensing, faults=faults, model=model, seed=seed, save_every=save_every,
             **initial)
    )  # fmt: skip
