"""The batched Euler kernel: equal to the one-by-one simulator, trial by trial.

The numba kernel is compared with the numpy reference and both with
``formationlab.simulate(..., integrator=Euler(dt))``; the stopping rules and
the classification are checked on hand-built cases.
"""

import math

import numba
import numpy as np
import pytest

import formationlab as fl
from formationlab.controllers import SignedAreaLaw, SquaredDistanceLaw
from formationlab.errors import FormationError, ParameterError
from formationlab.outcomes.analysis import classify
from formationlab.studies import batch
from formationlab.studies.batch import BatchResult, classify_batch, run_batch

SIM2 = {(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}  # section 4, simulation 2
SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
LAWS = {
    "distance": fl.DistanceLaw(k_c=2.0),
    "angle-restricted": fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5),
    "squared-distance": SquaredDistanceLaw(),
    "signed-area": SignedAreaLaw(k_s=1.0),
}
DT = 1e-3


def paper_triangle():
    return fl.Formation.from_alpha_table(SIM2, n=3, distances=1.0, diameters=0.2)


def square_one_diagonal():
    """The unit square, ring 1-2-3-4 plus diagonal 1-3: robots 2 and 4 only repel."""
    edges = [[1, 2], [2, 3], [3, 4], [4, 1], [1, 3]]
    return fl.Formation.from_template(SQUARE, edges=edges, orientation="template")


def draws(formation, count, half_width, seed):
    """Uniform positions in the box, overlapping draws rejected."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        q = rng.uniform(-half_width, half_width, size=(formation.n, 2))
        iu, ju = np.triu_indices(formation.n, k=1)
        if np.all(np.linalg.norm(q[ju] - q[iu], axis=-1) > formation.contact_matrix[iu, ju] + 0.05):
            out.append(q)
    return np.array(out)


@pytest.fixture(scope="module")
def cases():
    """(formation, law, q0) per law; the paper's triangle and the square with a non-edge."""
    out = {}
    for name, law in LAWS.items():
        for label, f, w in (
            ("triangle", paper_triangle(), 3.0),
            ("square", square_one_diagonal(), 1.5),
        ):
            out[name, label] = (f, law, draws(f, 6, w, seed=len(out)))
    return out


@pytest.fixture(scope="module")
def results(cases):
    """Both backends on every case (duration 2 s, so that some trials run to the end)."""
    kw = {"dt": DT, "duration": 2.0, "check_every": 7}
    return {
        key: {b: run_batch(f, law, q0, backend=b, **kw) for b in ("numba", "numpy")}
        for key, (f, law, q0) in cases.items()
    }


def test_result_fields_and_shapes(results, cases):
    res = results["angle-restricted", "triangle"]["numba"]
    assert isinstance(res, BatchResult)
    b, n = cases["angle-restricted", "triangle"][2].shape[:2]
    assert res.q_final.shape == res.u_final.shape == (b, n, 2)
    for name in (
        "outcome",
        "max_distance_error",
        "converged_time",
        "min_clearance",
        "steps",
        "net_speed",
    ):
        assert getattr(res, name).shape == (b,)
    assert res.steps.dtype == np.int64
    assert set(res.outcome) <= set(fl.OUTCOMES)


@pytest.mark.parametrize("law", list(LAWS))
@pytest.mark.parametrize("shape", ["triangle", "square"])
def test_numba_equals_numpy_reference(results, law, shape):
    a, b = results[law, shape]["numba"], results[law, shape]["numpy"]
    np.testing.assert_array_equal(a.steps, b.steps)
    np.testing.assert_array_equal(a.outcome, b.outcome)
    np.testing.assert_allclose(a.q_final, b.q_final, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.u_final, b.u_final, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.min_clearance, b.min_clearance, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(np.isnan(a.converged_time), np.isnan(b.converged_time))
    np.testing.assert_allclose(a.converged_time, b.converged_time, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.net_speed, b.net_speed, rtol=0, atol=1e-9)


@pytest.mark.parametrize("law", list(LAWS))
@pytest.mark.parametrize("shape", ["triangle", "square"])
def test_batch_equals_one_by_one_simulator(results, cases, law, shape):
    f, lw, q0 = cases[law, shape]
    res = results[law, shape]["numba"]
    for t in range(0, len(q0), 2):  # every other trial keeps the test fast
        steps = int(res.steps[t])
        collided = res.outcome[t] == "collision"
        if steps == 0 and not collided:
            np.testing.assert_array_equal(res.q_final[t], q0[t])
            continue
        # a collision ends at the last accepted state: the simulator needs one step more
        duration = (steps + collided) * DT
        sim = fl.simulate(f, lw, q0[t], duration=duration, integrator=fl.Euler(dt=DT))
        assert (sim.status == "step-collision") == collided
        np.testing.assert_allclose(res.q_final[t], sim.q[-1], rtol=0, atol=1e-9)
        np.testing.assert_allclose(res.u_final[t], sim.u[-1], rtol=0, atol=1e-9)
        # net speed between the trial's last two convergence checks (every 7 steps and
        # at step 2000), from the simulator's positions at those steps
        checks = [k for k in range(steps + 1) if k % 7 == 0 or k == 2000]
        net = None
        if len(checks) >= 2:
            k1, k0 = checks[-1], checks[-2]
            net = np.linalg.norm(sim.q[k1] - sim.q[k0], axis=-1).max() / ((k1 - k0) * DT)
            assert res.net_speed[t] == pytest.approx(net, rel=1e-6, abs=1e-9)
        else:
            assert np.isnan(res.net_speed[t])
        expected = classify(f, sim.q[-1], sim.u[-1], contact=collided, net_speed=net)
        assert res.outcome[t] == expected
        if not np.isnan(res.converged_time[t]) and steps >= 7:
            # a converged trial ends at a check: the simulator's own rule over 7 steps agrees
            assert sim.outcome(fl.Tolerances(window=7 * DT)) == expected
        clearance = fl.System(formation=f, law=lw).clearance(sim.q)
        assert res.min_clearance[t] == pytest.approx(clearance.min(), abs=1e-9)
        errors = np.abs(fl.distance_errors(f, sim.q[-1])).max()
        assert res.max_distance_error[t] == pytest.approx(errors, abs=1e-9)


def test_stopping_rules(results):
    # converged trials stopped at a multiple of check_every with every |u_i| <= speed
    # or a net speed <= speed; the others ran to the end (2000 steps) or were stopped
    # by contact.
    speed = fl.Tolerances().speed
    for per_backend in results.values():
        res = per_backend["numba"]
        conv = ~np.isnan(res.converged_time)
        assert np.all(res.steps[conv] % 7 == 0)
        np.testing.assert_allclose(res.converged_time[conv], res.steps[conv] * DT)
        slow = np.linalg.norm(res.u_final, axis=-1).max(axis=-1) <= speed
        assert np.all(slow[conv] | (res.net_speed[conv] <= speed))
        assert not np.any(slow[~conv] & (res.outcome[~conv] != "collision"))
        other = ~conv & (res.outcome != "collision")
        assert np.all(res.steps[other] == 2000)


def test_converged_time_is_the_first_check_passed():
    f = paper_triangle()
    law = LAWS["angle-restricted"]
    q0 = draws(f, 2, 3.0, seed=11)
    res = run_batch(f, law, q0, dt=DT, duration=10.0, check_every=25)
    for t in range(2):
        assert not np.isnan(res.converged_time[t])
        k = int(res.steps[t])
        sim = fl.simulate(f, law, q0[t], duration=k * DT, integrator=fl.Euler(dt=DT))
        speeds = np.linalg.norm(sim.u, axis=-1).max(axis=-1)  # at steps 0..k
        assert speeds[k] <= 1e-3
        assert np.all(speeds[:k:25] > 1e-3)  # every earlier check failed


def test_trial_at_the_desired_formation_stops_at_once():
    f = paper_triangle()
    tri = np.array([[0.0, 0.0], [0.5, math.sqrt(3) / 2], [1.0, 0.0]])  # clockwise, unit sides
    res = run_batch(f, LAWS["angle-restricted"], tri[None], dt=DT, duration=1.0)
    assert res.steps[0] == 0 and res.converged_time[0] == 0.0
    assert res.outcome[0] == "desired"
    assert res.min_clearance[0] == pytest.approx(0.8)  # 1 - a, a = 0.2


def test_step_into_contact_is_a_collision_at_the_previous_state():
    # Two robots 1.3 apart, d = 1, squared distance with k = 1: u_1 = (1.69 - 1) 1.3 = 0.897
    # along the line, so one step of dt = 0.65 brings them to r = 1.3 - 2 * 0.65 * 0.897
    # = 0.134 < a = 0.2: the step is rejected and the trial ends where it started.
    f = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    q0 = np.array([[[0.0, 0.0], [1.3, 0.0]]])
    for backend in ("numba", "numpy"):
        res = run_batch(f, SquaredDistanceLaw(), q0, dt=0.65, duration=6.5, backend=backend)
        assert res.outcome[0] == "collision"
        assert res.steps[0] == 0 and np.isnan(res.converged_time[0])
        np.testing.assert_array_equal(res.q_final[0], q0[0])
        np.testing.assert_allclose(res.u_final[0], [[0.897, 0.0], [-0.897, 0.0]], rtol=1e-12)
        assert res.min_clearance[0] == pytest.approx(1.1)
    sim = fl.simulate(f, SquaredDistanceLaw(), q0[0], duration=6.5, integrator=fl.Euler(dt=0.65))
    assert sim.status == "step-collision"


def test_short_runs_do_not_converge():
    f = paper_triangle()
    q0 = np.array([[[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]])
    res = run_batch(f, LAWS["distance"], q0, dt=DT, duration=0.05)
    assert res.outcome[0] == "not-converged" and res.steps[0] == 50


def test_chunking_and_compaction_do_not_change_results(monkeypatch):
    # Trials are independent: the result of a trial must not depend on its chunk, on
    # the number of threads, or on which other trials stopped before it (the kernel
    # compacts its live trials).
    f = square_one_diagonal()
    law = LAWS["angle-restricted"]
    q0 = draws(f, 23, 1.5, seed=5)
    full = run_batch(f, law, q0, dt=DT, duration=2.0, check_every=3)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        single = run_batch(f, law, q0, dt=DT, duration=2.0, check_every=3)
    finally:
        numba.set_num_threads(threads)
    monkeypatch.setattr(batch, "CHUNK", 4)
    small = run_batch(f, law, q0, dt=DT, duration=2.0, check_every=3)
    part = run_batch(f, law, q0[9:14], dt=DT, duration=2.0, check_every=3)
    for other, sl in ((small, slice(None)), (part, slice(9, 14)), (single, slice(None))):
        np.testing.assert_array_equal(other.q_final, full.q_final[sl])
        np.testing.assert_array_equal(other.steps, full.steps[sl])
        np.testing.assert_array_equal(other.min_clearance, full.min_clearance[sl])


def four_robots_two_triangles():
    """Triangles 1-2-3 and 2-3-4 sharing edge 2-3 (not rigid against folding robot 4)."""
    tpl = np.array([[0.0, 0.0], [1.0, -0.5], [1.0, 0.5], [1.6, 0.2]])
    edges = [[1, 2], [1, 3], [2, 3], [2, 4], [3, 4]]
    return fl.Formation.from_template(tpl, edges=edges), tpl


def test_classify_batch_equals_classify_on_every_class():
    f, tpl = four_robots_two_triangles()
    folded = tpl.copy()
    folded[3] = [0.4, 0.2]  # robot 4 reflected across edge 2-3: distances kept, one flip
    moving = np.full((4, 2), 0.1)
    states = [
        (tpl, np.zeros((4, 2)), False, "desired"),
        (tpl * [-1.0, 1.0], np.zeros((4, 2)), False, "mirror"),
        (
            folded + np.array([[0.0, 0.3], [0, 0], [0, 0], [0, 0]]),
            np.zeros((4, 2)),
            False,
            "incorrect",
        ),
        (folded, moving, False, "incorrect"),  # distances met, only triangle 2-3-4 flipped
        (tpl * 0.5, np.zeros((4, 2)), False, "incorrect"),  # stopped, distances not met
        (tpl * 0.5, moving, False, "not-converged"),
        (tpl, np.zeros((4, 2)), True, "collision"),  # a step was rejected at contact
        (np.array([[0.0, 0.0], [0.1, 0.0], [1.0, 0.5], [2.0, 0.0]]), moving, False, "collision"),
    ]
    q = np.array([s[0] for s in states])
    u = np.array([s[1] for s in states])
    contact = np.array([s[2] for s in states])
    got = classify_batch(f, q, u, contact=contact)
    for t, (qt, ut, ct, want) in enumerate(states):
        assert classify(f, qt, ut, contact=ct) == want
        assert got[t] == want


def test_classify_batch_agrees_with_classify_on_random_states(rng):
    f = square_one_diagonal()
    q = SQUARE + rng.normal(scale=0.004, size=(400, 4, 2))
    q[::3] = q[::3] * [-1.0, 1.0]  # mirrors
    q[::7] *= 0.9  # distances not met
    u = rng.normal(scale=1e-3, size=(400, 4, 2))
    tol = fl.Tolerances(distance=1e-2, speed=2e-3)
    got = classify_batch(f, q, u, tol)
    want = [classify(f, q[t], u[t], tol) for t in range(400)]
    np.testing.assert_array_equal(got, want)
    assert len(set(want)) >= 3


def test_input_errors():
    f = paper_triangle()
    law = LAWS["distance"]
    good = np.array([[[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]])
    with pytest.raises(FormationError, match=r"shape \(B, 3, 2\)"):
        run_batch(f, law, good[0], dt=DT, duration=1.0)
    overlap = good.copy()
    overlap[0, 1] = [-2.9, -3.0]
    with pytest.raises(FormationError, match="robots 1 and 2 overlap in trial 1"):
        run_batch(f, law, overlap, dt=DT, duration=1.0)
    with pytest.raises(ParameterError, match="backend"):
        run_batch(f, law, good, dt=DT, duration=1.0, backend="cuda")
    with pytest.raises(ParameterError, match="dt"):
        run_batch(f, law, good, dt=-1.0, duration=1.0)
    with pytest.raises(ParameterError, match="check_every"):
        run_batch(f, law, good, dt=DT, duration=1.0, check_every=0)


def test_other_laws_run_on_the_numpy_backend_only():
    class Scaled(fl.DistanceLaw):
        """A law of its own: its control is not the one its inherited kernel terms describe."""

        name = "scaled-distance-for-test"

        def control(self, formation, q):
            return 0.5 * super().control(formation, q)

    class Renamed(fl.DistanceLaw):
        name = "renamed-distance-for-test"

    f = paper_triangle()
    q0 = np.array([[[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]])
    with pytest.raises(ParameterError, match='backend="numpy"'):
        run_batch(f, Scaled(), q0, dt=DT, duration=0.1)
    res = run_batch(f, Scaled(), q0, dt=DT, duration=0.1, backend="numpy")
    ref = run_batch(f, fl.DistanceLaw(k_c=1.0), q0, dt=DT, duration=0.1)
    np.testing.assert_allclose(res.q_final, ref.q_final, atol=1e-12)
    # a subclass that keeps the control keeps the kernel
    same = run_batch(f, Renamed(), q0, dt=DT, duration=0.1)
    np.testing.assert_array_equal(
        same.q_final, run_batch(f, fl.DistanceLaw(), q0, dt=DT, duration=0.1).q_final
    )


@pytest.mark.parametrize(
    ("table", "outcome"),
    [
        ({(1, 2, 3): -1, (3, 1, 2): -1, (2, 1, 3): 1}, "desired"),  # simulation 1
        (SIM2, "incorrect"),  # simulation 2: the trapped symmetric equilibrium (paper NOTES)
    ],
)
def test_paper_section_4_runs_agree_with_the_simulator(table, outcome):
    # The initial state of section 4 is mirror-symmetric; in simulation 2 an exact run
    # stays in the symmetric subspace and stops at the shrunken triangle where the
    # repulsion of phi balances the push of psi. Rounding could break the symmetry
    # differently in the kernel: it must not (the run is trapped by t = 4 s).
    f = fl.Formation.from_alpha_table(table, n=3, distances=1.0, diameters=0.2)
    law = LAWS["angle-restricted"]
    q0 = np.array([[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]])
    sim = fl.simulate(f, law, q0, duration=4.0, integrator=fl.Euler(dt=DT))
    for backend in ("numba", "numpy"):
        res = run_batch(f, law, q0[None], dt=DT, duration=4.0, check_every=10**6, backend=backend)
        assert res.steps[0] == 4000
        np.testing.assert_allclose(res.q_final[0], sim.q[-1], rtol=0, atol=1e-12)
        assert res.outcome[0] == sim.outcome() == outcome


def test_non_finite_step_ends_the_trial_at_its_last_finite_state():
    # Squared distance from r = 1e120: u = k (r^2 - d^2) r overflows to infinity, so
    # the first step is not finite; like the simulator's "non-finite" status the trial
    # keeps q0 (and, moving with infinite speed and distances unmet, has not converged).
    f = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    q0 = np.array([[[0.0, 0.0], [1e120, 0.0]], [[0.0, 0.0], [1.5, 0.0]]])
    for backend in ("numba", "numpy"):
        res = run_batch(f, SquaredDistanceLaw(), q0, dt=DT, duration=0.01, backend=backend)
        np.testing.assert_array_equal(res.steps, [0, 10])
        np.testing.assert_array_equal(res.q_final[0], q0[0])
        assert res.outcome[0] == "not-converged" and np.isnan(res.converged_time[0])


@pytest.mark.parametrize(
    "law",
    [fl.AngleRestrictedLaw(k_c=1.5, k_a=2.0, theta=0.2), SignedAreaLaw(k=0.5, k_s=3.0, k_r=1.0)],
)
def test_angle_valued_alpha_on_a_ring(law):
    # A ring of four (no diagonals): restricted triples (i, j, k) whose j and k are not
    # neighbours, angle-valued alpha, non-default gains; kernel against the reference.
    f = fl.Formation.from_template(
        SQUARE, edges=[[1, 2], [2, 3], [3, 4], [4, 1]], alpha_values="angle"
    )
    assert f.alpha_values == "angle" and not np.all(np.isin(np.abs(f.alpha), [0.0, 1.0]))
    q0 = draws(f, 8, 1.5, seed=21)
    a, b = (run_batch(f, law, q0, dt=DT, duration=1.5, backend=x) for x in ("numba", "numpy"))
    np.testing.assert_array_equal(a.steps, b.steps)
    np.testing.assert_array_equal(a.outcome, b.outcome)
    np.testing.assert_allclose(a.q_final, b.q_final, rtol=0, atol=1e-9)


# ------------------------------------------------------ stopped: the net speed rule


class Relay(fl.DistanceLaw):
    """``u_i = (-sign(x_1 - 1/4), 0)``: explicit Euler from ``x_1 = 1/4 + dt/2`` chatters
    between ``1/4 +- dt/2`` (|u| = 1 at every step, no net motion: the scalar picture of
    a sliding-mode equilibrium)."""

    name = "batch-relay-for-test"

    def control(self, formation, q):
        q = np.asarray(q, dtype=float)
        u = np.zeros_like(q)
        u[..., 0] = -np.sign(q[..., :1, 0] - 0.25)
        return u


class Drift(fl.DistanceLaw):
    """``u_i = (2e-3, 0)``: a smooth motion, twice the speed tolerance."""

    name = "batch-drift-for-test"

    def control(self, formation, q):
        u = np.zeros_like(np.asarray(q, dtype=float))
        u[..., 0] = 2e-3
        return u


def test_chatter_at_rest_is_stopped_in_the_batch_as_in_the_simulator():
    # two robots 2 apart, d = 1: wherever they stop, the distance is not met
    f = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    q0 = np.array([[[0.25 + DT / 2, 0.0], [2.25 + DT / 2, 0.0]]])
    res = run_batch(f, Relay(), q0, dt=DT, duration=1.0, backend="numpy")
    # first test at k = 0 (no net speed yet), second at k = 10 (even: back at the start)
    assert res.steps[0] == 10 and res.converged_time[0] == pytest.approx(0.01)
    assert res.net_speed[0] < 1e-12 and np.abs(res.u_final[0]).max() == 1.0
    assert res.outcome[0] == "incorrect"
    sim = fl.simulate(f, Relay(), q0[0], duration=1.0, integrator=fl.Euler(dt=DT))
    assert sim.outcome() == "incorrect"
    # tests every 9 steps: one kick of dt remains, net speed 1e-3 / 9e-3 at every test
    odd = run_batch(f, Relay(), q0, dt=DT, duration=1.0, check_every=9, backend="numpy")
    assert odd.steps[0] == 1000 and np.isnan(odd.converged_time[0])
    assert odd.outcome[0] == "not-converged"
    # the last test (step 1000) comes one step after the one at 999
    assert odd.net_speed[0] == pytest.approx(1e-3 / 1e-3)
    # a smooth motion at 2e-3 is still moving, whatever the window
    for window in (0.01, 0.5):
        tol = fl.Tolerances(window=window)
        drift = run_batch(f, Drift(), q0, dt=DT, duration=1.0, tolerances=tol, backend="numpy")
        assert drift.outcome[0] == "not-converged" and drift.steps[0] == 1000
        assert drift.net_speed[0] == pytest.approx(2e-3)


def test_classify_batch_uses_the_net_speed_like_classify():
    f = paper_triangle()
    shrunk = np.array([[0.0, 0.0], [0.25, 0.4], [0.5, 0.0]])  # distances not met
    fast = np.full((3, 2), 0.5)
    net = np.array([0.0, 1e-3, 1.1e-3, np.nan, 5.0])
    q = np.repeat(shrunk[None], len(net), axis=0)
    u = np.repeat(fast[None], len(net), axis=0)
    got = classify_batch(f, q, u, net_speed=net)
    want = ["incorrect", "incorrect", "not-converged", "not-converged", "not-converged"]
    np.testing.assert_array_equal(got, want)
    for b in range(len(net)):
        assert classify(f, q[b], u[b], net_speed=net[b]) == want[b]
    assert classify(f, shrunk, fast) == "not-converged"  # no net speed: |u| decides


SLIDING_TRIAL = 5  # of the square study (seed 1, k_a = 1), docs/studies.md


def test_square_sliding_mode_equilibrium():
    # The square with both diagonals, k_a = 1: trial 5 of seed 1 ends at a sliding-mode
    # equilibrium on two switching surfaces (docs/studies.md). Explicit Euler at
    # dt = 1e-3 does not chatter with period 2 there: the iterates wander in a band of
    # about dt |u| (|u| = 0.54), so the net speed over the default 10 ms stays near 0.14
    # and the trial is "not-converged"; over a 2 s window the wandering averages out.
    from formationlab.io.scenario import load_scenario
    from formationlab.studies.config import BoxInitial
    from formationlab.studies.sampling import trial_initial_states

    f = load_scenario("examples/study-square.toml").formation
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=1.0, theta=0.5)
    q0 = trial_initial_states(f, BoxInitial(half_width=3.0), 1, [SLIDING_TRIAL])
    short = run_batch(f, law, q0, dt=DT, duration=15.0)
    assert short.outcome[0] == "not-converged" and short.net_speed[0] > 0.05
    assert np.linalg.norm(short.u_final[0], axis=-1).max() > 0.5
    tol = fl.Tolerances(window=2.0)
    a, b = (run_batch(f, law, q0, dt=DT, duration=15.0, tolerances=tol, backend=x)
            for x in ("numba", "numpy"))  # fmt: skip
    for res in (a, b):
        assert res.outcome[0] == "incorrect" and res.net_speed[0] <= 1e-3
        assert res.max_distance_error[0] > 0.9  # far from the square
    assert a.steps[0] == b.steps[0] == 4000  # the second test of the 2 s window
    sim = fl.simulate(
        f, law, q0[0], duration=b.steps[0] * DT, integrator=fl.Euler(dt=DT), backend="numpy"
    )
    np.testing.assert_allclose(sim.q[-1], b.q_final[0], rtol=0, atol=1e-9)
    # chattering amplifies rounding: the kernel's different order of operations ends
    # elsewhere in the chattering band (about dt |u|), not on the reference's state
    np.testing.assert_allclose(a.q_final[0], b.q_final[0], rtol=0, atol=1e-3)
    assert sim.outcome(tol) == "incorrect" and sim.outcome() == "not-converged"
    # the Filippov solution from there slides on the surfaces and comes to rest
    fil = fl.simulate(f, law, a.q_final[0], duration=2.0, integrator=fl.get_integrator("filippov"))
    assert fil.status == "success" and fil.stats["sliding_time"] > 1.99
    late = fil.q[np.searchsorted(fil.t, 1.0)]
    assert np.linalg.norm(fil.q[-1] - late, axis=-1).max() < 1e-5
    assert np.linalg.norm(fil.q[-1] - a.q_final[0], axis=-1).max() < 5e-3


def test_trials_thrown_far_are_classified_without_numpy_warnings():
    """A trial whose last accepted step threw a robot far (coordinates whose squares
    overflow) is a collision by its status; classifying the batch warns of nothing."""
    import warnings

    from formationlab.status import Status

    f = paper_triangle()
    x = np.array([[[0.0, 0.0], [1.0, 0.0], [0.5, 0.9]], [[0.0, 0.0], [1e200, -1e200], [0.5, 0.9]]])
    v = np.array([np.zeros((3, 2)), [[0.0, 0.0], [1e200, 1e200], [0.0, 0.0]]])
    status = np.array([Status.CONVERGED.code, Status.COLLISION.code], dtype=np.int8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = BatchResult.from_final(
            f, x=x, v=v, status=status, steps=np.array([10, 3]),
            min_clearance=np.array([0.5, 0.1]), net_speed=np.array([0.0, np.inf]),
            dt=1e-3, q_window=x.copy(), window_step=2,
        )  # fmt: skip
    assert res.outcome.tolist()[1] == "collision"
    assert not np.isfinite(res.max_distance_error[1])
