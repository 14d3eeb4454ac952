"""The Crazyflie runner (formationlab.robots) on the simulated link, every landing path, and
the cflib side of the seam against cflib's own encoders and decoders.

The simulated link (formationlab.robots.simulated) integrates the commands on simulated
time, so a flight of seconds runs in a fraction of one: the tests check where the drones
really are (the fleet's true positions), not only what the runner reported.
"""

from __future__ import annotations

import os
import signal
import struct

import numpy as np
import pytest
from _scenarios import triangle

from formationlab.errors import ParameterError, ScenarioError
from formationlab.outcomes.analysis import distance_errors
from formationlab.robots import (
    Fence,
    Flight,
    FlightConfig,
    FlightError,
    Landing,
    SimulatedFleet,
    fly,
)
from formationlab.robots.fence import guard
from formationlab.robots.plan import FlightPlan, FlightWarning
from formationlab.scenario import parse_scenario

SIMULATION_1 = "[[1, 2, 3, -1.0], [3, 1, 2, -1.0], [2, 1, 3, 1.0]]"
#: the paper's triangle with simulation 1's alpha table (the start turns the desired way, no
#: restriction active), from a start that fits a 4 m room
TRIANGLE = (
    triangle("flight-triangle", "30.0")
    .replace("[[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]", "[[-1.2, -1.0], [1.2, -1.0], [0.0, 1.2]]")
    .replace("[[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]]", SIMULATION_1)
)

TETRAHEDRON = """\
name = "flight-tetrahedron"
[robots]
positions = [[-0.8, -0.6, 0.0], [0.8, -0.5, 0.1], [0.0, 0.9, 0.0], [0.1, 0.0, 0.7]]
diameters = 0.2
[formation]
edges = "complete"
template = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.8660254038, 0.0],
            [0.5, 0.2886751346, 0.8164965809]]
orientation = "template"
[controller]
law = "chirality-restricted"
theta = 0.1
[simulation]
integrator = "euler"
dt = 1e-3
duration = 30.0
"""

CONFIG = FlightConfig(rate=20.0, height=0.5, max_speed=0.3)


def flight(text: str = TRIANGLE, config: FlightConfig = CONFIG, **fleet_options):
    scenario = parse_scenario(text)
    fleet = SimulatedFleet(scenario.q0[:, :2], **fleet_options)
    return scenario, fleet, Flight(scenario, fleet.drones, config=config, clock=fleet.clock)


def sent_at(drone, command: str) -> float:
    """The simulated time at which ``drone`` first received ``command``."""
    return next(t for t, c in drone.log if c == command)


def assert_all_landed(fleet: SimulatedFleet, skip: tuple[int, ...] = ()) -> None:
    """Every drone (but ``skip``, 0-based) was sent land then stop, is on the floor with its
    motors off, and did not fall; every link was closed."""
    for d in fleet.drones:
        commands = [c for _, c in d.log]
        assert commands[-1] == "close"
        if d.index in skip:
            continue
        assert commands[-3:-1] == ["land", "stop"], (d.uri, commands[-4:])
        assert d.mode == "ground" and not d.crashed
        assert fleet.x[d.index, 2] == 0.0


def test_the_drones_reach_the_formation_and_land():
    scenario, fleet, f = flight()
    start = fleet.positions
    result = f.run()
    assert result.landing is Landing.REACHED
    assert_all_landed(fleet)
    # where the drones really are: the desired triangle, landed vertically below it
    err = distance_errors(scenario.formation, fleet.positions[:, :2])
    assert np.max(np.abs(err)) <= CONFIG.tolerance
    assert np.max(np.abs(fleet.positions - start)) > 0.3  # (they did move)
    # in formation: at the flight height, no setpoint above the speed limit
    flying = result.t >= CONFIG.take_off_time
    assert np.max(np.abs(result.q[flying][-10:, :, 2] - CONFIG.height)) < 0.02
    assert np.max(np.linalg.norm(result.v, axis=-1)) <= CONFIG.max_speed * (1 + 1e-12)
    # hover: the law holds the formation reached; the lag's overshoot at the speed limit
    # (0.3 m/s for 0.2 s) stays small, and the formation settles well inside the tolerance
    hover = np.abs(distance_errors(scenario.formation, result.q[..., :2]))[
        result.t >= result.t[-1] - CONFIG.hover + 0.1
    ]
    assert np.max(hover) <= 1.5 * CONFIG.tolerance
    assert np.max(hover[-5:]) <= CONFIG.tolerance / 10
    # and the triangle turns the way the table asks (c_123 > 0 for these signs)
    (a, b), (c, d) = (
        fleet.positions[1, :2] - fleet.positions[0, :2],
        fleet.positions[2, :2] - fleet.positions[0, :2],
    )
    assert a * d - b * c > 0


def test_a_formation_in_space_flies_its_heights_above_the_floor():
    scenario, fleet, f = flight(TETRAHEDRON, FlightConfig(height=0.4, max_speed=0.3))
    take_off = fleet.drones[3]
    result = f.run()
    assert result.landing is Landing.REACHED, result.message
    assert_all_landed(fleet)
    # take-off heights: the scenario's start heights, the lowest at 0.4 m
    after = result.q[np.searchsorted(result.t, 2.0)]
    z0 = scenario.q0[:, 2]
    np.testing.assert_allclose(after[:, 2], z0 - z0.min() + 0.4, atol=0.04)
    assert take_off.log[0][1] == "take-off"
    last = result.q[-1]
    err = distance_errors(scenario.formation, last)
    assert np.max(np.abs(err)) <= 0.05
    assert np.all(result.q[result.t > 2.0][..., 2] > 0.2)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_lands_every_drone(sig):
    _, fleet, f = flight()
    before = signal.getsignal(sig)
    fleet.at(3.0, lambda: os.kill(os.getpid(), sig))
    result = f.run()
    assert result.landing is Landing.INTERRUPTED and result.signal == sig
    assert 3.0 - 1e-9 <= sent_at(fleet.drones[0], "land") <= 3.0 + 1 / CONFIG.rate + 1e-9
    assert_all_landed(fleet)
    assert signal.getsignal(sig) is before  # the handler given back


def test_a_keyboard_interrupt_lands_every_drone():
    _, fleet, f = flight()
    clock = fleet.clock
    sleep = clock.sleep

    def interrupted(seconds: float) -> None:
        sleep(seconds)
        if 2.5 <= clock.now() < 2.5 + 1 / CONFIG.rate:
            raise KeyboardInterrupt

    clock.sleep = interrupted  # type: ignore[method-assign]
    result = f.run()
    assert result.landing is Landing.INTERRUPTED
    assert_all_landed(fleet)


def test_an_exception_in_the_law_lands_every_drone(monkeypatch):
    _, fleet, f = flight()
    field = FlightPlan.field

    def failing(self, p, t):
        if t > 1.0:
            raise ZeroDivisionError("a law that fails")
        return field(self, p, t)

    monkeypatch.setattr(FlightPlan, "field", failing)
    result = f.run()
    assert result.landing is Landing.EXCEPTION
    assert isinstance(result.exception, ZeroDivisionError)
    assert "a law that fails" in result.message
    assert_all_landed(fleet)


def test_a_velocity_that_is_not_finite_lands(monkeypatch):
    _, fleet, f = flight()
    monkeypatch.setattr(FlightPlan, "field", lambda self, p, t: np.full_like(p, np.nan))
    result = f.run()
    assert result.landing is Landing.EXCEPTION and "not finite" in result.message
    assert np.all(result.v[-1] == 0)  # (nothing was sent from it)
    assert_all_landed(fleet)


def test_a_lost_link_lands_the_others():
    _, fleet, f = flight()
    fleet.at(3.0, fleet.drones[1].lose_link)
    result = f.run()
    assert result.landing is Landing.LINK_LOST
    assert "robot 2 (sim://2)" in result.message
    assert_all_landed(fleet, skip=(1,))
    # the lost drone heard nothing more: its watchdog cut the motors in the air
    lost = fleet.drones[1]
    assert "land" not in [c for _, c in lost.log]
    assert lost.crashed


def test_a_stale_position_lands_every_drone():
    _, fleet, f = flight()
    fleet.at(3.0, fleet.drones[2].mute)
    result = f.run()
    assert result.landing is Landing.STALE and "robot 3" in result.message
    # found after the stale limit, within one more period
    period = 1 / CONFIG.rate
    assert 3.0 + 3 * period < sent_at(fleet.drones[0], "land") <= 3.0 + 5 * period + 1e-9
    assert_all_landed(fleet)


def test_a_drone_outside_the_fence_lands_every_drone():
    _, fleet, f = flight()

    def gust() -> None:  # robot 1 blown through the wall x = -2
        fleet.x[0, 0] = -2.1

    fleet.at(4.0, gust)
    result = f.run()
    assert result.landing is Landing.FENCE and "robot 1" in result.message
    assert_all_landed(fleet)


def test_the_fence_removes_only_the_velocity_that_pushes_out():
    fence = Fence(bounds=(-1, 1, -1, 1, 0, 2), margin=0.2)
    q = np.array([[-0.9, 0.0, 1.0], [0.0, 0.95, 1.0], [0.0, 0.0, 1.0]])
    v = np.array([[-0.3, 0.2, 0.1], [0.1, 0.2, -0.1], [-0.3, 0.3, 0.3]])
    out = guard(fence, q, v)
    np.testing.assert_array_equal(out, [[0.0, 0.2, 0.1], [0.1, 0.0, -0.1], v[2]])
    assert fence.outside(np.array([[1.01, 0, 1], [0, 0, 1]])).tolist() == [True, False]


def test_a_fence_across_the_formation_holds_the_drones_in():
    close = TRIANGLE.replace(
        "[[-1.2, -1.0], [1.2, -1.0], [0.0, 1.2]]", "[[-0.3, -0.25], [0.3, -0.25], [0.0, 0.3]]"
    )  # (the triangle grows from here)
    _, _, free = flight(close)
    reach = np.max(free.run().q[..., 0])  # how far the law takes the drones along x
    wall = reach - 0.05
    config = FlightConfig(fence=Fence(bounds=(-2, wall, -2, 2, 0, 2), margin=0.2), duration=15.0)
    _, fleet, f = flight(close, config)
    result = f.run()
    assert result.landing in (Landing.REACHED, Landing.DURATION)
    assert wall - 0.2 < np.max(result.q[..., 0]) <= wall
    assert_all_landed(fleet)


def test_the_duration_lands_every_drone():
    _, fleet, f = flight(config=FlightConfig(duration=1.5))
    result = f.run()
    assert result.landing is Landing.DURATION
    assert result.landed_at - CONFIG.take_off_time == pytest.approx(1.5, abs=1e-9)
    assert_all_landed(fleet)


def test_robots_in_contact_land():
    _, fleet, f = flight()

    def bump() -> None:  # robot 3 knocked onto robot 1
        fleet.x[2, :2] = fleet.x[0, :2] + [0.05, 0.0]

    fleet.at(3.0, bump)
    result = f.run()
    assert result.landing is Landing.CONTACT
    assert_all_landed(fleet)


def test_landing_reaches_every_drone_when_one_link_fails():
    _, fleet, f = flight(config=FlightConfig(duration=1.0))

    def broken(duration: float) -> None:
        raise ConnectionError("radio gone")

    fleet.drones[0].land = broken  # type: ignore[method-assign]
    result = f.run()
    assert result.landing is Landing.DURATION
    assert result.problems[0].startswith("robot 1 (sim://1): land failed: ConnectionError")
    assert_all_landed(fleet, skip=(0,))


def test_a_drone_that_cannot_start_stops_the_flight_before_take_off():
    _, fleet, f = flight()

    def broken(*args: object) -> None:
        raise TimeoutError("no answer")

    fleet.drones[1].start = broken  # type: ignore[method-assign]
    with pytest.raises(FlightError, match=r"robot 2 \(sim://2\): cannot start: no answer"):
        f.run()
    assert all("take-off" not in [c for _, c in d.log] for d in fleet.drones)
    assert [c for _, c in fleet.drones[0].log] == ["close"]  # the started one closed


def test_no_position_stops_the_flight_before_take_off():
    _, fleet, f = flight()
    fleet.drones[2].mute()
    with pytest.raises(FlightError, match=r"no position from robot 3 \(sim://3\)"):
        f.run()
    assert all("take-off" not in [c for _, c in d.log] for d in fleet.drones)


def test_a_start_outside_the_fence_is_refused():
    _, _, f = flight(config=FlightConfig(fence=Fence(bounds=(-1, 1, -2, 2, 0, 2))))
    with pytest.raises(FlightError, match=r"robot 1 \(sim://1\), robot 2 \(sim://2\): outside"):
        f.run()


@pytest.mark.parametrize(
    ("extra", "key"),
    [
        ("[sensing]\nnoise = 0.01\n", "sensing"),
        ("[faults]\nstop = [{ robot = 1, at = 1.0 }]\n", "faults"),
        ("[[obstacles]]\ncircle = { center = [5.0, 5.0], radius = 0.2 }\n", "obstacles"),
        ('[robots.model]\nname = "unicycle"\n', "robots.model"),
    ],
)
def test_scenario_parts_a_flight_cannot_honour_are_refused_by_name(extra, key):
    text = TRIANGLE + extra
    if key == "robots.model":
        text = TRIANGLE.replace("diameters = 0.2\n", 'diameters = 0.2\nmodel = "unicycle"\n')
    scenario = parse_scenario(text)
    fleet = SimulatedFleet(scenario.q0)
    with pytest.raises(ScenarioError, match=key.replace(".", r"\.")) as info:
        Flight(scenario, fleet.drones, clock=fleet.clock)
    assert "a flight cannot honour" in str(info.value) or "unicycle" in str(info.value)


def test_a_quadrotor_scenario_flies_with_a_warning_naming_what_is_replaced():
    text = TRIANGLE.replace("diameters = 0.2\n", 'diameters = 0.2\nmodel = "quadrotor"\n')
    scenario = parse_scenario(text)
    fleet = SimulatedFleet(scenario.q0)
    with pytest.warns(FlightWarning, match="time_constant and max_accel"):
        f = Flight(scenario, fleet.drones, clock=fleet.clock)
    assert f.max_speed == 0.3


def test_one_uri_per_robot():
    scenario = parse_scenario(TRIANGLE)
    with pytest.raises(ParameterError, match="2 URIs for the 3 robots"):
        fly(scenario, ["sim://1", "sim://2"])
    with pytest.raises(ParameterError, match="mixes"):
        fly(scenario, ["sim://1", "sim://2", "radio://0/80/2M/E7E7E7E703"])


# -- the cflib side of the seam ---------------------------------------------------------------


class RecordingLink:
    """A link that keeps what cflib sends (a connected Crazyflie's link, without a radio)."""

    needs_resending = False

    def __init__(self) -> None:
        self.sent: list = []

    def send_packet(self, pk) -> None:
        self.sent.append((pk.port, pk.channel, bytes(pk.data)))


@pytest.fixture
def crazyflie(monkeypatch):
    """A cflib ``Crazyflie`` on a recording link, with the position variables in its log TOC
    (as cflib parses them from the firmware's TOC items) and a current firmware's protocol."""
    from cflib.crazyflie import Crazyflie
    from cflib.crazyflie.log import LogTocElement
    from cflib.crazyflie.toc import Toc

    cf = Crazyflie()
    cf.link = RecordingLink()
    cf.log.toc = Toc()
    monkeypatch.setattr(cf.platform, "get_protocol_version", lambda: 10)
    for ident, name in enumerate("xyz"):
        item = (
            bytes([LogTocElement.get_id_from_cstring("float")])
            + f"stateEstimate\0{name}\0".encode()
        )
        cf.log.toc.add_element(LogTocElement(ident, item))

    class Sync:
        def __init__(self) -> None:
            self.cf, self.closed = cf, 0

        def close_link(self) -> None:
            self.closed += 1

    return Sync()


def test_the_cflib_drone_sends_the_packets_cflib_defines(crazyflie):
    from cflib.crazyflie.commander import TYPE_VELOCITY_WORLD
    from cflib.crazyflie.high_level_commander import HighLevelCommander as HL
    from cflib.crtp.crtpstack import CRTPPort

    from formationlab.robots.cflib_drone import CflibDrone

    drone = CflibDrone(crazyflie)
    link = crazyflie.cf.link
    drone.take_off(0.5, 2.0)
    drone.velocity([0.1, -0.2, 0.05])
    drone.land(2.5)
    drone.stop()
    (p0, _, d0), (p1, c1, d1), (p2, c2, d2), (p3, _, d3), (p4, _, d4) = link.sent
    assert p0 == CRTPPort.SETPOINT_HL
    assert struct.unpack("<BBff?f", d0) == (HL.COMMAND_TAKEOFF_2, 0, 0.5, 0.0, False, 2.0)
    assert (p1, c1) == (CRTPPort.COMMANDER_GENERIC, 0)
    kind, *v = struct.unpack("<Bffff", d1)
    assert kind == TYPE_VELOCITY_WORLD
    np.testing.assert_allclose(v, [0.1, -0.2, 0.05, 0.0], rtol=1e-7)  # (float32 on the wire)
    assert (p2, c2) == (CRTPPort.COMMANDER_GENERIC, 1)  # notify setpoint stop: meta channel
    assert struct.unpack("<BI", d2) == (0, 0)
    assert p3 == CRTPPort.SETPOINT_HL
    assert struct.unpack("<BBff?f", d3) == (HL.COMMAND_LAND_2, 0, 0.0, 0.0, False, 2.5)
    assert p4 == CRTPPort.SETPOINT_HL
    assert struct.unpack("<BB", d4) == (HL.COMMAND_STOP, 0)


def test_the_cflib_drone_reads_positions_and_lost_links_through_cflib(crazyflie):
    from formationlab.robots.cflib_drone import POSITION, CflibDrone

    drone = CflibDrone(crazyflie)
    got, lost = [], []
    drone.start(0.05, lambda x, y, z: got.append((x, y, z)), lost.append)
    config = drone.log_config
    assert [v.name for v in config.variables] == list(POSITION)
    assert config.period_in_ms == 50 and config.valid
    assert crazyflie.cf.link.sent[0][0] == 5  # the log block created on the logging port
    # a log packet's payload, decoded by cflib's own unpacking into the runner's callback
    config.unpack_log_data(struct.pack("<fff", 0.25, -1.5, 0.5), 1234)
    assert got == [(0.25, -1.5, 0.5)]
    crazyflie.cf.connection_lost.call("radio://0/80/2M/E7E7E7E701", "Too many packets lost")
    assert lost == ["Too many packets lost"]
    drone.close()
    assert crazyflie.closed == 1


def test_a_link_that_fails_while_flying_lands_every_drone():
    _, fleet, f = flight()
    velocity = fleet.drones[2].velocity

    def failing(v) -> None:
        if fleet.t > 3.0:
            raise OSError("USB error")
        velocity(v)

    fleet.drones[2].velocity = failing  # type: ignore[method-assign]
    result = f.run()
    assert result.landing is Landing.EXCEPTION and "USB error" in result.message
    assert_all_landed(fleet)


def test_the_setpoints_are_the_simulators_field_at_the_measured_positions():
    from formationlab.models.limits import limit_speed
    from formationlab.scenario import closed_loop

    scenario, _, f = flight(config=FlightConfig(duration=3.0))
    result = f.run()
    system = closed_loop(scenario)  # the scenario's own closed loop, as `run` builds it
    flying = np.flatnonzero(result.t >= CONFIG.take_off_time)
    assert flying.size >= 50
    for k in flying:
        q = result.q[k]
        u = system.rhs(q[:, :2], result.t[k] - CONFIG.take_off_time)
        climb = CONFIG.climb_gain * (CONFIG.height - q[:, 2])
        expected = limit_speed(np.column_stack([u, climb]), CONFIG.max_speed)
        np.testing.assert_allclose(result.v[k], expected, rtol=0, atol=1e-12)
