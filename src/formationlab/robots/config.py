"""The settings of a flight and what it returns: :class:`FlightConfig`, :class:`FlightResult`,
and :class:`Landing`, why a flight landed (:mod:`formationlab.robots.crazyflie`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
from numpy.typing import NDArray

from ..errors import ParameterError
from ..validation import positive, whole
from .fence import Fence

__all__ = ["FlightConfig", "FlightResult", "Landing"]


class Landing(StrEnum):
    """Why a flight landed."""

    REACHED = "reached"
    DURATION = "duration"
    INTERRUPTED = "interrupted"
    EXCEPTION = "exception"
    LINK_LOST = "link-lost"
    STALE = "stale-position"
    FENCE = "fence"
    CONTACT = "contact"


@dataclass(frozen=True, kw_only=True)
class FlightConfig:
    """How to fly (the options of ``formationlab fly``); lengths in metres, times in seconds.

    ``duration`` None: the scenario's. ``tolerance``: largest distance error (and bearing
    error, radians) at which the formation counts as reached. ``climb_gain``: 1/s, of the
    height hold in the plane.
    """

    rate: float = 20.0
    height: float = 0.5
    max_speed: float = 0.3
    fence: Fence = field(default_factory=Fence)
    duration: float | None = None
    tolerance: float = 0.05
    hover: float = 2.0
    stale_periods: int = 3
    take_off_time: float = 2.0
    land_time: float = 2.0
    climb_gain: float = 1.0
    wait_positions: float = 5.0

    def __post_init__(self) -> None:
        for name in ("rate", "height", "max_speed", "tolerance", "take_off_time", "land_time",
                     "climb_gain", "wait_positions"):  # fmt: skip
            positive(getattr(self, name), name, owner="flight")
        if self.duration is not None:
            positive(self.duration, "duration", owner="flight")
        if self.rate > 100:
            raise ParameterError(
                f"--rate is at most 100 Hz (the Crazyflie logs every 10 ms), got {self.rate:g}",
                key="rate",
            )
        whole(self.stale_periods, "stale_periods", owner="flight")


@dataclass
class FlightResult:
    """What a flight did: why it landed and when (``landed_at``, seconds since take-off), and
    every control period's measured positions ``q`` ``(K, n, 3)`` and sent velocities ``v``
    ``(K, n, 3)`` at times ``t`` ``(K,)`` (seconds since take-off) up to the landing.
    ``problems``: robots whose landing, stop or close failed."""

    landing: Landing
    message: str
    landed_at: float
    t: NDArray[np.float64]
    q: NDArray[np.float64]
    v: NDArray[np.float64]
    problems: tuple[str, ...] = ()
    signal: int | None = None
    exception: BaseException | None = None
