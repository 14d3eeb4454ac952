"""Fly a scenario on Crazyflies: take off, run the law on the reported positions, land.

:class:`Flight` runs one flight of a scenario on ``n`` drones (one per robot, in robot
order; robot numbers 1-based in messages) behind the seam of :mod:`.link`: Crazyflies on
Bitcraze's ``cflib`` (:mod:`.cflib_drone`), or the simulated link (:mod:`.simulated`).
:func:`fly` connects to the URIs and runs it. The sequence:

1. stream every drone's position estimate (``stateEstimate.x/y/z`` at the control rate),
   wait for its estimator to settle and for a first position from each; refuse to take off
   from outside the fence or from robots in contact;
2. take off with the high-level commander to the formation's height (the plane at
   ``height``; in space the scenario's start heights, the lowest at ``height``,
   :func:`.plan.heights`);
3. every ``1 / rate`` seconds: the law's velocity at the measured positions
   (:meth:`.plan.FlightPlan.field`, the simulator's own field), in the plane with a
   climb term holding the height, scaled down to the speed limit (the package's
   :func:`~formationlab.models.limits.limit_speed`) and with the components pushing out of
   the fence near a wall removed (:func:`.fence.guard`), sent as world-frame velocity
   setpoints;
4. land every drone, for one of the reasons of :class:`Landing`: the formation reached
   (after hovering ``hover`` seconds), the duration over, Ctrl-C or SIGTERM, an exception
   in the law, a lost link, a stale position (none for ``stale_periods`` periods), a drone
   outside the fence, robots in contact. Landing is sent to every drone even when one
   link fails; then the motors are stopped and the links closed.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager

import numpy as np
from numpy.typing import NDArray

from ..errors import ParameterError
from ..models.limits import limit_speed
from ..outcomes.analysis import classify, touching
from ..outcomes.tolerances import Tolerances
from ..scenario import Scenario
from .config import FlightConfig, FlightResult, Landing
from .fence import guard
from .link import Clock, Drone, FlightError, LostLink, PositionUpdate, WallClock
from .plan import FlightPlan, flight_plan, heights

__all__ = ["Flight", "FlightConfig", "FlightError", "FlightResult", "Landing", "fly"]


class _Land(Exception):
    """A landing, raised to leave the control loop (a control-flow signal, not an error)."""

    def __init__(self, reason: Landing, message: str, exc: BaseException | None = None) -> None:
        super().__init__(message)
        self.reason, self.message, self.exc = reason, message, exc


class Flight:
    """One flight of ``scenario`` on ``drones`` (module docstring), on ``clock``.

    Parameters
    ----------
    scenario : Scenario
    drones : sequence of Drone
        One per robot, robot 1 first.
    config : FlightConfig
    clock : Clock, optional
        Default the wall clock; the simulated link's clock in tests.
    plan : FlightPlan, optional
        ``flight_plan(scenario)``, if already made.
    """

    def __init__(
        self,
        scenario: Scenario,
        drones: Sequence[Drone],
        *,
        config: FlightConfig | None = None,
        clock: Clock | None = None,
        plan: FlightPlan | None = None,
    ) -> None:
        self.plan: FlightPlan = plan or flight_plan(scenario)
        if len(drones) != self.plan.n:
            raise ParameterError(
                f"{len(drones)} drones for the {self.plan.n} robots of {scenario.name!r}: give "
                "one URI per robot, in robot order",
                key="uris",
            )
        self.drones = list(drones)
        self.config = config or FlightConfig()
        self.clock = clock or WallClock()
        self.period = 1.0 / self.config.rate
        self.heights = heights(self.plan, self.config.height)
        self.max_speed = min(self.config.max_speed, self.plan.max_speed or np.inf)
        self.duration = self.config.duration or scenario.duration
        fence = self.config.fence
        if np.any(self.heights < fence.low[2] + fence.margin) or np.any(
            self.heights > fence.high[2] - fence.margin
        ):
            raise ParameterError(
                f"the flight heights {np.round(self.heights, 3).tolist()} m are not inside the "
                f"fence's z range [{fence.low[2]:g}, {fence.high[2]:g}] less its margin: change "
                "--height or --fence",
                key="height",
            )
        n = self.plan.n
        self._q = np.full((n, 3), np.nan)
        self._stamp = np.full(n, -np.inf)
        self._lost: dict[int, str] = {}
        self._lock = threading.Lock()
        self._signal: int | None = None
        self._landing = False

    # -- what the links report (from cflib's threads too) ------------------------------------
    def _position(self, i: int) -> PositionUpdate:
        def update(x: float, y: float, z: float) -> None:
            with self._lock:
                self._q[i] = (x, y, z)
                self._stamp[i] = self.clock.now()

        return update

    def _lost_link(self, i: int) -> LostLink:
        def lost(reason: str) -> None:
            with self._lock:
                if not self._landing:
                    self._lost.setdefault(i, reason)

        return lost

    def _positions(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        with self._lock:
            return self._q.copy(), self._stamp.copy()

    # -- the flight ------------------------------------------------------------------------
    def run(self) -> FlightResult:
        """Fly (module docstring) and return what happened; raises :class:`FlightError` if the
        drones could not take off (nothing flew)."""
        self._t: list[float] = []
        self._qs: list[NDArray[np.float64]] = []
        self._vs: list[NDArray[np.float64]] = []
        started: list[int] = []
        problems: list[str] = []
        try:
            self._prepare(started)  # (Ctrl-C here stops it: nothing is flying)
            airborne_at = self.clock.now()
            with self._signals():
                try:
                    for d, h in zip(self.drones, self.heights, strict=True):
                        d.take_off(float(h), self.config.take_off_time)
                    self._fly(airborne_at)
                    raise AssertionError("a flight ends by landing")  # pragma: no cover
                except _Land as land:
                    reason = land
                except KeyboardInterrupt:
                    reason = _Land(Landing.INTERRUPTED, "interrupted (Ctrl-C)")
                except Exception as exc:  # a link failed while sending
                    reason = _Land(Landing.EXCEPTION, f"{type(exc).__name__}: {exc}", exc)
                landed_at = self.clock.now() - airborne_at
                self._land_all(problems)
        finally:
            for i in started:
                self._attempt(problems, i, "close", self.drones[i].close)
        return FlightResult(
            landing=reason.reason, message=reason.message, landed_at=landed_at, t=np.array(self._t),
            q=np.array(self._qs).reshape(-1, self.plan.n, 3),
            v=np.array(self._vs).reshape(-1, self.plan.n, 3),
            problems=tuple(problems), signal=self._signal, exception=reason.exc,
        )  # fmt: skip

    def _who(self, i: int) -> str:
        return f"robot {i + 1} ({self.drones[i].uri})"

    def _prepare(self, started: list[int]) -> None:
        """Start streaming, settle the estimators, wait for the first positions, check them."""
        for i, d in enumerate(self.drones):
            try:
                d.start(self.period, self._position(i), self._lost_link(i))
                started.append(i)
                d.settle()
            except Exception as exc:
                raise FlightError(f"{self._who(i)}: cannot start: {exc}") from exc
        end = self.clock.now() + self.config.wait_positions
        while True:
            q, stamp = self._positions()
            missing = np.flatnonzero(~np.isfinite(stamp))
            if not missing.size:
                break
            if self.clock.now() >= end:
                who = ", ".join(self._who(i) for i in missing)
                raise FlightError(
                    f"no position from {who} in {self.config.wait_positions:g} s: is its "
                    "positioning system (Lighthouse, Loco, motion capture) running?"
                )
            self.clock.sleep(self.period)
        outside = np.flatnonzero(self.config.fence.outside(q, axes=(0, 1)))
        if outside.size:
            raise FlightError(
                f"{', '.join(self._who(i) for i in outside)}: outside the fence "
                f"{self.config.fence.bounds} at the start: move the drone or change --fence"
            )
        if touching(self.plan.system.formation, q[:, : self.plan.dim]):
            raise FlightError(
                "robots stand in contact (closer than their diameters) at the start: move them"
            )

    def _check(self, now: float, q: NDArray, stamp: NDArray, airborne: bool) -> None:
        """Land for a signal, a lost link, a stale position or a drone outside the fence."""
        if self._signal is not None:
            name = signal.Signals(self._signal).name
            raise _Land(Landing.INTERRUPTED, f"interrupted ({name})")
        with self._lock:
            lost = dict(self._lost)
        if lost:
            i, why = min(lost.items())
            raise _Land(Landing.LINK_LOST, f"{self._who(i)}: link lost: {why}")
        late = np.flatnonzero(now - stamp > self.config.stale_periods * self.period + 1e-9)
        if late.size:
            i = int(late[0])
            raise _Land(
                Landing.STALE,
                f"{self._who(i)}: no position for {now - stamp[i]:.2f} s "
                f"(more than {self.config.stale_periods} periods)",
            )
        out = np.flatnonzero(self.config.fence.outside(q, axes=(0, 1, 2) if airborne else (0, 1)))
        if out.size:
            i = int(out[0])
            raise _Land(Landing.FENCE, f"{self._who(i)} is outside the fence at {q[i].round(3)}")

    def _law(self, q: NDArray[np.float64], t: float) -> NDArray[np.float64]:
        """The velocity setpoints ``(n, 3)`` at the measured positions ``q`` ``(n, 3)``."""
        dim = self.plan.dim
        try:
            u = np.asarray(self.plan.field(q[:, :dim], t), dtype=float)
            if not np.all(np.isfinite(u)):
                raise FloatingPointError("the law's velocity is not finite")
        except Exception as exc:
            raise _Land(
                Landing.EXCEPTION, f"the law failed: {type(exc).__name__}: {exc}", exc
            ) from exc
        if dim == 2:  # the plane at its height: a climb term holds it
            climb = self.config.climb_gain * (self.heights - q[:, 2])
            u = np.concatenate([u, climb[:, None]], axis=1)
        return u

    def _fly(self, start: float) -> None:
        """Take-off, formation, hover (the law holding the formation reached): one pass per
        control period until a landing."""
        cfg, plan = self.config, self.plan
        tol = Tolerances(distance=cfg.tolerance, bearing=cfg.tolerance)
        phase, phase_end, t0 = "take-off", start + cfg.take_off_time, start
        k = 0
        while True:
            now = self.clock.now()
            q, stamp = self._positions()
            self._check(now, q, stamp, airborne=phase != "take-off")
            v = None
            if phase == "take-off" and now >= phase_end - 1e-9:
                phase, t0 = "formation", now
            if phase in ("formation", "hover"):
                u = self._law(q, now - t0)
                p = q[:, : plan.dim]
                if touching(plan.system.formation, p):
                    raise _Land(Landing.CONTACT, "robots in contact: closer than their diameters")
                if phase == "hover" and now >= phase_end - 1e-9:
                    raise _Land(
                        Landing.REACHED, f"the formation is reached (within {cfg.tolerance:g})"
                    )
                if phase == "formation" and self._reached(p, u[:, : plan.dim], tol):
                    phase, phase_end = "hover", now + cfg.hover
                elif phase == "formation" and now - t0 >= self.duration - 1e-9:
                    raise _Land(Landing.DURATION, f"the duration ({self.duration:g} s) is over")
                v = guard(cfg.fence, q, limit_speed(u, self.max_speed))
            if v is not None:
                for d, vi in zip(self.drones, v, strict=True):
                    d.velocity(vi.tolist())
            self._t.append(now - start)
            self._qs.append(q)
            self._vs.append(np.zeros((plan.n, 3)) if v is None else v)
            k += 1
            self.clock.sleep(start + k * self.period - self.clock.now())

    def _reached(self, p: NDArray[np.float64], u: NDArray[np.float64], tol: Tolerances) -> bool:
        """Whether the desired formation is met at ``p`` (never while it marches)."""
        formation = self.plan.system.formation
        return not self.plan.marching and classify(formation, p, u, tol) == "desired"

    def _attempt(
        self, problems: list[str], i: int, what: str, action: Callable[..., object], *args: object
    ) -> None:
        try:
            action(*args)
        except Exception as exc:  # every drone gets its turn whatever one link does
            problems.append(f"{self._who(i)}: {what} failed: {type(exc).__name__}: {exc}")

    def _land_all(self, problems: list[str]) -> None:
        """Land every drone, wait for the descent, stop the motors (each drone whatever the
        others do)."""
        with self._lock:
            self._landing = True
        for i, d in enumerate(self.drones):
            self._attempt(problems, i, "land", d.land, self.config.land_time)
        end = self.clock.now() + self.config.land_time + 0.5
        while self.clock.now() < end - 1e-9:
            try:
                self.clock.sleep(min(self.period, end - self.clock.now()))
            except KeyboardInterrupt:  # (a second Ctrl-C must not leave drones in the air)
                self._signal = self._signal or signal.SIGINT
        for i, d in enumerate(self.drones):
            self._attempt(problems, i, "stop", d.stop)

    @contextmanager
    def _signals(self) -> Iterator[None]:
        """SIGINT and SIGTERM only note themselves while the drones fly (the loop lands, and a
        second signal does not stop the landing), in the main thread; elsewhere a
        KeyboardInterrupt lands the same way. Before take-off they stop the command as usual."""
        if threading.current_thread() is not threading.main_thread():
            yield
            return

        def note(signum: int, frame: object) -> None:
            self._signal = self._signal or signum

        old = {s: signal.signal(s, note) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield
        finally:
            for s, handler in old.items():
                signal.signal(s, handler)


def fly(
    scenario: Scenario, uris: Sequence[str], *, config: FlightConfig | None = None
) -> FlightResult:
    """Fly ``scenario`` on the drones at ``uris`` (one per robot, robot 1 first).

    ``sim://...`` URIs (all of them) fly the simulated link (:mod:`.simulated`), the drones
    standing at the scenario's start on the floor; any other URI is a Crazyflie reached with
    ``cflib`` (the ``robots`` extra).
    """
    plan, n = flight_plan(scenario), scenario.n  # (refused before any link opens)
    if len(uris) != n:
        raise ParameterError(
            f"--uris gives {len(uris)} URIs for the {n} robots of {scenario.name!r}: give one "
            "per robot, in robot order",
            key="uris",
        )
    sims = [u.startswith("sim://") for u in uris]
    if all(sims):
        from .simulated import SimulatedFleet  # a dry run: no cflib needed

        fleet = SimulatedFleet(scenario.q0[:, :2], uris=uris)
        return Flight(scenario, fleet.drones, config=config, clock=fleet.clock, plan=plan).run()
    if any(sims):
        raise ParameterError("--uris mixes sim:// and real drones: give one kind", key="uris")
    from .cflib_drone import connect  # optional extra (cflib)

    swarm, drones = connect(uris)
    try:
        return Flight(scenario, drones, config=config, plan=plan).run()
    finally:
        swarm.close_links()
