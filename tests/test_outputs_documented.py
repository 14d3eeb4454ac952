"""Every column of ``trials.parquet`` and every key of ``summary.json`` is defined in
docs/outputs.md: a small study and a small run of the triangle among obstacles under a
filter write their files, and each name they hold must be in the page's tables."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from formationlab.cli import _load_commands, app

_load_commands()
runner = CliRunner()

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "outputs.md"

#: the triangle among a disc and a triangle, under the decentralized filter, a sweep of
#: k_a and unicycle-free single integrators: every kind of column a study of it writes
SCENARIO = (
    (ROOT / "examples" / "triangle-obstacle.toml")
    .read_text()
    .replace("duration = 15.0", "duration = 0.05")
    .replace(
        "chunk_size = 250",
        "chunk_size = 4\ntrials = 4\nduration = 0.05\n[study.sweep]\nk_a = [1.0, 3.0]",
    )
    .replace("trials = 1000\n", "")
    .replace(
        'laws = ["distance", "angle-restricted", "squared-distance", "signed-area"]',
        'laws = ["angle-restricted"]',
    )
)


def _tables(text: str) -> dict[str, set[str]]:
    """The names in the first column of each table of the page, by the heading (or the
    line ending in ``:``) just above it."""
    out: dict[str, set[str]] = {}
    title = ""
    for line in text.splitlines():
        if line.startswith("#") or (line.endswith(":") and not line.startswith("|")):
            title = line.lstrip("#").strip()
        elif line.startswith("| `"):
            cell = line.split("|")[1]
            out.setdefault(title, set()).update(re.findall(r"`([^`]+)`", cell))
    return out


def _generic(column: str, swept: set[str]) -> str:
    """A column's name in the page: per-robot columns with ``<i>``, swept ones generic."""
    if column in swept:
        return "<swept parameter>"
    return re.sub(r"^(x|y|z|theta)\d+(_init)?$", r"\1<i>\2", column)


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> dict[str, object]:
    folder = tmp_path_factory.mktemp("outputs")
    path = folder / "s.toml"
    path.write_text(SCENARIO)
    res = runner.invoke(app, ["study", str(path), "--out", str(folder / "study")])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["run", str(path), "--out", str(folder / "run")])
    assert res.exit_code == 0, res.output
    return {
        "trials": pd.read_parquet(folder / "study" / "trials.parquet"),
        "study": json.loads((folder / "study" / "summary.json").read_text()),
        "run": json.loads((folder / "run" / "summary.json").read_text()),
    }


def test_the_page_parses_into_its_tables():
    tables = _tables(PAGE.read_text())
    assert {"trials.parquet", "summary.json of a study", "summary.json of a run"} <= set(tables)
    assert "min_robot_clearance" in tables["trials.parquet"]
    assert "x<i>_init" in tables["trials.parquet"]
    assert "below_safety_distance" in tables["Its `safety`:"]


def test_every_column_of_trials_parquet_is_documented(written):
    doc = _tables(PAGE.read_text())["trials.parquet"]
    swept = set(written["study"]["sweep"])
    assert swept == {"k_a"}
    columns = {_generic(c, swept) for c in written["trials"].columns}
    assert "min_obstacle_clearance" in columns and "<swept parameter>" in columns
    assert columns - doc == set(), "columns of trials.parquet missing from docs/outputs.md"


def test_every_key_of_summary_json_is_documented(written):
    tables = _tables(PAGE.read_text())
    study, run = written["study"], written["run"]
    assert set(study) - tables["summary.json of a study"] == set()
    for group in study["groups"]:
        assert set(group) - tables["Each entry of `groups`:"] == set()
    assert set(run) - tables["summary.json of a run"] == set()
    assert set(run["safety"]) - tables["Its `safety`:"] == set()
    assert "safety" in run and "below_safety_distance" in run  # (what the page defines)
