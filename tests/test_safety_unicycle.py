"""Unicycles in the filtered closed loop, through their near-identity points.

The filter acts on the points ``p_i = q_i + l (cos theta_i, sin theta_i)`` with the
distance ``D_s + 2 l`` (``point_safety_distance``; docs/safety.md, Unicycles): then
``|q_i - q_j| >= |p_i - p_j| - 2 l >= D_s``. From starts where the unfiltered unicycles
collide, under either filter the points keep ``D_s + 2 l`` at every step, and the centres
``D_s`` at every step and along every step (the straight segment an Euler step moves a
centre, the contact rule's swept test).
"""

import numpy as np
import pytest

from formationlab.controllers import SquaredDistanceLaw
from formationlab.dynamics import System
from formationlab.models import Unicycle
from formationlab.safety import SafetyFilter, point_safety_distance, unicycle_points
from formationlab.spec import Formation
from formationlab.studies.batch import run_batch

SQUARE = Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], orientation="free")
D_S, ELL, DT, STEPS = 0.25, 0.05, 1e-3, 1500
IU, JU = np.triu_indices(4, 1)


def _swept_centres(x0, x1):
    """Least centre distance over each straight Euler step; (B,)."""
    r0 = x0[:, JU, :2] - x0[:, IU, :2]
    dr = (x1[:, JU, :2] - x1[:, IU, :2]) - r0
    dd = np.sum(dr * dr, -1)
    s = np.clip(-np.sum(r0 * dr, -1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    m = r0 + s[..., None] * dr
    return np.sqrt(np.sum(m * m, -1)).min(-1)


@pytest.fixture(scope="module")
def colliding_unicycles():
    """Unicycle states (x, y, theta) from which the unfiltered squared-distance law collides."""
    rng = np.random.default_rng(7)
    p0 = []
    while len(p0) < 80:
        p = rng.uniform(-1.0, 1.0, (4, 2))
        d = np.linalg.norm(p[:, None] - p[None], axis=-1) + 9 * np.eye(4)
        if d.min() > D_S + 2 * ELL + 0.02:  # the points start outside D_s + 2 l
            p0.append(p)
    theta = rng.uniform(-np.pi, np.pi, (80, 4))
    heading = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    x0 = np.concatenate([np.stack(p0) - ELL * heading, theta[..., None]], axis=-1)
    plain = System(formation=SQUARE, law=SquaredDistanceLaw(), model=Unicycle(offset=ELL))
    x, hit = x0.copy(), np.zeros(len(x0), bool)
    for _ in range(STEPS):
        x1 = x + DT * plain.rhs(x)
        hit |= _swept_centres(x, x1) <= SQUARE.contact_matrix[0, 1]
        x = x1
    assert hit.sum() >= 20, "the unfiltered unicycles should collide from many of these starts"
    return x0[hit][:20]


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["barrier-decentralized", "barrier"])
def test_unicycle_points_keep_the_enlarged_distance(kind, colliding_unicycles):
    cfg = SafetyFilter(filter=kind, distance=point_safety_distance(D_S, ELL), gamma=100.0)
    model = Unicycle(offset=ELL)
    system = System(formation=SQUARE, law=SquaredDistanceLaw(), model=model, safety=cfg)
    x = colliding_unicycles.copy()
    least_points = least_centres = least_swept = np.inf
    for _ in range(STEPS):
        x1 = x + DT * system.rhs(x)  # explicit Euler, as the driver
        p = unicycle_points(x1[..., :2], x1[..., 2], ELL)
        least_points = min(least_points, np.linalg.norm(p[:, JU] - p[:, IU], axis=-1).min())
        q = x1[..., :2]
        least_centres = min(least_centres, np.linalg.norm(q[:, JU] - q[:, IU], axis=-1).min())
        least_swept = min(least_swept, _swept_centres(x, x1).min())
        x = x1
    assert least_points >= D_S + 2 * ELL  # at every step
    assert least_centres >= D_S and least_swept >= D_S  # at every step and along the steps
    assert least_points < D_S + 2 * ELL + 0.1  # the filter did act (the law drives them in)
    # the compiled batch path steps the same closed loop: no trial collides
    res = run_batch(SQUARE, SquaredDistanceLaw(), colliding_unicycles, dt=DT,
                    duration=STEPS * DT, model=model, safety=cfg)  # fmt: skip
    assert "collision" not in set(res.outcome)
    assert np.all(res.min_clearance >= D_S - SQUARE.contact_matrix[0, 1])
