"""What the flight runner needs of a drone and of the time: the seam between the runner and a link.

The runner (:mod:`formationlab.robots.crazyflie`) talks to each drone through :class:`Drone`
and reads and waits on the time through :class:`Clock`. Two implementations stand behind
the seam: Crazyflies on Bitcraze's ``cflib`` (:mod:`formationlab.robots.cflib_drone`) with
the wall clock (:class:`WallClock`), and the simulated link of
:mod:`formationlab.robots.simulated`, whose clock is simulated time (its ``sleep`` moves the
simulated drones), so that every path of a flight is tested in milliseconds.

Why the seam is here and not one level down (a fake ``cflib.crtp`` driver): to connect,
``cflib`` asks the firmware for its protocol version, downloads the log and parameter
tables of contents and every parameter value and lists the memories, from its own receive
thread with real-time retries; a fake driver would have to be a second firmware, and its
tests would run on the wall clock. The ``cflib`` side of the seam is thin (a call per
method) and its packets are tested against ``cflib``'s own encoders (docs/robots.md).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Protocol

from ..errors import UserInputError

__all__ = ["Clock", "Drone", "FlightError", "LostLink", "PositionUpdate", "WallClock"]

#: ``on_position(x, y, z)``: a drone's position estimate, metres, in the world frame
PositionUpdate = Callable[[float, float, float], None]
#: ``on_lost(reason)``: the link to a drone is lost (the reason as the link says it)
LostLink = Callable[[str], None]


class FlightError(UserInputError):
    """A flight that could not start (a link, the estimator, the drones' places)."""


class Drone(Protocol):
    """One drone as the runner commands it (world frame, metres, seconds).

    The runner calls :meth:`start` once, then :meth:`settle`, :meth:`take_off`,
    :meth:`velocity` once per control period, :meth:`land` and :meth:`stop`, and
    :meth:`close` at the end whatever happened. Any method may raise (a link that fails);
    the runner then lands the others.
    """

    uri: str

    def start(self, period: float, on_position: PositionUpdate, on_lost: LostLink) -> None:
        """Stream the position estimate every ``period`` seconds to ``on_position``, and call
        ``on_lost`` when the link is lost."""

    def settle(self) -> None:
        """Return when the drone's position estimator has settled (raise if it does not)."""

    def take_off(self, height: float, duration: float) -> None:
        """Rise vertically to ``height`` metres in ``duration`` seconds (high-level commander)."""

    def velocity(self, v: Sequence[float]) -> None:
        """Follow the world-frame velocity ``(vx, vy, vz)``, m/s, until the next setpoint."""

    def land(self, duration: float) -> None:
        """Stop following setpoints and descend to the floor in ``duration`` seconds."""

    def stop(self) -> None:
        """Turn the motors off (after landing)."""

    def close(self) -> None:
        """Close the link."""


class Clock(Protocol):
    """The time of a flight: :meth:`now` in seconds, :meth:`sleep` to wait."""

    def now(self) -> float: ...

    def sleep(self, seconds: float) -> None: ...


class WallClock:
    """The clock of a real flight: :func:`time.monotonic` and :func:`time.sleep`."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)
