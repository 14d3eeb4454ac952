"""Folders that cannot be written, optional parts missing, --force, help and messages.

Each case goes through the command line as a user types it (typer's CliRunner):
the exit status, the one ``error:`` line, no traceback, and the files on disk.
A write bit cleared on a folder is not enough when the tests run as root, so
unwritable folders are a path below a regular file, or a writer that raises
``PermissionError`` / ``ENOSPC`` (monkeypatched ``os.replace``, the last step of
every atomic write).
"""

from __future__ import annotations

import errno
import json
import os
import shutil
from pathlib import Path

import pytest
from _scenarios import triangle
from typer.testing import CliRunner, Result

from formationlab.cli import _load_commands, app
from formationlab.io import files as io_files

_load_commands()
runner = CliRunner()

SCENARIO = triangle(
    "short-triangle",
    "0.2",
    """\
[study]
trials = 4
chunk_size = 4
initial = { kind = "box", half_width = 3.0 }
""",
)


def invoke(*args: object, **kwargs: object) -> Result:
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False, **kwargs)  # type: ignore[arg-type]


def one_error_line(res: Result) -> str:
    """The single ``error:`` line of a failed command (and no traceback anywhere)."""
    assert "Traceback" not in res.output and "Traceback" not in res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, res.stderr
    return lines[0]


@pytest.fixture
def scenario(tmp_path: Path) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(SCENARIO)
    return path


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("run")
    (root / "s.toml").write_text(SCENARIO)
    res = invoke("run", root / "s.toml", "--out", root / "out", "-q")
    assert res.exit_code == 0, res.output
    return root / "out"


# ------------------------------------------------------------ folders that cannot be written

COMMANDS = {
    "run": lambda sc, out: ("run", sc, "--out", out),
    "study": lambda sc, out: ("study", sc, "--out", out),
    "equilibria": lambda sc, out: ("equilibria", sc, "--out", out, "--starts", 2),
    "paper": lambda sc, out: ("paper", "--out", out),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_an_output_path_below_a_file_is_one_line_and_exit_2(
    command: str, scenario: Path, tmp_path: Path
) -> None:
    blocker = tmp_path / "results"
    blocker.write_text("a file, not a folder")
    res = invoke(*COMMANDS[command](scenario, blocker / "run1"))
    assert res.exit_code == 2
    line = one_error_line(res)
    assert line == (
        f"error: cannot create the folder {blocker / 'run1'}: {blocker} is a file, not a "
        "folder; choose another folder"
    )
    assert blocker.read_text() == "a file, not a folder"


@pytest.mark.parametrize(
    ("code", "reason", "fix"),
    [
        (errno.EACCES, "permission denied", "choose a folder you can write to"),
        (
            errno.ENOSPC,
            "no space left on device",
            "free some space or choose a folder on another disk",
        ),
        (
            errno.EROFS,
            "read-only file system",
            "the file system is read-only; choose another folder",
        ),
    ],
)
@pytest.mark.parametrize("command", ["run", "study"])
def test_a_write_that_fails_is_one_line_naming_the_folder_and_the_reason(
    command: str,
    code: int,
    reason: str,
    fix: str,
    scenario: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    out = tmp_path / "out"

    def refuse(src: str, dst: str) -> None:
        raise OSError(code, os.strerror(code), src)

    monkeypatch.setattr(io_files.os, "replace", refuse)
    res = invoke(*COMMANDS[command](scenario, out))
    assert res.exit_code == 2
    line = one_error_line(res)
    first = "scenario.toml" if command == "run" else "manifest.json"
    folder = out if command == "run" else next((out / "chunks").iterdir())
    assert line == f"error: cannot write {first} in {folder}: {reason}; {fix}"
    leftovers = [p.name for p in out.rglob("*") if p.is_file()]
    assert leftovers == []  # the temporary file is removed, nothing half-written remains


def test_animate_into_a_folder_that_refuses_writes(
    run_folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def refuse(src: str, dst: str) -> None:
        raise PermissionError(errno.EACCES, "Permission denied", src)

    monkeypatch.setattr(io_files.os, "replace", refuse)
    res = invoke("animate", run_folder, "--format", "gif", "--frames", 3)
    assert res.exit_code == 2
    assert one_error_line(res) == (
        f"error: cannot write animation.gif in {run_folder}: permission denied; "
        "choose a folder you can write to"
    )
    assert not list(run_folder.glob("*animation*"))


def test_a_run_folder_that_cannot_be_read(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # a read error that no command expects still becomes one line naming the file
    from formationlab.cli._app import describe_os_error

    exc = PermissionError(errno.EACCES, "Permission denied", str(tmp_path / "trials.parquet"))
    assert describe_os_error(exc) == f"cannot use {tmp_path / 'trials.parquet'}: permission denied"


# ------------------------------------------------------------ optional parts


def test_mp4_without_the_video_extra(run_folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from formationlab.io import animation

    monkeypatch.setattr(animation, "ffmpeg_executable", lambda: None)
    res = invoke("animate", run_folder, "--format", "mp4")
    assert res.exit_code == 2
    assert one_error_line(res) == (
        "error: MP4 export needs the 'video' extra: pip install formationlab[video] "
        "(or an ffmpeg on the PATH)"
    )
    assert not list(run_folder.glob("animation*"))


def test_run_animate_without_the_video_extra_writes_gif_and_html(
    scenario: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from formationlab.io import animation

    monkeypatch.setattr(animation, "ffmpeg_executable", lambda: None)
    out = tmp_path / "out"
    res = invoke("run", scenario, "--out", out, "--animate", "--frames", 3)
    assert res.exit_code == 0, res.output
    assert "warning: animation.mp4 left out: MP4 export needs the 'video' extra" in res.stderr
    names = {p.name for p in out.iterdir()}
    assert {"animation.gif", "animation.html"} <= names and "animation.mp4" not in names
    manifest = json.loads((out / "summary.json").read_text())["manifest"]
    assert set(manifest) == names


# ------------------------------------------------------------ --force and the manifest


def test_force_removes_the_earlier_runs_files_and_keeps_the_users(
    scenario: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    assert invoke("run", scenario, "--out", out, "-q").exit_code == 0
    res = invoke("animate", out, "--format", "gif", "--frames", 3)
    assert res.exit_code == 0, res.output
    first = json.loads((out / "summary.json").read_text())["manifest"]
    assert "animation.gif" in first  # animate lists what it adds
    (out / "notes.txt").write_text("mine")
    res = invoke("run", scenario, "--out", out, "--force")
    assert res.exit_code == 0, res.output
    assert f"removed animation.gif of the earlier run in {out}" in res.stderr
    names = {p.name for p in out.iterdir()}
    manifest = json.loads((out / "summary.json").read_text())["manifest"]
    assert "animation.gif" not in names
    assert names == {*manifest, "notes.txt"}
    assert (out / "notes.txt").read_text() == "mine"


def test_force_on_a_folder_without_a_manifest_removes_known_outputs(
    scenario: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "animation.mp4").write_bytes(b"old")
    (out / "old_plot.png").write_bytes(b"old")
    (out / "data.csv").write_text("the user's")
    res = invoke("run", scenario, "--out", out, "--force", "-q")
    assert res.exit_code == 0, res.output
    names = {p.name for p in out.iterdir()}
    assert "animation.mp4" not in names and "old_plot.png" not in names
    assert "data.csv" in names


def test_study_force_replaces_an_earlier_study(scenario: Path, tmp_path: Path) -> None:
    out = tmp_path / "st"
    assert invoke("study", scenario, "--out", out).exit_code == 0
    (out / "shapes_old-law.png").write_bytes(b"stale")
    stale_chunks = out / "chunks" / "0123456789abcdef"
    stale_chunks.mkdir()
    (stale_chunks / "manifest.json").write_text("{}")
    res = invoke("study", scenario, "--out", out, "--force", "--trials", 2)
    assert res.exit_code == 0, res.output
    assert not (out / "shapes_old-law.png").exists()
    assert not stale_chunks.exists()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["trials_per_group"] == 2
    assert {p.name for p in out.iterdir()} == set(summary["manifest"])


# ------------------------------------------------------------ help and messages

ALL_COMMANDS = ("run", "validate", "animate", "study", "equilibria", "paper")


@pytest.mark.parametrize("command", ALL_COMMANDS)
def test_help_shows_conventional_usage_and_flags_without_a_type(command: str) -> None:
    res = invoke(command, "--help", env={"COLUMNS": "100"})
    assert res.exit_code == 0
    assert "<bool>" not in res.output
    assert "{" not in res.output.split("Usage:")[1].splitlines()[0]
    usage = res.output.split("Usage:")[1].splitlines()[0].split()
    expected = {
        "run": "SCENARIO",
        "validate": "SCENARIOS...",
        "animate": "FOLDER",
        "study": "SCENARIO",
        "equilibria": "SCENARIO",
    }
    if command in expected:
        assert usage[-1] == expected[command]
    else:
        assert usage[-1] == "[OPTIONS]"


def _help_words(command: str) -> list[str]:
    """Every word of a command's own help: its docstring and its parameters' help."""
    import typer.main

    group = typer.main.get_command(app)
    cmd = group.commands[command]  # type: ignore[attr-defined]
    texts = [cmd.help or "", *(getattr(p, "help", None) or "" for p in cmd.params)]
    return " ".join(texts).split()


@pytest.mark.parametrize("command", [*ALL_COMMANDS, "view"])
def test_help_at_80_columns_keeps_brackets_and_whole_words(command: str) -> None:
    res = invoke(command, "--help", env={"COLUMNS": "80"})
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert max(len(ln) for ln in lines) <= 80, res.output
    assert "…" not in res.output
    shown = res.output.split()
    # each word of the help is shown whole, brackets and hyphens kept ("[study]",
    # "formationlab[view]", "barrier-decentralized", "--from-study")
    missing = [w for w in _help_words(command) if w not in shown]
    assert not missing, (missing, res.output)


def test_the_bracketed_words_that_rich_swallowed_are_shown() -> None:
    view = invoke("view", "--help", env={"COLUMNS": "80"}).output
    assert "formationlab[view]`." in view.split()
    validate = invoke("validate", "--help", env={"COLUMNS": "80"}).output
    assert "([study] and [equilibria] too)." in " ".join(validate.split())
    study = invoke("study", "--help", env={"COLUMNS": "80"}).output
    assert '"barrier-decentralized"' in study.split() and "[safety]" in study.split()


def test_the_root_help_summarises_each_command_in_whole_words() -> None:
    res = invoke("--help", env={"COLUMNS": "80"})
    words = " ".join(res.output.split())
    assert "..." not in res.output.split("Commands:")[1]
    assert "figures 4-12, summary.json." in words  # the whole first line, wrapped


def test_root_help_has_no_bool_types() -> None:
    res = invoke("--help", env={"COLUMNS": "100"})
    assert res.exit_code == 0 and "--version" in res.output and "<bool>" not in res.output


def test_validate_counts_in_singular_and_plural(tmp_path: Path) -> None:
    two = tmp_path / "two.toml"
    two.write_text(
        SCENARIO.replace("[[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]", "[[-3.0, -3.0], [3.0, -3.0]]")
        .replace('orientation = "table"\n', "")
        .replace("alpha = [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]]\n", "")
        .replace('law = "angle-restricted"', 'law = "distance"')
        .replace("k_a = 3.0\ntheta = 0.5\n", "")
    )
    res = invoke("validate", two, tmp_path / "missing.toml")
    assert ", 2 robots, 1 edge (rigid)," in res.stdout, res.output


def test_the_distances_length_error_points_at_formation_distances(tmp_path: Path) -> None:
    path = tmp_path / "d.toml"
    path.write_text(SCENARIO.replace("distances = 1.0", "distances = [1.0, 1.0]"))
    res = invoke("validate", path)
    assert res.exit_code == 2
    assert f"error: {path}: formation.distances (line 7):" in res.stderr


def test_validate_and_run_print_the_size_of_the_run(scenario: Path, tmp_path: Path) -> None:
    res = invoke("validate", scenario)
    assert res.exit_code == 0
    assert "    200 steps, all saved: ~" in res.stdout
    assert "of memory, trajectory.nc at most ~" in res.stdout
    res = invoke("run", scenario, "--out", tmp_path / "o", "--save-every", 10)
    assert res.exit_code == 0
    assert "short-triangle: 200 steps, 21 saved: ~" in res.stderr


# ------------------------------------------------------------ files that cannot be read


def test_resume_over_a_damaged_chunk_names_it(scenario: Path, tmp_path: Path) -> None:
    out = tmp_path / "st"
    assert invoke("study", scenario, "--out", out).exit_code == 0
    chunk = next((out / "chunks").glob("*/g*-c*.parquet"))
    chunk.write_bytes(b"not parquet")
    res = invoke("study", scenario, "--out", out, "--resume")
    assert res.exit_code == 2
    line = one_error_line(res)
    assert line.startswith(f"error: cannot read {chunk} as a trials table (parquet): ")
    assert line.endswith("; delete it and resume again to rerun that chunk")


def test_equilibria_from_a_damaged_study_names_the_file(scenario: Path, tmp_path: Path) -> None:
    study = tmp_path / "st"
    study.mkdir()
    (study / "trials.parquet").write_bytes(b"PAR1 but not really")
    res = invoke(
        "equilibria", scenario, "--out", tmp_path / "eq", "--from-study", study, "--starts", 0
    )
    assert res.exit_code == 2
    line = one_error_line(res)
    assert line.startswith(
        f"error: cannot read {study / 'trials.parquet'} as a study's trials table: "
    )


@pytest.mark.parametrize("module", ["qpsolvers", "shapely"])
@pytest.mark.parametrize("command", ["validate", "run"])
def test_a_scenario_that_needs_the_safety_extra_says_which_to_install(
    tmp_path: Path, command: str, module: str
) -> None:
    # the plain install: the safety extra's modules cannot be imported (None in sys.modules)
    import subprocess
    import sys

    child = f"import sys; sys.modules[{module!r}] = None\nfrom formationlab.cli import main; main()"
    example = Path(__file__).parents[1] / "examples" / "ten-robots-gap.toml"
    out = tmp_path / "out"
    args = [command, str(example)] + (["--out", str(out)] if command == "run" else [])
    proc = subprocess.run(
        [sys.executable, "-c", child, *args], capture_output=True, text=True, timeout=300,
        check=False,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "ModuleNotFoundError" not in proc.stderr
    assert proc.stderr.strip() == (
        f"error: {example}: [safety] (line 54): safety filters and obstacles need the optional "
        f"part 'safety', which is not installed (no module {module!r}): "
        'pip install "formationlab[safety]"'
    )
    assert not out.exists()


def test_animation_formats_as_a_comma_separated_list(run_folder: Path, tmp_path: Path) -> None:
    # like the figures' --format png,pdf: a list in one option (or the option repeated)
    out = shutil.copytree(run_folder, tmp_path / "out")  # (the module's run stays unanimated)
    res = invoke("animate", out, "--format", "gif,html", "--frames", 3)
    assert res.exit_code == 0, res.output
    assert {p.name for p in out.glob("animation.*")} == {"animation.gif", "animation.html"}
    res = invoke("animate", out, "--format", "gif,jpg", "--frames", 3, "--force")
    assert res.exit_code == 2
    assert one_error_line(res) == (
        "error: unknown animation format 'jpg': choose from gif, mp4, html "
        "(a comma-separated list, e.g. --format gif,html)"
    )


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--trials", "-3"], "--trials takes a whole number of at least 1, not '-3'; "
         "give e.g. --trials 1"),
        (["-n", "0"], "--trials takes a whole number of at least 1, not '0'"),
        (["--seed", "-1"], "--seed takes a whole number from 0 to 9,223,372,036,854,775,807, "
         "not '-1'; give e.g. --seed 0"),
        (["--seed=2e3"], "--seed takes a whole number from 0 to"),
        (["--chunk-size", "abc"], "--chunk-size takes a whole number of at least 1, not 'abc'"),
    ],
)  # fmt: skip
def test_an_option_out_of_range_is_one_line_naming_it_its_value_and_the_fix(
    scenario: Path, tmp_path: Path, args: list[str], said: str
) -> None:
    """typer's words were pydantic's ("Input should be greater than or equal to 1"), under
    a usage block, without the value given or a fix."""
    res = invoke("study", scenario, "--out", tmp_path / "out", *args)
    assert res.exit_code == 2
    assert "Traceback" not in res.output and "Input should" not in res.output
    assert one_error_line(res).startswith(f"error: {said}"), res.output
    assert not (tmp_path / "out").exists()
    res = invoke("run", scenario, "--out", tmp_path / "out", "--save-every", "0")
    assert one_error_line(res) == (
        "error: --save-every takes a whole number of at least 1, not '0'; give e.g. --save-every 1"
    )
