"""Crazyflies behind the runner's seam, on Bitcraze's ``cflib`` (the ``robots`` extra).

:func:`connect` opens the links of a swarm in parallel (``cflib.crazyflie.swarm.Swarm`` with
``cflib.crtp.init_drivers()``); :class:`CflibDrone` is one Crazyflie as the runner's
:class:`~formationlab.robots.link.Drone`, each method one or two ``cflib`` calls:

* positions: a ``LogConfig`` of ``stateEstimate.x``, ``.y``, ``.z`` (floats) at the control
  period (the firmware logs in steps of 10 ms), its ``data_received_cb`` feeding the runner;
* a lost link: the ``Crazyflie``'s ``connection_lost`` and ``disconnected`` callbacks;
* the estimator: ``cflib.utils.reset_estimator.reset_estimator`` (reset the Kalman filter,
  then wait until the variance of its position has settled);
* take-off and landing: the high-level commander (``takeoff``, ``land``, ``stop``), the
  return to it after velocity setpoints with ``send_notify_setpoint_stop``;
* velocity: ``commander.send_velocity_world_setpoint(vx, vy, vz, 0)`` (no yaw rate).

Bitcraze's cflib: https://github.com/bitcraze/crazyflie-lib-python (its ``swarm``,
``log``, ``commander`` and ``high_level_commander`` modules).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ..errors import require_extra
from .link import FlightError, LostLink, PositionUpdate

__all__ = ["POSITION", "CflibDrone", "connect"]

#: the log variables of a drone's position estimate
POSITION = ("stateEstimate.x", "stateEstimate.y", "stateEstimate.z")


class CflibDrone:
    """One Crazyflie behind a ``cflib`` ``SyncCrazyflie`` (module docstring)."""

    def __init__(self, scf: Any) -> None:
        self.scf = scf
        self.cf = scf.cf
        self.uri = str(getattr(self.cf, "link_uri", "") or getattr(scf, "_link_uri", ""))
        self.log_config: Any = None

    def start(self, period: float, on_position: PositionUpdate, on_lost: LostLink) -> None:
        from cflib.crazyflie.log import LogConfig  # optional extra

        self.cf.connection_lost.add_callback(lambda uri, message: on_lost(str(message)))
        self.cf.disconnected.add_callback(lambda uri: on_lost("disconnected"))
        config = LogConfig(name="formationlab position", period_in_ms=round(1000 * period))
        for name in POSITION:
            config.add_variable(name, "float")

        def received(timestamp: int, data: dict[str, float], logconf: Any) -> None:
            on_position(*(float(data[name]) for name in POSITION))

        config.data_received_cb.add_callback(received)
        self.cf.log.add_config(config)
        config.start()
        self.log_config = config

    def settle(self) -> None:
        from cflib.utils.reset_estimator import reset_estimator  # optional extra

        reset_estimator(self.cf)

    def take_off(self, height: float, duration: float) -> None:
        self.cf.high_level_commander.takeoff(height, duration)

    def velocity(self, v: Sequence[float]) -> None:
        vx, vy, vz = (float(c) for c in v)
        self.cf.commander.send_velocity_world_setpoint(vx, vy, vz, 0.0)

    def land(self, duration: float) -> None:
        self.cf.commander.send_notify_setpoint_stop()  # back to the high-level commander
        self.cf.high_level_commander.land(0.0, duration)

    def stop(self) -> None:
        self.cf.high_level_commander.stop()

    def close(self) -> None:
        if self.log_config is not None:
            self.log_config.stop()
        self.scf.close_link()


def connect(uris: Sequence[str], *, cache: str | None = None) -> tuple[Any, list[CflibDrone]]:
    """Open the links to ``uris`` in parallel: ``(swarm, drones)``, drones in the order of
    ``uris`` (``cache``: a folder for ``cflib``'s tables of contents, faster reconnects).

    Raises
    ------
    MissingExtraError
        Without ``cflib`` (``pip install "formationlab[robots]"``).
    FlightError
        A link that does not open (``cflib``'s message).
    """
    require_extra("robots", ("cflib",), "Crazyflie flights")
    import cflib.crtp  # optional extra
    from cflib.crazyflie.swarm import CachedCfFactory, Swarm  # optional extra

    cflib.crtp.init_drivers()
    swarm = Swarm(list(uris), factory=CachedCfFactory(rw_cache=cache))
    try:
        swarm.open_links()
    except Exception as exc:
        first = exc.__cause__ or exc  # (Swarm raises a summary from the first thread's error)
        reason = str(first).strip().splitlines()[-1] if str(first).strip() else type(first).__name__
        raise FlightError(f"cannot open the links to {', '.join(uris)}: {reason}") from exc
    found: dict[str, Any] = {}
    swarm.parallel_safe(lambda scf: found.__setitem__(scf.cf.link_uri, scf))
    return swarm, [CflibDrone(found[u]) for u in uris]
