"""A run or a trial whose robots come closer than the safety filter's ``D_s`` says so.

The paper's continuous condition with a huge ``gamma`` and a coarse step lets a pair jump
inside ``D_s`` (docs/safety.md, "Discrete-time safety of an Euler step"): ``formationlab
run`` prints it in its verdict and a warning and writes ``below_safety_distance`` in
``summary.json``; a study writes it per trial in ``trials.parquet`` and counts it per group
in ``summary.json``. The discrete condition (the default) keeps every pair apart at every
step: nothing is flagged for a start that is clear. ``SafetyFilter.below`` decides, in one
place, for the compiled loop and the numpy driver alike.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from formationlab.cli import _load_commands, app
from formationlab.safety import SafetyFilter
from formationlab.safety.config import BELOW_TOLERANCE

_load_commands()
runner = CliRunner()

#: the paper's triangle pulled hard (k_c = 20) under the centralized filter with the
#: continuous condition, gamma = 1e6 and dt = 0.02: from this start (every pair at least
#: 0.97 m apart, D_s = 0.9) robots come 0.884 m apart, and the run still ends `desired`
SCENARIO = """\
name = "{name}"

[robots]
positions = [[-2.93, -2.87], [0.59, -1.83], [-2.29, 1.97]]
diameters = 0.2

[formation]
edges = "complete"
distances = 1.0
orientation = "table"
alpha = [[1, 2, 3, -1.0], [3, 1, 2, -1.0], [2, 1, 3, 1.0]]

[controller]
law = "angle-restricted"
k_c = 20.0

[simulation]
integrator = "euler"
dt = 0.02
duration = 0.5

[safety]
filter = "barrier"
distance = 0.9
gamma = 1e6
condition = "{condition}"

[study]
trials = 20
initial = {{ kind = "box", half_width = 3.0 }}
laws = ["angle-restricted"]
"""


def _scenario(tmp_path: Path, condition: str) -> Path:
    path = tmp_path / f"{condition}.toml"
    path.write_text(SCENARIO.format(name=condition, condition=condition))
    return path


def test_least_distance_and_below_against_hand_values():
    f = SafetyFilter(filter="barrier", distance=0.5, sensing_radius=2.0)
    q = np.array(
        [
            [[0.0, 0.0], [0.3, 0.4], [5.0, 0.0]],  # pair 1-2 at 0.5
            [[0.0, 0.0], [3.0, 0.0], [0.0, 4.0]],  # no pair within the radius 2
        ]
    )
    np.testing.assert_allclose(f.least_distance(q), [0.5, np.inf])
    np.testing.assert_allclose(f.least_distance(q[0]), 0.5)  # one state: a scalar
    below = f.below([0.5, 0.5 * (1 - 2 * BELOW_TOLERANCE), 0.4, np.inf, np.nan])
    np.testing.assert_array_equal(below, [False, True, True, False, False])


def test_run_says_when_robots_come_below_the_safety_distance(tmp_path: Path):
    out = tmp_path / "breach"
    res = runner.invoke(app, ["run", str(_scenario(tmp_path, "continuous")), "--out", str(out)])
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "success" and summary["outcome"] == "desired"
    assert summary["below_safety_distance"] is True
    assert summary["safety"]["below_safety_distance"] is True
    least = summary["safety"]["min_pair_distance"]
    assert least == pytest.approx(0.884, abs=2e-3)  # measured at every step
    assert "below the safety distance: two robots came 0.884 m apart" in res.output
    assert "closer than the safety filter's distance D_s = 0.9" in res.output
    assert 'condition = "discrete"' in res.output  # and what keeps them apart


def test_run_under_the_discrete_condition_is_not_flagged(tmp_path: Path):
    out = tmp_path / "kept"
    res = runner.invoke(app, ["run", str(_scenario(tmp_path, "discrete")), "--out", str(out)])
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["below_safety_distance"] is False
    assert summary["safety"]["below_safety_distance"] is False
    assert 0.9 <= summary["safety"]["min_pair_distance"] < 0.95
    assert "below the safety distance" not in res.output and "D_s" not in res.output


@pytest.mark.parametrize("condition", ["continuous", "discrete"])
def test_study_flags_and_counts_trials_below_the_safety_distance(tmp_path: Path, condition):
    out = tmp_path / condition
    res = runner.invoke(app, ["study", str(_scenario(tmp_path, condition)), "--out", str(out)])
    assert res.exit_code == 0, res.output
    df = pd.read_parquet(out / "trials.parquet")
    assert df["below_safety_distance"].dtype == bool
    starts = np.stack(
        [df[[f"x{i}_init", f"y{i}_init"]].to_numpy() for i in (1, 2, 3)], axis=1
    )  # (B, 3, 2)
    inside = SafetyFilter(filter="barrier", distance=0.9).below(
        SafetyFilter(filter="barrier").least_distance(starts)
    )  # trials that start inside D_s
    np.testing.assert_array_equal(
        df["below_safety_distance"], df["min_pair_distance"] < 0.9 * (1 - BELOW_TOLERANCE)
    )
    assert np.all(df.loc[inside, "below_safety_distance"])
    clear = df[~inside]
    if condition == "continuous":  # some clear starts jump inside D_s, and some end desired
        assert clear["below_safety_distance"].sum() >= 10
    else:  # the discrete condition keeps every clear start >= D_s at every step
        assert not clear["below_safety_distance"].any()
        assert np.all(clear["min_pair_distance"] >= 0.9 * (1 - BELOW_TOLERANCE))
    summary = json.loads((out / "summary.json").read_text())
    (group,) = summary["groups"]
    assert group["below_safety_distance"] == int(df["below_safety_distance"].sum())
    said = f"{group['below_safety_distance']} of 20 trials had two robots closer than"
    assert (said in res.output) == (group["below_safety_distance"] > 0)


def test_a_single_run_measures_clearances_and_the_filters_pairs_at_every_step_alike():
    """The compiled single run and the numpy driver: the same least robot-robot and
    robot-obstacle clearances and least distance of the filter's pairs, over every step
    (the triangle among a disc and a triangle, decentralized filter; save_every = 50 saves
    only a few states, and the least over them is larger)."""
    import dataclasses
    import warnings

    from formationlab.io.scenario import load_scenario
    from formationlab.scenario.loop import run_scenario

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (the example's start note)
        example = Path(__file__).resolve().parents[1] / "examples" / "triangle-obstacle.toml"
        sc = dataclasses.replace(load_scenario(example), duration=2.0)
    a = run_scenario(sc, backend="numba", save_every=50)
    b = run_scenario(sc, backend="numpy", save_every=50)
    for name in ("min_robot_clearance", "min_obstacle_clearance"):
        assert getattr(a, name) == pytest.approx(getattr(b, name), abs=1e-9)
    assert a.safety.least_distance == pytest.approx(b.safety.least_distance, abs=1e-9)
    # the robots' centres: the least distance is the robot clearance plus a_ij = 0.2
    assert a.safety.least_distance == pytest.approx(a.min_robot_clearance + 0.2, abs=1e-12)
    assert 0 < a.min_obstacle_clearance < 1 and not a.below_safety_distance
    saved = SafetyFilter(filter="barrier-decentralized").least_distance(a.q).min()
    assert a.safety.least_distance <= saved
    summary = a.summary()
    assert summary["min_robot_clearance"] == a.min_robot_clearance
    assert summary["min_obstacle_clearance"] == a.min_obstacle_clearance
