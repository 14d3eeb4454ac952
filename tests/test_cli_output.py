"""What the commands print: any scenario name without font warnings, a study table that
fits the terminal, the kernel compilation announced and kept out of the throughput, one
consistent verdict per run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from _scenarios import triangle
from typer.testing import CliRunner, Result

from formationlab.cli import _load_commands, app
from formationlab.cli.run import _verdict
from formationlab.plotting import fonts

_load_commands()
runner = CliRunner()

SCENARIO = triangle(
    "NAME",
    "0.3",
    """\
[study]
trials = 30
chunk_size = 30
initial = { kind = "box", half_width = 3.0 }
laws = ["distance", "angle-restricted", "squared-distance", "signed-area"]
[study.sweep]
k_a = [0.5, 3.0]
""",
)

UNICODE = "Fórmation — 三角形 $5"


def invoke(*args: object, env: dict[str, str] | None = None) -> Result:
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False, env=env)


# ------------------------------------------------------------ any scenario name


def test_displayable_keeps_what_a_font_has_and_replaces_the_rest() -> None:
    shown = fonts.displayable(UNICODE)
    missing = fonts.missing_characters(UNICODE)
    assert "DejaVu Sans" in fonts.font_families()
    assert "ó" not in missing and "—" not in missing  # DejaVu Sans has them
    for original, drawn in zip(UNICODE.replace("$", ""), shown.replace("\\$", ""), strict=True):
        assert drawn == ("?" if original in missing else original)
    assert "\\$5" in shown  # not the start of a formula


def test_a_unicode_name_draws_without_warnings(tmp_path: Path) -> None:
    path = tmp_path / "u.toml"
    path.write_text(SCENARIO.replace("NAME", UNICODE))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a glyph warning would fail the run
        res = invoke("run", path, "--out", tmp_path / "o", "--animate", "--frames", 3)
    assert res.exit_code == 0, res.output
    assert "UserWarning" not in res.stderr and "Glyph" not in res.stderr
    missing = fonts.missing_characters(UNICODE)
    if missing:
        assert f"note: the figures show ? for {missing}: no installed font" in res.stderr


def test_a_unicode_name_in_a_subprocess_prints_no_warning(tmp_path: Path) -> None:
    # the user's terminal: no pytest filters, warnings printed with their source lines
    path = tmp_path / "u.toml"
    path.write_text(SCENARIO.replace("NAME", UNICODE))
    proc = subprocess.run(
        [sys.executable, "-c", "from formationlab.cli import main; main()", "run", str(path),
         "--out", str(tmp_path / "o")],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "Warning" not in proc.stderr and "Traceback" not in proc.stderr


# ------------------------------------------------------------ the study table


@pytest.fixture(scope="module")
def study_out(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("study")
    path = root / "s.toml"
    path.write_text(SCENARIO.replace("NAME", "table-study"))
    out = root / "out"
    res = invoke("study", path, "--out", out, env={"COLUMNS": "80"})
    assert res.exit_code == 0, res.output
    return path, out


def table_lines(output: str) -> list[str]:
    lines = output.splitlines()
    start = next(i for i, ln in enumerate(lines) if "outcome fractions" in ln)
    end = next(i for i, ln in enumerate(lines) if "trial-steps in" in ln)
    return lines[start:end]


@pytest.mark.parametrize("columns", [80, 100])
def test_the_study_table_fits_the_terminal(
    study_out: tuple[Path, Path], columns: int, tmp_path: Path
) -> None:
    path, _ = study_out
    res = invoke("study", path, "--out", tmp_path / "o", env={"COLUMNS": str(columns)})
    assert res.exit_code == 0
    lines = table_lines(res.stdout)
    assert max(len(ln) for ln in lines) <= columns
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    text = "\n".join(lines)
    for g in summary["groups"]:  # every fraction and interval is in the table, unabridged
        for o in summary["outcomes"]:
            lo, hi = g["ci95"][o]
            assert f"{g['fractions'][o]:.3f}" in text
            assert f"{lo:.3f}-{hi:.3f}" in text
    assert "angle-restricted" in text and "…" not in text


def test_a_quiet_study_prints_nothing_but_writes_the_same_trials(
    study_out: tuple[Path, Path], tmp_path: Path
) -> None:
    path, out = study_out
    res = invoke("study", path, "--out", tmp_path / "q", "--quiet")
    assert res.exit_code == 0
    assert res.output == ""  # no progress, notes, table or "wrote" line
    assert (tmp_path / "q" / "trials.parquet").read_bytes() == (out / "trials.parquet").read_bytes()


def test_a_wide_terminal_gets_one_line_per_group(
    study_out: tuple[Path, Path], tmp_path: Path
) -> None:
    path, _ = study_out
    res = invoke("study", path, "--out", tmp_path / "o", env={"COLUMNS": "200"})
    lines = table_lines(res.stdout)
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    g = summary["groups"][0]
    lo, hi = g["ci95"]["desired"]
    row = next(ln for ln in lines if ln.startswith("│ distance "))
    assert f"{g['fractions']['desired']:.3f} [{lo:.3f}, {hi:.3f}]" in row
    assert max(len(ln) for ln in lines) <= 200


@pytest.mark.slow
def test_the_first_study_announces_the_compilation_and_times_it_apart(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text(SCENARIO.replace("NAME", "cold").replace("trials = 30", "trials = 8"))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache"), "COLUMNS": "120"}
    cmd = [sys.executable, "-c", "from formationlab.cli import main; main()", "study", str(path)]

    cold = subprocess.run([*cmd, "--out", str(tmp_path / "a")], capture_output=True, text=True,
                          env=env, check=False)  # fmt: skip
    assert cold.returncode == 0, cold.stderr
    assert "compiling kernels (once; later studies load them from the cache) ..." in cold.stderr
    s = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert s["compile_time_s"] > 1.0  # a cold numba cache: seconds
    assert s["trial_steps_per_s"] == pytest.approx(s["trial_steps"] / s["wall_time_s"])
    assert f"after {s['compile_time_s']:.1f} s preparing the compiled kernels" in cold.stdout

    warm = subprocess.run([*cmd, "--out", str(tmp_path / "b")], capture_output=True, text=True,
                          env=env, check=False)  # fmt: skip
    assert warm.returncode == 0, warm.stderr
    assert "compiling kernels" not in warm.stderr
    w = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert w["compile_time_s"] < s["compile_time_s"]


# ------------------------------------------------------------ the verdict of a run


def summary(outcome: str, converged: float | None, speed: float, error: float) -> dict:
    return {
        "outcome": outcome,
        "converged_time": converged,
        "final_time": 20.0,
        "final_speed": speed,
        "net_speed": speed,
        "max_distance_error": error,
        "tolerances": {"distance": 0.01, "speed": 0.001, "window": 0.01},
    }


def test_a_desired_shape_still_moving_is_said_in_one_breath() -> None:
    # the ten-robots case: error just under the tolerance while still moving
    line = _verdict(summary("desired", None, 0.0012, 0.00981))
    assert line == (
        "outcome desired, max |r_ij - d_ij| = 0.00981 (within the tolerance 0.01), "
        "still moving at the end (0.0012 m/s > 0.001); ran to t = 20 s"
    )
    assert "not converged" not in line


def test_the_other_verdicts() -> None:
    assert _verdict(summary("desired", 2.25, 0.0, 1e-14)) == (
        "outcome desired, max |r_ij - d_ij| = 1e-14, converged at t = 2.25 s; ran to t = 20 s"
    )
    assert _verdict(summary("not-converged", None, 1.4, 0.364)) == (
        "outcome not-converged, max |r_ij - d_ij| = 0.364, still moving at the end "
        "(1.4 m/s > 0.001); ran to t = 20 s"
    )


def test_run_prints_the_verdict(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text(SCENARIO.replace("NAME", "short").replace("duration = 0.3", "duration = 1.0"))
    res = invoke("run", path, "--out", tmp_path / "o")
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert res.stdout.strip() == f"short: {_verdict(s)}; wrote {tmp_path / 'o'}/"
    # when the robots stopped and how long the run lasted (trajectory.nc's end), both said
    assert f"ran to t = {s['final_time']:.4g} s" in res.stdout and s["final_time"] == 1.0
    if s["converged_time"] is not None:
        assert f"converged at t = {s['converged_time']:.3g} s" in res.stdout
