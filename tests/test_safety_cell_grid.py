"""The decentralized filter of many robots: neighbours by a grid of cells (safety/cell_grid.py)."""

import numpy as np
import pytest

from formationlab.neighbours.cell_grid import build_grid, neighbours_of
from formationlab.safety import (
    SafetyFilter,
    decentralized_commands,
    decentralized_filter,
    decentralized_reference,
    neighbour_lists,
    sensed_pairs,
)


def _swarm(rng, n, spread):
    """``n`` robots in a box of side ``spread * sqrt(n)``, none closer than 0.35."""
    side = spread * np.sqrt(n)
    q = rng.uniform(0.0, side, (n, 2))
    while True:
        d = np.linalg.norm(q[:, None] - q[None], axis=-1) + 9 * np.eye(n)
        close = np.flatnonzero(d.min(axis=1) < 0.35)
        if close.size == 0:
            return q
        q[close] = rng.uniform(0.0, side, (close.size, 2))


@pytest.mark.parametrize("spread", [0.8, 6.0])  # dense, and spread out (larger cells)
def test_grid_neighbours_equal_the_pair_search(rng, spread):
    q = _swarm(rng, 400, spread)
    radius = 1.3
    ptr, nbr = neighbour_lists(sensed_pairs(q, radius), 1, 400)
    x0, y0, side, nx, ny, start, order = build_grid(q, radius)
    assert nx * ny <= 4 * 400 + 16 and side >= radius
    out = np.empty(400, np.int64)
    for i in range(400):
        deg = neighbours_of(i, q, radius * radius, x0, y0, side, nx, ny, start, order, out)
        assert out[:deg].tolist() == nbr[ptr[i] : ptr[i + 1]].tolist()


@pytest.mark.parametrize("max_speed", [None, 1.0])
def test_sparse_filter_equals_the_clarabel_reference(rng, max_speed):
    q = _swarm(rng, 200, 0.8)
    u_hat = 2.0 * rng.normal(size=(200, 2)) - 2.0 * (q - q.mean(axis=0))  # squeezed together
    cfg = SafetyFilter(filter="barrier-decentralized", distance=0.3, gamma=1.0,
                       sensing_radius=1.2, max_speed=max_speed)  # fmt: skip
    res = decentralized_filter(cfg, q, u_hat)
    ref, codes = decentralized_reference(cfg, q, u_hat)
    assert np.count_nonzero(codes) > 50  # many robots' rows bind
    np.testing.assert_allclose(res.u, ref, rtol=0, atol=1e-8)
    unchanged = codes == 0
    assert res.u[unchanged].tobytes() == u_hat[unchanged].tobytes()  # bit for bit
    assert decentralized_commands(cfg, q, u_hat).tobytes() == res.u.tobytes()


def test_batched_sparse_filter_equals_one_by_one(rng):
    q = np.stack([_swarm(rng, 100, 0.8) for _ in range(3)])
    u_hat = rng.normal(size=q.shape) - 2.0 * (q - q.mean(axis=1, keepdims=True))
    cfg = SafetyFilter(filter="barrier-decentralized", distance=0.3, gamma=1.0,
                       sensing_radius=1.2)  # fmt: skip
    res = decentralized_filter(cfg, q, u_hat)
    for t in range(3):
        one = decentralized_filter(cfg, q[t], u_hat[t])
        assert one.u.tobytes() == res.u[t].tobytes()
        assert one.active.tolist() == res.active[t].tolist()
        mine = res.active_pairs[res.active_pairs[:, 0] == t, 1:]
        assert mine.tolist() == one.active_pairs[:, 1:].tolist()


@pytest.mark.parametrize(
    "q",
    [
        [[-3e154, -3e154], [3e154, -3e154], [0.0, 3e154], [0.0, 3e154 + 1.0]],
        [[-1e308, 0.0], [1e308, 0.0], [0.0, 0.0], [0.5, 0.0]],
        [[0.0, 0.0], [1e300, 0.0], [0.0, 0.5], [0.3, 0.5]],
        [[np.nan, 0.0], [0.0, 0.0], [0.0, 0.3], [np.inf, 5.0]],
    ],
    ids=["1e154", "extent-beyond-floats", "thin-and-huge", "non-finite"],
)
def test_the_grid_stays_in_bounds_for_huge_or_non_finite_positions(q):
    # a cell index from a coordinate around 1e154 was an integer conversion beyond int64
    q = np.array(q)
    x0, y0, side, nx, ny, start, order = build_grid(q, 1.3)
    assert 1 <= nx * ny <= 4 * len(q) + 16 and side >= 1.3
    assert start[-1] == len(q) and sorted(order.tolist()) == list(range(len(q)))
    out = np.empty(len(q), np.int64)
    finite = np.isfinite(q).all(axis=1)
    for i in np.flatnonzero(finite):
        deg = neighbours_of(i, q, 1.3 * 1.3, x0, y0, side, nx, ny, start, order, out)
        with np.errstate(over="ignore"):  # (1e308 - -1e308: infinitely far)
            far = np.hypot(*(q[finite] - q[i]).T)
        near = [j for j, r in zip(np.flatnonzero(finite), far, strict=True) if j != i and r <= 1.3]
        assert out[:deg].tolist() == near
