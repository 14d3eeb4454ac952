"""Obstacles and safety filters in the closed loop: System, simulate, run_batch, sampling.

The filter's own mathematics is tested in ``test_safety_filters.py``; here it is stepped
through the package's one time loop (``integrators.drive``) and judged by the contact
rule (``System.step_verdict``).
"""

import numpy as np
import pytest
import shapely

import formationlab as fl
from formationlab.controllers import DistanceLaw, SquaredDistanceLaw
from formationlab.dynamics import System
from formationlab.errors import ObstacleError, ParameterError
from formationlab.safety import (
    Circle,
    Polygon,
    SafetyFilter,
    obstacle_potential,
    segment_distances,
    swept_clearances,
)
from formationlab.status import Status
from formationlab.studies.batch import batch_backend, run_batch
from formationlab.studies.config import BoxInitial
from formationlab.studies.sampling import trial_initial_states

TRIANGLE = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
SQUARE = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], orientation="free")
PAPER_START = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]
D_S = 0.3


def _swept_pair_distance(q):
    """Least centre distance over the straight steps between saved states ``(T, n, 2)``."""
    x0, x1 = q[:-1], q[1:]
    iu, ju = np.triu_indices(q.shape[1], 1)
    r0 = x0[:, ju] - x0[:, iu]
    dr = (x1[:, ju] - x1[:, iu]) - r0
    dd = np.sum(dr * dr, -1)
    s = np.clip(-np.sum(r0 * dr, -1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    m = r0 + s[..., None] * dr
    return float(np.sqrt(np.sum(m * m, -1)).min())


# ------------------------------------------------------------------ swept obstacle contact


def test_swept_clearances_equal_shapely(rng):
    circle = Circle(center=[0.3, -0.2], radius=0.7)
    poly = Polygon(vertices=[[1.0, 1.0], [3.0, 1.2], [2.0, 2.0], [2.2, 3.0], [0.8, 2.5]])
    q0 = rng.uniform(-2, 4, (400, 2))
    q1 = q0 + rng.normal(0, 1.5, (400, 2))
    radii = np.array([0.1])
    got = swept_clearances(q0[:, None], q1[:, None], radii, [circle, poly])[:, 0]
    segs = shapely.linestrings(np.stack([q0, q1], axis=1))
    disc = shapely.Point(circle.center).buffer(circle.radius, quad_segs=4096)
    # the disc as a 16384-gon lies inside the disc by at most R (1 - cos(pi/16384))
    ref_c = np.where(
        shapely.intersects(segs, disc),
        np.nan,
        shapely.distance(shapely.Point(circle.center), segs) - circle.radius,
    )
    ok = np.isfinite(ref_c)
    np.testing.assert_allclose(got[ok, 0], ref_c[ok] - 0.1, atol=1e-12)
    assert np.all(got[~ok, 0] <= -0.1 + 1e-7)
    shape = shapely.Polygon(poly.vertices)
    outside = ~shapely.intersects(segs, shape)
    np.testing.assert_allclose(got[outside, 1], shapely.distance(shape, segs)[outside] - 0.1)
    assert np.all(got[~outside, 1] <= -0.1 + 1e-12)  # the segment meets or enters the polygon
    assert outside.sum() > 100 and (~outside).sum() > 20


def test_segment_distances_by_hand():
    # crossing, parallel at distance 1, collinear apart by 2, touching at an end
    p0 = np.array([[0.0, -1.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    p1 = np.array([[0.0, 1.0], [1.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    a = np.array([[-1.0, 0.0], [0.0, 1.0], [3.0, 0.0], [1.0, 1.0]])
    b = np.array([[1.0, 0.0], [1.0, 1.0], [4.0, 0.0], [2.0, 5.0]])
    np.testing.assert_array_equal(segment_distances(p0, p1, a, b), [0.0, 1.0, 2.0, 0.0])


# ------------------------------------------------------------------ the contact rule


def test_step_verdict_names_robot_and_obstacle():
    wall = Polygon(vertices=[[0.0, -1.0], [0.02, -1.0], [0.02, 1.0], [0.0, 1.0]])
    system = System(
        formation=TRIANGLE, law=DistanceLaw(), obstacles=[Circle(center=[5, 5], radius=1), wall]
    )
    x0 = np.array([[-0.5, 0.0], [-3.0, -3.0], [-3.0, 3.0]])
    through = x0 + np.array([[1.0, 0.0], [0, 0], [0, 0]])  # robot 1 jumps through the thin wall
    into = x0 + np.array([[0.45, 0.0], [0, 0], [0, 0]])  # robot 1 ends touching it (radius 0.1)
    verdict, _ = system.step_verdict(np.stack([x0, x0, x0]), np.stack([through, into, x0]))
    assert [Status.from_code(c) for c in verdict[:2]] == [Status.STEP_TOO_LARGE, Status.COLLISION]
    assert verdict[2] == 0
    msg = system.step_message(x0, through, Status.STEP_TOO_LARGE, 1.0, 1e-3)
    assert "robot 1 passes through obstacle 2" in msg and "reduce dt" in msg
    msg = system.step_message(x0, into, Status.COLLISION, 1.0, 1e-3)
    assert "robot 1 into contact with obstacle 2" in msg
    assert system.clearance(into) == pytest.approx(-0.05, abs=1e-12)


@pytest.mark.parametrize(
    "name", ["distance", "angle-restricted", "squared-distance", "signed-area"]
)
def test_a_step_into_contact_blames_the_step_only_under_a_barrier_law(name):
    """The paper's laws have phi infinite at contact: a step into contact is too large.
    The comparison laws have no barrier: their flow itself can bring robots together."""
    from formationlab.controllers import LAWS

    law = LAWS[name]()
    system = System(formation=TRIANGLE, law=law)
    x0 = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]])
    into = x0 + np.array([[0.0, 0], [-0.85, 0.0], [0, 0]])  # robots 1, 2 end 0.15 < 0.2 apart
    msg = system.step_message(x0, into, Status.COLLISION, 1.0, 1e-3)
    assert "robots 1 and 2" in msg
    assert law.barrier_at_contact == (name in ("distance", "angle-restricted"))
    if law.barrier_at_contact:
        assert "cannot touch" in msg and "reduce dt" in msg
    else:
        assert "no barrier at contact" in msg and "safety filter" in msg and "reduce" not in msg


def test_no_obstacles_and_no_filter_is_todays_loop(rng):
    q = rng.uniform(-3, 3, (5, 3, 2))
    plain = System(formation=TRIANGLE, law=DistanceLaw())
    none = System(formation=TRIANGLE, law=DistanceLaw(), safety=SafetyFilter(filter="none"))
    np.testing.assert_array_equal(plain.rhs(q), none.rhs(q))
    np.testing.assert_array_equal(plain.rhs(q), DistanceLaw().control(TRIANGLE, q))
    a = fl.simulate(TRIANGLE, DistanceLaw(), PAPER_START, duration=2.0)
    b = fl.simulate(TRIANGLE, DistanceLaw(), PAPER_START, duration=2.0, safety="none")
    np.testing.assert_array_equal(a.q, b.q)
    assert a.safety is None and b.safety is None


@pytest.mark.parametrize("kind", ["barrier", "barrier-decentralized"])
def test_inactive_filter_changes_nothing_bit_for_bit(kind):
    """With gamma large the barrier never binds from the paper's start: the run is exact."""
    cfg = SafetyFilter(filter=kind, distance=0.2, gamma=1e4)
    for backend in ("numpy", "numba"):  # each path against its own plain run
        plain = fl.simulate(TRIANGLE, DistanceLaw(), PAPER_START, duration=5.0, backend=backend)
        filt = fl.simulate(
            TRIANGLE, DistanceLaw(), PAPER_START, duration=5.0, safety=cfg, backend=backend
        )
        assert not filt.safety.active.any() and filt.safety.status.max() == 0
        np.testing.assert_array_equal(plain.q, filt.q)
        np.testing.assert_array_equal(plain.u, filt.u)


# ------------------------------------------------------------------ Lyapunov function


@pytest.mark.parametrize(
    ("law", "rate"), [(DistanceLaw(k_c=2.0), 1.0), (SquaredDistanceLaw(k=1.5, k_r=2.0), 1.5)]
)
def test_field_descends_V_with_the_obstacle_term(law, rate):
    """``u = -rate grad V`` with the obstacles' repulsion in V (finite differences).

    ``rate = k_c / 2`` for the distance law (V = sum phi_i, eq. 9), ``k`` for the
    squared-distance law (W = V + (k_r / k) Gamma): the weight of the obstacle term in
    V is what makes the repelled field a gradient of it.
    """
    obstacles = [
        Circle(center=[0.2, -0.5], radius=0.3),
        Polygon(vertices=[[1, 1], [2, 1], [1.5, 2]]),
    ]
    system = System(formation=TRIANGLE, law=law, obstacles=obstacles)
    q = np.array([[-0.2, -0.1], [0.9, -0.6], [1.2, 0.5]])
    assert system.obstacle_clearances(q).min() < 0.5  # inside Khatib's range
    grad = np.zeros_like(q)
    h = 1e-6
    for i in range(3):
        for d in range(2):
            e = np.zeros_like(q)
            e[i, d] = h
            grad[i, d] = (system.potential(q + e) - system.potential(q - e)) / (2 * h)
    np.testing.assert_allclose(system.rhs(q), -rate * grad, rtol=1e-6, atol=1e-8)
    rep = law.obstacle_repulsion()
    extra = system.potential(q) - law.potential(TRIANGLE, q)
    radii = TRIANGLE.diameters / 2
    ref = obstacle_potential(
        q, radii, obstacles, eta=rep.repulsion.eta, influence=rep.repulsion.influence
    )
    assert extra == pytest.approx(rep.weight * ref) and ref > 0


# ------------------------------------------------------------------ runs


def test_obstacle_on_the_way_does_not_make_the_distance_law_collide():
    """A disc on the paper's start: Khatib's repulsion (gain k_c) keeps every robot off it.

    The same disc with a law that has no obstacle repulsion (squared distance, k_r = 0)
    is run into, and the run says which robot and which obstacle.
    """
    disc = Circle(center=[0.0, -1.0], radius=0.6)
    res = fl.simulate(TRIANGLE, DistanceLaw(), PAPER_START, duration=15.0, obstacles=[disc])
    assert res.status == "success" and res.outcome() != "collision"
    assert res.safety.obstacle_clearance.min() > 0
    assert swept_clearances(res.q[:-1], res.q[1:], TRIANGLE.diameters / 2, [disc]).min() > 0
    assert np.all(np.diff(res.V) <= 1e-12)  # V with the obstacle term decreases
    bare = fl.simulate(
        TRIANGLE, SquaredDistanceLaw(k_r=0.0), PAPER_START, duration=15.0, obstacles=[disc]
    )
    assert bare.status.contact and bare.outcome() == "collision"
    assert "obstacle 1 (circle at (0, -1) of radius 0.6)" in bare.message


#: seconds of the filtered runs from colliding starts (the unfiltered law collides before)
FILTERED_RUN = 2.0


@pytest.fixture(scope="module")
def colliding_square_starts():
    """Starts (pairs >= D_s apart) from which the unfiltered squared-distance law collides
    within ``FILTERED_RUN`` seconds (most of them collide in the first half second)."""
    q0 = trial_initial_states(SQUARE, BoxInitial(half_width=1.5), seed=5, trials=np.arange(256))
    iu, ju = np.triu_indices(4, 1)
    far = np.linalg.norm(q0[:, ju] - q0[:, iu], axis=-1).min(-1) > D_S + 0.02
    q0 = q0[far]
    res = run_batch(SQUARE, SquaredDistanceLaw(), q0, dt=1e-3, duration=10.0)
    hit = (np.asarray(res.outcome) == "collision") & (res.steps * 1e-3 < FILTERED_RUN)
    assert hit.sum() >= 20
    return q0[hit]


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["barrier-decentralized", "barrier"])
def test_filter_keeps_D_s_at_and_along_every_step(kind, colliding_square_starts):
    law = SquaredDistanceLaw()
    cfg = SafetyFilter(filter=kind, distance=D_S, gamma=100.0)
    starts = colliding_square_starts[: 8 if kind == "barrier-decentralized" else 3]
    active = 0
    for q0 in starts:
        res = fl.simulate(SQUARE, law, q0, duration=FILTERED_RUN, safety=cfg)
        assert res.status == "success", res.message
        assert res.safety.pair_distance.min() >= D_S - 1e-9
        assert _swept_pair_distance(res.q) >= D_S - 1e-9
        assert res.safety.status.max() <= 1  # unchanged or solved, never relaxed
        active += int(res.safety.active.any())
    assert active == len(starts)
    # and through run_batch (the numpy driver path the study takes): the least clearance
    # over every accepted state of every trial
    batch = run_batch(
        SQUARE, law, colliding_square_starts[: 8 if kind == "barrier-decentralized" else 2],
        dt=1e-3, duration=FILTERED_RUN, safety=cfg,
    )  # fmt: skip
    assert "collision" not in list(batch.outcome)
    a = SQUARE.contact_matrix[0, 1]
    assert np.min(batch.min_clearance) >= D_S - a - 1e-9


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["none", "barrier-decentralized", "barrier"])
def test_no_run_enters_an_obstacle(kind):
    obstacles = (
        Circle(center=[0.0, 0.0], radius=0.35),
        Polygon(vertices=[[0.6, 0.6], [1.3, 0.7], [0.8, 1.3]]),
    )
    count = 64 if kind != "barrier" else 6
    q0 = trial_initial_states(
        SQUARE, BoxInitial(half_width=1.5), seed=2, trials=np.arange(count), obstacles=obstacles
    )
    cfg = SafetyFilter(filter=kind, distance=D_S, gamma=100.0)
    law = SquaredDistanceLaw(k_r=0.0)  # no Khatib repulsion: only the filter keeps them off
    # 1.5 s: without a filter 55 of the 64 runs hit an obstacle or each other by then
    res = run_batch(SQUARE, law, q0, dt=1e-3, duration=1.5, safety=cfg, obstacles=obstacles)
    outcome = np.asarray(res.outcome)
    if kind == "none":
        assert np.sum(outcome == "collision") >= 5  # the check can fail
        return
    assert "collision" not in list(outcome)
    radius = SQUARE.diameters[0] / 2
    # min_clearance covers robot-obstacle clearances of every accepted state
    starts = System(formation=SQUARE, law=law, obstacles=obstacles).clearance(q0)
    kept = np.minimum(starts, cfg.d_obstacle - radius)
    assert np.all(res.min_clearance >= kept - 1e-9)
    for q in q0[:2]:
        run = fl.simulate(SQUARE, law, q, duration=1.5, safety=cfg, obstacles=obstacles)
        swept = swept_clearances(run.q[:-1], run.q[1:], SQUARE.diameters / 2, obstacles)
        assert swept.min() > 0 and run.status == "success"


# ------------------------------------------------------------------ batches and starts


def test_batch_with_obstacles_and_filter_is_the_single_run():
    disc = (Circle(center=[0, 0], radius=0.5),)
    assert batch_backend("numba") == ("numba", "")
    assert batch_backend("numba", (), SafetyFilter()) == ("numba", "")  # filter "none"
    assert batch_backend("numba", disc, SafetyFilter(filter="barrier")) == ("numba", "")
    q0 = trial_initial_states(
        TRIANGLE, BoxInitial(half_width=3.0), seed=4, trials=range(6), obstacles=disc
    )
    cfg = SafetyFilter(filter="barrier-decentralized", distance=0.3)
    kw = {"dt": 1e-3, "duration": 3.0, "obstacles": disc, "safety": cfg}
    a = run_batch(TRIANGLE, DistanceLaw(), q0, backend="numba", **kw)
    b = run_batch(TRIANGLE, DistanceLaw(), q0, backend="numpy", **kw)
    np.testing.assert_allclose(a.q_final, b.q_final, rtol=0, atol=1e-12)  # compiled, driver
    for t in range(3):  # each trial of the batch is the single run
        one = fl.simulate(
            TRIANGLE, DistanceLaw(), q0[t], duration=a.steps[t] * 1e-3, safety=cfg, obstacles=disc
        )
        np.testing.assert_allclose(one.q[-1], a.q_final[t], rtol=0, atol=1e-12)


def test_starts_clear_of_obstacles_and_unchanged_without():
    disc = (Circle(center=[0, 0], radius=1.5),)
    plain = trial_initial_states(TRIANGLE, BoxInitial(half_width=3.0), seed=9, trials=range(200))
    same = trial_initial_states(
        TRIANGLE, BoxInitial(half_width=3.0), seed=9, trials=range(200), obstacles=()
    )
    np.testing.assert_array_equal(plain, same)
    clear = trial_initial_states(
        TRIANGLE, BoxInitial(half_width=3.0), seed=9, trials=range(200), obstacles=disc
    )
    assert np.linalg.norm(clear, axis=-1).min() > 1.5 + 0.1
    assert np.linalg.norm(plain, axis=-1).min() < 1.6  # the obstacle did reject draws


def test_obstacle_on_a_start_is_refused():
    with pytest.raises(ObstacleError, match="robot 3 starts inside or touching obstacle 1"):
        fl.simulate(
            TRIANGLE,
            DistanceLaw(),
            PAPER_START,
            duration=1.0,
            obstacles=[Circle(center=[0, 3.2], radius=0.5)],
        )
    with pytest.raises(ParameterError, match="below the contact distance"):
        fl.simulate(
            TRIANGLE,
            DistanceLaw(),
            PAPER_START,
            duration=1.0,
            safety=SafetyFilter(filter="barrier", distance=0.1),
        )


def test_simulate_names_a_safety_argument_it_cannot_use():
    from formationlab.errors import ParameterError

    q0 = np.array([[-1.0, -1.0], [1.0, -1.0], [0.0, 1.2]])
    with pytest.raises(ParameterError, match="safety must be a SafetyFilter or a filter's name"):
        fl.simulate(TRIANGLE, "distance", q0, duration=0.1, safety=3)
    with pytest.raises(ParameterError, match="barrier"):  # a misspelt name: the filter says
        fl.simulate(TRIANGLE, "distance", q0, duration=0.1, safety="barier")
    run = fl.simulate(TRIANGLE, "distance", q0, duration=0.1, safety="barrier")
    assert run.status.value == "success"
