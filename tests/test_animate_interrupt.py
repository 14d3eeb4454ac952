"""SIGINT and SIGTERM to ``animate`` at its start, mid-way, its last file and at the very end
of writing; and a signal that comes as any command ends.

Each signal lands where the program printed a line (``_paused``: it waits there for the
signal), never after a sleep. Each ends with ``128 +`` the signal, a message that says which
animations were written whole, the manifest listing exactly those, no temporary file and
every other file of the run's folder as it was.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _paused import interrupted
from _scenarios import triangle
from typer.testing import CliRunner

from formationlab.cli import _load_commands, app
from formationlab.io.animation import missing_writer

_load_commands()

needs_ffmpeg = pytest.mark.skipif(missing_writer("mp4") is not None, reason="no ffmpeg")


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A finished run's folder (the paper's triangle for 1 s), without animations."""
    base = tmp_path_factory.mktemp("animate")
    scenario = base / "s.toml"
    scenario.write_text(triangle("animated", "1.0"))
    out = base / "run"
    done = CliRunner().invoke(app, ["run", str(scenario), "--out", str(out), "-q"])
    assert done.exit_code == 0, done.output
    return out


def _copy(run: Path, tmp_path: Path) -> tuple[Path, dict[str, bytes]]:
    folder = tmp_path / "run"
    shutil.copytree(run, folder)
    return folder, {p.name: p.read_bytes() for p in folder.iterdir()}


def _listed(folder: Path) -> list[str]:
    return json.loads((folder / "summary.json").read_text())["manifest"]


def _check(folder: Path, before: dict[str, bytes], written: list[str]) -> None:
    """The run's files as they were, the animations ``written`` whole and listed, nothing
    else (no temporary file, no lock)."""
    names = {p.name for p in folder.iterdir()}
    assert names == set(before) | set(written), names
    for name, data in before.items():
        if name != "summary.json":
            assert (folder / name).read_bytes() == data, name
    assert _listed(folder) == [*json.loads(before["summary.json"])["manifest"], *written]


POINTS = [
    # (marker, formats, written whole before the signal)
    ("writing animation.gif ...", "gif,html", []),  # its start: the first file's first frame
    # mid-way: as the encoder starts
    pytest.param(
        "writing animation.mp4 ...", "gif,mp4,html", ["animation.gif"], marks=needs_ffmpeg
    ),
    ("writing animation.html ...", "gif,html", ["animation.gif"]),  # its last file
]


@pytest.mark.parametrize(("marker", "formats", "written"), POINTS)
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_while_animating_keeps_the_whole_files_and_says_which(
    finished_run: Path, tmp_path: Path, marker: str, formats: str, written: list[str], sig: int
) -> None:
    folder, before = _copy(finished_run, tmp_path)
    args = ["animate", str(folder), "--format", formats, "--frames", "30"]
    status, out = interrupted(args, marker, sig)
    assert status == 128 + sig, out
    assert "Traceback" not in out and "error:" not in out and "Exception ignored" not in out
    assert out.count(marker) == 1, out  # said once (an interrupted print was said again)
    said = out.strip().splitlines()[-1]
    left = [f"animation.{f}" for f in formats.split(",") if f"animation.{f}" not in written]
    if written:
        assert said == (
            f"interrupted; {', '.join(written)} written whole in {folder} (not {', '.join(left)})"
        )
    else:
        assert said == f"interrupted before an animation was written whole; {folder} is as it was"
    _check(folder, before, written)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_at_the_end_of_writing_is_said_with_every_file_whole(
    finished_run: Path, tmp_path: Path, sig: int
) -> None:
    folder, before = _copy(finished_run, tmp_path)
    # the last line the command prints: its last file written, the manifest listing it
    status, out = interrupted(
        ["animate", str(folder), "--format", "html"], f"wrote {folder}/animation.html", sig
    )
    assert status == 128 + sig, out
    assert "Traceback" not in out and "error:" not in out
    assert out.strip().splitlines()[-1] == f"interrupted; animation.html written whole in {folder}"
    _check(folder, before, ["animation.html"])


#: ``formationlab`` with a SIGTERM that comes once the command's work is done, as it lets go
#: of its output folder's claim
_LATE = """\
import signal
from formationlab.cli import _app, main
release = _app._release_claims
def late():
    release()
    signal.raise_signal(signal.SIGTERM)
_app._release_claims = late
main()
"""


def test_a_signal_as_the_command_ends_is_not_lost(finished_run: Path, tmp_path: Path) -> None:
    folder, before = _copy(finished_run, tmp_path)
    proc = subprocess.run(
        [sys.executable, "-c", _LATE, "animate", str(folder), "--format", "html"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    # was "Aborted!" and 1 (click's word for a KeyboardInterrupt that reached it)
    assert proc.returncode == 143, proc.stderr
    assert "Traceback" not in proc.stderr and "Aborted" not in proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        "interrupted as the command ended; what it wrote is whole (as it said above)"
    )
    assert proc.stdout == f"wrote {folder}/animation.html\n"
    _check(folder, before, ["animation.html"])


#: ``formationlab`` with a SIGTERM as ``run`` lets go of an earlier run's files, its last step
_LATE_RUN = """\
import signal
from formationlab.io import files
remove_stale = files.remove_stale
def late(*args):
    removed = remove_stale(*args)
    signal.raise_signal(signal.SIGTERM)
    return removed
files.remove_stale = late
from formationlab.cli import main
main()
"""


def test_a_signal_as_run_ends_keeps_its_results_listed_and_says_so(tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(triangle("ending", "0.5"))
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, "-c", _LATE_RUN, "run", str(scenario), "--out", str(out),
         "--animate", "--frames", "10", "-q"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 143, proc.stderr  # was "interrupted" alone: what was kept?
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        f"interrupted as the run ended; its results are whole in {out}"
    )
    summary = json.loads((out / "summary.json").read_text())
    assert {"animation.gif", "animation.html"} <= set(summary["manifest"])
    assert {p.name for p in out.iterdir()} == set(summary["manifest"])


@needs_ffmpeg
def test_a_signal_as_the_encoder_starts_leaves_no_encoder_and_no_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the signal arrives inside subprocess.Popen, once ffmpeg runs: matplotlib never learnt
    # of the process, which wrote the temporary file after it had been removed
    from formationlab.io.animation import save_animation
    from formationlab.plotting.animation import animate_run

    q = np.array([[[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]]] * 3)
    anim = animate_run(
        np.arange(3.0), q, edges=np.array([[0, 1], [1, 2]]), diameters=np.full(3, 0.1), title="t"
    )
    started: list[subprocess.Popen[bytes]] = []
    popen = subprocess.Popen

    def signalled_popen(*args, **kwargs):
        started.append(popen(*args, **kwargs))  # (kept: its input stays open)
        signal.raise_signal(signal.SIGINT)  # Python's handler: KeyboardInterrupt
        return started[-1]

    monkeypatch.setattr(subprocess, "Popen", signalled_popen)
    with pytest.raises(KeyboardInterrupt):
        save_animation(anim, tmp_path / "animation", formats=["mp4"])
    monkeypatch.undo()
    (encoder,) = started
    assert encoder.poll() is not None  # ended (it kept waiting for frames)
    assert encoder.stdin is not None and encoder.stdin.closed
    assert list(tmp_path.iterdir()) == []  # no half-written file, no temporary one


def test_an_interrupted_message_is_printed_once(capsys: pytest.CaptureFixture[str]) -> None:
    # rich keeps what it was writing when a signal stops the write, and printed it again
    # with the next message
    from formationlab.cli._app import err_console

    class Stopping:
        def __init__(self) -> None:
            self.text = ""

        def write(self, text: str) -> int:
            stop = not self.text
            self.text += text
            if stop:
                raise KeyboardInterrupt  # as a signal does once the line is out
            return len(text)

        def flush(self) -> None:
            pass

    stream = Stopping()
    old = sys.stderr
    sys.stderr = stream  # type: ignore[assignment]
    try:
        with pytest.raises(KeyboardInterrupt):
            err_console.print("first", markup=False, highlight=False)
        err_console.print("second", markup=False, highlight=False)
    finally:
        sys.stderr = old
    assert stream.text == "first\nsecond\n"
