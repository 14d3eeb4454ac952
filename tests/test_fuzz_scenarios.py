"""The scenario fuzzer: drawn scenario files, valid and broken, through every command.

Every command ends with status 0, 1, 2 or 130, without a traceback, a stray warning, an
abort or an out-of-memory death, within :data:`_fuzz.COMMAND_SECONDS` (the commands run
in a worker process under a memory limit, ``tests/_fuzz.py``), and a refusal names the key
that was changed and its line. ``validate`` sees many files; the files it accepts also go
through ``run`` (a few steps), ``study`` (a few trials), ``equilibria`` (a few starts) and
``animate``, and a file it refuses is refused by ``run`` with the same message.

Budget: the default profile keeps the module under about 40 s; ``FORMATIONLAB_FUZZ=long``
selects a long one for a local hunt. What a hunt finds is kept in ``tests/data/fuzz_corpus/``
(one file per case, its expected ending in its first line) and replayed below.
"""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest
from _fuzz import Drawn, Worker, outcome_problem, refusal_problem, scenarios
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

settings.register_profile(
    "fuzz-ci", max_examples=150, deadline=None, derandomize=True, database=None,
    suppress_health_check=list(HealthCheck),
)  # fmt: skip
settings.register_profile(
    "fuzz-long", max_examples=3000, deadline=None, suppress_health_check=list(HealthCheck)
)
_LONG = os.environ.get("FORMATIONLAB_FUZZ") == "long"
_PROFILE = settings.get_profile("fuzz-long" if _LONG else "fuzz-ci")
#: examples of the commands after validate (each a run, a study, equilibria, an animation)
_COMMANDS = settings(_PROFILE, max_examples=1000 if _LONG else 8)

CORPUS = Path(__file__).parent / "data" / "fuzz_corpus"


@pytest.fixture(scope="module")
def worker() -> Iterator[Worker]:
    w = Worker()
    yield w
    w.close()


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


def _write(folder: Path, drawn: Drawn) -> Path:
    path = folder / "drawn.toml"
    path.write_text(drawn.text, encoding="utf-8")
    return path


def _check(worker: Worker, args: list[str], drawn: Drawn) -> dict:
    answer = worker.invoke(args)
    problem = outcome_problem(answer)
    assert problem is None, f"{' '.join(args[:1])} of {drawn.change}:\n{drawn.text}\n{problem}"
    return answer


@settings(_PROFILE)
@given(drawn=scenarios())
def test_validate_ends_cleanly_and_names_the_changed_key(
    worker: Worker, folder: Path, drawn: Drawn
) -> None:
    path = _write(folder, drawn)
    answer = _check(worker, ["validate", str(path)], drawn)
    if answer["exit"] == 2:
        problem = refusal_problem(drawn, answer["output"])
        assert problem is None, f"{drawn.change}:\n{drawn.text}\n{problem}"


@_COMMANDS
@given(drawn=scenarios(), save_every=st.sampled_from([1, 2]))
def test_every_command_ends_cleanly(
    worker: Worker, folder: Path, drawn: Drawn, save_every: int
) -> None:
    path = _write(folder, drawn)
    checked = _check(worker, ["validate", str(path)], drawn)
    out = folder / "out"
    shutil.rmtree(out, ignore_errors=True)
    run = ["run", str(path), "--out", str(out / "run"), "-q", "--save-every", str(save_every)]
    answer = _check(worker, run, drawn)
    if checked["exit"] == 2:  # refused: by run too, with the same message
        assert answer["exit"] == 2
        assert _errors(answer["output"]) == _errors(checked["output"])
        return
    if answer["exit"] in (0, 1):
        _check(worker, ["animate", str(out / "run"), "--frames", "3", "--format", "gif"], drawn)
    study = ["study", str(path), "--out", str(out / "study"), "-q", "--trials", "2"]
    _check(worker, [*study, "--duration", "0.05", "--dt", "0.01"], drawn)
    equilibria = ["equilibria", str(path), "--out", str(out / "eq"), "-q", "--starts", "2"]
    _check(worker, [*equilibria, "--duration", "0.1"], drawn)


def _errors(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("error:")]


# ------------------------------------------------------------------------ the corpus

_EXPECT = re.compile(r"#\s*expect:\s*exit\s+(\d+)(?:\s+key\s+(\S+)\s+line\s+(\d+))?")


def _corpus() -> list[Path]:
    return sorted(CORPUS.glob("*.toml"))


def _expected(path: Path) -> tuple[int, str | None, int | None]:
    """``# expect: exit 2 key sensing.delay line 12`` (or ``# expect: exit 0``), line 1."""
    m = _EXPECT.match(path.read_text(encoding="utf-8").splitlines()[0])
    assert m, f"{path.name}: its first line must be '# expect: exit N [key K line L]'"
    return int(m.group(1)), m.group(2), int(m.group(3)) if m.group(3) else None


@pytest.mark.parametrize("path", _corpus(), ids=lambda p: p.stem)
def test_corpus_case(worker: Worker, tmp_path: Path, path: Path) -> None:
    """A case the fuzzer found: validate and the command that reads the key's table (run,
    study, equilibria) end as recorded, at the recorded key and line."""
    status, key, line = _expected(path)
    table = (key or "").split(".")[0]
    command = table if table in ("study", "equilibria") else "run"  # the table's reader
    for args in (["validate", str(path)], [command, str(path), "--out", str(tmp_path), "-q"]):
        answer = worker.invoke(args)
        problem = outcome_problem(answer)
        assert problem is None, f"{args[0]} {path.name}: {problem}"
        assert answer["exit"] == status, answer["output"]
        if key is not None:
            assert f"{key} (line {line})" in answer["output"], answer["output"]
        if status == 2:
            assert "Traceback" not in answer["output"]


def test_corpus_is_not_empty() -> None:
    assert len(_corpus()) >= 5
