"""Formations that move as a rigid body: the fit, the outcomes ``drifting`` and ``rotating``.

Hand-built rigid motions (a translation, a rotation about a chosen centre) are
fitted and classified with the velocities they were built with; rest and slow
shape changes keep today's outcomes; the answer does not depend on where the
formation is, how it is turned or how its robots are numbered; the batched
kernel, its numpy specification and the one-by-one simulator agree trial by
trial on the hexagon, whose angle-restricted law drifts (``docs/drifting.md``).
"""

import numpy as np
import pytest

import formationlab as fl
from formationlab.io.scenario import load_scenario
from formationlab.outcomes.analysis import classify, final_motion
from formationlab.outcomes.batch import classify_batch
from formationlab.outcomes.rigid_motion import rigid_motion
from formationlab.studies.batch import run_batch
from formationlab.studies.config import BoxInitial
from formationlab.studies.sampling import trial_initial_states

SHAPE = np.array([[0.0, 0.0], [1.3, 0.1], [0.4, 1.1], [-0.6, 0.7]])  # distances far from d = 1


def _rot(phi):
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[c, -s], [s, c]])


def _formation():
    return fl.Formation.from_distances(4, distances=1.0, diameters=0.1)


def _translating(v, T=3.0, dt=0.01):
    t = np.arange(0.0, T + dt / 2, dt)
    return t, SHAPE[None] + t[:, None, None] * np.asarray(v)


def _rotating(omega, centre, T=3.0, dt=0.01):
    t = np.arange(0.0, T + dt / 2, dt)
    q = np.stack([centre + (SHAPE - centre) @ _rot(omega * s).T for s in t])
    return t, q


def _velocities(q, v, omega, centre):
    """The rigid field u_i = v + omega k x (q_i - c) at ``q``, ``v`` the translation part."""
    p = q - centre
    return v + omega * np.stack([-p[..., 1], p[..., 0]], axis=-1)


def test_rigid_translation_is_drifting_with_its_velocity():
    f, v = _formation(), np.array([0.3, -0.4])
    t, q = _translating(v)
    m = final_motion(t, q)
    np.testing.assert_allclose(m.velocity, v, atol=1e-12)
    assert abs(m.omega) < 1e-12 and m.shape_rate < 1e-12 and m.window == pytest.approx(2.0)
    assert m.speed == pytest.approx(0.5)
    u = np.broadcast_to(v, q[-1].shape)
    assert classify(f, q[-1], u, motion=m) == "drifting"
    assert classify(f, q[-1], u) == "not-converged"  # no motion known: as before


def test_rigid_rotation_is_rotating_with_its_angular_velocity_and_centre():
    f, omega, centre = _formation(), -0.4, np.array([2.0, -1.0])
    t, q = _rotating(omega, centre)
    m = final_motion(t, q)
    assert m.omega == pytest.approx(omega, rel=1e-12)
    np.testing.assert_allclose(m.centre, centre, atol=1e-10)
    u = _velocities(q[-1], 0.0, omega, centre)
    np.testing.assert_allclose(m.velocity, u.mean(axis=0), atol=1e-12)  # of the centroid
    assert m.speed == pytest.approx(np.linalg.norm(u, axis=-1).max(), rel=1e-12)
    assert m.shape_rate < 1e-12
    assert classify(f, q[-1], u, motion=m) == "rotating"
    # a rotation too slow to move any robot about the centroid by 2 cm/s: a drift
    slow = final_motion(*_rotating(1e-4, np.array([300.0, 0.0])))
    assert slow.speed > fl.Tolerances().shape > slow.spin
    assert classify(f, q[-1], u, motion=slow) == "drifting"


def test_rest_and_met_distances_keep_their_outcomes():
    f = _formation()
    t = np.arange(0.0, 3.0, 0.01)
    still = np.broadcast_to(SHAPE, (t.size, 4, 2))
    m = final_motion(t, still)
    assert m.speed == 0.0 and m.shape_rate == 0.0
    assert classify(f, SHAPE, np.zeros((4, 2)), motion=m) == "incorrect"
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    g = fl.Formation.from_template(square, edges=[[1, 2], [2, 3], [3, 4], [4, 1], [1, 3]])
    tt, qq = t, square[None] + t[:, None, None] * np.array([0.5, 0.0])
    mm = final_motion(tt, qq)
    assert classify(g, qq[-1], np.full((4, 2), 0.5), motion=mm) == "desired"  # met wins
    # contact wins over everything
    assert classify(f, SHAPE, np.zeros((4, 2)), contact=True, motion=mm) == "collision"


def test_changing_shape_and_short_runs_are_not_rigid():
    f = _formation()
    t = np.arange(0.0, 3.0 + 1e-9, 0.01)
    grow = SHAPE[None] * (1.0 + 0.05 * t[:, None, None]) + t[:, None, None] * [0.5, 0.0]
    m = final_motion(t, grow)  # grows by 5 % a second while it translates
    # a scaling is not a rotation: the fit leaves all of it (phi = 0)
    b = grow[-1] - grow[-1].mean(axis=0)
    a = grow[-201] - grow[-201].mean(axis=0)
    assert m.shape_rate == pytest.approx(np.linalg.norm(b - a, axis=-1).max() / 2.0, rel=1e-9)
    assert m.shape_rate > fl.Tolerances().shape
    assert classify(f, grow[-1], np.full((4, 2), 0.5), motion=m) == "not-converged"
    short = final_motion(t[:150], grow[:150])  # 1.49 s < the 2 s window
    assert np.isnan(short.speed)
    assert classify(f, grow[149], np.full((4, 2), 0.5), motion=short) == "not-converged"


@pytest.mark.parametrize("kind", ["translate", "rotate", "relabel"])
def test_classification_is_invariant(kind, rng):
    f, omega, centre = _formation(), 0.3, np.array([-1.0, 0.5])
    t, q = _rotating(omega, centre)
    base = final_motion(t, q)
    if kind == "translate":
        shift = rng.normal(size=2) * 10
        q2, turn, perm = q + shift, np.eye(2), np.arange(4)
    elif kind == "rotate":
        turn = _rot(rng.uniform(0, 2 * np.pi))
        q2, perm, shift = q @ turn.T, np.arange(4), np.zeros(2)
    else:
        perm, turn, shift = rng.permutation(4), np.eye(2), np.zeros(2)
        q2 = q[:, perm]
    m = final_motion(t, q2)
    assert m.omega == pytest.approx(base.omega, rel=1e-10)
    assert m.speed == pytest.approx(base.speed, rel=1e-10)
    assert m.shape_rate == pytest.approx(base.shape_rate, abs=1e-12)
    np.testing.assert_allclose(m.velocity, turn @ base.velocity, atol=1e-12)
    np.testing.assert_allclose(m.centre, turn @ base.centre + shift, atol=1e-9)
    u = _velocities(q2[-1], 0.0, omega, turn @ centre + shift)
    assert classify(f, q2[-1], u, motion=m) == classify(f, q[-1], u, motion=base) == "rotating"


def test_classify_batch_equals_classify_on_rigid_motions():
    f = _formation()
    runs = [
        _translating([0.3, -0.4]),
        _rotating(-0.4, np.array([2.0, -1.0])),
        _translating([1e-2, 0.0]),  # slower than the shape tolerance: not rigid
        _rotating(1e-4, np.array([300.0, 0.0])),
    ]
    before = np.stack([q[-201] for _, q in runs])
    after = np.stack([q[-1] for _, q in runs])
    motion = rigid_motion(before, after, np.full(len(runs), 2.0))
    u = np.ones_like(after)
    labels = classify_batch(f, after, u, motion=motion)
    one = [classify(f, after[b], u[b], motion=motion[b]) for b in range(len(runs))]
    assert list(labels) == one == ["drifting", "rotating", "not-converged", "drifting"]


def test_tolerances_of_the_rigid_motion_are_checked():
    with pytest.raises(fl.errors.ParameterError, match="shape"):
        fl.Tolerances(shape=0.0)
    with pytest.raises(fl.errors.ParameterError, match="drift_window"):
        fl.Tolerances(drift_window=-1.0)
    assert fl.Tolerances(drift_window=2.0).drift_steps(1e-3) == 2000


# ------------------------------------------------ the hexagon: kernel = driver = simulator


SHORT = fl.Tolerances(drift_window=0.5, shape=5e-2)


@pytest.fixture(scope="module")
def hexagon_runs():
    """40 box starts (seed 3) for 20 s, then the moving ones continued for 0.6 s by each path.

    Explicit Euler chattering on switching surfaces amplifies rounding: over 20 s
    the differences between the paths' arithmetic grow to the chatter's size
    (1e-2), over 2.5 s to 1e-7. The outcomes agree after 20 s; the states and
    motions are compared to 1e-9 over a short continuation from a state already on
    the moving shape, with a drift window of 0.5 s (the shape tolerance widened to
    the chatter of a window that short: 5e-3 m over 0.5 s).
    """
    sc = load_scenario("examples/hexagon.toml")
    q0 = trial_initial_states(sc.formation, BoxInitial(half_width=3.0), 3, np.arange(40))
    kw = {"dt": 1e-3, "duration": 20.0}
    long = {b: run_batch(sc.formation, sc.law, q0, backend=b, **kw) for b in ("numba", "numpy")}
    moving = np.flatnonzero(np.isin(long["numba"].outcome, ["drifting", "rotating"]))
    starts = long["numba"].q_final[moving]
    kw = {"dt": 1e-3, "duration": 0.6, "tolerances": SHORT}
    short = {
        b: run_batch(sc.formation, sc.law, starts, backend=b, **kw) for b in ("numba", "numpy")
    }
    return sc, long, starts, short


def test_kernel_and_driver_agree_on_drifting_trials(hexagon_runs):
    _, long, _, short = hexagon_runs
    assert list(long["numba"].outcome) == list(long["numpy"].outcome)
    assert {"drifting", "rotating"} <= set(long["numba"].outcome)
    a, b = short["numba"], short["numpy"]
    assert list(a.outcome) == list(b.outcome)
    assert list(a.outcome) == [o for o in long["numba"].outcome if o in ("drifting", "rotating")]
    np.testing.assert_allclose(a.q_final, b.q_final, rtol=0, atol=1e-9)
    for name in ("velocity", "omega", "speed", "shape_rate", "window"):
        np.testing.assert_allclose(getattr(a.motion, name), getattr(b.motion, name), atol=1e-8)
    assert np.all(a.motion.window == pytest.approx(0.5))
    # the same drift as over the 20 s run's 2 s window, to the chatter's size
    far = long["numba"].motion[np.isin(long["numba"].outcome, ["drifting", "rotating"])]
    np.testing.assert_allclose(a.motion.omega, far.omega, atol=2e-2)
    # the trials that stopped never reached the window: no motion
    stopped = long["numba"].status == fl.status.Status.CONVERGED.code
    assert stopped.any() and np.isnan(long["numba"].motion.speed[stopped]).all()


def test_single_runs_agree_with_the_batch_on_drifting_trials(hexagon_runs):
    sc, _, starts, short = hexagon_runs
    batch = short["numba"]
    for outcome in ("drifting", "rotating"):
        k = int(np.flatnonzero(batch.outcome == outcome)[0])
        res = fl.simulate(
            sc.formation, sc.law, starts[k], duration=0.6, integrator=fl.Euler(dt=1e-3)
        )
        assert res.outcome(SHORT) == outcome
        m = res.motion(SHORT)
        np.testing.assert_allclose(res.q[-1], batch.q_final[k], rtol=0, atol=1e-9)
        np.testing.assert_allclose(m.velocity, batch.motion.velocity[k], atol=1e-8)
        assert m.omega == pytest.approx(batch.motion.omega[k], abs=1e-8)
        rm = res.summary(SHORT)["rigid_motion"]
        np.testing.assert_allclose(rm["velocity"], batch.motion.velocity[k], atol=1e-8)
        assert (rm["centre"] is None) == (outcome == "drifting")


def test_a_study_without_moving_shapes_keeps_its_tables():
    """The paper's triangle: every trial labelled as without the rigid-motion outcomes."""
    from formationlab.studies import parse_study, run_study
    from formationlab.studies.runner import StudySetup

    f = fl.Formation.from_alpha_table({(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}, n=3)
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    config = parse_study({"trials": 200, "laws": ["distance", "angle-restricted"]})
    setup = StudySetup(formation=f, law=law, config=config, dt=1e-2, duration=6.0)
    res = run_study(setup, seed=4)
    classic = ["desired", "mirror", "incorrect", "collision", "not-converged"]
    assert res.summary["outcomes"] == classic
    for entry in res.summary["groups"]:
        assert list(entry["counts"]) == classic == list(entry["settled_counts"])
    # trial by trial: today's rule (no motion) on the kernel's final states
    q0 = trial_initial_states(f, config.initial, 4, np.arange(200))
    for g, lw in enumerate((fl.DistanceLaw(k_c=2.0), law)):
        batch = run_batch(f, lw, q0, dt=1e-2, duration=6.0)
        contact = np.isin(batch.status, [s.code for s in fl.status.Status if s.contact])
        today = classify_batch(
            f, batch.q_final, batch.u_final, contact=contact, net_speed=batch.net_speed
        )
        rows = res.trials[res.trials["group"] == g]
        assert list(rows["outcome"]) == list(today) == list(batch.outcome)
        assert {"drift_vx", "drift_vy", "drift_omega", "shape_rate"} <= set(rows.columns)


def test_the_drifting_examples_load_with_their_studies():
    from pathlib import Path

    from formationlab.studies import parse_study, study_groups

    folder = Path(__file__).resolve().parents[1] / "examples" / "drifting"
    files = sorted(folder.glob("*.toml"))
    assert len(files) == 7
    for path in files:
        sc = load_scenario(path)
        config = parse_study(sc.study)
        groups = study_groups(sc.formation, sc.law, config)
        assert config.trials == 1000 and len(groups) == len(config.sweep.get("k_a", [0])) * len(
            config.sweep.get("theta", [0])
        )
        if sc.formation.template is not None:  # a regular polygon of side 1 on its graph
            t = sc.formation.template
            assert np.linalg.norm(t[1] - t[0]) == pytest.approx(1.0, rel=1e-12)


def test_run_command_says_the_formation_drifts(hexagon_runs, tmp_path):
    import json
    import re
    from pathlib import Path

    from typer.testing import CliRunner

    from formationlab.cli import _load_commands, app

    _load_commands()
    _, long, starts, _ = hexagon_runs
    k = int(
        np.flatnonzero(
            long["numba"].outcome[np.isin(long["numba"].outcome, ["drifting", "rotating"])]
            == "drifting"
        )[0]
    )
    text = (Path(__file__).resolve().parents[1] / "examples" / "hexagon.toml").read_text()
    pos = "positions = [" + ", ".join(f"[{float(x)!r}, {float(y)!r}]" for x, y in starts[k]) + "]"
    text = re.sub(r"positions = \[\[.*?\]\]", pos, text, count=1, flags=re.S)
    text = text.replace("duration = 20.0", "duration = 2.5")
    (tmp_path / "drift.toml").write_text(text)
    res = CliRunner().invoke(
        app, ["run", str(tmp_path / "drift.toml"), "--out", str(tmp_path / "o")]
    )
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["outcome"] == "drifting" and summary["rigid_motion"]["centre"] is None
    speed = summary["rigid_motion"]["speed"]
    assert speed == pytest.approx(float(np.hypot(*summary["rigid_motion"]["velocity"])), rel=1e-6)
    assert f"outcome drifting at {speed:.3g} m/s" in res.output
    assert summary["tolerances"]["drift_window"] == 2.0
