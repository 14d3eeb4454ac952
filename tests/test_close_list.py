"""The compiled run's lists: close pairs on a cell grid, rows by robot, threads.

The close list (formationlab.neighbours.close_list) against a brute-force search over every pair on
random and adversarial layouts; the compiled run on one thread against several, bit for
bit; a list rebuilt at every step against one rebuilt rarely, bit for bit (each robot's
sum has one order whatever the list holds beyond what acts); the run's memory layout.
"""

import numpy as np
import pytest

import formationlab as fl
from formationlab.engine.layout import run_layout
from formationlab.engine.saving import saved_rows
from formationlab.formation.templates import lattice
from formationlab.integrators.compiled import run_compiled
from formationlab.neighbours.close_list import close_list
from formationlab.neighbours.kdtree import non_edges


def length(r):
    """``|r|`` of a difference in the plane (numpy's hypot) or in space (the root of its
    squares summed in order, as the compiled search sums them)."""
    return np.hypot(*r) if r.size == 2 else np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])


def brute(q, radius, reach, exclude):
    skip = {tuple(e) for e in exclude.tolist()}
    n = len(q)
    found = [
        (i, j)
        for i in range(n)
        for j in range(i + 1, n)
        if (i, j) not in skip and length(q[j] - q[i]) - radius[i] - radius[j] < reach
    ]
    return np.array(found, dtype=np.int64).reshape(-1, 2)


def layout(kind: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, float]:
    """Positions, radii and a reach: random, on cell borders, in one cell, with far outliers."""
    if kind == "random":
        q = rng.uniform(0, 10, (400, 2))
        return q, rng.uniform(0.05, 0.2, len(q)), 0.4
    if kind == "cell-borders":  # a grid whose spacing is the cells' side: pairs at the reach
        side = 0.2 + 0.5  # 2 max radius + reach
        g = np.arange(15) * side
        q = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
        return q, np.full(len(q), 0.1), 0.5
    if kind == "one-cell":
        q = rng.uniform(0, 0.1, (70, 2))
        return q, rng.uniform(0.0, 0.02, len(q)), 0.05
    if kind == "outliers":
        far = [[1e6, 1e6], [-1e6, 5.0], [1e6, 1e6 + 0.5]]
        q = np.concatenate([rng.uniform(0, 3, (90, 2)), far])
        return q, np.full(len(q), 0.1), 0.4
    # in space: random in a box, a cubic grid whose spacing is the cells' side, a tall
    # column (many robots over one square of the plane), a flat layer (one cell deep)
    if kind == "space-random":
        q = rng.uniform(0, 5, (500, 3))
        return q, rng.uniform(0.05, 0.2, len(q)), 0.4
    if kind == "space-cell-borders":
        g = np.arange(8) * (0.2 + 0.5)
        q = np.stack(np.meshgrid(g, g, g), axis=-1).reshape(-1, 3)
        return q, np.full(len(q), 0.1), 0.5
    if kind == "space-column":
        q = np.column_stack([rng.uniform(0, 0.6, (300, 2)), rng.uniform(0, 60, 300)])
        return q, np.full(len(q), 0.1), 0.4
    q = np.column_stack([rng.uniform(0, 6, (300, 2)), np.full(300, 2.0)])
    return q, np.full(len(q), 0.1), 0.4


PLANE_KINDS = ["random", "cell-borders", "one-cell", "outliers"]
SPACE_KINDS = ["space-random", "space-cell-borders", "space-column", "space-layer"]


@pytest.mark.parametrize("kind", PLANE_KINDS + SPACE_KINDS)
def test_the_close_list_is_exactly_the_pairs_within_reach(kind):
    rng = np.random.default_rng(11)
    q, radius, reach = layout(kind, rng)
    every = brute(q, radius, reach, np.zeros((0, 2), np.int64))
    exclude = every[::4]  # some close pairs are edges: left out
    pairs, ptr, rows = close_list(q, radius, reach, exclude)
    expected = brute(q, radius, reach, exclude)
    if kind.endswith("cell-borders"):  # exactly at the reach: rounding may put a pair either side
        diff = {tuple(p) for p in pairs.tolist()} ^ {tuple(p) for p in expected.tolist()}
        for i, j in diff:
            gap = length(q[j] - q[i]) - radius[i] - radius[j]
            assert gap == pytest.approx(reach, rel=1e-12)
        assert len(expected) > 100  # the layout does put pairs at the reach
    else:
        np.testing.assert_array_equal(pairs, expected)
        assert len(expected) > (0 if kind == "outliers" else 50)
    # each robot's row: its pairs, as p (first robot) or ~p (second), sorted by partner
    for i in range(len(q)):
        row = rows[ptr[i] : ptr[i + 1]]
        p = np.where(row >= 0, row, ~row)
        assert np.all(pairs[p, np.where(row >= 0, 0, 1)] == i)
        partner = pairs[p, np.where(row >= 0, 1, 0)]
        assert np.all(np.diff(partner) > 0)
    assert ptr[-1] == 2 * len(pairs)


def test_non_edges_drops_exactly_the_edges():
    rng = np.random.default_rng(3)
    n = 500
    pairs = np.unique(np.sort(rng.integers(0, n, (3000, 2)), axis=1), axis=0)
    pairs = pairs[pairs[:, 0] < pairs[:, 1]]
    edges = np.concatenate([pairs[::3], [[0, 1], [2, 499]]])
    kept = non_edges(pairs, edges, n)
    edge_set = {tuple(e) for e in edges.tolist()}
    np.testing.assert_array_equal(kept, [p for p in pairs.tolist() if tuple(p) not in edge_set])
    assert non_edges(pairs, np.zeros((0, 2), np.int64), n).shape == pairs.shape


def swarm(n: int, law: str, seed: int, spread: float):
    """A lattice patch with Delaunay edges, robots close enough for repulsion and switching."""
    tpl = lattice("triangular", n, 1.0)
    orient = "template" if law == "angle-restricted" else "free"
    f = fl.Formation.from_template(
        tpl,
        edges=fl.build_edges("delaunay", tpl),
        diameters=0.3,
        orientation=orient,
        one_based=False,
    )
    rng = np.random.default_rng(seed)
    q0 = 0.45 * tpl + rng.normal(0.0, spread, tpl.shape)  # squeezed: non-neighbours within s0
    lw = fl.get_law(law, **({"theta": 0.05} if law == "angle-restricted" else {}))
    return f, lw, q0


@pytest.mark.parametrize("law", ["distance", "angle-restricted", "squared-distance"])
def test_threads_give_the_same_bits_as_one_thread(law):
    f, lw, q0 = swarm(300, law, seed=2, spread=0.02)
    terms = lw.compiled_terms(f)
    kw = {"dt": 1e-3, "n_steps": 300, "save_every": 7}
    one = run_compiled(terms, q0, parallel=False, **kw)
    many = run_compiled(terms, q0, parallel=True, **kw)
    assert one.status == many.status
    np.testing.assert_array_equal(one.k, many.k)
    np.testing.assert_array_equal(one.x, many.x)
    np.testing.assert_array_equal(one.v, many.v)
    assert one.min_clearance == many.min_clearance
    # repulsion acts: some non-neighbours are within s0
    q = one.x[0]
    from formationlab.neighbours.kdtree import close_pairs

    p = non_edges(close_pairs(q, 0.3 + lw.repulsion.influence), f.edges, f.n)
    assert len(p) > 50


def test_a_list_rebuilt_every_step_gives_the_same_bits():
    f, lw, q0 = swarm(200, "distance", seed=4, spread=0.02)
    layout_ = run_layout(lw.compiled_terms(f))
    kw = {"dt": 2e-3, "n_steps": 400, "save_every": 50}
    tight = run_compiled(layout_._replace(skin=1e-12), q0, **kw)  # rebuilt at every step
    loose = run_compiled(layout_._replace(skin=3.0), q0, **kw)  # many pairs, rarely rebuilt
    usual = run_compiled(layout_, q0, **kw)
    np.testing.assert_array_equal(tight.x, loose.x)
    np.testing.assert_array_equal(tight.x, usual.x)
    np.testing.assert_array_equal(tight.v, usual.v)
    moved = np.abs(usual.x[-1] - usual.x[0]).max()
    assert moved > layout_.skin  # the usual list was rebuilt along the way


def test_a_run_that_moves_far_follows_the_driver():
    # robots cross the patch: the close list is rebuilt many times
    f, lw, _ = swarm(80, "distance", seed=0, spread=0.0)
    q0 = f.template[np.random.default_rng(8).permutation(f.n)]  # every robot in another's place
    a = fl.simulate(f, lw, q0, duration=1.0, save_every=100, backend="numba")
    b = fl.simulate(f, lw, q0, duration=1.0, save_every=100, backend="numpy")
    assert a.status == b.status
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-9)
    assert np.abs(a.q[-1] - a.q[0]).max() > 1.0


def test_the_run_keeps_exactly_the_saved_states():
    f, lw, q0 = swarm(60, "distance", seed=1, spread=0.02)
    for steps, every in [(100, 10), (101, 10), (7, 1), (5, 9)]:
        out = run_compiled(lw.compiled_terms(f), q0, dt=1e-3, n_steps=steps, save_every=every)
        expected = sorted({*range(0, steps + 1, every), steps})
        np.testing.assert_array_equal(out.k, expected)
        assert saved_rows(steps, every) == len(expected) == out.x.base.shape[-3]


def test_restricted_terms_take_twelve_bytes_each():
    f, lw, _ = swarm(300, "angle-restricted", seed=0, spread=0.0)
    terms = lw.compiled_terms(f)
    lay = run_layout(terms)
    t = lay.term_j.size
    assert t == terms.term_i.size > 1000
    assert lay.term_j.dtype == lay.term_k.dtype == lay.term_s.dtype == np.int32
    assert lay.term_stride == 0 and lay.term_w.size == 1  # sign-valued alpha: one weight
    per_term = (lay.term_j.nbytes + lay.term_k.nbytes + lay.term_s.nbytes) / t
    assert per_term == 12
    # angle-valued alpha: one weight per term, and still the same field
    tpl = lattice("triangular", 30, 1.0) + np.random.default_rng(0).normal(0, 0.05, (30, 2))
    angles = fl.Formation.from_template(
        tpl,
        edges=fl.build_edges("delaunay", tpl),
        diameters=0.2,
        alpha_values="angle",
        one_based=False,
    )
    lay2 = run_layout(lw.compiled_terms(angles))
    assert lay2.term_stride == 1 and lay2.term_w.size == lay2.term_j.size
    q0 = tpl + np.random.default_rng(5).normal(0, 0.05, (30, 2))
    a = fl.simulate(angles, lw, q0, duration=0.5, save_every=100, backend="numba")
    b = fl.simulate(angles, lw, q0, duration=0.5, save_every=100, backend="numpy")
    assert a.status == b.status == "success"
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-10)


@pytest.mark.parametrize("law", ["distance", "angle-restricted", "signed-area"])
def test_numbering_the_robots_by_the_graph_changes_only_the_order_of_close_pairs(law):
    # a lattice numbered at random: the run renumbers it by reverse Cuthill-McKee
    f, lw, q0 = swarm(300, law, seed=3, spread=0.02)
    shuffle = np.random.default_rng(0).permutation(f.n)
    back = np.argsort(shuffle)
    tpl = f.template[shuffle]
    g = fl.Formation.from_template(
        tpl,
        edges=back[f.edges],
        diameters=0.3,
        orientation="template" if law == "angle-restricted" else "free",
        one_based=False,
    )
    q = q0[shuffle]
    terms = lw.compiled_terms(g, pairs=False)
    kw = {"dt": 1e-3, "n_steps": 200, "save_every": 20}
    plain = run_compiled(run_layout(terms, reorder=False), q, **kw)
    lay = run_layout(terms, reorder=True)
    assert not np.array_equal(lay.perm, np.arange(f.n))
    renumbered = run_compiled(lay, q, **kw)
    threads = run_compiled(lay, q, parallel=True, **kw)
    np.testing.assert_array_equal(renumbered.x, threads.x)  # the same bits on threads
    np.testing.assert_allclose(renumbered.x, plain.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(renumbered.v, plain.v, rtol=1e-10, atol=1e-10)
    # far apart (no pair within s0): nothing but the numbers changes, bit for bit
    spread = 2.0 * tpl + np.random.default_rng(1).normal(0.0, 0.02, tpl.shape)
    a = run_compiled(run_layout(terms, reorder=False), spread, **kw)
    b = run_compiled(lay, spread, **kw)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.v, b.v)


def test_the_faster_of_one_thread_and_the_threads_gives_the_same_run(monkeypatch):
    # from PARALLEL_FROM robots the run times one thread and the threads on its second and
    # third segments (here every 1 % of the run: a progress callback) and keeps the faster
    import formationlab.integrators.compiled as compiled

    monkeypatch.setattr(compiled, "PARALLEL_FROM", 10)
    f, lw, q0 = swarm(120, "distance", seed=6, spread=0.02)
    terms = lw.compiled_terms(f)
    seen = []
    kw = {"dt": 1e-3, "n_steps": 400, "save_every": 10}
    probed = run_compiled(terms, q0, progress=seen.append, **kw)
    one = run_compiled(terms, q0, parallel=False, **kw)
    assert len(seen) > 3
    assert probed.threads in (1, compiled.numba.get_num_threads())
    np.testing.assert_array_equal(probed.x, one.x)
    np.testing.assert_array_equal(probed.v, one.v)


def test_a_law_whose_kernel_terms_take_no_pairs_keyword_still_runs_compiled():
    from dataclasses import dataclass

    from formationlab.controllers.terms import LOG_BARRIER, build_terms

    @dataclass(frozen=True, kw_only=True)
    class Older(fl.DistanceLaw):  # kernel_terms(formation), as laws were written before
        name = "older-distance"

        def control(self, formation, q):
            return super().control(formation, q)

        def kernel_terms(self, formation):
            rep = self.repulsion
            return build_terms(
                formation, kind=LOG_BARRIER, edge_gain=self.k_c, repulsion_gain=self.k_c,
                eta=rep.eta, influence=rep.influence,
            )  # fmt: skip

    q0 = [[-1.2, -0.9], [1.4, -0.7], [0.1, 1.3]]
    f = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
    a = fl.simulate(f, Older(), q0, duration=0.5)
    b = fl.simulate(f, fl.DistanceLaw(), q0, duration=0.5)
    assert a.stats["backend"] == "numba"
    np.testing.assert_array_equal(a.q, b.q)


EXTREME = {
    "far apart (1e154)": [[-3e154, -3e154], [3e154, -3e154], [0.0, 3e154], [0.0, 3e154 + 1.0]],
    "extent beyond floats": [[-1e308, 0.0], [1e308, 0.0], [0.0, 0.0], [0.05, 0.0]],
    "thin and huge": [[0.0, 0.0], [1e300, 0.0], [0.0, 0.5], [0.3, 0.5]],
    "NaN": [[np.nan, 0.0], [0.0, 0.0], [0.0, 0.3], [5.0, 5.0]],
    "infinite": [[np.inf, 0.0], [0.0, -np.inf], [0.0, 0.3], [0.0, 0.0]],
    "far apart in space": [[0.0, 0.0, -3e154], [0.0, 0.0, 3e154], [1.0, 0.0, 0.0], [1.0, 0.0, 0.3]],
    "depth beyond floats": [[0.0, 0.0, -1e308], [0.0, 0.0, 1e308], [0.0, 0.0, 0.0], [0, 0, 0.05]],
    "NaN in space": [[0.0, 0.0, np.nan], [0.0, 0.0, 0.0], [0.0, 0.3, 0.0], [5.0, 5.0, 5.0]],
}


@pytest.mark.parametrize("kind", list(EXTREME))
def test_the_cell_grid_stays_in_bounds_for_huge_or_non_finite_positions(kind):
    # The cell of a coordinate around 1e154 (the first Euler step of a scenario placed
    # there) was an integer conversion beyond int64: a negative cell count, writes out of
    # the grid's bounds and an abort (munmap_chunk) when the run's memory was freed.
    from formationlab.neighbours.cell_grid import bin_points

    q = np.array(EXTREME[kind])
    n = len(q)
    cell_of, items = np.zeros(n, np.int32), np.zeros(n, np.int32)
    start = np.full(4 * n + 17, -7, np.int32)
    nx, ny, nz = bin_points(q, 0.5, cell_of, items, start)[:3]
    assert nx >= 1 and ny >= 1 and nz >= 1 and nx * ny * nz <= start.size - 1
    assert np.all((cell_of >= 0) & (cell_of < nx * ny * nz))
    assert sorted(items.tolist()) == list(range(n))  # each robot in exactly one cell
    # the pairs between finite robots are still exactly those within reach
    finite = np.isfinite(q).all(axis=1)
    pairs, _, _ = close_list(q, 0.1, 0.5)
    radius = np.full(n, 0.1)
    with np.errstate(over="ignore"):  # (1e308 - -1e308: infinitely far)
        expected = brute(np.where(finite[:, None], q, 0.0), radius, 0.5, np.zeros((0, 2), int))
    expected = [tuple(p) for p in expected.tolist() if finite[p[0]] and finite[p[1]]]
    assert [tuple(p) for p in pairs.tolist() if finite[p[0]] and finite[p[1]]] == expected


def test_in_space_the_cells_are_cubes_each_holding_its_points():
    # the close list of a swarm in space bins its robots into cubes (a column over the
    # plane held a whole column of robots: O(n^(4/3)) candidates for a patch of n)
    from formationlab.neighbours.cell_grid import bin_points

    q = lattice("fcc", 2000, 1.0)
    n = len(q)
    cell_of, items = np.zeros(n, np.int32), np.zeros(n, np.int32)
    start = np.zeros(4 * n + 17, np.int32)
    nx, ny, nz, side, x0, y0, z0 = bin_points(q, 0.7, cell_of, items, start)
    assert nz > 3 and nx * ny * nz <= start.size - 1 and side >= 0.7
    corner = np.array([x0, y0, z0])
    cx, cy, cz = np.floor((q - corner) / side).astype(int).T
    np.testing.assert_array_equal(cell_of, (cx * ny + cy) * nz + cz)
    counts = np.diff(start[: nx * ny * nz + 1])
    assert counts.max() <= 4 * side**3 + 8  # about fcc's density (sqrt 2 per unit volume)
    for c in np.flatnonzero(counts)[:50]:
        inside = items[start[c] : start[c + 1]]
        assert np.all(cell_of[inside] == c) and np.all(np.diff(inside) > 0)
