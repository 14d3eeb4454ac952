"""Figures for papers: units on every axis, vector formats, log V, visible coinciding lines,
one colour per robot and per edge, animation frames that show the transient."""

from __future__ import annotations

import copy
import io
import json
import re
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from _scenarios import triangle
from matplotlib.colors import to_hex, to_rgba
from matplotlib.figure import Figure
from rich.console import Console
from typer.testing import CliRunner, Result

import formationlab as fl
import formationlab.io
from formationlab.cli import _load_commands, _progress, app
from formationlab.errors import ParameterError
from formationlab.io import figures as io_figures
from formationlab.plotting.animation import animate_run, frame_indices, used_indices
from formationlab.plotting.colors import edge_colors, robot_colors
from formationlab.plotting.paper import paper_figures
from formationlab.plotting.runs import plot_lyapunov, run_figures
from formationlab.scenario import parse_scenario

_load_commands()
runner = CliRunner()


def _settling(T: int = 15_001, n: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A run of 15 s whose robots settle with a time constant of 0.3 s: ``t``, ``q``."""
    t = np.linspace(0.0, 15.0, T)
    start = np.array([[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]])[:n]
    end = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.87]])[:n]
    w = np.exp(-t / 0.3)[:, None, None]
    return t, w * start + (1 - w) * end


def test_the_frames_of_a_settling_run_show_its_transient() -> None:
    t, q = _settling()
    even = frame_indices(t, 150)
    moving = frame_indices(t, 150, q)
    assert len(moving) <= 150 and moving[0] == 0 and moving[-1] == len(t) - 1
    # 95 % of the motion happens in the first 0.9 s (3 time constants): evenly in time
    # that is 6 % of the frames; half the frames follow the motion, so over half here
    assert np.mean(t[even] < 0.9) < 0.07
    assert np.mean(t[moving] < 0.9) > 0.5
    # and the still end keeps frames (half of them follow the clock): no jump of seconds
    assert np.max(np.diff(t[moving])) < 2 * 15.0 / 75


def test_the_frames_of_a_still_run_are_even_in_time() -> None:
    t = np.linspace(0.0, 10.0, 1001)
    q = np.zeros((len(t), 3, 2))
    np.testing.assert_array_equal(frame_indices(t, 50, q), frame_indices(t, 50))


def test_an_animation_of_the_states_read_has_the_same_frames() -> None:
    t, q = _settling()
    for n, frames in ((3, 150), (3, 20)):
        rows = used_indices(t, frames, n, q)
        assert len(rows) <= 2000 + frames
        sub_frames = frame_indices(t[rows], frames, q[rows])
        np.testing.assert_array_equal(t[rows][sub_frames], t[frame_indices(t, frames, q)])


# ------------------------------------------------------------ every figure the commands write

UNIT = re.compile(r"\[[^\]]+\]|\(dimensionless[,)]")

SCENARIO = triangle(
    "fig-triangle",
    "1.0",
    """\
[study]
trials = 4
chunk_size = 4
initial = { kind = "box", half_width = 3.0 }
laws = ["distance", "angle-restricted"]
[study.sweep]
k_a = [1.0, 3.0]
""",
)


def invoke(*args: object) -> Result:
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """The figures the commands save, by file name (each still saved, as a PNG)."""
    seen: dict[str, Any] = {}
    save = io_figures.save_figures

    def record(fig: Any, stem: Any, formats: tuple[str, ...] = ("png",), **kw: Any) -> Any:
        seen[Path(stem).name] = fig
        return save(fig, stem, formats, **kw)

    monkeypatch.setattr(io_figures, "save_figures", record)
    monkeypatch.setattr(formationlab.io, "save_figures", record)
    return seen


def _unlabelled(fig: Any) -> list[str]:
    """The axes of ``fig`` with ticks but without a label that gives a unit."""
    bad = []
    for k, ax in enumerate(fig.axes):
        if not ax.axison:
            continue
        axes = [("x", ax.xaxis), ("y", ax.yaxis)]
        if hasattr(ax, "zaxis"):
            axes.append(("z", ax.zaxis))
        for name, axis in axes:
            if not len(axis.get_ticklocs()) or not axis.get_visible():
                continue  # a panel of shapes, without a scale
            label = axis.get_label_text()
            shared = name == "y" and not label and k > 0  # the row's first panel says it
            if not shared and not (UNIT.search(label) or label == "robot number"):
                bad.append(f"axes {k} {name}: {label!r}")
    return bad


def test_every_figure_of_the_commands_has_labelled_axes_with_units(
    tmp_path: Path, drawn: dict[str, Any]
) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO)
    assert invoke("run", scenario, "--out", tmp_path / "run", "-q").exit_code == 0
    res = invoke("study", scenario, "--out", tmp_path / "study", "-q", "--trials", 4)
    assert res.exit_code == 0, res.output
    res = invoke(
        "equilibria", scenario, "--out", tmp_path / "eq", "--starts", 4, "-q",
        "--follow", "k_a=2:3", "--follow-steps", 2,
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    run = parse_scenario(SCENARIO)
    res1 = fl.simulate(run.formation, run.law, run.q0, duration=1.0, integrator=run.integrator)
    paper = SimpleNamespace(simulation_1=res1, simulation_2=res1, simulation_2_unperturbed=res1)
    drawn.update(paper_figures(paper))
    expected = {"trajectories", "controls_x", "lyapunov", "distance_errors", "desired",
                "fractions", "shape_error", "gallery", "continuation", "fig07_lyapunov",
                "fig09_distance_errors"}  # fmt: skip
    assert expected <= set(drawn), sorted(drawn)
    bad = {name: _unlabelled(fig) for name, fig in drawn.items() if _unlabelled(fig)}
    assert not bad, bad
    traj = drawn["trajectories"].axes[0]
    assert (traj.get_xlabel(), traj.get_ylabel()) == ("x [m]", "y [m]")
    assert drawn["controls_x"].axes[0].get_ylabel() == "velocity in x [m/s]"
    assert drawn["fig05_velocity_x"].axes[0].get_xlabel() == "time [s]"
    assert drawn["desired"].axes[0].get_xlabel() == "k_a [1/s]"


def _triangle_run() -> Any:
    run = parse_scenario(SCENARIO.replace("duration = 1.0", "duration = 0.5"))
    return fl.simulate(run.formation, run.law, run.q0, duration=0.5, integrator=run.integrator)


def test_v_on_a_log_axis_where_it_is_positive_and_symlog_said_where_not() -> None:
    res = _triangle_run()
    assert np.all(res.V > 0)
    fig = Figure()
    ax = fig.add_subplot()
    plot_lyapunov(res, ax=ax, log=True)
    assert ax.get_yscale() == "log" and "log scale" in ax.get_ylabel()
    below = copy.copy(res)
    object.__setattr__(below, "V", res.V - res.V[-1] - 1.0)  # negative at the end
    fig = Figure()
    ax = fig.add_subplot()
    plot_lyapunov(below, ax=ax, log=True)
    assert ax.get_yscale() == "symlog" and "symlog: linear within ±0.01" in ax.get_ylabel()
    # a converged V's round-off below zero keeps the log axis, down to 1e-12 of its top
    rounded = copy.copy(res)
    object.__setattr__(rounded, "V", np.append(res.V[:-1], -1e-17))
    fig = Figure()
    ax = fig.add_subplot()
    plot_lyapunov(rounded, ax=ax, log=True)
    assert ax.get_yscale() == "log" and ax.get_ylim()[0] >= 0.5e-12 * res.V.max()


def test_lines_that_coincide_stay_visible_and_colours_are_one_per_robot_and_edge() -> None:
    res = _triangle_run()
    figs = run_figures(res)
    errors = figs["distance_errors"].axes[0].get_lines()[:3]  # r12, r13, r23
    styles = [(tuple(to_rgba(ln.get_color())), str(ln.get_linestyle())) for ln in errors]
    assert len({s[1] for s in styles}) == 3  # a dashed line over a solid one shows both
    assert [s[0] for s in styles] == [tuple(c) for c in edge_colors(3)]
    robots = robot_colors(3)
    paths = [ln for ln in figs["trajectories"].axes[0].get_lines() if ln.get_label()[:5] == "robot"]
    controls = figs["controls_y"].axes[0].get_lines()[:3]
    for lines in (paths, controls):
        assert [tuple(to_rgba(ln.get_color())) for ln in lines] == [tuple(c) for c in robots]
    assert len({str(ln.get_linestyle()) for ln in controls}) == 3
    # the animation: the robots' discs in the same colours
    anim = animate_run(res.t, res.q, edges=res.formation.edges, diameters=np.full(3, 0.2))
    discs = [p for p in anim._fig.axes[0].patches if hasattr(p, "get_radius")]
    assert [tuple(to_rgba(d.get_facecolor()))[:3] for d in discs[:3]] == [c[:3] for c in robots]
    assert anim._fig.axes[0].get_xlabel() == "x [m]"
    anim._draw_was_started = True  # never saved: no "deleted without rendering" warning


# ------------------------------------------------------------ --format


def test_format_pdf_svg_writes_vector_figures(tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO.replace("duration = 1.0", "duration = 0.2"))
    out = tmp_path / "out"
    res = invoke("run", scenario, "--out", out, "-q", "--format", "pdf,svg")
    assert res.exit_code == 0, res.output
    assert (out / "trajectories.pdf").read_bytes()[:5] == b"%PDF-"
    svg = (out / "trajectories.svg").read_text()
    assert svg.startswith("<?xml") and "<svg" in svg[:1000]
    assert not list(out.glob("*.png"))
    manifest = json.loads((out / "summary.json").read_text())["manifest"]
    assert {"lyapunov.pdf", "lyapunov.svg"} <= set(manifest)


@pytest.mark.parametrize("command", ["run", "study", "equilibria", "paper"])
def test_an_unknown_figure_format_is_refused_by_name(tmp_path: Path, command: str) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO)
    args = [] if command == "paper" else [scenario]
    res = invoke(command, *args, "--out", tmp_path / "o", "--format", "png,jpg")
    assert res.exit_code == 2
    assert "error: unknown figure format 'jpg': choose from png, pdf, svg" in res.stderr
    assert not (tmp_path / "o").exists()


def test_figure_formats_reads_a_comma_list() -> None:
    assert io_figures.figure_formats("png, PDF,svg,pdf") == ("png", "pdf", "svg")
    with pytest.raises(ParameterError, match="no format"):
        io_figures.figure_formats(" , ")


# ------------------------------------------------------------ progress


def test_progress_shows_on_a_terminal_only_and_not_when_quiet(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    terminal = Console(file=io.StringIO(), force_terminal=True, width=80)
    log = Console(file=io.StringIO(), force_terminal=False)
    assert _progress.shows_progress(False, terminal)
    assert not _progress.shows_progress(True, terminal)  # --quiet
    assert not _progress.shows_progress(False, log)  # a log or a pipe
    for quiet in (False, True):
        monkeypatch.setattr(
            _progress, "err_console", Console(file=io.StringIO(), force_terminal=True, width=80)
        )
        with _progress.stage_bar("reproducing", 2, quiet=quiet) as now:
            now("simulation 1")
            _progress.err_console.file.flush()
        with _progress.progress_bar("writing animation.gif", quiet=quiet, total=4) as update:
            update(2)
        text = _progress.err_console.file.getvalue()
        assert (
            "reproducing: simulation 1" in text and "writing animation.gif" in text
        ) is not quiet
        assert (text == "") is quiet


def test_the_html_animation_plays_when_opened(tmp_path: Path) -> None:
    from formationlab.io.animation import save_animation

    t, q = _settling(T=41)
    anim = animate_run(t, q, edges=np.array([[0, 1], [1, 2], [0, 2]]), diameters=np.full(3, 0.2),
                       max_frames=4)  # fmt: skip
    (page,) = save_animation(anim, tmp_path / "animation", formats=["html"])
    text = page.read_text()
    player = re.search(r"\b(anim[0-9a-f]+) = new Animation\(", text)
    assert player is not None
    onload = text.index("window.addEventListener('load'")
    assert text.index(f"{player.group(1)}.play_animation();", onload) > onload


def test_the_html_page_of_a_run_in_the_plane_holds_its_states_not_images(tmp_path: Path) -> None:
    from formationlab.cli.animate import write_animation

    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO)
    sc = parse_scenario(SCENARIO)
    res = fl.simulate(sc.formation, sc.law, sc.q0, duration=1.0, integrator=sc.integrator)
    (page,) = write_animation(tmp_path, res, "fig-triangle", 40, ("html",))
    text = page.read_text()
    assert "data:image" not in text and len(text) < 200_000  # 1,001 states of 3 robots
    data = json.loads(re.search(r"<script id='states'[^>]*>(.*?)</script>", text, re.S)[1])
    rows = used_indices(res.t, 40, 3, res.q)
    np.testing.assert_allclose(data["t"], res.t[rows], atol=1e-6)
    np.testing.assert_allclose(data["q"], res.q[rows], atol=0.6e-4)  # rounded to 0.1 mm
    frames = frame_indices(res.t[rows], 40, res.q[rows])
    assert data["frames"] == frames.tolist() and len(frames) <= 40
    assert data["edges"] == res.formation.edges.tolist()
    assert data["colors"] == [to_hex(c) for c in robot_colors(3)]
    assert "draw(0); play();" in text  # it starts playing when opened
