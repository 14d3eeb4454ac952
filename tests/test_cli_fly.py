"""The ``fly`` command on the simulated link: a dry run, its log, its exit statuses, and bad
input refused with one line."""

from __future__ import annotations

import csv
import gc
import warnings
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner, Result

import formationlab.robots as robots
from formationlab.cli import _load_commands, app
from formationlab.robots import FlightResult, Landing

_load_commands()
runner = CliRunner()
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "paper-simulation-1.toml"
SIM = "sim://1,sim://2,sim://3"


def invoke(*args: object) -> Result:
    return runner.invoke(app, ["fly", *(str(a) for a in args)], catch_exceptions=False)


def test_a_dry_run_reaches_the_formation_and_writes_its_log(tmp_path):
    log = tmp_path / "flight.csv"
    r = invoke(EXAMPLE, "--uris", SIM, "--fence", "-4,4,-4,4,0,2", "--log", log)
    assert r.exit_code == 0, r.output
    assert "landed: reached" in r.output
    with log.open() as f:
        rows = list(csv.DictReader(f))
    periods = int(r.stdout.split("; ")[1].split()[0])
    assert len(rows) == 3 * periods and {row["robot"] for row in rows} == {"1", "2", "3"}
    speeds = [np.hypot(float(w["vx"]), np.hypot(float(w["vy"]), float(w["vz"]))) for w in rows]
    assert max(speeds) <= 0.3 + 1e-5 and max(speeds) > 0.29  # (the limit held and was reached)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (("--uris", "sim://1,sim://2"), "2 URIs for the 3 robots"),
        (("--uris", SIM, "--fence", "-4,4,-4"), "--fence takes six numbers"),
        (("--uris", SIM, "--fence", "4,-4,-4,4,0,2"), "the fence's x range"),
        (("--uris", SIM), "outside the fence"),
        (("--uris", SIM, "--fence", "-4,4,-4,4,0,2", "--rate", "500"), "at most 100 Hz"),
        (("--uris", SIM, "--fence", "-4,4,-4,4,0,2", "--height", "2.5"), "flight heights"),
    ],
)
def test_bad_input_is_one_error_line(args, words):
    r = invoke(EXAMPLE, *args)
    assert r.exit_code == 2
    assert r.output.count("error:") == 1 and words in r.output, r.output
    assert "Traceback" not in r.output


def test_a_scenario_part_a_flight_cannot_honour_is_named(tmp_path):
    text = EXAMPLE.read_text() + "\n[[obstacles]]\ncircle = { center = [9.0, 9.0], radius = 0.2 }\n"
    path = tmp_path / "obstacle.toml"
    path.write_text(text)
    r = invoke(path, "--uris", SIM, "--fence", "-4,4,-4,4,0,2")
    assert r.exit_code == 2 and "obstacles" in r.output and "cannot honour" in r.output


@pytest.mark.parametrize(
    ("landing", "signal", "code"),
    [
        (Landing.DURATION, None, 0),
        (Landing.LINK_LOST, None, 1),
        (Landing.STALE, None, 1),
        (Landing.INTERRUPTED, 2, 130),
        (Landing.INTERRUPTED, 15, 143),
    ],
)
def test_the_exit_status_says_how_the_flight_ended(monkeypatch, landing, signal, code):
    def landed(scenario, uris, *, config=None) -> FlightResult:
        empty = np.zeros((0, 3, 3))
        return FlightResult(
            landing=landing, message="robot 2 (sim://2): link lost: test", landed_at=1.0,
            t=np.zeros(0), q=empty, v=empty, problems=("robot 1: stop failed: x",), signal=signal,
        )  # fmt: skip

    monkeypatch.setattr(robots, "fly", landed)
    r = invoke(EXAMPLE, "--uris", SIM)
    assert r.exit_code == code, r.output
    assert f"landed: {landing.value}" in r.output
    assert "warning: robot 1: stop failed: x" in r.output


def test_a_link_cflib_cannot_open_stops_the_command_before_take_off():
    import socket

    with socket.socket() as s:  # a port with nothing listening: cflib's TCP link is refused
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    uris = ",".join([f"tcp://127.0.0.1:{port}"] * 3)
    with warnings.catch_warnings():
        # cflib's TCP driver leaves its socket open when the connection is refused: collected
        # here, not in a later test
        warnings.simplefilter("ignore", ResourceWarning)
        r = invoke(EXAMPLE, "--uris", uris, "--fence", "-4,4,-4,4,0,2")
        code, output = r.exit_code, r.output
        del r
        gc.collect()
    assert code == 2
    assert "error: cannot open the links to tcp://127.0.0.1" in output
    assert "Connection refused" in output
    assert "Traceback" not in output and output.count("error:") == 1
    assert "cflib: Couldn't load link driver" in output  # (cflib's own lines, one each)
