"""The ``run``, ``validate`` and ``animate`` commands: files written, and bad input refused.

Every bad input must give exit status 2, a one-line ``error:`` message that
names the problem, no traceback, and leave the output folder as it was.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from _scenarios import triangle
from typer.testing import CliRunner, Result

import formationlab as fl
from formationlab.cli import _load_commands, app
from formationlab.io.netcdf import write_trajectory
from formationlab.scenario import parse_scenario

_load_commands()
runner = CliRunner()

ALPHA = "alpha = [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]]"
SCENARIO = triangle("short-triangle", "0.5")


def invoke(*args: object) -> Result:
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """One short run of the paper's simulation 2 (0.5 s), stored every 10 steps."""
    root = tmp_path_factory.mktemp("run")
    scenario = root / "short.toml"
    scenario.write_text(SCENARIO)
    out = root / "out"
    res = invoke("run", scenario, "--out", out, "--save-every", 10, "--quiet")
    assert res.exit_code == 0, res.output
    return scenario, out


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())} if folder.exists() else {}


# ---------------------------------------------------------------- what run writes


def test_run_writes_netcdf_summary_and_plots(finished_run: tuple[Path, Path]) -> None:
    scenario, out = finished_run
    names = {p.name for p in out.iterdir()}
    assert {"trajectory.nc", "summary.json", "scenario.toml"} <= names
    assert {
        "trajectories.png",
        "controls_x.png",
        "controls_y.png",
        "lyapunov.png",
        "distance_errors.png",
    } <= names
    assert not [n for n in names if n.startswith(".")], "temporary files left behind"
    assert (out / "scenario.toml").read_text() == scenario.read_text()


def test_netcdf_layout_and_values(finished_run: tuple[Path, Path]) -> None:
    scenario, out = finished_run
    with xr.open_dataset(out / "trajectory.nc", engine="h5netcdf") as ds:
        assert ds["q"].dims == ("time", "robot", "axis")
        assert ds["u"].dims == ("time", "robot", "axis")
        assert ds["V"].dims == ("time",)
        assert ds["sigma"].dims == ("time", "surface")
        assert ds["robot"].values.tolist() == [1, 2, 3]
        assert ds["axis"].values.tolist() == ["x", "y"]
        assert ds["time"].attrs["units"] == "s"
        assert ds.attrs["scenario"] == scenario.read_text()
        assert ds.attrs["formationlab_version"] == fl.__version__
        assert json.loads(ds.attrs["law"])["k_a"] == 3.0
        assert json.loads(ds.attrs["integrator"]) == {"name": "euler", "dt": 1e-3}
        # --save-every 10 with dt = 1e-3 over 0.5 s: 50 stored steps plus t = 0
        np.testing.assert_allclose(ds["time"].values, np.arange(51) * 0.01, atol=1e-12)
        q = ds["q"].values
        u = ds["u"].values
    # what is stored is what a full-resolution run computes at those times
    sc = parse_scenario(SCENARIO)
    ref = fl.simulate(sc.formation, sc.law, sc.q0, duration=0.5, integrator=sc.integrator)
    np.testing.assert_allclose(q, ref.q[::10], rtol=0, atol=1e-12)
    np.testing.assert_allclose(u, ref.u[::10], rtol=0, atol=1e-9)


def test_summary_has_the_issue_keys(finished_run: tuple[Path, Path]) -> None:
    _, out = finished_run
    s = json.loads((out / "summary.json").read_text())
    for key in ("outcome", "final_positions", "distance_errors", "max_distance_error"):
        assert key in s
    assert "converged_time" in s  # null when not converged
    assert s["outcome"] in fl.OUTCOMES
    assert s["scenario"] == "short-triangle"
    assert set(s["distance_errors"]) == {"1-2", "1-3", "2-3"}
    assert s["diagnostics"]["steps"] == 500  # all steps computed, 1 in 10 stored
    text = (out / "summary.json").read_text()
    # counts as integers; one evaluation more than steps: the velocity at the final state
    assert '"steps": 500,' in text and '"rhs_evaluations": 501,' in text
    assert isinstance(s["diagnostics"]["switch_count"], int)
    assert isinstance(s["diagnostics"]["wall_time_s"], float)
    q = np.array(s["final_positions"])
    r12 = np.linalg.norm(q[1] - q[0])
    assert s["distance_errors"]["1-2"] == pytest.approx(r12 - 1.0)
    assert s["max_distance_error"] == pytest.approx(max(map(abs, s["distance_errors"].values())))


def test_second_run_into_the_same_folder_is_refused_and_nothing_changes(
    finished_run: tuple[Path, Path],
) -> None:
    scenario, out = finished_run
    before = snapshot(out)
    res = invoke("run", scenario, "--out", out)
    assert res.exit_code == 2
    assert "--force" in res.stderr and "summary.json" in res.stderr
    assert "Traceback" not in res.output
    assert snapshot(out) == before


def test_force_replaces_the_files(tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO.replace("duration = 0.5", "duration = 0.1"))
    out = tmp_path / "out"
    assert invoke("run", scenario, "--out", out, "-q").exit_code == 0
    scenario.write_text(SCENARIO.replace("duration = 0.5", "duration = 0.2"))
    assert invoke("run", scenario, "--out", out, "-q", "--force").exit_code == 0
    assert json.loads((out / "summary.json").read_text())["final_time"] == pytest.approx(0.2)


def test_animate_writes_gif_mp4_and_a_self_contained_html(
    finished_run: tuple[Path, Path], tmp_path: Path
) -> None:
    from PIL import Image

    _, out = finished_run
    res = invoke("animate", out, "--frames", 4)
    assert res.exit_code == 0, res.output
    with Image.open(out / "animation.gif") as gif:
        assert getattr(gif, "n_frames", 1) == 4
    mp4 = (out / "animation.mp4").read_bytes()
    assert mp4[4:8] == b"ftyp"  # an MP4 container
    html = (out / "animation.html").read_text()
    # a run in the plane: the page draws the states itself, no embedded images
    assert "<html>" in html and "<canvas" in html and "data:image/png" not in html
    assert "http://" not in html and "https://" not in html  # works offline
    before = snapshot(out)
    again = invoke("animate", out, "--frames", 4)
    assert again.exit_code == 2 and "--force" in again.stderr
    assert snapshot(out) == before
    for p in out.glob("animation.*"):
        p.unlink()


def test_animate_needs_a_run_folder(tmp_path: Path) -> None:
    res = invoke("animate", tmp_path)
    assert res.exit_code == 2 and "no trajectory.nc" in res.stderr
    res = invoke("animate", tmp_path / "missing")
    assert res.exit_code == 2 and "not a folder" in res.stderr


def test_validate_reports_each_file(tmp_path: Path) -> None:
    good = tmp_path / "good.toml"
    good.write_text(SCENARIO)
    bad = tmp_path / "bad.toml"
    bad.write_text(SCENARIO.replace("k_c = 2.0", "kc = 2.0"))
    res = invoke("validate", good)
    assert res.exit_code == 0 and "ok:" in res.stdout and "3 robots" in res.stdout
    res = invoke("validate", good, bad)
    assert res.exit_code == 2
    assert "ok:" in res.stdout and "Did you mean 'k_c'" in res.stderr


def test_version_is_printed() -> None:
    res = invoke("--version")
    assert res.exit_code == 0 and res.output == f"formationlab {fl.__version__}\n"


@pytest.mark.parametrize("command", ["run", "validate", "animate"])
def test_help_has_an_example(command: str) -> None:
    res = invoke(command, "--help")
    assert res.exit_code == 0
    assert "Example" in res.stdout and "formationlab " + command in res.stdout


# ---------------------------------------------------------------- bad input through the CLI

BAD = {
    "toml syntax error": (("k_c = 2.0", "k_c = = 2.0"), "TOML syntax error"),
    "unknown key": (("distances = 1.0", "distnces = 1.0"), "did you mean 'distances'"),
    "wrong type": (("theta = 0.5", 'theta = "half"'), "expected a number"),
    "wrong shape": (("[0.0, 3.0]]", "[0.0]]"), "pair [x, y]"),
    "positions and diameters differ": (
        ("diameters = 0.2", "diameters = [0.2, 0.2]"),
        "3 positions but 2",
    ),
    "nan": (("[0.0, 3.0]]", "[nan, 3.0]]"), "finite"),
    "infinite": (("duration = 0.5", "duration = inf"), "finite"),
    "d_ij <= a_ij": (("diameters = 0.2", "diameters = 1.2"), "must exceed the contact distance"),
    "overlap at start": (("[0.0, 3.0]]", "[-2.9, -3.0]]"), "overlap"),
    "edge to missing robot": (
        ('edges = "complete"', "edges = [[1, 2], [2, 3], [1, 5]]"),
        "robot 5",
    ),
    "edge to itself": (('edges = "complete"', "edges = [[1, 2], [2, 3], [3, 3]]"), "to itself"),
    "duplicate edge": (('edges = "complete"', "edges = [[1, 2], [2, 3], [2, 1]]"), "given twice"),
    "orientation without template": (
        ('orientation = "table"', 'orientation = "mirror"'),
        "needs a template",
    ),
    "table without alpha": (
        ("alpha = [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]]", ""),
        "needs formation.alpha",
    ),
    "collinear template": (
        (
            f'distances = 1.0\norientation = "table"\n{ALPHA}',
            "template = [[0, 0], [0, 1], [0, 2]]",
        ),
        "collinear",
    ),
    "disconnected graph": (
        (
            f'edges = "complete"\ndistances = 1.0\norientation = "table"\n{ALPHA}',
            "edges = [[1, 2]]",
        ),
        "not connected",
    ),
    "dt not positive": (("dt = 1e-3", "dt = 0.0"), "dt must be a finite number > 0"),
    "duration not positive": (("duration = 0.5", "duration = -1.0"), "must be > 0, got -1.0"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_scenario_exits_2_with_one_clear_line_and_writes_nothing(
    case: str, tmp_path: Path
) -> None:
    (old, new), fragment = BAD[case]
    assert old in SCENARIO, "the test's edit must apply"
    path = tmp_path / "bad.toml"
    path.write_text(SCENARIO.replace(old, new, 1))
    out = tmp_path / "out"
    res = invoke("run", path, "--out", out)
    assert res.exit_code == 2
    assert res.stderr.startswith("error: ")
    assert fragment in res.stderr
    assert res.stderr.count("\n") == 1, res.stderr  # one line
    assert "Traceback" not in res.output
    assert not out.exists()


def test_missing_scenario_file(tmp_path: Path) -> None:
    res = invoke("run", tmp_path / "nope.toml", "--out", tmp_path / "out")
    assert res.exit_code == 2 and "does not exist" in res.stderr
    assert not (tmp_path / "out").exists()


def test_a_run_that_stops_early_writes_its_results_and_exits_1(tmp_path: Path) -> None:
    # dt = 1 s: an Euler step carries two robots through each other, a step the integrator
    # refuses (the exact flow cannot touch: phi_ij is infinite at contact)
    path = tmp_path / "coarse.toml"
    path.write_text(
        SCENARIO.replace("dt = 1e-3", "dt = 1.0").replace("duration = 0.5", "duration = 3.0")
    )
    out = tmp_path / "out"
    res = invoke("run", path, "--out", out, "-q")
    assert res.exit_code == 1
    assert "stopped early" in res.stderr and "reduce dt" in res.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "step-too-large" and s["outcome"] == "collision"
    assert "pass through each other" in s["message"]
    with xr.open_dataset(out / "trajectory.nc", engine="h5netcdf") as ds:
        assert ds.attrs["status"] == "step-too-large"


def test_output_folder_that_is_a_file_is_refused(tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO)
    target = tmp_path / "file"
    target.write_text("keep me")
    res = invoke("run", scenario, "--out", target)
    assert res.exit_code == 2 and "is a file" in res.stderr
    assert target.read_text() == "keep me"


def test_non_rigid_graph_warns_and_runs(tmp_path: Path) -> None:
    text = (
        SCENARIO.replace(
            "positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]",
            "positions = [[0.0, 0.0], [1.5, 0.0], [1.5, 1.5], [0.0, 1.5]]",
        )
        .replace('edges = "complete"', "edges = [[1, 2], [2, 3], [3, 4], [4, 1]]")
        .replace('orientation = "table"\n', "")
        .replace("alpha = [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]]\n", "")
        .replace('law = "angle-restricted"', 'law = "distance"')
        .replace("k_a = 3.0\ntheta = 0.5\n", "")
    )
    path = tmp_path / "ring.toml"
    path.write_text(text)
    res = invoke("run", path, "--out", tmp_path / "out", "-q")
    assert res.exit_code == 0, res.output
    assert "warning:" in res.stderr and "not rigid" in res.stderr
    with xr.open_dataset(tmp_path / "out" / "trajectory.nc", engine="h5netcdf") as ds:
        assert "sigma" not in ds  # the distance law has no switching surfaces
        assert ds["edge"].values.tolist() == ["1-2", "1-4", "2-3", "3-4"]


def test_a_failed_write_leaves_the_previous_file_intact(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sc = parse_scenario(SCENARIO.replace("duration = 0.5", "duration = 0.01"))
    res = fl.simulate(sc.formation, sc.law, sc.q0, duration=sc.duration)
    target = tmp_path / "trajectory.nc"
    target.write_bytes(b"previous results")

    write_bytes = Path.write_bytes

    def broken(self, data):  # (the netCDF is composed in memory, then written as bytes)
        write_bytes(self, bytes(data)[:100])
        raise OSError("disk full")

    monkeypatch.setattr(Path, "write_bytes", broken)
    with pytest.raises(OSError, match=f"cannot write trajectory.nc in {tmp_path}: disk full"):
        write_trajectory(res, target)
    assert target.read_bytes() == b"previous results"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["trajectory.nc"]


@pytest.mark.parametrize("name", ["square-with-diagonals", "hexagon", "ten-robots"])
def test_examples_run_through_the_cli(name: str, tmp_path: Path) -> None:
    """The README's examples run (shortened to 0.05 s; the paper's two are run above and in
    test_scenario.py)."""
    path = Path(__file__).resolve().parents[1] / "examples" / f"{name}.toml"
    raw = tomllib.loads(path.read_text())
    duration = raw["simulation"]["duration"]
    short = tmp_path / path.name
    short.write_text(path.read_text().replace(f"duration = {duration}", "duration = 0.05"))
    res = invoke("run", short, "--out", tmp_path / "out", "-q")
    assert res.exit_code == 0, res.output
    with xr.open_dataset(tmp_path / "out" / "trajectory.nc", engine="h5netcdf") as ds:
        assert ds.sizes["robot"] == len(raw["robots"]["positions"])
        n, edges = ds.sizes["robot"], raw["formation"]["edges"]
        assert ds.sizes["edge"] == (n * (n - 1) // 2 if edges == "complete" else len(edges))


def test_animation_frames_are_bounded_evenly_spaced_and_keep_both_ends() -> None:
    from formationlab.plotting.animation import frame_indices

    t = np.linspace(0.0, 60.0, 60_001)
    idx = frame_indices(t, 150)
    assert len(idx) == 150 and idx[0] == 0 and idx[-1] == len(t) - 1
    np.testing.assert_allclose(np.diff(t[idx]), 60.0 / 149, atol=1e-3 + 1e-12)
    short = np.arange(10.0)
    np.testing.assert_array_equal(frame_indices(short, 150), np.arange(10))
