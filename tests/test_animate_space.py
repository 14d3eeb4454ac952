"""Animations of formations in space: ``animate`` and ``run --animate`` on a run in 3-D.

What a frame draws is read back from its artists (the robots' points, the edges, the
numbers, the camera, the axes' limits) and held against ``trajectory.nc``, read on its
own with xarray; the files are checked for their frames. docs/three-d.md says what the
animation shows.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import xarray as xr
from matplotlib.collections import PathCollection
from typer.testing import CliRunner, Result

import formationlab.io.animation as io_animation
from formationlab.cli import _load_commands, app
from formationlab.cli.animate import write_animation
from formationlab.plotting.animation import animate_run, frame_indices
from formationlab.plotting.animation_space import AZIMUTH_STEP

_load_commands()
runner = CliRunner()
EXAMPLE = Path(__file__).parents[1] / "examples" / "space" / "tetrahedron-mirror.toml"
#: the example's first 0.4 s: the robots still move fast (from 0.1 to 0.4 m/s)
SHORT = ("duration = 10.0", "duration = 0.4")


def invoke(*args: object) -> Result:
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


def short_scenario(folder: Path, extra: str = "") -> Path:
    text = EXAMPLE.read_text()
    assert SHORT[0] in text
    path = folder / "short.toml"
    path.write_text(text.replace(*SHORT) + extra)
    return path


@pytest.fixture(scope="module")
def space_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tetrahedron's first 0.4 s (200 steps, 21 saved states), not animated."""
    root = tmp_path_factory.mktemp("space-anim")
    out = root / "out"
    res = invoke("run", short_scenario(root), "--out", out, "--save-every", 10, "--quiet")
    assert res.exit_code == 0, res.output
    return out


def frames_of(
    nc: Path, out: Path, frames: int, monkeypatch: pytest.MonkeyPatch
) -> list[dict[str, Any]]:
    """Animate the run of ``nc`` into ``out`` as `animate` does (a GIF) and return what each
    frame drew: the robots' points and faces, the edges, the numbers, the camera's azimuth
    and the title."""
    seen: list[dict[str, Any]] = []
    real = io_animation.save_animation

    def probing(anim: Any, stem: Any, **kw: Any) -> Any:
        ax = anim._fig.axes[0]
        (points,) = [c for c in ax.collections if isinstance(c, PathCollection)]
        lines = [c for c in ax.collections if hasattr(c, "_segments3d")]

        @contextmanager
        def progress(name: str) -> Iterator[Any]:
            def update(done: int, total: int) -> None:  # frame done - 1 is drawn
                seen.append(
                    {
                        "points": np.column_stack(points._offsets3d),
                        "lines": [np.array(c._segments3d, dtype=float) for c in lines],
                        "labels": [(t.get_text(), t.get_position_3d()) for t in ax.texts],
                        "azim": ax.azim,
                        "title": ax.get_title(),
                    }
                )

            yield update

        return real(anim, stem, **{**kw, "progress": progress})

    monkeypatch.setattr(io_animation, "save_animation", probing)
    with xr.open_dataset(nc) as ds:
        write_animation(out, ds, "probe", frames, ("gif",))
    return seen


def drawn_by_hand(anim: Any) -> Any:
    """``anim``, its frames to be drawn by calling its function (not saved): matplotlib's
    flag that it was rendered, so that it does not warn when the animation is deleted."""
    anim._draw_was_started = True
    return anim


def test_animate_writes_a_gif_and_an_html_of_the_frames(space_run: Path) -> None:
    from PIL import Image

    res = invoke("animate", space_run, "--frames", 4, "--format", "gif", "--format", "html")
    assert res.exit_code == 0, res.output
    with Image.open(space_run / "animation.gif") as gif:
        assert getattr(gif, "n_frames", 1) == 4
        assert gif.size[0] > 300 and gif.size[1] > 300
    html = (space_run / "animation.html").read_text()
    assert html.count("data:image/png;base64") == 4
    assert "http://" not in html and "https://" not in html  # works offline
    manifest = json.loads((space_run / "summary.json").read_text())["manifest"]
    assert {"animation.gif", "animation.html"} <= set(manifest)


def test_each_frame_draws_the_trajectory_at_its_time(
    space_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen = frames_of(space_run / "trajectory.nc", tmp_path, 5, monkeypatch)
    with xr.open_dataset(space_run / "trajectory.nc") as ds:
        t, q = ds["time"].values, ds["q"].values
        pairs = ds["edge_robots"].values - 1
    assert q.shape == (21, 4, 3) and len(seen) == 5
    assert (tmp_path / "animation.gif").is_file()
    labels = [f"{time:.2f}" for time in t]
    assert len(set(labels)) == len(t)  # saved 0.02 s apart: the title's time names the state
    rows = []
    for frame in seen:
        row = labels.index(frame["title"].removeprefix("probe: t = ").removesuffix(" s"))
        rows.append(row)
        np.testing.assert_allclose(frame["points"], q[row], rtol=0, atol=1e-12)
        ends = np.stack([q[row, pairs[:, 0]], q[row, pairs[:, 1]]], axis=1)
        graph = [seg for seg in frame["lines"] if seg.shape == (len(pairs), 2, 3)]
        assert len(graph) == 1
        np.testing.assert_allclose(graph[0], ends, rtol=0, atol=1e-12)
        assert [text for text, _ in frame["labels"]] == [" 1", " 2", " 3", " 4"]
        np.testing.assert_allclose([xyz for _, xyz in frame["labels"]], q[row], atol=1e-12)
    # the frames spaced by time and motion (frame_indices), from the first state to the last
    assert rows[0] == 0 and rows[-1] == len(t) - 1
    np.testing.assert_array_equal(rows, frame_indices(t, 5, q))
    # the robots move between frames: a frame drawn at another time would not match
    assert np.abs(np.diff(q[rows], axis=0)).max(axis=(1, 2)).min() > 1e-2
    np.testing.assert_allclose(np.diff([f["azim"] for f in seen]), AZIMUTH_STEP, rtol=1e-12)


def test_the_camera_turns_and_the_axes_have_one_scale(space_run: Path) -> None:
    with xr.open_dataset(space_run / "trajectory.nc") as ds:
        t, q = ds["time"].values, ds["q"].values
        edges = ds["edge_robots"].values - 1
    anim = drawn_by_hand(animate_run(t, q, edges=edges, diameters=np.full(4, 0.2), max_frames=4))
    ax = anim._fig.axes[0]
    assert ax.name == "3d"
    azimuths = []
    for k in range(4):
        anim._func(k)
        azimuths.append(ax.azim)
    np.testing.assert_allclose(np.diff(azimuths), AZIMUTH_STEP, rtol=1e-12)
    assert AZIMUTH_STEP > 0
    spans = [np.diff(lim)[0] for lim in (ax.get_xlim(), ax.get_ylim(), ax.get_zlim())]
    np.testing.assert_allclose(spans, spans[0], rtol=1e-12)  # one scale on all three axes
    np.testing.assert_allclose(ax.get_box_aspect(), ax.get_box_aspect()[0], rtol=1e-12)
    lows = np.array([ax.get_xlim()[0], ax.get_ylim()[0], ax.get_zlim()[0]])
    assert (q.min(axis=(0, 1)) - 0.2 >= lows).all()  # every robot, with its diameter, inside
    assert (q.max(axis=(0, 1)) + 0.2 <= lows + spans[0]).all()
    assert [ax.get_xlabel(), ax.get_ylabel(), ax.get_zlabel()] == ["x [m]", "y [m]", "z [m]"]
    with pytest.raises(ValueError, match="headings belong to runs in the plane"):
        animate_run(t, q, edges=edges, diameters=np.full(4, 0.2), headings=np.zeros((21, 4)))


def test_a_stopped_robot_turns_grey(space_run: Path) -> None:
    with xr.open_dataset(space_run / "trajectory.nc") as ds:
        t, q = ds["time"].values, ds["q"].values
        edges = ds["edge_robots"].values - 1
    anim = animate_run(
        t, q, edges=edges, diameters=np.full(4, 0.2), max_frames=5, stops=[(2, 0.25)]
    )
    drawn_by_hand(anim)
    ax = anim._fig.axes[0]
    (points,) = [c for c in ax.collections if isinstance(c, PathCollection)]
    grey = (0.55, 0.55, 0.55)
    at = t[frame_indices(t, 5, q)]  # the frames' times (spaced by time and motion)
    assert 0 < (at >= 0.25).sum() < 5  # frames before the stop and after it
    for k, stopped in enumerate(at >= 0.25):
        anim._func(k)
        face = PathCollection.get_facecolor(points)[:, :3]  # by robot, not by depth
        assert np.allclose(face[2], grey) == stopped
        assert not any(np.allclose(face[i], grey) for i in (0, 1, 3))


def test_run_animate_draws_a_run_in_space(tmp_path: Path) -> None:
    from PIL import Image

    out = tmp_path / "out"
    scenario = short_scenario(tmp_path)
    res = invoke("run", scenario, "--out", out, "--save-every", 10, "--animate", "--frames", 3)
    assert res.exit_code == 0, res.output
    with Image.open(out / "animation.gif") as gif:
        assert getattr(gif, "n_frames", 1) == 3
    assert (out / "animation.html").read_text().count("data:image/png;base64") == 3
    manifest = json.loads((out / "summary.json").read_text())["manifest"]
    assert "animation.gif" in manifest and "animation.html" in manifest


def test_a_run_in_the_plane_is_still_drawn_in_the_plane() -> None:
    t = np.linspace(0.0, 1.0, 5)
    q = np.zeros((5, 3, 2)) + np.arange(3)[:, None]
    edges = [[0, 1], [1, 2]]
    anim = drawn_by_hand(animate_run(t, q, edges=edges, diameters=np.full(3, 0.2), max_frames=3))
    ax = anim._fig.axes[0]
    assert ax.name == "rectilinear" and ax.get_aspect() == 1.0
    with pytest.raises(ValueError, match=r"\(T, n, 2\) or \(T, n, 3\)"):
        animate_run(t, np.zeros((5, 3, 4)), edges=[[0, 1]], diameters=np.full(3, 0.2))


@pytest.mark.parametrize("n", [30, 2100])
def test_many_robots_in_space_are_points_without_numbers(rng, n) -> None:
    # beyond 12 robots no numbers; beyond 2,000 one colour and the lines one broken line
    t = np.linspace(0.0, 1.0, 5)
    q = rng.normal(size=(1, n, 3)) * 5 + np.cumsum(rng.normal(size=(5, n, 3)) * 0.1, axis=0)
    edges = np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1)
    anim = animate_run(t, q, edges=edges, diameters=np.full(n, 0.2), max_frames=3)
    ax = drawn_by_hand(anim)._fig.axes[0]
    anim._func(1)
    (points,) = [c for c in ax.collections if isinstance(c, PathCollection)]
    row = frame_indices(t, 3, q)[1]
    assert 0 < row < 4
    np.testing.assert_allclose(np.column_stack(points._offsets3d), q[row], atol=1e-12)
    assert len(ax.texts) == 0
    colours = np.unique(PathCollection.get_facecolor(points), axis=0)
    assert len(colours) == (1 if n > 2000 else n)
    if n > 2000:
        lines = [line for line in ax.lines if len(line.get_data_3d()[0]) == 3 * n]
        assert len(lines) == 1  # the edges: n lines of 2 points and a NaN each
        xyz = np.column_stack(lines[0].get_data_3d()).reshape(n, 3, 3)
        np.testing.assert_allclose(xyz[:, 0], q[row], atol=1e-12)
        np.testing.assert_allclose(xyz[:, 1], q[row, edges[:, 1]], atol=1e-12)
        assert np.isnan(xyz[:, 2]).all()
