"""The bearing-only law of Zhao and Zelazo (IEEE TAC 61(5), 2016) and bearing rigidity.

Their published results, reproduced: the centroid and the scale are invariant along the
flow (Lemma 2; to rounding along explicit Euler: the commands sum to zero, and a step grows
the sum of squared distances to the centroid by exactly dt^2 sum ||u_i||^2), the Lyapunov
rate of Theorem 5, almost global convergence on infinitesimally bearing-rigid formations,
the unstable reversed equilibrium, and the coincidence of infinitesimal bearing rigidity
with infinitesimal distance rigidity in the plane (Theorem 8).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import formationlab as fl
from formationlab.controllers.bearing import (
    bearing_controls,
    bearing_lyapunov,
    bearing_lyapunov_rate,
    leader_target,
    target,
)
from formationlab.controllers.kinds.bearing import bearing_force
from formationlab.errors import FormationError, ScenarioError
from formationlab.formation.bearing_rigidity import (
    bearing_nullity,
    bearing_realisation,
    bearing_rigidity_matrix,
    is_infinitesimally_bearing_rigid,
)
from formationlab.formation.graphs import delaunay_edges, knn_edges
from formationlab.formation.rigidity import rigidity_matrix
from formationlab.formation.templates import lattice
from formationlab.outcomes.analysis import bearing_errors
from formationlab.scenario import parse_scenario, run_scenario
from formationlab.studies import run_batch, trial_initial_states
from formationlab.studies.config import BoxInitial

TRIANGLE = fl.Formation.from_template([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]])
SQUARE = fl.Formation.from_template(
    [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
    edges=[[1, 2], [2, 3], [3, 4], [4, 1], [1, 3], [2, 4]],
)
HEXAGON = fl.Formation.from_template(
    [[np.cos(a), np.sin(a)] for a in np.arange(6) * np.pi / 3],
    edges=[[1, 2], [2, 3], [3, 4], [4, 5], [5, 6], [6, 1], [1, 3], [1, 4], [1, 5]],
)


def _projection(g: np.ndarray) -> np.ndarray:
    g = g / np.linalg.norm(g)
    return np.eye(2) - np.outer(g, g)


def _starts(formation: fl.Formation, count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        q = rng.uniform(-3.0, 3.0, size=(formation.n, 2))
        d = np.linalg.norm(q[:, None] - q[None], axis=-1) + 10 * np.eye(formation.n)
        if d.min() > 0.5:
            out.append(q)
    return np.array(out)


def test_the_term_is_minus_the_projection_of_the_desired_bearing():
    rng = np.random.default_rng(0)
    for _ in range(100):
        r, b = rng.normal(size=2), rng.normal(size=2)
        b /= np.linalg.norm(b)
        k = rng.uniform(0.1, 3.0)
        want = -k * _projection(r) @ b  # -P_{g_ij} g*_ij, eq. (11)
        got = np.array(bearing_force(r[0], r[1], b[0], b[1], k))
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)
        # the same for every length along the bearing: the term needs no distance
        np.testing.assert_allclose(bearing_force(*(3.7 * r), b[0], b[1], k), got, atol=1e-15)


def test_every_robot_sums_its_neighbours_terms():
    f = HEXAGON.with_bearings()
    q = _starts(f, 1, 1)[0]
    u = bearing_controls(f, q, k=1.5)
    want = np.zeros_like(q)
    for (i, j), b in zip(f.edges, f.bearings, strict=True):
        want[i] -= 1.5 * _projection(q[j] - q[i]) @ b
        want[j] -= 1.5 * _projection(q[i] - q[j]) @ (-b)  # g*_ji = -g*_ij
    np.testing.assert_allclose(u, want, rtol=0, atol=1e-14)


@pytest.mark.parametrize("formation", [TRIANGLE, SQUARE, HEXAGON], ids=["3", "4", "6"])
def test_the_centroid_and_the_scale_are_invariant_along_euler(formation):
    f = formation.with_bearings()
    law = fl.BearingLaw(k=1.3)
    dt = 1e-2
    for q in _starts(f, 5, 2):
        c0 = q.mean(axis=0)
        for _ in range(300):
            u = law.control(f, q)
            assert np.abs(u.sum(axis=0)).max() < 1e-13  # the commands sum to zero
            s2 = np.sum((q - q.mean(axis=0)) ** 2)
            q_next = q + dt * u
            grown = np.sum((q_next - q_next.mean(axis=0)) ** 2) - s2
            # p^T u = 0 (e_ij^T P_{g_ij} = 0): the squared scale grows by exactly dt^2 |u|^2
            np.testing.assert_allclose(grown, dt * dt * np.sum(u * u), rtol=1e-6, atol=1e-14)
            q = q_next
        np.testing.assert_allclose(q.mean(axis=0), c0, rtol=0, atol=1e-12)


def test_a_simulated_run_keeps_the_centroid_to_1e_12():
    law = fl.BearingLaw()
    for q0 in _starts(SQUARE, 3, 3):
        res = fl.simulate(SQUARE, law, q0, duration=5.0, integrator=fl.get_integrator("euler"))
        drift = np.abs(res.q.mean(axis=-2) - q0.mean(axis=0)).max()
        assert drift < 1e-12


def test_the_lyapunov_rate_is_the_derivative_and_never_positive():
    f = SQUARE.with_bearings()
    for q in _starts(f, 20, 4):
        u = bearing_controls(f, q)
        rate = bearing_lyapunov_rate(f, q)
        assert rate <= 0
        h = 1e-6
        fd = (bearing_lyapunov(f, q + h * u) - bearing_lyapunov(f, q - h * u)) / (2 * h)
        np.testing.assert_allclose(fd, rate, rtol=1e-6)


def test_v_is_zero_exactly_at_the_target_and_decreases_along_a_run():
    f = TRIANGLE.with_bearings()
    q = 2.5 * bearing_realisation(f) + [1.0, -2.0]
    assert bearing_lyapunov(f, q) < 1e-28
    np.testing.assert_allclose(target(f, q), q, atol=1e-14)
    res = fl.simulate(f, fl.BearingLaw(), _starts(f, 1, 5)[0], duration=30.0)
    v = bearing_lyapunov(f, res.q)
    assert np.all(np.diff(v) <= 1e-12) and v[-1] < 1e-6 * v[0]


def test_the_reversed_formation_is_an_unstable_equilibrium():
    f = TRIANGLE.with_bearings()
    q = -bearing_realisation(f)  # every bearing reversed: p* turned by pi
    np.testing.assert_allclose(bearing_controls(f, q), 0.0, atol=1e-15)
    np.testing.assert_allclose(bearing_errors(f, q), 2.0, atol=1e-12)
    law = fl.BearingLaw()
    still = fl.simulate(f, law, q, duration=2.0)
    assert still.outcome() == "incorrect"
    nudge = np.array([[0.0, 0.0], [0.0, 0.01], [0.0, 0.0]])
    nudged = fl.simulate(f, law, q + nudge, duration=40.0)
    assert nudged.outcome() == "desired"


def test_bearings_given_per_edge_fix_the_same_shape_as_the_template():
    f = HEXAGON.with_bearings()
    given = fl.Formation.from_distances(6, edges=HEXAGON.edges + 1).with_bearings(f.bearings)
    np.testing.assert_allclose(bearing_realisation(given), bearing_realisation(f), atol=1e-9)
    # rows given for edges in another order and direction are stored for (i < j)
    rows = [[0.0, 1.0], [1.0, 0.0], [1.0, 1.0]]
    g = TRIANGLE.with_bearings(rows, edges=[[3, 1], [1, 2], [2, 3]])
    np.testing.assert_allclose(g.bearings, [[1, 0], [0, -1], [2**-0.5, 2**-0.5]], atol=1e-15)


def test_bearings_that_do_not_fix_the_shape_are_refused():
    path = fl.Formation.from_distances(3, edges=[[1, 2], [2, 3]]).with_bearings([[1, 0], [0, 1]])
    with pytest.raises(FormationError, match="do not fix the shape"):
        bearing_realisation(path)
    with pytest.raises(FormationError, match="not zero"):
        TRIANGLE.with_bearings([[0, 0], [1, 0], [0, 1]])
    with pytest.raises(FormationError, match="one \\[x, y\\] per edge"):
        TRIANGLE.with_bearings([[1, 0]])
    with pytest.raises(FormationError, match="template or are given per edge"):
        fl.Formation.from_distances(3).with_bearings()
    with pytest.raises(FormationError, match="needs desired bearings"):
        fl.BearingLaw().control(fl.Formation.from_distances(3), np.zeros((3, 2)))
    # from the template when the formation has none
    q = np.array([[0.0, 0.0], [1.0, 0.2], [0.3, 1.0]])
    law = fl.BearingLaw()
    np.testing.assert_array_equal(
        law.control(TRIANGLE, q), law.control(TRIANGLE.with_bearings(), q)
    )


def test_each_law_is_judged_by_what_it_controls():
    f = TRIANGLE.with_bearings()
    q0 = np.array([[0.3, -1.5], [2.0, 0.4], [-1.2, 1.1]])
    bearing = fl.simulate(TRIANGLE, fl.BearingLaw(), q0, duration=30.0)
    assert bearing.formation.bearings is not None and bearing.outcome() == "desired"
    # the distances of a bearing run are the start's scale, not the template's
    assert np.abs(fl.outcomes.analysis.distance_errors(TRIANGLE, bearing.q[-1])).max() > 0.1
    distance = fl.simulate(f, fl.DistanceLaw(), q0, duration=20.0)
    assert distance.formation.bearings is None and distance.outcome() in ("desired", "mirror")


def test_the_compiled_batch_is_the_numpy_batch():
    q0 = _starts(SQUARE, 64, 6)
    law = fl.BearingLaw(k=0.8)
    a = run_batch(SQUARE, law, q0, dt=1e-2, duration=8.0, backend="numpy")
    b = run_batch(SQUARE, law, q0, dt=1e-2, duration=8.0)
    np.testing.assert_array_equal(a.outcome, b.outcome)
    np.testing.assert_allclose(b.q_final, a.q_final, rtol=0, atol=1e-12)


@pytest.mark.parametrize("formation", [TRIANGLE, SQUARE], ids=["triangle", "square"])
def test_almost_every_start_reaches_the_desired_bearings(formation):
    """Zhao and Zelazo's Theorem 5 on 10,000 random starts: every trial reaches the desired
    bearings, except those whose robots meet on the way (the law has no barrier at contact;
    reported here, counted by a study)."""
    q0 = trial_initial_states(formation, BoxInitial(half_width=3.0), 7, np.arange(10_000))
    b = run_batch(formation, fl.BearingLaw(), q0, dt=1e-2, duration=60.0)
    kinds, counts = np.unique(b.outcome, return_counts=True)
    found = dict(zip(kinds.tolist(), counts.tolist(), strict=True))
    print(f"{formation.n} robots, 10,000 starts: {found}")
    assert set(found) <= {"desired", "collision"}
    assert found["desired"] >= 9_000


def _distance_rigid(q: np.ndarray, edges: np.ndarray) -> bool:
    r = rigidity_matrix(q, edges).toarray()
    return np.linalg.matrix_rank(r) == 2 * len(q) - 3


def test_bearing_rigidity_is_distance_rigidity_in_the_plane_on_random_frameworks():
    rng = np.random.default_rng(8)
    agree = rigid = 0
    for _ in range(1000):
        n = int(rng.integers(3, 9))
        pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)])
        keep = rng.random(len(pairs)) < rng.uniform(0.3, 0.9)
        edges = pairs[keep]
        if not len(edges):
            continue
        q = rng.normal(size=(n, 2))
        ib = is_infinitesimally_bearing_rigid(q, edges)
        assert ib == _distance_rigid(q, edges), (n, edges.tolist())
        agree += 1
        rigid += ib
    assert agree > 950 and 100 < rigid < agree - 100  # both answers were tested


@pytest.mark.parametrize("kind", ["triangular", "square", "hexagonal"])
def test_bearing_rigidity_is_distance_rigidity_on_lattices(kind):
    q = lattice(kind, 60)
    for edges in (delaunay_edges(q), knn_edges(q, 3), knn_edges(q, 6)):
        assert is_infinitesimally_bearing_rigid(q, edges) == _distance_rigid(q, edges)


def test_the_rigidity_matrix_annihilates_translations_and_scaling():
    q = lattice("triangular", 30)
    edges = delaunay_edges(q)
    rb = bearing_rigidity_matrix(q, edges)
    assert rb.shape == (2 * len(edges), 2 * len(q))
    for v in (np.tile([1.0, 0.0], len(q)), np.tile([0.0, 1.0], len(q)), q.ravel()):
        assert np.abs(rb @ v).max() < 1e-12
    assert bearing_nullity(q, edges) == 3


def test_the_sparse_rank_agrees_with_the_dense_one_beyond_the_dense_limit(monkeypatch):
    import formationlab.formation.bearing_rigidity as br

    q = lattice("triangular", 600)
    full = delaunay_edges(q)
    thin = full[np.random.default_rng(9).random(len(full)) < 0.55]
    dense = [bearing_nullity(q, e) for e in (full, thin)]
    monkeypatch.setattr(br, "DENSE_BEARING_LIMIT", 100)
    sparse = [bearing_nullity(q, e) for e in (full, thin)]
    assert dense[0] == 3 and dense[1] > 3
    assert sparse == dense


@pytest.mark.parametrize("leaders", [(1, 4), (1, 3, 5), (2, 5, 6)])
def test_followers_reach_the_formation_the_leaders_define(leaders):
    """Zhao and Zelazo (IEEE TCNS 4(3), 2017), Theorem 1: leaders standing still (robots
    stopped from the start) fix the position and the scale; the followers reach
    ``p*_f = -L_ff^-1 L_fl p_l`` under the bearing-only law."""
    f = HEXAGON.with_bearings()
    lead = np.array(leaders) - 1
    t = bearing_realisation(f)
    q0 = 1.6 * _starts(f, 1, 11)[0]
    q0[lead] = [0.5, -1.0] + 2.3 * t[lead]  # leaders where a copy of the target has them
    want = leader_target(f, leaders, q0[lead])
    # the closed form is that copy: the target's shape through the leaders, scaled, placed
    np.testing.assert_allclose(want, [0.5, -1.0] + 2.3 * t, rtol=0, atol=1e-12)
    faults = fl.Faults(stop=[fl.Stop(robot=r, at=0.0) for r in leaders])
    euler = fl.get_integrator("euler", dt=1e-2)
    res = fl.simulate(
        f, fl.BearingLaw(), q0, duration=400.0, faults=faults, save_every=1000, integrator=euler
    )
    assert res.outcome() == "desired"
    np.testing.assert_allclose(res.q[-1], want, rtol=0, atol=1e-6)
    # (two neighbouring leaders, 1 and 2, pin the far robots weakly: slower, same target)


def test_leaders_that_do_not_pin_the_followers_are_refused():
    f = HEXAGON.with_bearings()
    with pytest.raises(FormationError, match="at least two leaders"):
        leader_target(f, [1], [[0.0, 0.0]])
    # robots 1 and 4 are on one line through the centre with 2..6 around: collinear
    # leaders on a bearing edge still pin the hexagon (their distance sets the scale)
    leader_target(f, [1, 4], [[1.0, 0.0], [-1.0, 0.0]])


# ----------------------------------------------------------------------------- scenario files

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _scenario(formation: str, law: str = "bearing") -> str:
    return (
        "[robots]\npositions = [[0.3, -1.5], [2.0, 0.4], [-1.2, 1.1]]\n"
        f'[formation]\n{formation}\n[controller]\nlaw = "{law}"\n'
        '[simulation]\nintegrator = "euler"\ndt = 0.01\nduration = 40.0\n'
    )


def test_a_scenario_takes_bearings_from_its_template_or_per_edge():
    tpl = parse_scenario(_scenario("template = [[0, 0], [1, 0], [0.5, 0.8660254037844386]]"))
    given = parse_scenario((EXAMPLES / "bearing-triangle-given.toml").read_text())
    np.testing.assert_allclose(given.formation.bearings, tpl.formation.bearings, atol=1e-15)
    assert not given.warnings and not tpl.warnings
    run = run_scenario(given)
    assert run.outcome() == "desired"


@pytest.mark.parametrize(
    ("formation", "law", "key", "words"),
    [
        ('edges = [[1, 2], [2, 3]]\nbearings = [[1, 0], [0, 1]]', "bearing",
         "formation.bearings", "do not fix the shape"),
        ('edges = [[1, 2], [2, 3], [3, 1]]\nbearings = [[1, 0], [0, 1]]', "bearing",
         "formation.bearings", "one [x, y] per edge (3 edges)"),
        ('edges = [[1, 2], [2, 3], [3, 1]]\nbearings = [[1, 0], [0, 0], [0, 1]]', "bearing",
         "formation.bearings", "not zero"),
        ('edges = [[1, 2], [2, 3], [3, 1]]', "bearing", "formation.template",
         "needs desired bearings"),
        ('template = [[0, 0], [1, 0], [0.5, 0.9]]\nedges = { knn = 2 }\n'
         'bearings = [[1, 0], [0, 1], [1, 1]]', "bearing", "formation.bearings",
         "need the edges as a list of pairs"),
    ],
)  # fmt: skip
def test_bearings_a_scenario_cannot_use_are_refused_by_key(formation, law, key, words):
    with pytest.raises(ScenarioError) as info:
        parse_scenario(_scenario(formation, law))
    assert info.value.key == key and words in str(info.value)


def test_bearings_that_no_law_reads_are_warned_about():
    text = _scenario("edges = [[1, 2], [2, 3], [3, 1]]\nbearings = [[1, 0], [-1, 2], [-1, -2]]")
    sc = parse_scenario(text.replace('law = "bearing"', 'law = "distance"'))
    assert any("formation.bearings" in w and "reads no bearings" in w for w in sc.warnings)
    studied = parse_scenario(
        text.replace('law = "bearing"', 'law = "distance"')
        + '[study]\ntrials = 10\nlaws = ["distance", "bearing"]\n'
    )
    assert not any("formation.bearings" in w for w in studied.warnings)
    assert studied.formation.bearings is not None  # kept for the study's bearing law


# ----------------------------------------------------------------------------- frame errors


def test_a_frame_error_is_checked_and_drawn_from_the_seed():
    with pytest.raises(fl.errors.ParameterError, match="frame_error"):
        fl.Sensing(frame_error=-0.1)
    with pytest.raises(fl.errors.ParameterError, match="turned at random already"):
        fl.Sensing(frames="local", frame_error=0.1)
    system = fl.dynamics.System(
        formation=SQUARE, law=fl.BearingLaw(), sensing=fl.Sensing(frame_error=0.2, seed=3)
    )
    ch = system.channel(None, 1e-2)
    a = ch.angles(np.zeros((1, 4, 2)), np.arange(1))
    assert a.shape == (1, 4) and 0.01 < np.abs(a).max() < 1.0
    again = fl.dynamics.System(
        formation=SQUARE, law=fl.BearingLaw(), sensing=fl.Sensing(frame_error=0.2, seed=3)
    ).channel(None, 1e-2)
    np.testing.assert_array_equal(again.angles(np.zeros((1, 4, 2)), np.arange(1)), a)


def test_turned_frames_make_a_bearing_formation_drift_and_leave_a_distance_one():
    """Each robot's command in a frame turned by its own error: the commands no longer sum
    to zero, so the bearing formation keeps moving (it drifts), while the distance law,
    which reads lengths and radial directions, runs as before."""
    q0 = _starts(SQUARE, 16, 3)
    seeds = [(1, t) for t in range(16)]
    turned = fl.Sensing(frame_error=0.05)
    for law, same in ((fl.BearingLaw(), False), (fl.DistanceLaw(), True)):
        plain = run_batch(SQUARE, law, q0, dt=1e-2, duration=30.0)
        err = run_batch(SQUARE, law, q0, dt=1e-2, duration=30.0, sensing=turned, seeds=seeds)
        gap = np.abs(err.q_final - plain.q_final).max()
        assert (gap < 1e-9) if same else (gap > 1e-3)
        if not same:
            assert np.mean(err.outcome == "drifting") > 0.5


# ----------------------------------------------------------------------------- equilibria


def test_equilibria_are_found_modulo_translation_and_scale():
    """The bearing law's equilibria form orbits of translations and scalings (not rotations):
    the desired one is stable once those three modes are removed, the reversed one a saddle,
    and end states of every size merge into one equilibrium."""
    from formationlab.equilibria import catalogue, rigid_modes

    f = TRIANGLE.with_bearings()
    law = fl.BearingLaw()
    t = bearing_realisation(f)
    ends = np.array([s * t + c for s, c in ((1.0, [0, 0]), (2.5, [1, -2]), (0.7, [3, 3]))])
    cat = catalogue(f, law, ends, extra=[-1.3 * t])
    kinds = sorted((eq.desired, eq.stability) for eq in cat.equilibria)
    assert kinds == [(False, "saddle"), (True, "stable")]
    assert cat.counts[0] == 3  # the three sizes are one equilibrium
    modes = rigid_modes(t, "scale")
    np.testing.assert_allclose(modes.T @ modes, np.eye(3), atol=1e-12)
    jac_dir = law.control(f, t + 1e-6 * modes[:, 2].reshape(-1, 2)) - law.control(f, t)
    assert np.abs(jac_dir).max() < 1e-12  # scaling is a zero mode of the bearing law


def test_the_pettingzoo_environment_runs_the_bearing_law_and_rewards_its_bearings():
    from formationlab.envs import law_policy, parallel_env

    env = parallel_env(parse_scenario((EXAMPLES / "bearing-triangle.toml").read_text()))
    obs, _ = env.reset(seed=0)
    policy = law_policy(env)
    for _ in range(4000):
        obs, rewards, term, trunc, infos = env.step(policy(obs))
        if any(term.values()) or any(trunc.values()):
            break
    assert all(info["outcome"] == "desired" for info in infos.values())
    # the reward is minus each robot's bearing errors, each within the tolerance 1e-2 twice
    assert all(-2e-2 <= r < 0 for r in rewards.values())


def test_two_marching_leaders_carry_the_bearing_formation():
    """Several leaders given v_ref (the translational maneuver, Zhao and Zelazo 2017): in
    steady state every robot moves at v_ref, and the followers lag behind the target by
    bearing errors that grow in proportion to the speed (the law has no feedforward)."""
    from formationlab.marching import Marching

    f = HEXAGON.with_bearings()
    t = bearing_realisation(f)
    q0 = 1.6 * _starts(f, 1, 11)[0]
    q0[[0, 3]] = [0.5, -1.0] + 2.3 * t[[0, 3]]
    euler = fl.get_integrator("euler", dt=1e-2)
    lag = []
    for v in (0.02, 0.1):
        march = Marching(velocity=[v, 0.0], leader=[1, 4])
        assert march.leaders == (1, 4)
        res = fl.simulate(
            f, fl.BearingLaw(), q0, duration=300.0, marching=march, integrator=euler,
            save_every=100,
        )  # fmt: skip
        speed = (res.q[-1] - res.q[-2]) / (res.t[-1] - res.t[-2])
        np.testing.assert_allclose(speed, np.broadcast_to([v, 0.0], speed.shape), atol=1e-9)
        lag.append(bearing_errors(res.formation, res.q[-1]).max())
    assert 4.0 < lag[1] / lag[0] < 6.5
    with pytest.raises(fl.errors.ParameterError, match="each robot once"):
        Marching(velocity=[0.1, 0.0], leader=[1, 1])
    with pytest.raises(fl.errors.ParameterError, match="leader 9 is not a robot"):
        Marching(velocity=[0.1, 0.0], leader=[1, 9]).check(f)


def test_leaders_moving_apart_scale_the_bearing_formation():
    """The scaling maneuver (Zhao and Zelazo 2017): leaders 1 and 4, each with its own
    velocity, move apart along their bearing; the formation the leaders define
    (``leader_target``) grows, and the followers track it. Leaders standing still: the
    target exactly. Moving: a steady lag relative to the scale (the bearing-only law has
    no feedforward: its correction is bounded while the followers' needed speed grows with
    their distance to the centre), nearly in proportion to the speed."""
    from formationlab.marching import Marching

    f = HEXAGON.with_bearings()
    t = bearing_realisation(f)
    q0 = 1.6 * _starts(f, 1, 11)[0]
    q0[[0, 3]] = [0.5, -1.0] + 2.3 * t[[0, 3]]
    out = (t[0] - t[3]) / np.linalg.norm(t[0] - t[3])  # along the bearing from 4 to 1
    euler = fl.get_integrator("euler", dt=1e-2)
    lag = {}
    for v in (0.0, 0.01, 0.05):
        march = Marching(velocity=[v * out, -v * out], leader=(1, 4))
        assert march.per_leader
        res = fl.simulate(
            f, fl.BearingLaw(), q0, duration=300.0, marching=march, integrator=euler,
            save_every=100,
        )  # fmt: skip
        for robot, velocity in ((0, v * out), (3, -v * out)):  # each leader its own
            moved = (res.q[-1, robot] - res.q[0, robot]) / res.t[-1]
            np.testing.assert_allclose(moved, velocity, rtol=0, atol=1e-12)
        rel = []
        for q in res.q[-20:]:
            scale = np.linalg.norm(q[0] - q[3])
            rel.append(np.abs(q - leader_target(f, [1, 4], q[[0, 3]])).max() / scale)
        lag[v] = rel[-1]
        np.testing.assert_allclose(rel, rel[-1], rtol=1e-4, atol=1e-9)  # a steady lag
    assert lag[0.0] < 1e-9
    assert 3.5 < lag[0.05] / lag[0.01] < 5.5  # (4.1 measured)
    # what run's summary.json says of the maneuver: the followers' distance to the target
    marching = res.summary()["marching"]
    assert "centroid_velocity_error_final" not in marching  # (no one reference velocity)
    q = res.q[-1]
    gap = np.linalg.norm(q - leader_target(f, [1, 4], q[[0, 3]]), axis=-1).max()
    assert marching["leader_target_error_final"] == pytest.approx(gap, rel=1e-12)
    assert marching["leader_target_scale_final"] == pytest.approx(
        np.linalg.norm(q[0] - q[3]) / 2, rel=1e-9
    )
    assert lag[0.01] < 0.02


def test_a_velocity_per_leader_is_checked_by_name():
    from formationlab.marching import Marching

    with pytest.raises(fl.errors.ParameterError, match="one per leader \\(2 rows\\)"):
        Marching(velocity=[[0.1, 0.0], [0.0, 0.1], [0.2, 0.2]], leader=(1, 2))
    with pytest.raises(fl.errors.ParameterError, match="finite \\[vx, vy\\]"):
        Marching(velocity=[[0.1, 0.0], [0.0, 0.1]])  # every robot: one velocity
    base = (EXAMPLES / "bearing-square.toml").read_text()
    cases = {
        "leader = [1, 3]\nvelocity = [[0.1, 0.0]]": "marching.velocity",
        'kind = "motion-parameters"\nvelocity = [[0.1, 0.0], [0.0, 0.1]]': "marching.velocity",
        "leader = [1, 3]\nvelocity = [[0.1, 0.0], [0.0]]": "marching.velocity",
    }
    for table, key in cases.items():
        with pytest.raises(ScenarioError, match=key.replace(".", "\\.")):
            parse_scenario(base + "\n[marching]\n" + table + "\n")
    text = base + "\n[marching]\nleader = [1, 3]\nvelocity = [[-0.1, 0], [0.1, 0]]\n"
    march = parse_scenario(text).marching
    assert march.leaders == (1, 3) and march.per_leader
    np.testing.assert_array_equal(march.reference(0.0), [[-0.1, 0.0], [0.1, 0.0]])


# ----------------------------------------------------------------------------- every layer


@pytest.mark.parametrize(
    "case", ["plain", "leaders", "obstacle-and-filter", "frame-error-noise-drop", "stop"]
)
@pytest.mark.parametrize("model", ["single", "single-limited", "double", "unicycle-heading"])
def test_a_single_run_on_the_compiled_loop_follows_the_driver(model, case):
    """The bearing law under every robot model with leaders, an obstacle and a filter,
    sensing faults and a stopped robot: the engine's loop against the numpy driver."""
    from test_compiled_models import assert_follows
    from test_compiled_stages import MODELS, both

    from formationlab.marching import Marching
    from formationlab.safety import SafetyFilter
    from formationlab.safety.obstacles import Circle

    kw = {
        "plain": {},
        "leaders": {"marching": Marching(velocity=[0.2, -0.1], leader=[1, 2])},
        "obstacle-and-filter": {
            "obstacles": (Circle(center=[0.2, -1.8], radius=0.2),),
            "safety": SafetyFilter(filter="barrier-decentralized", distance=0.25, gamma=50.0),
        },
        "frame-error-noise-drop": {
            "sensing": fl.Sensing(frame_error=0.05, noise=0.01, drop=0.3, seed=4)
        },
        "stop": {"faults": fl.Faults(stop=[fl.Stop(robot=3, at=0.5)])},
    }[case]
    if case == "obstacle-and-filter" and model == "double":
        kw.pop("safety")  # (no filter holds a double integrator: refused, tested elsewhere)
    q0 = np.array([[-1.2, -0.9], [1.4, -0.7], [0.1, 1.3]])
    law = fl.BearingLaw(k=1.0, k_r=1.0)  # with the repulsion (and so the obstacles' one)
    a, b = both(
        TRIANGLE, law, q0, model=MODELS[model], duration=2.0, save_every=5,
        integrator=fl.Euler(dt=1e-2), **kw,
    )  # fmt: skip
    assert_follows(a, b, scale=3.0, tol=1e-11)
    assert a.formation.bearings is not None


def test_a_bearing_swarm_runs_on_the_lists_layout_as_the_driver():
    points = lattice("triangular", 150)
    f = fl.Formation.from_template(points, edges=delaunay_edges(points), one_based=False)
    q0 = points + np.random.default_rng(12).normal(0.0, 0.05, points.shape)
    from test_compiled_models import assert_follows
    from test_compiled_stages import both

    assert f.n > fl.formation.spec.DENSE_LIMIT
    a, b = both(f, fl.BearingLaw(), q0, duration=0.5, save_every=10)
    assert_follows(a, b, scale=float(np.abs(q0).max()))


def test_a_study_reports_the_bearing_error_of_a_bearing_law():
    import pandas as pd

    from formationlab.studies.summary import _steady

    q0 = _starts(SQUARE, 32, 13)
    bearing = run_batch(SQUARE, fl.BearingLaw(), q0, dt=1e-2, duration=60.0)
    distance = run_batch(SQUARE, fl.DistanceLaw(), q0, dt=1e-2, duration=20.0)
    assert np.isnan(distance.max_bearing_error).all()
    ok = bearing.outcome == "desired"
    assert ok.sum() > 25 and np.all(bearing.max_bearing_error[ok] <= 1e-2)
    want = np.max(bearing_errors(bearing_formation := SQUARE.with_bearings(), bearing.q_final), -1)
    assert bearing_formation.bearings is not None
    np.testing.assert_allclose(bearing.max_bearing_error, want, rtol=0, atol=1e-15)
    rows = pd.DataFrame(
        {"outcome": bearing.outcome, "max_distance_error": bearing.max_distance_error,
         "max_bearing_error": bearing.max_bearing_error}
    )  # fmt: skip
    shape, _ = _steady(rows)
    err = bearing.max_bearing_error[bearing.outcome != "collision"]
    assert shape is not None and shape["median"] == pytest.approx(np.median(err), abs=1e-15)


def test_the_viewer_plots_the_bearing_errors_live_and_in_a_replay(tmp_path):
    from formationlab.io.netcdf import write_trajectory
    from formationlab.viewer.sources import open_session

    path = EXAMPLES / "bearing-triangle.toml"
    live = open_session(path)
    assert live.info()["errors_kind"] == "bearing"
    live.step(50)
    fr = live.frame()
    want = bearing_errors(live.system.formation, live.system.model.points(live.state))
    assert fr.header["errors_kind"] == "bearing"
    np.testing.assert_allclose(fr.header["errors"], want, rtol=0, atol=1e-15)
    run = run_scenario(parse_scenario(path.read_text()), save_every=50)
    (tmp_path / "run").mkdir()
    write_trajectory(run, tmp_path / "run" / "trajectory.nc", attrs={"scenario": path.read_text()})
    replay = open_session(tmp_path / "run")
    info = replay.info()
    assert info["errors_kind"] == "bearing"
    np.testing.assert_allclose(
        info["series"]["errors"][0][-1], bearing_errors(run.formation, run.q[-1])[0], atol=1e-12
    )
    # a distance run plots distances
    assert open_session(EXAMPLES / "hexagon.toml").info()["errors_kind"] == "distance"
