"""No silent loss of results: one writer per folder, Ctrl-C while writing, a full disk.

The processes are real (``formationlab`` started as a shell starts it) and the tests
synchronise on what they print, not on the clock.
"""

from __future__ import annotations

import fcntl
import json
import os
import resource
import signal
import subprocess
from pathlib import Path

import pytest
import xarray as xr
from _scenarios import triangle
from test_cli_interrupt import CLI, _read_until, start
from typer.testing import CliRunner

from formationlab.cli import _load_commands, app
from formationlab.io.claim import LOCK_NAME

_load_commands()
runner = CliRunner()


def invoke(*args: object):
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


def error_lines(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln.startswith("error:")]


def test_a_second_writer_is_refused_and_the_first_keeps_its_files(tmp_path: Path) -> None:
    scenario = tmp_path / "long.toml"
    # RK4 on the stepping driver: minutes, until the signal below
    scenario.write_text(triangle("long", "1000.0").replace('"euler"', '"rk4"'))
    out = tmp_path / "out"
    first = start(["run", str(scenario), "--out", str(out)], group=False)
    seen = _read_until(first, "running (at t = ")  # the folder is claimed and being written
    holder = json.loads((out / LOCK_NAME).read_text())
    assert holder["pid"] == first.pid
    for force in ([], ["--force"]):  # --force replaces a finished run's files, not a running one's
        res = invoke("run", scenario, "--out", out, "-q", *force)
        assert res.exit_code == 2
        assert "Traceback" not in res.output
        (line,) = error_lines(res.stderr)
        assert line.startswith(f"error: {out} is being written by process {first.pid} on ")
        assert "formationlab run" in line and "choose another --out" in line
    first.send_signal(signal.SIGINT)
    _, rest = first.communicate(timeout=120)
    assert first.returncode == 130, "".join(seen) + rest
    summary = json.loads((out / "summary.json").read_text())  # the first run's, whole
    assert summary["status"] == "interrupted" and summary["source"] == str(scenario)
    with xr.open_dataset(out / "trajectory.nc", engine="h5netcdf") as ds:
        assert float(ds["time"][-1]) == pytest.approx(summary["final_time"], abs=0)
    assert {p.name for p in out.iterdir()} == set(summary["manifest"])  # no lock left


def test_a_dead_writers_lock_is_taken_over_and_force_removes_its_temporary_files(
    tmp_path: Path,
) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(triangle("short", "0.05"))
    out = tmp_path / "out"
    out.mkdir()
    # what a writer killed with SIGKILL leaves: its lock file (unlocked: the kernel freed the
    # lock with the process) and the temporary file it was writing
    dead = {"pid": 2**22 + 1, "host": "somewhere", "started": "2026-01-01T00:00:00+0000"}
    (out / LOCK_NAME).write_text(json.dumps(dead))
    partial = out / ".trajectory.nc.0123abcd.nc"
    partial.write_bytes(b"\x89HDF\r\n" + bytes(100))
    mine = out / ".notes.txt"  # a hidden file of the user's: not a temporary file of ours
    mine.write_text("keep")
    res = invoke("run", scenario, "--out", out, "-q")
    assert res.exit_code == 2 and "is not empty" in error_lines(res.stderr)[0]
    assert partial.exists() and not (out / LOCK_NAME).exists()  # nothing removed unasked
    (out / LOCK_NAME).write_text(json.dumps(dead))
    res = invoke("run", scenario, "--out", out, "-q", "--force")
    assert res.exit_code == 0, res.output
    assert (
        f"warning: {out} was claimed by process {2**22 + 1} on somewhere (since "
        "2026-01-01T00:00:00+0000), which no longer runs" in res.stderr
    )
    names = {p.name for p in out.iterdir()}
    assert names == {*json.loads((out / "summary.json").read_text())["manifest"], ".notes.txt"}
    assert mine.read_text() == "keep"


def test_ctrl_c_while_writing_keeps_the_finished_run_and_says_so(tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    # 340,001 saved states of 3 robots: above the size at which `run` says it is writing
    scenario.write_text(triangle("writing", "340.0"))
    out = tmp_path / "out"
    proc = start(["run", str(scenario), "--out", str(out)], group=False)
    seen = _read_until(proc, "writing trajectory.nc (340,001 saved states")
    proc.send_signal(signal.SIGINT)
    _, rest = proc.communicate(timeout=120)
    err = "".join(seen) + rest
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "Exception ignored" not in err
    assert not error_lines(err)  # a deliberate stop is not an error
    said = [s for s in err.splitlines() if s.startswith("interrupted")]
    assert said == [
        f"interrupted while writing the results; they were written whole first: {out} "
        "holds scenario.toml, trajectory.nc, summary.json (no figures)"
    ]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "success" and summary["final_time"] == pytest.approx(340.0)
    with xr.open_dataset(out / "trajectory.nc", engine="h5netcdf") as ds:
        assert ds.sizes["time"] == 340_001 and float(ds["time"][-1]) == pytest.approx(340.0)
        assert ds["q"][-1].values.shape == (3, 2)
    assert {p.name for p in out.iterdir()} == set(summary["manifest"])


def test_a_full_disk_is_one_error_line(tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(triangle("full", "20.0"))
    whole = tmp_path / "whole"
    assert invoke("run", scenario, "--out", whole, "-q").exit_code == 0  # (kernels cached)
    size = (whole / "trajectory.nc").stat().st_size
    out = tmp_path / "out"
    out.mkdir()
    (out / "trajectory.nc").write_bytes(b"an earlier run's")  # replaced whole or not at all
    limit = size // 2  # scenario.toml fits, trajectory.nc does not

    def file_size_limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    proc = subprocess.run(
        [*CLI, "run", str(scenario), "--out", str(out), "--force"],
        capture_output=True, text=True, timeout=300, preexec_fn=file_size_limit,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr  # (a crash was -11)
    assert "Traceback" not in proc.stderr and "HDF5" not in proc.stderr
    (line,) = error_lines(proc.stderr)
    assert line.startswith(f"error: cannot write trajectory.nc in {out}: file too large; ")
    assert len(proc.stderr.strip().splitlines()) == 2  # the plan's line and the error
    assert (out / "trajectory.nc").read_bytes() == b"an earlier run's"
    assert sorted(p.name for p in out.iterdir()) == ["scenario.toml", "trajectory.nc"]
    assert not list(tmp_path.glob("core*")) and not list(out.glob("core*"))


@pytest.mark.parametrize("command", ["run", "study", "study --resume", "equilibria", "paper",
                                     "animate"])  # fmt: skip
def test_every_writing_command_is_refused_a_claimed_folder(command: str, tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    study = '[study]\ntrials = 4\nchunk_size = 4\ninitial = { kind = "box", half_width = 3.0 }\n'
    scenario.write_text(triangle("claimed", "0.05", study))
    out = tmp_path / "out"
    if command == "animate":
        assert invoke("run", scenario, "--out", out, "-q").exit_code == 0
    else:
        out.mkdir()
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    # another process's claim: the lock file locked through a descriptor of its own (a lock
    # of another open file conflicts within one process as between two)
    holder = {"pid": 4242, "host": "elsewhere", "started": "2026-01-01T00:00:00+0000"}
    (out / LOCK_NAME).write_text(json.dumps(holder))
    fd = os.open(out / LOCK_NAME, os.O_RDWR)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    try:
        args = {
            "run": ("run", scenario, "--out", out, "--force"),
            "study": ("study", scenario, "--out", out, "--force"),
            "study --resume": ("study", scenario, "--out", out, "--resume"),
            "equilibria": ("equilibria", scenario, "--out", out, "--starts", 2, "--force"),
            "paper": ("paper", "--out", out, "--force"),
            "animate": ("animate", out, "--force", "--format", "html"),
        }[command]
        res = invoke(*args)
    finally:
        os.close(fd)
    assert res.exit_code == 2, res.output
    (line,) = error_lines(res.stderr)
    assert line == (
        f"error: {out} is being written by process 4242 on elsewhere (since "
        "2026-01-01T00:00:00+0000); wait for it to end, or choose another --out"
    )
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.name != LOCK_NAME}
    assert after == before  # nothing written, nothing removed
