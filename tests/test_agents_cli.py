"""Robots as agents through the command line: [sensing], [faults] and [asynchronous] in
`validate`, `run`, `animate` and `study`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import xarray as xr
from _scenarios import triangle
from typer.testing import CliRunner

from formationlab.cli import _load_commands, app

_load_commands()
CLI = CliRunner()

AGENTS = """\
[sensing]
frames = "local"
noise = 0.005
delay = 0.002
drop = 0.1
mismatch = 0.01
seed = 2
[faults]
stop = [{ robot = 3, at = 0.3 }]
"""


def invoke(*args: object) -> object:
    return CLI.invoke(app, [str(a) for a in args])


@pytest.mark.slow
def test_run_writes_what_the_robots_sensed_and_the_stop(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text(triangle("sensed", "0.6", AGENTS))
    check = invoke("validate", path)
    assert check.exit_code == 0, check.output
    assert "sensing (frames local, noise 0.005, delay 0.002, drop 0.1, mismatch 0.01, seed 2)" in (
        check.output
    )
    assert "faults (robot 3 stops at 0.3 s)" in check.output
    res = invoke("run", path, "--out", tmp_path / "out", "--animate", "--frames", "4")
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["sensing"]["frames"] == "local" and summary["sensing"]["seed"] == 2
    assert set(summary["sensing"]["own_distances"]) == {"1-2", "1-3", "2-3"}
    assert summary["faults"] == {"stop": [{"robot": 3, "at": 0.3}]}
    with xr.open_dataset(tmp_path / "out" / "trajectory.nc") as ds:
        assert json.loads(ds.attrs["sensing"])["noise"] == 0.005
        q = ds["q"].values
        t = ds["time"].values
    stopped = t >= 0.3
    assert (q[stopped, 2] == q[stopped][0, 2]).all()  # robot 3 stays where it stopped
    assert (tmp_path / "out" / "animation.gif").stat().st_size > 0
    again = invoke("animate", tmp_path / "out", "--format", "gif", "--force")
    assert again.exit_code == 0, again.output


def test_an_asynchronous_run_says_how_often_each_robot_updated(tmp_path: Path) -> None:
    path = tmp_path / "a.toml"
    extra = "[asynchronous]\nperiods = [0.001, 0.002, 0.004]\njitter = 0.2\n"
    path.write_text(triangle("async", "0.2", extra))
    res = invoke("run", path, "--out", tmp_path / "out")
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["asynchronous"]["periods"] == [0.001, 0.002, 0.004]
    updates = summary["asynchronous"]["updates"]
    assert updates[0] > updates[1] > updates[2] > 0  # robot 1 updates most often


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        ("[asynchronous]\nperiods = [0.001, 0.002]\n", "one number or one per robot (3 robots"),
        ("[asynchronous]\njitter = 1.0\n", "jitter is a fraction of each period in [0, 1)"),
        ("[asynchronous]\nperiods = -1.0\n", "robot 1"),
        (
            "[asynchronous]\n[[obstacles]]\ncircle = { center = [0.0, 0.0], radius = 0.2 }\n",
            "does not take [[obstacles]]",
        ),
    ],
)
def test_bad_asynchronous_tables_are_one_line(tmp_path: Path, extra: str, words: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(triangle("bad", "0.2", extra))
    res = invoke("run", path, "--out", tmp_path / "out")
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    assert words in " ".join(res.output.split())
    assert not (tmp_path / "out").exists()


def test_a_study_sweeps_a_fault_given_on_the_command_line(tmp_path: Path) -> None:
    path = tmp_path / "st.toml"
    extra = (
        '[sensing]\nframes = "local"\n[faults]\nstop = [{ robot = 2, at = inf }]\n'
        '[study]\ntrials = 4\nlaws = ["distance"]\ndt = 0.01\n'
    )
    path.write_text(triangle("st", "2.0", extra))
    out = tmp_path / "out"
    res = invoke(
        "study", path, "--out", out, "--sweep", "mismatch=0,0.05", "--sweep", "stop_at=0.5"
    )
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    points = [g["parameters"] for g in summary["groups"]]
    assert points == [{"mismatch": 0.0, "stop_at": 0.5}, {"mismatch": 0.05, "stop_at": 0.5}]
    assert all(g["faults"]["stop"] == [{"robot": 2, "at": 0.5}] for g in summary["groups"])
    assert all(g["shape_error"]["median"] >= 0 for g in summary["groups"])
    assert list(out.glob("shape_error*.png"))
    bad = invoke("study", path, "--out", tmp_path / "o2", "--sweep", "noise")
    assert bad.exit_code != 0 and "KEY=V1,V2" in bad.output
