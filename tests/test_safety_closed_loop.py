"""Closed loops under the safety filters, with a forward-Euler loop of the test's own.

Why Euler keeps the barrier in discrete time: ``|r|^2`` (and the squared distance to a
convex obstacle piece) is convex, so along a step ``h(q + s u) >= h(q) + s grad h . u
>= h - s gamma h^3`` for ``s`` in ``[0, dt]``, which stays ``>= 0`` while
``dt gamma h^2 <= 1``. The checks below hold at every step and along every step
(the minimum distance over the straight segment each robot travels).
"""

import numpy as np
import pytest

from formationlab.controllers import DistanceLaw, SquaredDistanceLaw
from formationlab.formation.spec import Formation
from formationlab.safety import (
    Circle,
    Polygon,
    SafetyFilter,
    grad_obstacle_potential,
    obstacle_contacts,
)

SQUARE = Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], orientation="free")
D_S = 0.25
DT = 1e-3


def _swept_min_distance(x0, x1):
    """Minimum over each step of the pair distances, robots moving on straight lines; (B,)."""
    n = x0.shape[-2]
    iu, ju = np.triu_indices(n, 1)
    r0 = x0[..., ju, :] - x0[..., iu, :]
    dr = (x1[..., ju, :] - x1[..., iu, :]) - r0
    dd = np.sum(dr * dr, -1)
    s = np.clip(-np.sum(r0 * dr, -1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    closest = r0 + s[..., None] * dr
    return np.sqrt(np.sum(closest * closest, -1)).min(-1)


def _swept_circle_clearance(x0, x1, circle):
    """Minimum over each step of ``|q - c| - R`` for every robot; (B, n)."""
    w0 = x0 - circle.center
    dq = x1 - x0
    dd = np.sum(dq * dq, -1)
    s = np.clip(-np.sum(w0 * dq, -1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    closest = w0 + s[..., None] * dq
    return np.sqrt(np.sum(closest * closest, -1)) - circle.radius


def _starts(rng, count, *, half_width, min_gap, obstacles=(), d_o=0.0):
    out = []
    while len(out) < count:
        q = rng.uniform(-half_width, half_width, (4, 2))
        d = np.linalg.norm(q[:, None] - q[None], axis=-1) + 9 * np.eye(4)
        clear = [ob.signed_distance(q)[0].min() for ob in obstacles]
        if d.min() > min_gap and all(c > d_o + 0.05 for c in clear):
            out.append(q)
    return np.stack(out)


@pytest.fixture(scope="module")
def colliding_starts():
    """Starts from which the unfiltered squared-distance law collides (Krick et al. 2009)."""
    rng = np.random.default_rng(7)
    law = SquaredDistanceLaw()
    q0 = _starts(rng, 60, half_width=1.5, min_gap=D_S + 0.05)
    x = q0.copy()
    collided = np.zeros(len(q0), bool)
    for _ in range(1500):
        x1 = x + DT * law.control(SQUARE, x)
        collided |= _swept_min_distance(x, x1) <= SQUARE.contact_matrix[0, 1]
        x = x1
    assert collided.sum() >= 10, "the unfiltered law should collide from many of these starts"
    return q0[collided]


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["barrier-decentralized", "barrier"])
def test_filter_keeps_every_pair_at_the_safety_distance(kind, colliding_starts):
    law = SquaredDistanceLaw()
    cfg = SafetyFilter(filter=kind, distance=D_S, gamma=100.0)
    cfg.check_contact(SQUARE.contact_matrix)
    x = colliding_starts if kind == "barrier-decentralized" else colliding_starts[:6]
    worst = np.inf
    active_steps = 0
    for _ in range(1500):
        res = cfg.apply(x, law.control(SQUARE, x))
        assert res.ok, res.message
        active_steps += bool(res.active.any())
        x1 = x + DT * res.u
        worst = min(worst, _swept_min_distance(x, x1).min())
        x = x1
    assert worst >= D_S - 1e-9, worst
    assert active_steps > 100


@pytest.mark.slow
def test_no_run_enters_an_obstacle():
    circle = Circle(center=[0.0, 0.0], radius=0.35)
    tri = Polygon(vertices=[[0.6, 0.6], [1.3, 0.7], [0.8, 1.3]])
    obstacles = (circle, tri)
    law = SquaredDistanceLaw()
    radii = SQUARE.diameters / 2
    rng = np.random.default_rng(3)
    cfg = SafetyFilter(filter="barrier-decentralized", distance=D_S, gamma=100.0)
    q0 = _starts(
        rng, 40, half_width=1.5, min_gap=D_S + 0.05, obstacles=obstacles, d_o=cfg.d_obstacle
    )
    results = {}
    for kind in ("none", "barrier-decentralized", "barrier"):
        cfg = SafetyFilter(filter=kind, distance=D_S, gamma=100.0)
        x = q0.copy() if kind != "barrier" else q0[:5].copy()
        entered = np.zeros(len(x), bool)
        worst_circle, worst_poly = np.inf, np.inf
        for _ in range(1000):
            u = cfg.apply(x, law.control(SQUARE, x), obstacles=obstacles).u
            x1 = x + DT * u
            entered |= obstacle_contacts(x1, radii, obstacles).any(axis=(-2, -1))
            worst_circle = min(worst_circle, _swept_circle_clearance(x, x1, circle).min())
            # a polygon's clearance along a step: the segment against the polygon (shapely)
            worst_poly = min(worst_poly, _swept_polygon_clearance(x, x1, tri))
            x = x1
        results[kind] = (entered, worst_circle, worst_poly)
    assert results["none"][0].sum() >= 5  # without a filter, runs do enter the obstacles
    d_o = cfg.d_obstacle
    for kind in ("barrier-decentralized", "barrier"):
        entered, wc, wp = results[kind]
        assert not entered.any(), kind
        assert wc >= d_o - 1e-9 and wp >= d_o - 1e-9, (kind, wc, wp)


def _swept_polygon_clearance(x0, x1, polygon):
    import shapely

    segs = shapely.linestrings(np.stack([x0, x1], axis=-2).reshape(-1, 2, 2))
    return float(shapely.distance(shapely.Polygon(polygon.vertices), segs).min())


def test_obstacle_on_the_way_does_not_make_the_distance_law_collide(rng):
    """The paper's law (eq. 8) with Khatib's repulsion from a disc the formation contracts onto.

    Starts: the paper's section-4 start, and robots spread on a circle of radius 3 around
    the obstacle. Without the obstacle term every run ends inside the disc (checked, so the
    test can fail); with ``-k_c grad gamma`` added, no robot ever touches it.
    """
    formation = Formation.from_distances(3, distances=1.0, diameters=0.2)
    law = DistanceLaw()
    circle = Circle(center=[0.0, -1.0], radius=0.6)
    radii = formation.diameters / 2
    angles = (
        rng.uniform(0, 2 * np.pi, 7)[:, None]
        + np.array([0.0, 2.1, 4.2])
        + rng.uniform(-0.3, 0.3, (7, 3))
    )
    ring = circle.center + 3.0 * np.stack([np.cos(angles), np.sin(angles)], axis=-1)
    q0 = np.concatenate([[[[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]], ring])
    for repel in (False, True):
        x = q0.copy()
        touched = np.zeros(len(x), bool)
        worst = np.inf
        for _ in range(6000):
            u = law.control(formation, x)
            if repel:
                u = u - law.k_c * grad_obstacle_potential(
                    x, radii, [circle], eta=law.repulsion.eta, influence=law.repulsion.influence
                )
            x1 = x + DT * u
            touched |= obstacle_contacts(x1, radii, [circle]).any(axis=(-2, -1))
            worst = min(worst, float((_swept_circle_clearance(x, x1, circle) - radii).min()))
            x = x1
        if repel:
            assert not touched.any() and worst > 0.0, worst
        else:
            assert touched.all()


@pytest.mark.parametrize("kind", ["barrier", "barrier-decentralized"])
def test_head_on_deadlock_is_a_fixed_point_of_the_filtered_field(kind):
    """Two robots swapping places head-on through a symmetric filter stop at ``|r| = D_s``.

    ``u_hat_i = -k (q_i - g_i)`` with goals swapped. On the line, at ``q_1 = (-D_s/2, 0)``,
    ``q_2 = (D_s/2, 0)``, ``h = 0`` and the constraint ``2 (q_1 - q_2).(u_1 - u_2) >= 0`` cuts
    the approach, and symmetry leaves nothing else: ``u = 0`` with the pair constraint
    active, although ``u_hat != 0``. Off the line by ``+-delta``, the tangential part
    ``k delta`` of ``u_hat`` survives the projection and pushes the robots further off
    (``u_1y > 0 > u_2y``): the deadlock is unstable across the line, a saddle.
    """
    k, goal = 1.0, 1.0
    cfg = SafetyFilter(filter=kind, distance=D_S, gamma=100.0)

    def field(q):
        g = np.array([[goal, 0.0], [-goal, 0.0]])
        u_hat = -k * (q - g)
        return u_hat, cfg.apply(q, u_hat)

    q_star = np.array([[-D_S / 2, 0.0], [D_S / 2, 0.0]])
    u_hat, res = field(q_star)
    assert np.linalg.norm(u_hat) > 1.0
    np.testing.assert_allclose(res.u, 0.0, atol=1e-8)
    assert res.active_pairs.tolist() == [[0, 0, 1]] and res.active.all()
    # the filtered Euler loop from a symmetric start approaches it along the line
    x = np.array([[-1.0, 0.0], [1.0, 0.0]])
    gaps = []
    for _ in range(3000):
        x = x + DT * field(x)[1].u
        gaps.append(x[1, 0] - x[0, 0])
    assert np.all(np.diff(gaps) <= 0) and np.all(np.array(gaps) >= D_S - 1e-12)
    assert np.abs(x[:, 1]).max() == 0.0  # symmetry keeps the robots on the line
    # h_dot = -gamma h^3 makes the approach slow (h ~ t^(-1/2)), but the field dies out
    assert np.linalg.norm(field(x)[1].u) < 0.02 * np.linalg.norm(field(x)[0])
    # transverse instability
    delta = 1e-3
    _, off = field(q_star + np.array([[0.0, delta], [0.0, -delta]]))
    assert off.u[0, 1] > 0 > off.u[1, 1]
