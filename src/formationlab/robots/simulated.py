"""A simulated link: drones that integrate the commands they receive, on simulated time.

:class:`SimulatedFleet` holds ``n`` simulated drones (:class:`SimulatedDrone`, each a
:class:`~formationlab.robots.link.Drone`) and their clock (:class:`SimulatedClock`): the
runner's ``sleep`` advances the simulated time and moves the drones, so that a flight of a
minute runs in a fraction of a second and nothing waits on the wall clock. It is what
``formationlab fly --uris sim://1,sim://2,...`` flies (a dry run), and what the tests fly
every landing path on.

Each drone is the package's quadrotor model (:class:`~formationlab.models.Quadrotor`): a
first-order lag of the velocity behind its setpoint within speed and acceleration limits,
stepped by explicit Euler every ``dt`` seconds. What commands it follows:

* a **velocity setpoint** (:meth:`SimulatedDrone.velocity`), until the next one; like the
  firmware's setpoint watchdog, one older than ``level_after`` seconds is replaced by zero
  velocity and one older than ``cut_after`` seconds cuts the motors;
* the **high-level commander** (take-off, land, and the return to it after setpoints): a
  straight line to a goal at constant speed in the given time, tracked by a velocity
  setpoint with a proportional correction, the goal then held;
* **stop**: motors off. A drone whose motors stop above ``crash_height`` falls, and is
  marked :attr:`SimulatedDrone.crashed`.

Its position estimate (with optional Gaussian noise) is delivered every period asked for in
``start``. Faults are scheduled with :meth:`SimulatedFleet.at` (any callable at a simulated
time): :meth:`SimulatedDrone.lose_link` (the link's loss is reported, and commands are
dropped from then on, as ``cflib`` drops packets on a closed link),
:meth:`SimulatedDrone.mute` (positions stop coming), or a signal sent to the process.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..models import Quadrotor
from .link import LostLink, PositionUpdate

__all__ = ["CRAZYFLIE", "SimulatedClock", "SimulatedDrone", "SimulatedFleet"]

#: the simulated drones' velocity response, of the order of a Crazyflie 2.x under its
#: velocity controller: 0.2 s lag, 1 m/s (its position controller's velocity limit), and
#: about g tan(20 deg) of acceleration (its tilt limit)
CRAZYFLIE = Quadrotor(time_constant=0.2, max_accel=3.5, max_speed=1.0)

#: gain, 1/s, with which a high-level goal is tracked
_TRACK = 2.0


@dataclass(eq=False)
class SimulatedDrone:
    """One simulated drone (module docstring); its state is a row of its fleet's."""

    fleet: SimulatedFleet
    index: int
    uri: str
    period: float = 0.0
    on_position: PositionUpdate | None = None
    on_lost: LostLink | None = None
    mode: str = "ground"  # "ground", "goal" (high-level commander), "velocity"
    setpoint: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    setpoint_time: float = 0.0
    goal: tuple[NDArray[np.float64], NDArray[np.float64], float, float] | None = None
    next_report: float = 0.0
    linked: bool = True
    muted: bool = False
    crashed: bool = False
    log: list[tuple[float, str]] = field(default_factory=list)  # (time, command)

    @property
    def position(self) -> NDArray[np.float64]:
        return self.fleet.x[self.index, :3].copy()

    # -- the Drone protocol --------------------------------------------------------------
    def start(self, period: float, on_position: PositionUpdate, on_lost: LostLink) -> None:
        self.period, self.on_position, self.on_lost = period, on_position, on_lost
        self.next_report = self.fleet.t

    def settle(self) -> None:
        return None

    def take_off(self, height: float, duration: float) -> None:
        if self._received("take-off"):
            q = self.position
            self._to(np.array([q[0], q[1], height]), duration)

    def velocity(self, v: Sequence[float]) -> None:
        if self._received("velocity"):
            self.mode, self.setpoint = "velocity", np.array(v, dtype=float)
            self.setpoint_time = self.fleet.t

    def land(self, duration: float) -> None:
        if self._received("land"):
            q = self.position
            self._to(np.array([q[0], q[1], 0.0]), duration)

    def stop(self) -> None:
        if self._received("stop"):
            self._cut()

    def close(self) -> None:
        self.log.append((self.fleet.t, "close"))

    # -- faults ----------------------------------------------------------------------------
    def lose_link(self, reason: str = "too many packets lost") -> None:
        """The link breaks: reported once through ``on_lost``; later commands are dropped."""
        self.linked = False
        if self.on_lost is not None:
            self.on_lost(reason)

    def mute(self) -> None:
        """Positions stop coming (the link still takes commands)."""
        self.muted = True

    # -- inside ------------------------------------------------------------------------------
    def _received(self, command: str) -> bool:
        if not self.linked:
            return False
        self.log.append((self.fleet.t, command))
        return True

    def _to(self, target: NDArray[np.float64], duration: float) -> None:
        self.mode = "goal"
        self.goal = (self.position, target, self.fleet.t, self.fleet.t + max(duration, 1e-9))

    def _cut(self) -> None:
        if self.mode != "ground" and self.fleet.x[self.index, 2] > self.fleet.crash_height:
            self.crashed = True
        self.mode = "ground"
        self.fleet.x[self.index, 2] = 0.0  # (a fall: it ends on the floor)
        self.fleet.x[self.index, 3:] = 0.0

    def command(self, t: float) -> NDArray[np.float64] | None:
        """The velocity setpoint at time ``t`` (None: motors off)."""
        if self.mode == "velocity":
            age = t - self.setpoint_time
            if age > self.fleet.cut_after:
                self._cut()
                return None
            return self.setpoint if age <= self.fleet.level_after else np.zeros(3)
        if self.mode == "goal":
            assert self.goal is not None
            p0, p1, t0, t1 = self.goal
            s = min(max((t - t0) / (t1 - t0), 0.0), 1.0)
            feed = (p1 - p0) / (t1 - t0) if s < 1.0 else np.zeros(3)
            return feed + _TRACK * (p0 + s * (p1 - p0) - self.position)
        return None


class SimulatedClock:
    """Simulated time: :meth:`sleep` moves the fleet's drones (module docstring)."""

    def __init__(self, fleet: SimulatedFleet) -> None:
        self.fleet = fleet

    def now(self) -> float:
        return self.fleet.t

    def sleep(self, seconds: float) -> None:
        self.fleet.advance(seconds)


class SimulatedFleet:
    """Simulated drones on the floor at ``starts`` ``(n, 3)`` (or ``(n, 2)``: ``z = 0``).

    Parameters
    ----------
    starts : array_like, shape (n, 2) or (n, 3)
        Where the drones stand, metres.
    model : Quadrotor
        Their velocity response (:data:`CRAZYFLIE` by default).
    dt : float
        Euler step, s.
    noise : float
        Standard deviation of the position estimates' noise, metres (with ``rng``).
    level_after, cut_after : float
        The setpoint watchdog: seconds without a setpoint after which a drone holds zero
        velocity, then cuts its motors.
    crash_height : float
        A drone whose motors stop higher than this falls (:attr:`SimulatedDrone.crashed`).
    uris : sequence of str, optional
        The drones' URIs (default ``sim://1``, ``sim://2``, ...).
    """

    def __init__(
        self,
        starts: ArrayLike,
        *,
        model: Quadrotor = CRAZYFLIE,
        dt: float = 0.005,
        noise: float = 0.0,
        rng: np.random.Generator | None = None,
        level_after: float = 0.5,
        cut_after: float = 2.0,
        crash_height: float = 0.05,
        uris: Sequence[str] | None = None,
    ) -> None:
        q = np.asarray(starts, dtype=float)
        q = np.concatenate([q, np.zeros((len(q), 3 - q.shape[1]))], axis=1) if q.shape[1] < 3 else q
        self.x = np.concatenate([q, np.zeros_like(q)], axis=1)
        self.model, self.dt, self.noise = model, dt, noise
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.level_after, self.cut_after, self.crash_height = level_after, cut_after, crash_height
        self.t = 0.0
        uris = uris if uris is not None else [f"sim://{i + 1}" for i in range(len(q))]
        self.drones = [SimulatedDrone(self, i, u) for i, u in enumerate(uris)]
        self.clock = SimulatedClock(self)
        self._events: list[tuple[float, Callable[[], object]]] = []

    @property
    def positions(self) -> NDArray[np.float64]:
        """The drones' true positions ``(n, 3)``."""
        return self.x[:, :3].copy()

    def at(self, t: float, action: Callable[[], object]) -> None:
        """Call ``action`` when the simulated time reaches ``t``."""
        self._events.append((t, action))
        self._events.sort(key=lambda e: e[0])

    def advance(self, seconds: float) -> None:
        """Move the drones ``seconds`` on, delivering positions and scheduled events."""
        end = self.t + max(seconds, 0.0)
        while self.t < end - 1e-12:
            h = min(self.dt, end - self.t)
            self._step(h)
            self.t += h
            self._report()
            while self._events and self._events[0][0] <= self.t + 1e-12:
                self._events.pop(0)[1]()

    def _step(self, h: float) -> None:
        u = np.zeros((len(self.drones), 3))
        flying = np.zeros(len(self.drones), dtype=bool)
        for d in self.drones:
            c = d.command(self.t)
            if c is not None:
                u[d.index], flying[d.index] = c, True
        x = self.x + h * self.model.derivative(self.x, u)
        x[~flying] = self.x[~flying]
        below = x[:, 2] < 0.0
        x[below, 2], x[below, 5] = 0.0, np.maximum(x[below, 5], 0.0)
        self.x = x

    def _report(self) -> None:
        for d in self.drones:
            if d.on_position is None or d.muted or not d.linked:
                continue
            if self.t >= d.next_report - 1e-9:
                d.next_report += d.period
                q = d.position + (self.rng.normal(0.0, self.noise, 3) if self.noise else 0.0)
                d.on_position(float(q[0]), float(q[1]), float(q[2]))
