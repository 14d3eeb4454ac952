"""Extreme but finite inputs: a clear error or an honest status, never an abort.

Positions around 1e154 (whose squared distances overflow), 1e150 and 1e-150, huge gains
and zero diameters through the compiled single run and the command line. The command
runs as a subprocess: an out-of-bounds write in compiled code ends the process with
SIGABRT (status -6 here), which no in-process test can observe.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _scenarios import triangle

import formationlab as fl
from formationlab.errors import FormationError, UserInputError
from formationlab.safety import SafetyFilter
from formationlab.simulation.batch import simulate_batch

TEMPLATE = [[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]]
START = np.array([[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]])
LAW = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
CLI = [sys.executable, "-c", "from formationlab.cli import main; main()"]


def refused(scenario: Path) -> str:
    """What ``validate`` says of ``scenario``, after checking that it refused it cleanly."""
    proc = subprocess.run(
        [*CLI, "validate", str(scenario)], capture_output=True, text=True, timeout=600, check=False
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    return proc.stderr.strip()


def run(formation, law, q0, backend="numba"):
    with np.errstate(all="ignore"):
        return fl.simulate(
            formation, law, q0, duration=0.05, integrator=fl.Euler(dt=1e-3), backend=backend
        )


def test_huge_gains_end_non_finite_on_the_command_line(tmp_path: Path) -> None:
    # the first step is not finite; the close list was then built from it: a scenario
    # around 1e154 (now refused by validate) ended in SIGABRT (munmap_chunk) this way
    text = triangle("strong", "1.0").replace("k_c = 2.0", "k_c = 1e300")
    assert "1e300" in text
    scenario = tmp_path / "strong.toml"
    scenario.write_text(text)
    out = tmp_path / "out"
    proc = subprocess.run(
        [*CLI, "run", str(scenario), "--out", str(out), "-q"],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert proc.returncode == 1, proc.stderr  # not -6 (SIGABRT)
    assert "Traceback" not in proc.stderr
    assert "Warning" not in proc.stderr + proc.stdout  # (numpy's overflow warnings leaked)
    error = [ln for ln in proc.stderr.splitlines() if ln.startswith("error:")]
    assert len(error) == 1 and "produced NaN or infinite positions" in error[0]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "non-finite"


def test_positions_beyond_1e150_are_refused_by_validate(tmp_path: Path) -> None:
    text = triangle("far", "1.0").replace(
        "positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]",
        "positions = [[-3e154, -3e154], [3e154, -3e154], [0.0, 3e154]]",
    )
    scenario = tmp_path / "far.toml"
    scenario.write_text(text)
    proc = subprocess.run(
        [*CLI, "validate", str(scenario)], capture_output=True, text=True, timeout=600, check=False
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.strip() == (
        f"error: {scenario}: robots.positions (line 3): positions has coordinates up to 3e+154, "
        "beyond 1e+150: squared distances would overflow double precision; scale the scenario "
        "(positions, distances, diameters) to moderate numbers"
    )


def test_positions_around_1e154_are_refused_and_huge_gains_end_non_finite() -> None:
    # squared distances overflow: the law's forces would come out 0 (a run that lies)
    f = fl.Formation.from_template(TEMPLATE, diameters=0.2)
    with pytest.raises(UserInputError, match="initial positions has coordinates up to 3e"):
        run(f, LAW, START * 1e154)
    strong = fl.AngleRestrictedLaw(k_c=1e300, k_a=1e300, theta=0.5)
    runs = [run(f, strong, START, backend) for backend in ("numba", "numpy")]
    for r in runs:  # the first step reaches 1.6e297: squared distances overflow there
        assert r.status == "non-finite" and r.t[-1] == 0.0, (r.stats["backend"], r.message)
        assert np.all(np.isfinite(r.q))  # the last finite state is kept
        assert "whatever dt" in r.message  # a smaller step would not help
    batch = simulate_batch(f, strong, START[None], duration=0.05)[0]  # a batch of one
    assert batch.status == "non-finite" and batch.t[-1] == 0.0


def test_large_positions_and_zero_diameters_run() -> None:
    # coordinates up to the limit, 1e150
    wide = run(fl.Formation.from_template(TEMPLATE, diameters=0.2), LAW, START * 3e149)
    assert wide.status == "success" and np.all(np.isfinite(wide.q))
    points = run(fl.Formation.from_template(TEMPLATE, diameters=0.0), LAW, START)
    assert points.status == "success" and np.all(np.isfinite(points.q))


def test_tiny_positions_are_refused_as_overlapping() -> None:
    f = fl.Formation.from_template(TEMPLATE, diameters=0.2)
    with pytest.raises(FormationError, match="robots 1 and 2 overlap in the initial positions"):
        run(f, LAW, START * 1e-150)


def test_a_delay_whose_measurements_do_not_fit_is_refused_by_validate(tmp_path: Path) -> None:
    # [sensing] delay = 1e6 s at dt = 1e-3: a ring of 1e9 steps of every robot's measurement
    # of every other (about 140 GB) was allocated at the run's first step, in a traceback
    scenario = tmp_path / "late.toml"
    scenario.write_text(triangle("late", "1.0") + "\n[sensing]\ndelay = 1e6\n")
    message = refused(scenario)
    assert message.startswith(f"error: {scenario}: sensing.delay (line ")
    assert "1e+09 steps of dt = 0.001 s" in message and "use a shorter delay" in message
    # a delay that fits runs, in Python as on the command line
    f = triangle_formation()
    ok = fl.simulate(f, LAW, START, duration=0.05, sensing=fl.Sensing(delay=0.01))
    assert ok.status == "success"
    with pytest.raises(FormationError, match=r"sensing\.delay = 1e\+06 s"):
        fl.simulate(f, LAW, START, duration=0.05, sensing=fl.Sensing(delay=1e6))


def triangle_formation() -> fl.Formation:
    return fl.Formation.from_template(TEMPLATE, diameters=0.2)


#: a key set to a value that sizes the work beyond reason, and the key the refusal names
HUGE_WORK = {
    "simulation-dt": ("dt = 1e-300\n", "simulation.dt", "1e+300 steps"),
    "study-dt": ("[study]\ntrials = 4\ndt = 1e-300\n", "study.dt", "1e+300 steps"),
    "study-duration": ("[study]\ntrials = 4\nduration = 1e300\n", "study.duration", "steps"),
    "equilibria-dt": ("[equilibria]\ndt = 1e-300\n", "equilibria.dt", "6e+301 steps"),
    "equilibria-duration": ("[equilibria]\nduration = 1e300\n", "equilibria.duration", "1e+07"),
    "equilibria-starts": ("[equilibria]\nstarts = 1000000000000000\n", "equilibria.starts", ""),
}


@pytest.mark.parametrize("case", sorted(HUGE_WORK))
def test_work_beyond_reason_is_refused_by_validate_with_its_key(case: str, tmp_path: Path) -> None:
    # these went through validate and then ended in OverflowError, numba's "Int value is
    # too large" or an allocation of petabytes
    table, key, figure = HUGE_WORK[case]
    text = triangle("huge", "1.0")
    if not table.startswith("["):  # the triangle's own [simulation] table
        text = text.replace("dt = 1e-3\n", table)
    else:
        text += "\n" + table
    scenario = tmp_path / "huge.toml"
    scenario.write_text(text)
    message = refused(scenario)
    assert message.startswith(f"error: {scenario}: {key} (line "), message
    assert figure in message and len(message) < 400, message


def test_periods_that_would_never_end_are_refused_by_validate(tmp_path: Path) -> None:
    # [asynchronous] periods = 1e-300: validate said "15,000 steps" and the run never ended
    scenario = tmp_path / "eager.toml"
    scenario.write_text(triangle("eager", "15.0") + "\n[asynchronous]\nperiods = 1e-300\n")
    message = refused(scenario)
    assert message.startswith(f"error: {scenario}: asynchronous.periods (line "), message
    assert "4.5e+301 wake-ups in 15 s" in message


def test_a_speed_polygon_of_a_hundred_million_sides_is_refused(tmp_path: Path) -> None:
    # [safety] speed_sides = 100000000: 2.5 GB of rows, then an allocation traceback
    table = '[safety]\nfilter = "barrier"\ndistance = 0.25\nmax_speed = 1.0\n'
    scenario = tmp_path / "round.toml"
    scenario.write_text(triangle("round", "1.0") + "\n" + table + "speed_sides = 100000000\n")
    message = refused(scenario)
    assert message.startswith(f"error: {scenario}: safety.speed_sides (line "), message
    assert "at most 256, got 100,000,000" in message
    assert (
        fl.simulate(
            triangle_formation(),
            LAW,
            START,
            duration=0.01,
            safety=SafetyFilter(filter="barrier", distance=0.25, max_speed=1.0, speed_sides=256),
        ).status
        == "success"
    )


@pytest.mark.parametrize(
    ("table", "words"),
    [
        ([[1, 2]], "an alpha row is \\[i, j, k, alpha\\]"),
        ([5], "an alpha row is"),
        ([[1, 2, "a", 1]], "three robots i, j, k \\(whole numbers\\)"),
        ([[1, 2, 3.5, 1]], "three robots i, j, k \\(whole numbers\\)"),
        ({1: 1}, "three robots"),
        ({(1, 2, 3): "x"}, "alpha_123 must be a finite non-zero number, got 'x'"),
    ],
)
def test_an_alpha_table_of_odd_rows_is_refused_by_name(table, words):
    """Rows of the wrong length or kind ended in IndexError or ValueError."""
    with pytest.raises(fl.errors.FormationError, match=words) as info:
        fl.Formation.from_alpha_table(table, n=3)
    assert info.value.key == "alpha"
    f = fl.Formation.from_alpha_table([[1, 2, 3, 1.0], [3.0, 1, 2, 1]], n=3)  # floats: whole
    assert f.alpha[0, 1, 2] == 1 and f.alpha[2, 0, 1] == 1


@pytest.mark.parametrize(
    ("robots", "key"),
    [
        # points 1e150 m ahead of robots 6 m apart: the offset, not the headings
        ('model = "unicycle"\noffset = 1e150\n', "robots.offset"),
        # points beyond the coordinates' limit: the offset too (was "robots.initial hand points")
        ('model = "unicycle"\noffset = 1e200\n', "robots.offset"),
        # robots 1 and 2 face each other 0.6 m apart, points 0.35 m ahead: the headings
        ('model = "unicycle"\noffset = 0.35\nheadings = [0.0, 3.14159, 0.0]\n', "robots.headings"),
    ],
)
def test_hand_points_that_overlap_name_their_cause(robots, key, tmp_path: Path) -> None:
    text = triangle("hands", "1.0").replace("[robots]\n", "[robots]\n" + robots)
    text = text.replace("[-3.0, -3.0], [3.0, -3.0]", "[-0.3, -3.0], [0.3, -3.0]")
    scenario = tmp_path / "hands.toml"
    scenario.write_text(text)
    message = refused(scenario)
    assert message.startswith(f"error: {scenario}: {key} (line "), message


@pytest.mark.parametrize("stop", ["{ robot = 1, at = -1.0 }", '{ robot = 1, at = "x" }'])
def test_a_bad_stop_time_is_refused_at_its_line(stop: str, tmp_path: Path) -> None:
    """A stop time below 0 was refused at the [faults] header's line, as 'faults.stop at'."""
    text = triangle("stops", "1.0") + f"\n[faults]\nstop = [{stop}]\n"
    scenario = tmp_path / "stops.toml"
    scenario.write_text(text)
    line = text.splitlines().index(f"stop = [{stop}]") + 1
    message = refused(scenario)
    assert message.startswith(f"error: {scenario}: faults.stop"), message
    assert f"(line {line}): " in message, message


def test_a_lattice_spacing_too_small_for_double_precision_is_refused(tmp_path: Path) -> None:
    """spacing = 1e-300 was refused as 'robots 1, 2 and 3 are collinear' (their triple
    products underflow): now by what is wrong, the spacing."""
    from formationlab.formation.templates import SPACING_FLOOR, lattice

    text = triangle("tiny", "1.0").replace(
        'orientation = "table"\nalpha = [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]]\n',
        'template = { lattice = "triangular", count = 3, spacing = 1e-300 }\n',
    )
    scenario = tmp_path / "tiny.toml"
    scenario.write_text(text.replace("distances = 1.0\n", ""))
    message = refused(scenario)
    assert message.startswith(f"error: {scenario}: formation.template (line "), message
    assert "spacing of 1e-300 m is below 1e-50 m" in message, message
    q = lattice("square", 4, spacing=SPACING_FLOOR)  # the floor itself is a formation
    f = fl.Formation.from_template(q, diameters=0.0)
    assert f.distances.min() == pytest.approx(SPACING_FLOOR)


def test_a_huge_noise_ends_non_finite_with_a_message_not_a_traceback(tmp_path: Path) -> None:
    """A non-finite step under noisy sensing: the message used to evaluate the command again
    outside the stepping driver, which owns the measurements, and ended in a traceback."""
    scenario = tmp_path / "noisy.toml"
    scenario.write_text(triangle("noisy", "0.2") + "\n[sensing]\nnoise = 1e200\n")
    proc = subprocess.run(
        [*CLI, "run", str(scenario), "--out", str(tmp_path / "out"), "-q"],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "NaN or infinite positions" in proc.stderr and "noise = 1e+200" in proc.stderr
    assert (tmp_path / "out" / "trajectory.nc").is_file()  # what ran is kept


@pytest.mark.parametrize(
    ("obstacle", "words"),
    [
        ("polygon = [[10, 10], [1e300, 10], [10, 1e300]]", "polygon coordinates reach 1e+300"),
        ("circle = { center = [1e200, 0.0], radius = 1.0 }", "circle coordinates reach 1e+200"),
        ("circle = { center = [5.0, 5.0], radius = 1e160 }", "circle coordinates reach 1e+160"),
    ],
)
def test_an_obstacle_beyond_the_coordinate_limit_is_refused(obstacle, words, tmp_path):
    """Accepted before, with numpy's and shapely's overflow warnings in the output."""
    scenario = tmp_path / "far.toml"
    scenario.write_text(triangle("far", "0.2") + "\n[[obstacles]]\n" + obstacle + "\n")
    message = refused(scenario)
    assert f"{scenario}: obstacles, item 1 (line " in message and words in message, message
    assert "Warning" not in message


def test_a_tiny_polygon_keeps_every_vertex() -> None:
    """A closing repeat of the first vertex was tolerated to within 1e-8 m: every vertex of a
    polygon smaller than that was 'a repeat', and a triangle of 1e-9 m lost its last vertex
    (refused as 'not simple', quoting two vertices)."""
    pytest.importorskip("shapely")
    from formationlab.safety.obstacles import Polygon

    tiny = [[0.0, 0.0], [1e-9, 0.0], [1e-9, 1e-9]]
    assert Polygon(vertices=tiny).vertices.tolist() == tiny
    closed = Polygon(vertices=[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [1e-12, 0.0]])
    assert len(closed.vertices) == 3  # a repeat to within its size is still let go
