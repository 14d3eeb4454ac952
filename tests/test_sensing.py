"""Robots that sense: local frames, the measurement channel, mismatch, faults.

The paper's laws as per-robot controllers equal the centralized laws in every frame
(rotations); the channel's delay, drops, range and noise do what they say on hand-built
cases; the defaults change nothing; a seed fixes a run wherever it runs.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from _scenarios import clear_starts, triangle
from typer.testing import CliRunner

import formationlab as fl
from formationlab.cli import _load_commands, app
from formationlab.controllers import laws_in
from formationlab.dynamics import System
from formationlab.errors import ParameterError, ScenarioError
from formationlab.models import DoubleIntegrator, Unicycle
from formationlab.scenario import parse_scenario
from formationlab.sensing import (
    Channel,
    Faults,
    Sensing,
    Stop,
    local_controls,
    measured,
    rotate,
)
from formationlab.studies.batch import run_batch

KERNEL_LAWS = laws_in(2)
TRIANGLE = fl.Formation.from_template([[0, 0], [1, 0], [0.5, 0.8]], diameters=0.2)
SQUARE = parse_scenario(
    Path(__file__).parents[1].joinpath("examples/square-with-diagonals.toml").read_text()
).formation
Q0 = np.array([[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]])


# ----------------------------------------------------------------------------- local frames


@pytest.mark.parametrize("name", KERNEL_LAWS)
@pytest.mark.parametrize("formation", [TRIANGLE, SQUARE], ids=["triangle", "square"])
def test_local_frames_equal_the_centralized_law(name: str, formation: fl.Formation) -> None:
    law = fl.get_law(name)
    q = clear_starts(formation.n, 20, 1)
    u = law.control(formation, q)
    angles = np.random.default_rng(2).uniform(-np.pi, np.pi, (20, formation.n))
    terms = law.compiled_terms(formation)
    u_local = local_controls(terms, measured(q, angles))
    assert np.abs(u).max() > 0.1  # the comparison is not of zeros
    tol = 1e-12 * np.abs(u).max()
    if name == "bearing":  # bearings need a common frame: aligned, the same; turned, not
        aligned = local_controls(terms, measured(q, np.zeros_like(angles)))
        np.testing.assert_allclose(aligned, u, rtol=0, atol=tol)
        assert np.abs(rotate(u_local, angles) - u).max() > 1e-3
        return
    np.testing.assert_allclose(rotate(u_local, angles), u, rtol=0, atol=tol)
    # and the commands really are in the robots' frames: unrotated, they differ
    assert np.abs(u_local - u).max() > 1e-3


@pytest.mark.parametrize("name", KERNEL_LAWS)
@pytest.mark.parametrize(
    "model",
    [Unicycle(mapping="near-identity"), Unicycle(mapping="heading"), DoubleIntegrator()],
    ids=["near-identity", "heading", "double-integrator"],
)
def test_local_frames_in_the_closed_loop_of_every_model(name: str, model: object) -> None:
    law = fl.get_law(name)
    q = clear_starts(TRIANGLE.n, 5, 3)
    x = model.initial_state(q, **({"headings": np.linspace(0, 3, 3)} if model.has_heading else {}))  # type: ignore[attr-defined]
    central = System(formation=TRIANGLE, law=law, model=model)  # type: ignore[arg-type]
    local = dataclasses.replace(central, sensing=Sensing(frames="local", seed=5))
    a, b = central.rhs(x), local.rhs(x)
    if name == "bearing":  # turned frames turn the measured bearings: a real change
        common = dataclasses.replace(central, sensing=Sensing(frames="global", seed=5))
        np.testing.assert_allclose(common.rhs(x), a, rtol=0, atol=1e-12 * np.abs(a).max())
        assert np.abs(b - a).max() > 1e-3
        return
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-12 * np.abs(a).max())


def test_unicycle_frames_are_their_headings() -> None:
    """A unicycle measures in its heading's frame: z_ij = R(-theta_i) (p_j - p_i)."""
    model = Unicycle(mapping="heading")
    system = System(
        formation=TRIANGLE, law=fl.DistanceLaw(), model=model, sensing=Sensing(frames="local")
    )
    x = model.initial_state(Q0, headings=[0.3, -1.0, 2.0])
    ch = system.channel(None, 1e-3)
    z, _ = ch.field(x[None], np.arange(1))
    expect = rotate(Q0[1] - Q0[0], np.array(-0.3))
    np.testing.assert_allclose(z[0, 0, 1], expect, atol=1e-15)


def test_a_reflected_frame_breaks_the_angular_term_not_the_distance_term() -> None:
    """The angle-restricted law needs a common sense of rotation, not a common frame.

    A robot whose frame is a reflection measures mirrored triangles: ``k x`` and the
    triple products change sign, so its angular term points the wrong way; the distance
    term, built of lengths and radial directions, is unchanged.
    """
    f = TRIANGLE
    q = clear_starts(f.n, 10, 7)
    reflect = np.array([[1.0, 0.0], [0.0, -1.0]])
    for name, same in (("distance", True), ("angle-restricted", False)):
        law = fl.get_law(name, theta=2.0) if name == "angle-restricted" else fl.get_law(name)
        terms = law.compiled_terms(f)
        z = measured(q, None) @ reflect.T  # every robot's view, mirrored
        u = local_controls(terms, z) @ reflect.T  # commanded in the mirrored frame, mapped back
        central = law.control(f, q)
        if same:
            np.testing.assert_allclose(u, central, atol=1e-12)
        else:
            assert np.abs(u - central).max() > 0.1


# ----------------------------------------------------------------------------- the defaults


def test_the_papers_sensing_changes_nothing() -> None:
    law = fl.AngleRestrictedLaw()
    plain = fl.simulate(TRIANGLE, law, Q0, duration=3.0)
    ideal = fl.simulate(TRIANGLE, law, Q0, duration=3.0, sensing=Sensing(), faults=Faults())
    np.testing.assert_array_equal(ideal.x, plain.x)
    q0 = clear_starts(TRIANGLE.n, 6, 4) * 2
    a = run_batch(TRIANGLE, law, q0, dt=1e-2, duration=5.0)
    b = run_batch(TRIANGLE, law, q0, dt=1e-2, duration=5.0, sensing=Sensing(), faults=Faults())
    np.testing.assert_array_equal(a.q_final, b.q_final)


def test_zero_faults_on_the_sensed_path_give_todays_run() -> None:
    """Local frames without faults, through the stepping driver: today's run to rounding."""
    law = fl.AngleRestrictedLaw()
    plain = fl.simulate(TRIANGLE, law, Q0, duration=5.0, backend="numpy")
    local = fl.simulate(TRIANGLE, law, Q0, duration=5.0, sensing=Sensing(frames="local", seed=9))
    np.testing.assert_allclose(local.x, plain.x, rtol=0, atol=1e-11)
    assert local.outcome() == plain.outcome()


# ----------------------------------------------------------------------------- the channel


def _channel(sensing: Sensing, trials: int = 1, dt: float = 0.1) -> Channel:
    return Channel(
        sensing, TRIANGLE, fl.DistanceLaw(), fl.SingleIntegrator(), list(range(trials)), dt
    )


def test_a_delay_of_k_steps_uses_the_state_k_steps_ago() -> None:
    ch = _channel(Sensing(delay=0.3), dt=0.1)  # three steps
    assert ch.m == 3
    live = np.arange(1)
    states = [Q0 + 0.1 * k * np.array([[1.0, 0], [0, 1.0], [-1.0, 0]]) for k in range(8)]
    for k, q in enumerate(states):
        z, seen = ch.observe(q[None], live, k)
        if k < 3:  # nothing has arrived yet: a robot sees no one
            assert not seen[0][~np.eye(3, dtype=bool)].any()
        else:
            np.testing.assert_array_equal(z[0], measured(states[k - 3], None))
            assert seen[0].all()


def test_a_lost_measurement_leaves_the_last_one_received() -> None:
    ch = _channel(Sensing(drop=0.5), trials=1)
    live = np.arange(1)
    last = measured(Q0, None)
    fresh_count = 0
    for k in range(200):
        q_shift = Q0.copy()
        q_shift[:, 0] += np.arange(3) * 1e-3 * k  # every step's measurements are new
        z, seen = ch.observe(q_shift[None], live, k)
        truth = measured(q_shift, None)
        off = ~np.eye(3, dtype=bool)
        fresh = np.all(np.isclose(z[0], truth), axis=-1) & off
        held = np.all(np.isclose(z[0], last), axis=-1) & off
        never = ~seen[0] & off  # lost before a first one arrived: nothing to hold
        assert np.all((fresh | held | never)[off])  # each measurement is new or the one held
        assert not (never & (k > 20)).any()
        fresh_count += int(fresh[off].sum())
        last = z[0]
    assert 0.4 < fresh_count / (200 * 6) < 0.6  # lost with probability 1/2


def test_robots_out_of_range_are_not_seen_and_their_terms_drop_out() -> None:
    q = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 5.0]])
    law = fl.DistanceLaw()
    system = System(formation=TRIANGLE, law=law, sensing=Sensing(range=2.0))
    u = system.rhs(q)
    # robots 1 and 2 see only each other: their commands are the one edge's terms
    alone = fl.Formation.from_distances(2, distances=float(TRIANGLE.distances[0]), diameters=0.2)
    np.testing.assert_allclose(u[:2], law.control(alone, q[:2]), atol=1e-12)
    assert np.all(u[2] == 0)  # robot 3 sees no one


def test_noise_has_the_standard_deviation_it_is_given() -> None:
    ch = _channel(Sensing(noise=0.05), trials=4)
    live = np.arange(4)
    errors = []
    for k in range(300):
        z, _ = ch.observe(np.broadcast_to(Q0, (4, 3, 2)), live, k)
        errors.append(z - measured(Q0, None))
    e = np.array(errors)[..., ~np.eye(3, dtype=bool), :]
    assert abs(e.std() - 0.05) < 0.002 and abs(e.mean()) < 0.002


def test_each_robot_holds_its_own_desired_distances() -> None:
    system = System(
        formation=TRIANGLE,
        law=fl.get_law("squared-distance"),
        sensing=Sensing(mismatch=0.05, seed=1),
    )
    own = system.channel(None, 1e-3).own_distance[0]
    d, a = TRIANGLE.distances, 0.2
    assert own.shape == (3, 2) and np.all(own[:, 0] != own[:, 1])
    assert np.all(np.abs(own - d[:, None]) <= 0.5 * (d[:, None] - a))
    # robot i's command is the law's with robot i's own distances
    q = clear_starts(TRIANGLE.n, 1, 5)[0]
    u = system.rhs(q)
    for robot in range(3):
        mine = np.array(
            [own[e, 0] if i == robot else own[e, 1] for e, (i, j) in enumerate(TRIANGLE.edges)]
        )
        edges = TRIANGLE.edges + 1
        f_i = fl.Formation.from_distances(3, edges=edges, distances=mine, diameters=0.2)
        np.testing.assert_allclose(
            u[robot], fl.get_law("squared-distance").control(f_i, q)[robot], atol=1e-12
        )


# ----------------------------------------------------------------------------- seeds


def test_a_seed_fixes_a_noisy_run_and_another_seed_changes_it() -> None:
    law = fl.AngleRestrictedLaw()
    s = Sensing(frames="local", noise=0.02, drop=0.2, mismatch=0.02, delay=0.002, seed=3)
    a = fl.simulate(TRIANGLE, law, Q0, duration=2.0, sensing=s)
    b = fl.simulate(TRIANGLE, law, Q0, duration=2.0, sensing=s)
    c = fl.simulate(TRIANGLE, law, Q0, duration=2.0, sensing=dataclasses.replace(s, seed=4))
    np.testing.assert_array_equal(a.x, b.x)
    assert np.abs(a.x - c.x).max() > 1e-4


def test_a_trial_is_the_same_alone_and_in_any_batch() -> None:
    law = fl.DistanceLaw()
    s = Sensing(noise=0.02, drop=0.3, mismatch=0.03)
    q0 = clear_starts(TRIANGLE.n, 5, 8) * 2
    seeds = [(7, t) for t in range(5)]
    whole = run_batch(TRIANGLE, law, q0, dt=1e-2, duration=4.0, sensing=s, seeds=seeds)
    for t in (0, 3):
        alone = run_batch(
            TRIANGLE, law, q0[t : t + 1], dt=1e-2, duration=4.0, sensing=s, seeds=seeds[t : t + 1]
        )
        np.testing.assert_array_equal(alone.q_final[0], whole.q_final[t])
    # a single run with seed s is the trial with seed s (noisy trials never stop early)
    one = fl.simulate(TRIANGLE, law, q0[0], duration=4.0, integrator=fl.Euler(dt=1e-2),
                      sensing=dataclasses.replace(s, seed=11))  # fmt: skip
    alone = run_batch(TRIANGLE, law, q0[:1], dt=1e-2, duration=4.0, sensing=s, seeds=[11])
    np.testing.assert_array_equal(one.q[-1], alone.q_final[0])


# ----------------------------------------------------------------------------- faults


def test_a_stopped_robot_stays_where_it_stopped() -> None:
    res = fl.simulate(
        TRIANGLE, fl.DistanceLaw(), Q0, duration=4.0, faults=Faults(stop=[Stop(robot=2, at=1.0)])
    )
    k = int(np.searchsorted(res.t, 1.0))
    assert np.all(res.q[k:, 1] == res.q[k, 1])
    assert np.abs(res.q[k - 10, 1] - res.q[0, 1]).max() > 0.1  # it moved before
    assert np.abs(res.q[-1, 0] - res.q[k, 0]).max() > 1e-3  # the others go on


# ----------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"noise": -0.1}, "sensing.noise must be a finite number >= 0"),
        ({"drop": 1.0}, "sensing.drop must be a finite number in [0, 1)"),
        ({"frames": "body"}, 'sensing.frames must be one of "global", "local"'),
        ({"range": 0.0}, "sensing.range must be a number > 0"),
        ({"seed": -1}, "sensing.seed must be a whole number"),
    ],
)
def test_bad_sensing_is_a_clear_error(kwargs: dict, words: str) -> None:
    with pytest.raises(ParameterError, match=None) as err:
        Sensing(**kwargs)
    assert words in str(err.value)


def test_faults_name_existing_robots_once() -> None:
    with pytest.raises(ParameterError, match="robot 4 does not exist: the formation has 3"):
        System(formation=TRIANGLE, law=fl.DistanceLaw(), faults=Faults(stop=[Stop(robot=4)]))
    with pytest.raises(ParameterError, match="numbered from 1"):
        Stop(robot=0)
    with pytest.raises(ParameterError, match="more than once"):
        Faults(stop=[Stop(robot=1), Stop(robot=1, at=2.0)])


@pytest.mark.parametrize("integrator", ["implicit-euler", "filippov"])
def test_sensing_needs_an_explicit_scheme(integrator: str) -> None:
    with pytest.raises(ParameterError, match="explicit fixed-step integrator"):
        fl.simulate(
            TRIANGLE,
            "distance",
            Q0,
            duration=1.0,
            integrator=integrator,
            sensing=Sensing(noise=0.01),
        )


_load_commands()
CLI = CliRunner()


@pytest.mark.parametrize(
    ("table", "words"),
    [
        ("[sensing]\ndelay = 0.0015\n", "sensing.delay (line"),
        ("[sensing]\ndrop = 1.5\n", "sensing.drop"),
        ("[sensing]\nnoise = -1\n", "sensing.noise"),
        ("[sensing]\nnoize = 0.1\n", "noise"),
        ("[faults]\nstop = [{ robot = 7, at = 1.0 }]\n", "robot 7 does not exist"),
    ],
)
def test_bad_tables_fail_validate_and_run_with_one_line(
    tmp_path: Path, table: str, words: str
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(triangle("bad", "1.0", table))
    for args in (["validate", str(path)], ["run", str(path), "-o", str(tmp_path / "out")]):
        res = CLI.invoke(app, args)
        assert res.exit_code == 2, res.output
        assert "Traceback" not in res.output
        assert words in res.output
    assert not (tmp_path / "out").exists()  # nothing half-written


def test_a_robot_that_stops_later_needs_a_fixed_step_scheme(tmp_path: Path) -> None:
    """A stop at t > 0 makes the field depend on time, which filippov does not step: the
    scenario says so at the integrator's line (validate and run alike), not the run."""
    text = triangle("late", "1.0", "[faults]\nstop = [{ robot = 2, at = 0.5 }]\n")
    path = tmp_path / "late.toml"
    path.write_text(text.replace('"euler"\ndt = 1e-3', '"filippov"'))
    for args in (["validate", str(path)], ["run", str(path), "-o", str(tmp_path / "out")]):
        res = CLI.invoke(app, args)
        assert res.exit_code == 2, res.output
        assert "Traceback" not in res.output
        assert "simulation.integrator (line" in res.output
        assert "robot 2 stops at t = 0.5 s" in res.output
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("at", [0.0, np.inf])
def test_a_stop_at_the_start_or_never_leaves_the_field_constant_in_time(at: float) -> None:
    faults = Faults(stop=[Stop(robot=2, at=at)])
    system = System(formation=TRIANGLE, law=fl.DistanceLaw(), faults=faults)
    assert not system.time_dependent
    run = fl.simulate(TRIANGLE, "distance", Q0, duration=0.5, integrator="filippov", faults=faults)
    moved = np.abs(run.q[-1] - Q0).max(axis=-1)
    assert (moved[1] == 0.0) == (at == 0.0)  # robot 2 held only when it stops at t = 0
    assert System(formation=TRIANGLE, law=fl.DistanceLaw(),
                  faults=Faults(stop=[Stop(robot=2, at=0.25)])).time_dependent  # fmt: skip


def test_a_delay_that_is_not_whole_steps_says_what_to_use() -> None:
    with pytest.raises(
        ScenarioError, match=r"not a multiple of the step dt = 0.001 s.*use 0.001 s|use 0.002 s"
    ):
        parse_scenario(triangle("d", "1.0", "[sensing]\ndelay = 0.0015\n"))


def _noisy_study(tmp_path: Path, chunk_size: int, workers: int | None) -> object:
    from formationlab.io.scenario import load_scenario
    from formationlab.studies import parse_study
    from formationlab.studies.runner import StudySetup, run_study

    path = tmp_path / f"s{chunk_size}.toml"
    path.write_text(
        triangle(
            "noisy-study",
            "3.0",
            '[sensing]\nframes = "local"\ndrop = 0.2\n[faults]\nstop = [{ robot = 2, at = inf }]\n'
            f'[study]\ntrials = 6\nchunk_size = {chunk_size}\nlaws = ["distance"]\n',
        )
    )
    sc = load_scenario(path)
    config = parse_study(sc.study, dt=1e-2, sweep={"noise": [0.0, 0.03], "stop_at": [1.0]})
    setup = StudySetup.from_scenario(sc, config)
    assert setup.backend == ("numba", "")  # the compiled sensed path (test_sensed_kernel.py)
    return run_study(setup, seed=3, workers=workers).trials


def test_a_noisy_study_is_the_same_whatever_chunks_and_workers(tmp_path: Path) -> None:
    one = _noisy_study(tmp_path, 6, None)
    other = _noisy_study(tmp_path, 2, 2)
    import pandas as pd

    pd.testing.assert_frame_equal(one, other, check_exact=True)
    assert set(one["noise"]) == {0.0, 0.03} and set(one["stop_at"]) == {1.0}
    quiet, noisy = (one[one["noise"] == v] for v in (0.0, 0.03))
    assert not np.array_equal(quiet["x1"].to_numpy(), noisy["x1"].to_numpy())


@pytest.mark.parametrize("sensing", [Sensing(delay=0.05), Sensing(drop=0.9, seed=1)])
def test_robots_waiting_for_a_measurement_are_not_at_rest(sensing: Sensing) -> None:
    """Before a first measurement arrives the robots stand still: that is not convergence."""
    q0 = np.broadcast_to(Q0, (2, 3, 2)).copy()
    res = run_batch(TRIANGLE, fl.DistanceLaw(), q0, dt=1e-2, duration=10.0, sensing=sensing)
    assert np.all(res.steps > 5)
    assert list(res.outcome) == ["desired", "desired"]
