"""What ``run`` and ``animate`` write for many robots: compressed netCDF equal to the run,
the per-edge table above the list limit, figures of bounded size, 10,000 robots animated."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr
from _scenarios import lattice as lattice_text
from PIL import Image
from typer.testing import CliRunner, Result

import formationlab as fl
from formationlab.cli import _load_commands, app
from formationlab.io.edges import EDGE_TABLE, read_edge_table
from formationlab.io.figures import save_figure
from formationlab.io.netcdf import COMPRESSION, load_trajectory, write_trajectory
from formationlab.plotting.animation import frame_indices, path_indices, used_indices
from formationlab.plotting.runs import run_figures
from formationlab.simulation import run as simulation

_load_commands()
runner = CliRunner()


def invoke(*args: object) -> Result:
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


def lattice(tmp: Path, n: int, *, law: str = "distance", duration: float = 0.01) -> Path:
    path = tmp / f"lattice-{n}.toml"
    path.write_text(lattice_text(n, law=law, duration=duration))
    return path


@pytest.fixture(scope="module")
def run_200(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, fl.SimulationResult]:
    """200 robots, angle-restricted (549 edges, 1,363 surfaces): the CLI's folder and the run."""
    from formationlab.io.scenario import load_scenario

    root = tmp_path_factory.mktemp("run200")
    scenario = lattice(root, 200, law="angle-restricted", duration=0.05)
    out = root / "out"
    res = invoke("run", scenario, "--out", out, "--save-every", 5, "-q")
    assert res.exit_code == 0, res.output
    sc = load_scenario(scenario)
    result = fl.simulate(
        sc.formation, sc.law, sc.x0, duration=sc.duration, integrator=sc.integrator, save_every=5
    )
    return out, result


def test_trajectory_nc_is_compressed_chunked_and_equal_to_the_run(run_200) -> None:
    out, res = run_200
    with h5py.File(out / "trajectory.nc") as f:
        for name in ("q", "u", "V", "sigma", "distance_error", "edge", "surface"):
            assert f[name].compression == "gzip", name
            assert f[name].compression_opts == COMPRESSION and f[name].shuffle, name
        assert f["q"].chunks == (len(res.t), 200, 2)  # whole states: 11 of 3.2 kB in 1 MB
    ds = load_trajectory(out / "trajectory.nc")
    np.testing.assert_array_equal(ds["time"].values, res.t)
    for name, value in (("q", res.q), ("u", res.u), ("V", res.V), ("sigma", res.sigma)):
        np.testing.assert_array_equal(ds[name].values, value, err_msg=name)
    np.testing.assert_array_equal(ds["distance_error"].values, res.distance_errors)
    assert ds["edge"].values.tolist() == res.edge_labels  # labels read back as strings
    assert ds["surface"].values.tolist() == res.restriction_labels
    assert int(ds.attrs["save_every"]) == 5 and len(ds["time"]) == 11  # 0, 5, ..., 50


def test_a_long_state_is_split_into_chunks_of_about_a_megabyte(tmp_path: Path) -> None:
    from formationlab.io import netcdf

    n = 3
    f = fl.Formation.from_distances(n, distances=1.0, diameters=0.2)
    res = fl.simulate(f, "distance", [[-3, -3], [3, -3], [0, 3]], duration=0.01)
    ds = netcdf.trajectory_dataset(res)
    enc = netcdf.encoding(ds)
    assert enc["q"]["chunksizes"] == (len(res.t), n, 2)
    big = ds.assign(q=(("time", "robot", "axis"), np.zeros((len(res.t), n, 2))))
    old = netcdf.CHUNK_BYTES
    try:
        netcdf.CHUNK_BYTES = 32  # a state (48 bytes) larger than a chunk: split by robots
        assert netcdf.encoding(big)["q"]["chunksizes"] == (1, 2, 2)
    finally:
        netcdf.CHUNK_BYTES = old


def test_the_per_edge_table_above_the_limit_is_read_back(run_200) -> None:
    out, res = run_200
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_edges"] == 549 > simulation.LIST_LIMIT
    assert summary["distance_errors_table"] == EDGE_TABLE and EDGE_TABLE in summary["manifest"]
    for key in ("distance_errors", "final_positions", "edges", "active_restrictions_final"):
        assert key not in summary, key
    table = read_edge_table(out / EDGE_TABLE)
    with xr.open_dataset(out / "trajectory.nc", engine="h5netcdf") as ds:
        final = ds["distance_error"].values[-1]
        np.testing.assert_array_equal(table["distance_error"], final)
        np.testing.assert_array_equal(np.stack([table["i"], table["j"]], 1), ds["edge_robots"])
    assert table["edge"].tolist() == res.edge_labels
    stats = summary["distance_error_stats"]
    assert stats["max_abs"] == float(np.max(np.abs(final)))
    assert stats["p90_abs"] == pytest.approx(float(np.percentile(np.abs(final), 90)))
    assert stats["within_tolerance"] == int(np.sum(np.abs(final) <= 0.01))


def test_the_table_is_written_just_above_the_limit(tmp_path: Path, monkeypatch) -> None:
    """A formation of m edges: no table with LIST_LIMIT = m, a table with LIST_LIMIT = m - 1."""
    scenario = lattice(tmp_path, 30, duration=0.002)
    m = len(fl.io.scenario.load_scenario(scenario).formation.edges)
    monkeypatch.setattr(simulation, "LIST_LIMIT", m)
    assert invoke("run", scenario, "--out", tmp_path / "at", "-q").exit_code == 0
    at = json.loads((tmp_path / "at" / "summary.json").read_text())
    assert len(at["distance_errors"]) == m and not (tmp_path / "at" / EDGE_TABLE).exists()
    monkeypatch.setattr(simulation, "LIST_LIMIT", m - 1)
    assert invoke("run", scenario, "--out", tmp_path / "above", "-q").exit_code == 0
    above = json.loads((tmp_path / "above" / "summary.json").read_text())
    assert "distance_errors" not in above
    table = read_edge_table(tmp_path / "above" / EDGE_TABLE)
    assert (
        dict(zip(table["edge"].tolist(), table["distance_error"].tolist(), strict=True))
        == (at["distance_errors"])
    )


def test_figures_of_200_robots_have_a_bounded_size_and_no_robot_legend(run_200, tmp_path) -> None:
    out, res = run_200
    figures = run_figures(res, prefix="lattice-200")
    for name, fig in figures.items():
        ax = fig.axes[0]
        legend = ax.get_legend()
        entries = 0 if legend is None else len(legend.get_texts())
        assert entries <= 4, name  # at most the bands' three and "restriction active"
        assert len(ax.get_lines()) + len(ax.collections) <= 10, name  # collections, not 200
        with Image.open(save_figure(fig, tmp_path / f"{name}.png")) as im:
            assert im.size[0] <= 800 and im.size[1] <= 800, (name, im.size)
    for name in ("trajectories", "controls_x", "distance_errors"):  # what run wrote
        with Image.open(out / f"{name}.png") as im:
            assert im.size[0] <= 800 and im.size[1] <= 800, (name, im.size)


def test_an_animation_reads_only_the_states_it_draws() -> None:
    t = np.linspace(0.0, 10.0, 10_001)
    for n, frames in ((3, 150), (200, 40), (10_000, 10)):
        rows = used_indices(t, frames, n)
        sub = t[rows]
        np.testing.assert_array_equal(sub[frame_indices(sub, frames)], t[frame_indices(t, frames)])
        np.testing.assert_array_equal(
            sub[path_indices(sub, frames, n)], t[path_indices(t, frames, n)]
        )
    # 10 frames and 20 trail states (200,000 trail vertices / 10,000 robots) of 10,001
    assert len(used_indices(t, 10, 10_000)) <= 30


def test_animate_draws_10000_robots(tmp_path: Path) -> None:
    scenario = lattice(tmp_path, 10_000, duration=0.003)
    out = tmp_path / "out"
    assert invoke("run", scenario, "--out", out, "-q").exit_code == 0
    res = invoke("animate", out, "--format", "gif", "--frames", 3)
    assert res.exit_code == 0, res.output
    with Image.open(out / "animation.gif") as gif:
        assert gif.n_frames == 3 and gif.size == (450, 450)
        gif.seek(2)
        drawn = np.asarray(gif.convert("RGB"))
    blue = np.all(np.abs(drawn.astype(int) - [31, 119, 180]) < 40, axis=-1)  # "C0" points
    rows, cols = np.flatnonzero(blue.any(axis=1)), np.flatnonzero(blue.any(axis=0))
    assert blue.mean() > 0.02  # robots drawn, and over the whole round patch:
    assert rows[-1] - rows[0] > 0.6 * 450 and cols[-1] - cols[0] > 0.6 * 450
    manifest = json.loads((out / "summary.json").read_text())["manifest"]
    assert "animation.gif" in manifest


def test_many_robots_in_an_animation_mark_stopped_and_constrained_ones() -> None:
    from matplotlib.figure import Figure

    from formationlab.plotting.animation import _Collections, _Points
    from formationlab.plotting.runs import robot_colors

    n = 300
    rng = np.random.default_rng(3)
    trail = rng.uniform(0, 30, (1, n, 2)) + np.zeros((4, 1, 1))
    dead, ring = np.zeros(n, bool), np.zeros(n, bool)
    dead[7], ring[5] = True, True  # robot 8 stopped (grey), robot 6 ringed red
    ax = Figure().add_subplot()
    robots = _Collections(ax, np.full(n, 0.2), robot_colors(n))
    robots.draw(trail, dead, ring)
    face, edge = robots.discs.get_facecolor(), robots.discs.get_edgecolor()
    np.testing.assert_allclose(face[7, :3], 0.55)
    np.testing.assert_allclose(edge[5, :3], [0.8627, 0.0784, 0.2353], atol=1e-3)  # crimson
    assert not np.allclose(face[0, :3], 0.55)
    points = _Points(Figure().add_subplot(), 2.0, n)  # beyond 2,000 robots: points
    points.draw(trail, dead, ring)
    assert len(points.discs.get_xdata()) == n - 1 and len(points.stopped.get_xdata()) == 1
    assert points.ringed.get_xdata()[0] == trail[-1, 5, 0]


def test_write_trajectory_of_a_paper_run_round_trips(tmp_path: Path) -> None:
    from formationlab.studies.paper import PaperSetup

    res = PaperSetup(duration=1.0).run(2, perturbation=1e-6)
    write_trajectory(res, tmp_path / "t.nc")
    ds = load_trajectory(tmp_path / "t.nc")
    np.testing.assert_array_equal(ds["q"].values, res.q)
    np.testing.assert_array_equal(ds["sigma"].values, res.sigma)
    assert ds["axis"].values.tolist() == ["x", "y"]
