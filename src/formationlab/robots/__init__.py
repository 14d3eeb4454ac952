"""Real robots: fly a scenario on Crazyflies (docs/robots.md).

* :mod:`.crazyflie`: :class:`Flight` and :func:`fly`, the runner: take-off, the law on the
  reported positions at a fixed rate, the speed limit and the geofence, and landing on
  every way a flight can end (:class:`Landing`);
* :mod:`.config`: :class:`FlightConfig`, :class:`FlightResult`, :class:`Landing`;
* :mod:`.plan`: what a scenario asks of the drones, and what a flight refuses by name;
* :mod:`.fence`: the geofence;
* :mod:`.link`: the seam between the runner and a link (:class:`~.link.Drone`, the clock);
* :mod:`.cflib_drone`: Crazyflies on Bitcraze's ``cflib`` (the ``robots`` extra);
* :mod:`.simulated`: the simulated link the tests (and ``--uris sim://1,...``) fly.

Nothing here has been flown on real drones by us (docs/robots.md).
"""

from .crazyflie import Flight, FlightConfig, FlightResult, Landing, fly
from .fence import Fence
from .link import FlightError
from .simulated import SimulatedFleet

__all__ = [
    "Fence",
    "Flight",
    "FlightConfig",
    "FlightError",
    "FlightResult",
    "Landing",
    "SimulatedFleet",
    "fly",
]
