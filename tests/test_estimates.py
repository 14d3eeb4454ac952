"""Estimates before work: a study too large is refused at its key and line with a figure a
person reads, and the number of trials the refusal advises is accepted; what sizes memory
honours a memory limit; the checks of a formation are bounded; and what the scenario
fuzzer found placed at the right key (``tests/test_fuzz_scenarios.py`` replays the files).
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

import formationlab as fl
from formationlab import resources
from formationlab.cli import _load_commands, _plan, app
from formationlab.cli._app import printable
from formationlab.errors import ScenarioError
from formationlab.formation.realisability import realisability_problems
from formationlab.scenario import parse_scenario
from formationlab.validation import line_of

_load_commands()


def triangle(*, duration: float = 0.05) -> str:
    """A triangle of the distance law, steps of 0.01 s for ``duration`` seconds."""
    return (
        "[robots]\npositions = [[-1.0, -1.0], [1.0, -1.0], [0.0, 1.0]]\n[formation]\n"
        'distances = 1.0\n[controller]\nlaw = "distance"\n[simulation]\ndt = 0.01\n'
        f"duration = {duration!r}\n"
    )


def _study(tmp_path: Path, trials: int) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(f"{triangle()}[study]\ntrials = {trials}\n", encoding="utf-8")
    return path


def _line(path: Path, key: str) -> int:
    line = line_of(path.read_text(encoding="utf-8"), key)
    assert line is not None
    return line


@pytest.mark.parametrize("command", ["validate", "study"])
def test_a_study_of_too_many_trials_is_refused_at_its_key(tmp_path: Path, command: str) -> None:
    path = _study(tmp_path, 10**15)
    args = [command, str(path)] + (["--out", str(tmp_path / "out")] if command == "study" else [])
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2, res.output
    assert not isinstance(res.exception, Exception) or isinstance(res.exception, SystemExit)
    assert "Traceback" not in res.output
    assert f"study.trials (line {_line(path, 'study.trials')})" in res.output
    # figures a person reads: the trial-steps and a size in a unit
    assert "5e+15 trial-steps, more than 1e+13" in res.output
    assert re.search(r"~[\d.e+]+ [kMGT]?B of memory", res.output)
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_the_trials_option_is_named_when_it_is_too_large(tmp_path: Path) -> None:
    path = _study(tmp_path, 2)
    res = CliRunner().invoke(
        app, ["study", str(path), "--out", str(tmp_path / "o"), "--trials", str(10**14)]
    )
    assert res.exit_code == 2, res.output
    assert "--trials 100000000000000: 100,000,000,000,000 trials of 5 steps" in res.output


def test_the_trials_a_refusal_advises_are_accepted(monkeypatch) -> None:
    monkeypatch.setattr(_plan, "available_memory", lambda: 8e9)
    plan = _plan.StudyPlan(trials=10**12, groups=4, steps=15_000, robots=3)
    problem = _plan.check_study(plan)
    assert problem is not None
    most = int(re.search(r"use at most ([\d,]+) trials", problem).group(1).replace(",", ""))
    # the table binds: 0.8 x 8 GB / (4 x 864 B) = 1,851,851 trials (the trial-steps allow
    # 1e13 / (4 x 15,000) = 166,666,666)
    assert most == 1_851_851
    assert _plan.check_study(_plan.StudyPlan(trials=most, groups=4, steps=15_000, robots=3)) is None
    assert _plan.check_study(_plan.StudyPlan(trials=most + 1, groups=4, steps=15_000, robots=3))


def test_a_study_refused_by_memory_alone_says_how_much(monkeypatch) -> None:
    monkeypatch.setattr(_plan, "available_memory", lambda: 1e9)
    # 1e7 trials of 3 robots: 8 x 3 x (24 + 12) = 864 bytes each, 8.64 GB in all
    problem = _plan.check_study(_plan.StudyPlan(trials=10**7, groups=1, steps=10, robots=3))
    assert problem is not None and "~8.64 GB of memory for its table of trials" in problem
    assert "trial-steps" not in problem
    assert "use at most 925,925 trials" in problem  # 0.8 x 1e9 / 864


def test_available_memory_honours_an_address_space_limit(monkeypatch) -> None:
    import resource

    monkeypatch.setattr(resource, "getrlimit", lambda what: (4 << 30, 4 << 30))
    used = resources._meminfo("VmSize:", "/proc/self/status")
    if used is None:
        pytest.skip("no /proc/self/status on this system")
    room = resources._address_room()
    assert room is not None and abs(room - ((4 << 30) - used)) < 64 << 20
    assert resources.available_memory() <= max(room, 0.0) + (64 << 20)


def test_an_alpha_table_on_many_robots_builds_no_cube() -> None:
    n = 3000  # a dense alpha of (n, n, n) would be 216 GB
    start = time.perf_counter()
    f = fl.Formation.from_alpha_table(
        [[1, 2, 3, 1.0]], n=n, edges=[[i, i + 1] for i in range(1, n)] + [[1, 3]], distances=1.0
    )
    assert time.perf_counter() - start < 10
    assert f.restricted_triples.tolist() == [[0, 1, 2], [0, 2, 1]]
    assert f.restricted_alpha.tolist() == [1.0, -1.0]


def test_the_realisability_check_of_a_large_complete_graph_is_bounded() -> None:
    n = 400  # 10.6 million triangles, and least squares on 79,800 pairs: both skipped
    f = fl.Formation.from_distances(n, edges="complete", distances=1.0, diameters=0.01)
    start = time.perf_counter()
    problems = realisability_problems(f)
    assert time.perf_counter() - start < 10
    assert len(problems) == 1 and "multidimensional scaling" in problems[0]


def test_line_of_finds_quoted_keys_of_any_characters() -> None:
    text = '[robots]\na = 1\n"ü" = 1.0\n"\\u0000" = 2\n[x]\nk."q.r" = 3\n'
    assert line_of(text, "robots.ü") == 3
    assert line_of(text, "robots.\x00") == 4
    assert line_of(text, "x.k.q.r") == 6


def test_messages_print_control_characters_as_escapes() -> None:
    assert printable("key '\x00' and \x1b[31m\n\tok") == "key '\\x00' and \\x1b[31m\n\tok"


def test_a_bad_period_names_the_list_and_the_robot() -> None:
    text = triangle() + "[asynchronous]\nperiods = [0.01, -1.0, 0.01]\n"
    with pytest.raises(ScenarioError) as err:
        parse_scenario(text)
    assert err.value.key == "asynchronous.periods"
    line = line_of(text, "asynchronous.periods")
    assert f"asynchronous.periods (line {line}): periods, robot 2, must be" in str(err.value)


def test_a_duration_too_long_is_named_before_the_delay_it_sizes() -> None:
    text = triangle(duration=1e300) + "[sensing]\nnoise = 0.01\ndelay = 0.02\n"
    with pytest.raises(ScenarioError) as err:
        parse_scenario(text)
    assert err.value.key == "simulation.dt"  # duration / dt: the steps of the run
    assert "1e+302 steps" in str(err.value)
