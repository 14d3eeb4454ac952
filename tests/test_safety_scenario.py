"""[[obstacles]] and [safety] in scenario files and commands; deadlocks found by equilibria."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner, Result

from formationlab.cli import _load_commands, app
from formationlab.dynamics import System
from formationlab.equilibria.report import find_equilibria, parse_equilibria
from formationlab.errors import ScenarioError
from formationlab.integrators import get_integrator
from formationlab.io.scenario import load_scenario
from formationlab.safety import Circle, Polygon, SafetyFilter
from formationlab.scenario import parse_scenario

_load_commands()
runner = CliRunner()
EXAMPLES = Path(__file__).parent.parent / "examples"

BASE = """\
name = "tri"
[robots]
positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]
diameters = 0.2
[formation]
distances = 1.0
[controller]
law = "distance"
[simulation]
dt = 1e-3
duration = 0.6
"""
OBSTACLES = """
[[obstacles]]
circle = { center = [-1.6, -1.7], radius = 0.4 }

[[obstacles]]
polygon = [[1.4, -2.4], [2.2, -1.6], [1.2, -1.2]]
"""
SAFETY = """
[safety]
filter = "barrier-decentralized"
distance = 0.3
gamma = 100.0
max_speed = 4.0
"""


def invoke(*args: object) -> Result:
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


def test_keys_build_obstacles_and_filter():
    sc = parse_scenario(BASE + OBSTACLES + SAFETY)
    circle, tri = sc.obstacles
    assert isinstance(circle, Circle) and isinstance(tri, Polygon)
    np.testing.assert_array_equal(circle.center, [-1.6, -1.7])
    assert tri.vertices.shape == (3, 2)
    assert sc.safety == SafetyFilter(
        filter="barrier-decentralized", distance=0.3, gamma=100.0, max_speed=4.0
    )
    plain = parse_scenario(BASE)
    assert plain.obstacles == () and plain.safety is None


@pytest.mark.parametrize(
    ("extra", "key", "words"),
    [
        (
            "[[obstacles]]\ncircle = { center = [0.0, 0.0], radius = 0.5 }\n"
            "[[obstacles]]\ncircle = { center = [3.0, -3.2], radius = 0.5 }\n",
            "obstacles",
            ["obstacles, item 2 (line 15)", "overlaps robot 2's start", "move the obstacle"],
        ),
        (
            "[[obstacles]]\npolygon = [[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]\n",
            "obstacles",
            ["obstacles, item 1 (line 13)", "is not simple", "without self-intersections"],
        ),
        (
            '[safety]\nfilter = "barrier"\ndistance = 0.1\n',
            "safety.distance",
            ["safety.distance (line 15)", "below the contact distance", "use distance >= 0.2"],
        ),
        (
            '[safety]\nfilter = "barrier"\ngamma = -1.0\n',
            "safety.gamma",
            ["safety.gamma (line 15)", "gamma must be >= 0"],
        ),
        (
            '[safety]\nfilter = "barier"\n',
            "safety.filter",
            ["safety.filter (line 14)", "'barrier-decentralized'"],
        ),
        ("[safety]\nfliter = 1\n", "safety.fliter", ["did you mean 'filter'"]),
        ("[[obstacles]]\nsquare = 1.0\n", "obstacles", ["either circle = {"]),
    ],
)
def test_bad_keys_name_the_key_and_the_fix(extra, key, words):
    with pytest.raises(ScenarioError) as err:
        parse_scenario(BASE + "\n" + extra, source="bad.toml")
    assert err.value.key == key
    for w in words:
        assert w in str(err.value), str(err.value)


def test_keys_without_a_filter_warn():
    sc = parse_scenario(BASE + "[safety]\ndistance = 0.3\n")
    assert sc.safety is not None and not sc.safety.enabled
    assert any("no effect" in w and "distance" in w for w in sc.warnings)


def test_a_safety_distance_wider_than_the_start_warns(tmp_path):
    """Robots that start closer than D_s: the filter can only push them apart until they
    reach it (was accepted without a word)."""
    text = BASE.replace("[3.0, -3.0]", "[-2.6, -3.0]").replace("[0.0, 3.0]", "[-2.2, -3.0]")
    sc = parse_scenario(text + '[safety]\nfilter = "barrier"\ndistance = 0.9\n')
    said = [w for w in sc.warnings if w.startswith("[safety] distance = 0.9")]
    assert len(said) == 1, sc.warnings
    assert "robots 1 and 2 start 0.4 m apart (and 2 more pairs), closer than it" in said[0]
    clear = parse_scenario(text + '[safety]\nfilter = "barrier"\ndistance = 0.3\n')
    assert not any("closer than it" in w for w in clear.warnings)
    path = tmp_path / "close.toml"
    path.write_text(text + '[safety]\nfilter = "barrier"\ndistance = 0.9\n')
    res = invoke("validate", path)
    assert res.exit_code == 0 and "closer than it" in res.output, res.output


def test_validate_checks_the_tables(tmp_path):
    good, bad = tmp_path / "good.toml", tmp_path / "bad.toml"
    good.write_text(BASE + OBSTACLES + SAFETY)
    bad.write_text(BASE + '\n[safety]\nfilter = "barrier"\ndistance = 0.1\n')
    res = invoke("validate", good, bad)
    assert res.exit_code == 2
    assert "2 obstacles, safety filter barrier-decentralized (D_s = 0.3)" in res.stdout
    assert "safety.distance (line 15)" in res.stderr and "Traceback" not in res.stderr


@pytest.fixture(scope="module")
def filtered_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("safety-run")
    scenario = root / "tri.toml"
    scenario.write_text(BASE + OBSTACLES + SAFETY)
    out = root / "out"
    res = invoke("run", scenario, "--out", out, "--quiet")
    assert res.exit_code == 0, res.output
    return out


def test_run_writes_obstacles_and_the_filter_status(filtered_run):
    summary = json.loads((filtered_run / "summary.json").read_text())
    safety = summary["safety"]
    assert safety["filter"]["filter"] == "barrier-decentralized"
    assert safety["obstacles"][0] == {"circle": {"center": [-1.6, -1.7], "radius": 0.4}}
    counts = safety["status_counts"]
    assert sum(counts.values()) == 601 and counts["solved"] > 0  # active from this start
    assert safety["robots_ever_active"] and safety["min_pair_distance"] >= 0.3 - 1e-9
    assert safety["min_obstacle_clearance"] > 0.15 - 0.1 - 1e-9  # D_o - rho/2
    assert "safety.png" in summary["manifest"] and (filtered_run / "safety.png").is_file()
    ds = xr.open_dataset(filtered_run / "trajectory.nc", engine="h5netcdf")
    try:
        active = ds["filter_active"].values
        assert active.shape == (601, 3) and active.any()
        pairs = ds["active_pair"].values
        assert pairs.ndim == 2 and pairs.shape[1] == 3
        assert json.loads(ds.attrs["obstacles"]) == safety["obstacles"]
    finally:
        ds.close()


def test_animate_draws_obstacles_from_the_folder(filtered_run):
    res = invoke("animate", filtered_run, "--frames", 4, "--format", "gif")
    assert res.exit_code == 0, res.output
    assert (filtered_run / "animation.gif").stat().st_size > 1000


def test_study_with_a_filter_runs_compiled(tmp_path):
    scenario = tmp_path / "tri.toml"
    scenario.write_text(
        BASE + OBSTACLES + SAFETY
        + '\n[study]\ntrials = 4\nchunk_size = 4\ninitial = { kind = "box", half_width = 3.0 }\n'
    )  # fmt: skip
    out = tmp_path / "study"
    res = invoke("study", scenario, "--out", out, "--duration", "0.3", "--filter", "barrier")
    assert res.exit_code == 0, res.output
    assert "note:" not in res.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["backend"] == "numba" and summary["backend_used"] == "numba"
    assert summary["backend_note"] == ""
    assert summary["safety"]["filter"]["filter"] == "barrier"
    assert summary["groups"][0]["trials"] == 4
    bad = invoke("study", scenario, "--out", tmp_path / "x", "--filter", "qp")
    assert bad.exit_code == 2 and "--filter qp" in bad.stderr


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["barrier", "barrier-decentralized"])
def test_head_on_deadlock_is_found_and_classified(kind):
    """examples/head-on-deadlock.toml: robots 1 and 2 pushed into each other on a line.

    Found from the scenario's own run (a symmetric start on the line), refined on its
    KKT system and classified on the tangent space of the three active constraints.
    Hand-derived: the robots stop in a row 4, 1, 2, 3, consecutive pairs D_s = 0.3
    apart, at +-0.15 and +-0.45; ``u = 0`` there while the law's command is not zero.
    Off the line robots 1 and 2 slide past each other: at least one unstable direction.
    """
    sc = load_scenario(EXAMPLES / "head-on-deadlock.toml")
    # a coarser step and a shorter run reach the same deadlock (the refinement, not the
    # run, gives its digits): 5 s at dt = 5e-3 instead of 20 s at 1e-3
    sc = dataclasses.replace(
        sc, duration=5.0, integrator=get_integrator("euler", dt=5e-3),
        safety=dataclasses.replace(sc.safety, filter=kind),
    )  # fmt: skip
    report = find_equilibria(sc, parse_equilibria(sc))
    (eq,) = report.catalogue.equilibria
    assert eq.constraints == ("pair 1-2", "pair 1-4", "pair 2-3")
    x = np.sort(eq.q[:, 0] - eq.q[:, 0].mean())
    np.testing.assert_allclose(x, [-0.45, -0.15, 0.15, 0.45], atol=1e-9)
    np.testing.assert_allclose(eq.q[:, 1] - eq.q[:, 1].mean(), 0.0, atol=1e-9)
    assert eq.unstable_directions >= 1 and eq.stability in ("saddle", "degenerate")
    assert eq.attractive and not eq.desired
    system = System(formation=sc.formation, law=sc.law, safety=sc.safety)
    res = system.filter_result(eq.q)
    np.testing.assert_allclose(res.u, 0.0, atol=1e-8)
    u_hat = sc.law.control(sc.formation, eq.q)
    assert np.abs(u_hat).max() > 0.5  # the law pushes; the filter holds
    if kind == "barrier":  # KKT at u = 0: u_hat = sum_c lambda_c (-grad h_c), by hand
        force = np.zeros_like(u_hat)
        for lab, lam in zip(eq.constraints, eq.multipliers, strict=True):
            i, j = (int(r) - 1 for r in lab.removeprefix("pair ").split("-"))
            w = eq.q[i] - eq.q[j]
            force[i] += lam * (-2 * w)
            force[j] += lam * (2 * w)
        np.testing.assert_allclose(u_hat, force, atol=1e-9)
        assert np.all(eq.multipliers > 0)
    # transverse instability by hand: robots 1 and 2 nudged off the line move further off
    off = eq.q.copy()
    off[0, 1] += 1e-4
    off[1, 1] -= 1e-4
    u = system.rhs(off)
    assert u[0, 1] > 0 > u[1, 1]
    if kind == "barrier":
        assert eq.stability == "saddle" and eq.unstable_directions == 2
    lines = report.lines()
    assert "deadlock on pair 1-2, pair 1-4, pair 2-3" in lines[0]


@pytest.mark.slow
def test_square_deadlock_of_the_squared_distance_law_is_stable():
    """The deadlock that takes 45 % of the square's trials under the decentralized filter.

    Robots 3 and 4 on the wrong sides of each other, squeezed to D_s: an isosceles
    trapezoid. Refined from a rough hand-made guess, classified stable; the filtered
    closed loop started near it (pair 3-4 kept at D_s, the rest moved by 0.02) comes back.
    """
    sc = load_scenario(EXAMPLES / "square-safety.toml")
    system = System(formation=sc.formation, law=sc.law, safety=sc.safety)
    guess = np.array([[-0.45, -0.55], [0.45, -0.55], [-0.15, 0.55], [0.15, 0.55]])
    from formationlab.equilibria.constrained import classify_deadlock, refine_deadlock

    dead = refine_deadlock(system, guess)
    assert dead.success and dead.active.labels() == ("pair 3-4",)
    eq = classify_deadlock(system, dead)
    assert eq.stability == "stable" and eq.attractive and eq.outcome == "incorrect"
    assert np.linalg.norm(dead.q[2] - dead.q[3]) == pytest.approx(0.3, abs=1e-12)
    assert (
        np.abs(system.rhs(dead.q)).max() < 1e-9 < np.abs(sc.law.control(sc.formation, dead.q)).max()
    )
    start = dead.q.copy()
    start[:2] += np.array([[0.02, -0.01], [0.01, 0.02]])
    import formationlab as fl

    run = fl.simulate(sc.formation, sc.law, start, duration=12.0, safety=sc.safety)
    iu, ju = np.triu_indices(4, 1)
    r_end = np.linalg.norm(run.q[-1][ju] - run.q[-1][iu], axis=-1)
    r_eq = np.linalg.norm(dead.q[ju] - dead.q[iu], axis=-1)
    np.testing.assert_allclose(r_end, r_eq, atol=5e-3)
