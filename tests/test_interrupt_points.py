"""SIGINT and SIGTERM at points drawn at random (seeded) in a study and an equilibria search.

Each test starts ``formationlab`` as a subprocess and sends the signal drawn where the
program prints the line of the point drawn (it waits there for the signal, ``_paused``:
never a time, and no race with the program's next step on a loaded machine), then
checks: exit status ``128 +`` the signal (130, 143), a message that says what was kept,
no traceback, no temporary file and no half-written file (every file there reads whole).
Then ``--resume`` (interrupted again at a point drawn, then to the end) gives what an
uninterrupted command gives. Other points are tested in tests/test_cli_interrupt.py
(start-up, mid-run), tests/test_animate_interrupt.py (animation, the end of writing) and
tests/test_no_silent_loss.py (writing a run's results).
"""

from __future__ import annotations

import json
import random
import signal
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from _paused import interrupted
from _scenarios import triangle

#: the draws: which printed line each interruption waits for, and which signal it sends
DRAW = random.Random(40)
SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _interrupted(args: list[str], marker: str, sig: int) -> str:
    """Run the command, send ``sig`` where it prints a line holding ``marker`` (it waits
    there for the signal: ``_paused``); its output."""
    status, out = interrupted(args, marker, sig)
    assert status == 128 + sig, out
    assert "Traceback" not in out and "error:" not in out, out
    return out


def _no_temporary_files(folder: Path) -> None:
    hidden = [p for p in folder.rglob(".*") if p.name != ".formationlab.lock"]
    assert hidden == [], hidden


def _finish(args: list[str]) -> str:
    """Run the command to its end, in this process (no start-up to pay); its output."""
    from typer.testing import CliRunner

    from formationlab.cli import _load_commands, app

    _load_commands()
    done = CliRunner().invoke(app, args, catch_exceptions=False)
    assert done.exit_code == 0, done.output
    return done.output


@pytest.fixture(scope="module")
def scenario(tmp_path_factory) -> Path:
    """The paper's triangle: 96 trials in 12 chunks on the numpy driver, 80 random starts
    (3 blocks)."""
    path = tmp_path_factory.mktemp("scenario") / "tri.toml"
    path.write_text(
        triangle(
            "tri",
            "2.0",
            "[study]\ntrials = 96\nchunk_size = 8\nduration = 2.0\ndt = 1e-2\n"
            'backend = "numpy"\ninitial = { kind = "box", half_width = 3.0 }\n'
            'laws = ["distance"]\n'
            '[equilibria]\nstarts = 80\nduration = 5.0\nlaw = "distance"\n',
        )
    )
    return path


STUDY_POINTS = ["trials: 0 of 96 done", "trials: first chunk finished"]
RESUME_POINTS = ["resuming: ", "trials: "]


@pytest.mark.parametrize(
    ("point", "sig", "again", "sig2"),
    [
        (DRAW.choice(STUDY_POINTS), DRAW.choice(SIGNALS), DRAW.choice(RESUME_POINTS),
         DRAW.choice(SIGNALS))
    ],
)  # fmt: skip
def test_a_study_interrupted_and_resumed_at_drawn_points(
    tmp_path: Path, scenario: Path, point: str, sig: int, again: str, sig2: int
):
    out = tmp_path / "study"
    err = _interrupted(["study", str(scenario), "--out", str(out)], point, sig)
    assert "finished chunks are kept in" in err and "--resume to finish" in err
    assert not (out / "trials.parquet").exists() and not (out / "summary.json").exists()
    _no_temporary_files(out)
    for chunk in out.glob("chunks/*/g*-c*.parquet"):
        assert len(pd.read_parquet(chunk)) == 8  # whole chunks only
    err = _interrupted(["study", str(scenario), "--out", str(out), "--resume"], again, sig2)
    assert "finished chunks are kept in" in err
    _no_temporary_files(out)
    _finish(["study", str(scenario), "--out", str(out), "--resume"])
    whole = tmp_path / "whole"
    _finish(["study", str(scenario), "--out", str(whole)])
    assert (out / "trials.parquet").read_bytes() == (whole / "trials.parquet").read_bytes()


EQUILIBRIA_POINTS = [
    "equilibria: the scenario's run",
    "equilibria: the random starts",
    "random starts settled; Ctrl-C keeps",
]


@pytest.mark.parametrize(
    ("point", "sig"),
    [(DRAW.choice(EQUILIBRIA_POINTS), DRAW.choice(SIGNALS))],
)
def test_equilibria_interrupted_keeps_what_it_settled_and_resumes(
    tmp_path: Path, scenario: Path, point: str, sig: int
):
    from formationlab.io.equilibria import SettledFolder

    out = tmp_path / "eq"
    err = _interrupted(["equilibria", str(scenario), "--out", str(out)], point, sig)
    assert "settled random starts are kept in" in err and "--resume to finish" in err
    assert not (out / "equilibria.json").exists()
    _no_temporary_files(out)
    kept = 0
    for block in out.glob("settled/*/block-*.npz"):  # whole blocks only
        with np.load(block) as f:
            m = len(f["outcome"])
            assert f["q"].shape == (m, 3, 2) and m in (32, 80 - 64)
        kept += m
    said = int(err.split(" settled random starts are kept")[0].split()[-1].replace(",", ""))
    assert said == kept
    if point.startswith("random starts settled"):
        assert kept >= 32
    err = _finish(["equilibria", str(scenario), "--out", str(out), "--resume"])
    assert f"resuming: {kept:,} settled starts kept" in err
    assert not (out / "settled").exists()  # the search has ended: its blocks are let go
    whole = tmp_path / "whole"
    _finish(["equilibria", str(scenario), "--out", str(whole)])
    a = json.loads((out / "equilibria.json").read_text())
    b = json.loads((whole / "equilibria.json").read_text())
    assert [e["count"] for e in a["equilibria"]] == [e["count"] for e in b["equilibria"]]
    assert sorted(a["files"]) == sorted(b["files"]) and "gallery.png" in a["files"]
    assert SettledFolder(out, {}).settled() == 0


def test_resume_of_a_search_that_kept_nothing_here_is_refused(tmp_path: Path, scenario: Path):
    from typer.testing import CliRunner

    from formationlab.cli import _load_commands, app

    _load_commands()
    out = tmp_path / "eq"
    args = ["equilibria", str(scenario), "--out", str(out), "--resume"]
    done = CliRunner().invoke(app, args)
    assert done.exit_code == 2
    said = " ".join(done.output.split())
    assert f"nothing to resume: {out} does not exist; run without --resume" in said
    out.mkdir()  # a folder without settled starts of this search
    done = CliRunner().invoke(app, args)
    assert done.exit_code == 2
    assert "holds no settled starts; run without --resume" in " ".join(done.output.split())


RUN_POINTS = ["writing trajectory.nc (", "drawing the figures ..."]


@pytest.mark.parametrize(("point", "sig"), [(DRAW.choice(RUN_POINTS), DRAW.choice(SIGNALS))])
def test_a_run_interrupted_while_saving_or_drawing_keeps_its_results_whole(
    tmp_path: Path, point: str, sig: int
):
    import xarray as xr

    scenario = tmp_path / "s.toml"
    # 340,001 saved states of 3 robots: above the size at which `run` says what it writes
    scenario.write_text(triangle("big", "340.0"))
    out = tmp_path / "out"
    err = _interrupted(["run", str(scenario), "--out", str(out)], point, sig)
    said = [s for s in err.splitlines() if s.startswith("interrupted")]
    if point.startswith("writing"):  # the results are written whole first, then it stops
        assert said == [
            f"interrupted while writing the results; they were written whole first: {out} "
            "holds scenario.toml, trajectory.nc, summary.json (no figures)"
        ]
    else:
        assert said == [f"interrupted while drawing the figures; the run's results are in {out}"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "success" and summary["final_time"] == 340.0
    with xr.open_dataset(out / "trajectory.nc", engine="h5netcdf") as ds:
        assert ds.sizes["time"] == 340_001
    names = {p.name for p in out.iterdir()} - {".formationlab.lock"}
    assert names == set(summary["manifest"])  # every file listed, none half-written
    _no_temporary_files(out)
