"""Sparse paths equal the dense ones: laws, potentials, neighbour search, orientation lists.

Formations above ``DENSE_LIMIT`` robots never build ``n x n`` (or ``n^3``) arrays: their laws
sum over the edges, the restricted triples and the close pairs a k-d tree finds. Here the
sparse paths are forced on small formations (the limit patched to 0) and held against the
dense arithmetic, to 1e-12, with Khatib's repulsion and the restrictions active.
"""

import itertools

import numpy as np
import pytest

import formationlab as fl
from formationlab.controllers import angle_restricted, distance, squared_distance
from formationlab.neighbours.kdtree import close_pairs, non_edges


def random_formation(n: int, rng) -> tuple[fl.Formation, np.ndarray]:
    side = int(np.ceil(np.sqrt(n)))
    grid = np.stack(np.meshgrid(np.arange(side), np.arange(side)), axis=-1).reshape(-1, 2)
    tpl = grid[:n] * 0.75 + rng.uniform(-0.08, 0.08, (n, 2))  # non-neighbours within s0
    chain = [(i, i + 1) for i in range(n - 1)]
    extra = [p for p in itertools.combinations(range(n), 2) if rng.random() < 0.3]
    edges = sorted(set(chain) | set(extra))
    f = fl.Formation.from_template(tpl, edges=edges, diameters=0.3, one_based=False)
    q = tpl + rng.normal(0.0, 0.05, tpl.shape)
    while True:  # no overlap at the start
        d = np.linalg.norm(q[:, None] - q[None], axis=-1) + np.eye(n) * 9
        if d.min() > 0.35:
            return f, q
        q = q + rng.normal(0.0, 0.05, q.shape)


@pytest.fixture
def sparse(monkeypatch):
    """Force the listed (sparse) arithmetic on formations of any size."""

    def force():
        for mod in (angle_restricted, distance, squared_distance):
            monkeypatch.setattr(mod, "DENSE_LIMIT", 0)

    return force


@pytest.mark.parametrize("n", [3, 10, 30, 50])
@pytest.mark.parametrize("law", ["distance", "angle-restricted", "squared-distance", "signed-area"])
def test_sparse_laws_equal_the_dense_ones(n, law, sparse):
    rng = np.random.default_rng(n)
    f, q = random_formation(n, rng)
    lw = fl.get_law(law, **({"theta": 2.0} if law == "angle-restricted" else {}))
    batch = np.stack([q, q + rng.normal(0.0, 0.01, q.shape)])
    dense_u, dense_v = lw.control(f, batch), lw.potential(f, batch)
    # the repulsion is at work, and for the paper's law some restrictions are on
    system = fl.System(formation=f, law=lw)
    close = system.pair_clearances(q) < lw.repulsion.influence
    assert np.any(close & ~f.adjacency[np.triu_indices(n, 1)]) or n == 3
    if law == "angle-restricted":
        assert np.any(lw.switching(f, q) >= 0)
    sparse()
    np.testing.assert_allclose(lw.control(f, batch), dense_u, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(lw.potential(f, batch), dense_v, rtol=1e-12, atol=1e-12)


def brute(q, cutoff):
    n = len(q)
    return np.array(
        [(i, j) for i in range(n) for j in range(i + 1, n) if np.hypot(*(q[j] - q[i])) < cutoff],
        dtype=np.int64,
    ).reshape(-1, 2)


@pytest.mark.parametrize(
    "layout",
    ["random", "cell-borders", "one-cell", "outliers"],
)
def test_the_neighbour_search_finds_exactly_the_close_pairs(layout):
    rng = np.random.default_rng(5)
    cutoff = 0.7
    if layout == "random":
        q = rng.uniform(0, 10, (300, 2))
    elif layout == "cell-borders":  # on a grid of the cutoff itself: distances equal to it
        g = np.arange(12) * cutoff
        q = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    elif layout == "one-cell":
        q = rng.uniform(0, 0.1, (60, 2))
    else:
        q = np.concatenate(
            [rng.uniform(0, 3, (80, 2)), [[1e6, 1e6], [-1e6, 5.0], [1e6, 1e6 + 0.5]]]
        )
    found = close_pairs(q, cutoff)
    expected = brute(q, cutoff)
    # a pair at exactly the cutoff may fall either way by rounding; none is missed or extra
    diff = {tuple(p) for p in found} ^ {tuple(p) for p in expected}
    for i, j in diff:
        assert np.hypot(*(q[j] - q[i])) == pytest.approx(cutoff, rel=1e-12)
    if layout != "cell-borders":
        np.testing.assert_array_equal(found, expected)
    edges = expected[::3]
    kept = non_edges(found, edges, len(q))
    assert not ({tuple(p) for p in kept} & {tuple(p) for p in edges})


def square_lattice(side: int) -> tuple[np.ndarray, list[tuple[int, int]]]:
    idx = np.arange(side * side)
    tpl = np.stack([idx % side, idx // side], axis=1).astype(float)
    edges = [(i, i + 1) for i in idx if (i + 1) % side] + [(i, i + side) for i in idx[:-side]]
    diag = [(i, i + side + 1) for i in idx[:-side] if (i + 1) % side]
    return tpl, edges + diag


def test_an_orientation_from_a_lattice_skips_exactly_its_collinear_triples():
    tpl, edges = square_lattice(4)
    f = fl.Formation.from_template(tpl, edges=edges, one_based=False)
    from formationlab.formation.orientation import neighbour_triples

    t = neighbour_triples(f.edges, f.n)
    r1 = tpl[t[:, 1]] - tpl[t[:, 0]]
    r2 = tpl[t[:, 2]] - tpl[t[:, 0]]
    collinear = np.abs(r1[:, 0] * r2[:, 1] - r1[:, 1] * r2[:, 0]) < 1e-9
    assert f.collinear_skipped == int(collinear.sum()) > 0
    np.testing.assert_array_equal(f.restricted_triples, t[~collinear])
    # the orientation still drives the lattice to itself: every kept triple agrees
    assert fl.outcomes.analysis.orientation_agreement(f, tpl) == (len(t) - collinear.sum(), 0)


def test_a_component_whose_triples_are_all_collinear_is_refused():
    line = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]
    with pytest.raises(fl.FormationError, match="collinear"):
        fl.Formation.from_template(line, edges=[(1, 2), (2, 3)])
    assert fl.Formation.from_template(line, edges=[(1, 2), (2, 3)], orientation="free").n == 3


def test_large_formations_keep_no_dense_orientation_arrays():
    tpl, edges = square_lattice(10)  # 100 robots > DENSE_LIMIT
    f = fl.Formation.from_template(tpl, edges=edges, one_based=False)
    assert f.alpha is None and f.has_orientation and len(f.restricted_triples) > 0
    with pytest.raises(fl.FormationError, match="restricted_triples"):
        _ = f.restricted
    q = tpl + np.random.default_rng(2).normal(0, 0.05, tpl.shape)
    law = fl.AngleRestrictedLaw(theta=0.3)
    u = law.control(f, q)
    assert u.shape == (100, 2) and np.all(np.isfinite(u))
