"""Sign-valued orientation data held compactly, read as the same float64 numbers.

The formation holds sign-valued ``alpha`` and the surfaces' ``beta`` as int8 signs and
gives them back as float64, bit for bit; other values stay float64. The compiled run
makes each surface's ``beta`` positive by exchanging the corners ``b`` and ``c`` and
stores it once when every one is the same: the same decisions, bit for bit.
"""

import numpy as np
import pytest

import formationlab as fl
from formationlab.engine.layout import run_layout
from formationlab.formation.orientation import alpha_from_shape, switching_surfaces
from formationlab.formation.templates import lattice
from formationlab.integrators.compiled import run_compiled


def patch(n: int, values: str, seed: int = 0) -> fl.Formation:
    tpl = lattice("triangular", n, 1.0) + np.random.default_rng(seed).normal(0, 0.03, (n, 2))
    edges = fl.build_edges("delaunay", tpl)
    return fl.Formation.from_template(
        tpl, edges=edges, diameters=0.2, alpha_values=values, one_based=False
    )


@pytest.mark.parametrize("values", ["sign", "angle"])
def test_alpha_and_beta_read_back_as_the_numbers_they_come_from(values):
    f = patch(200, values)
    t64, a64, _ = alpha_from_shape(f.template, np.asarray(f.edges, np.int64), values)
    order = np.lexsort((t64[:, 2], t64[:, 1], t64[:, 0]))
    t64, a64 = t64[order], a64[order]
    alpha = f.restricted_alpha
    assert alpha.dtype == np.float64 and not alpha.flags.writeable
    assert alpha.tobytes() == a64.tobytes()  # bit for bit
    tris, beta, surface = f.surfaces
    want = switching_surfaces(t64, a64)
    assert beta.dtype == np.float64 and not beta.flags.writeable
    assert beta.tobytes() == want[1].tobytes()
    np.testing.assert_array_equal(tris, want[0])
    np.testing.assert_array_equal(surface, want[2])
    held = f.half_alpha()
    assert held.dtype == (np.int8 if values == "sign" else np.float64)
    held_beta = f.held_surfaces[1]
    assert held_beta.dtype == (np.int8 if values == "sign" else np.float64)
    assert "restricted_alpha" not in vars(f) and "surfaces" not in vars(f)
    # the halves j < k the formation holds, with their alpha, bit for bit
    half = t64[:, 1] < t64[:, 2]
    np.testing.assert_array_equal(f.restricted_halves, t64[half])
    assert f.restricted_halves.dtype == np.int32
    assert held.astype(np.float64).tobytes() == a64[half].tobytes()
    idx = np.array([5, 0, len(held) - 1, 17])
    assert f.half_alpha(idx).tobytes() == held[idx].tobytes()
    np.testing.assert_array_equal(f.half_surface, want[2][half])
    # both orders derived from the halves: the lists of before, in their order
    np.testing.assert_array_equal(f.restricted_triples, t64)
    np.testing.assert_array_equal(f.triple_surface, want[2])
    first = np.unique(want[2], return_index=True)[1]
    assert f.surface_labels == ["alpha_{}{}{}".format(*(t64[m] + 1)) for m in first]
    # rebuilt from what it gives, a formation holds the same
    g = f.with_diameters(0.25)
    assert g.restricted_alpha.tobytes() == alpha.tobytes()
    assert g.half_alpha().dtype == held.dtype


def test_values_other_than_plus_and_minus_one_stay_float64():
    table = {(1, 2, 3): 2.5, (2, 3, 1): 1.0, (3, 1, 2): -1.0}
    f = fl.Formation.from_alpha_table(table, n=3, distances=1.0)
    assert f.half_alpha().dtype == np.float64
    assert f.alpha[0, 1, 2] == 2.5 and f.alpha[0, 2, 1] == -2.5
    signs = fl.Formation.from_alpha_table({(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}, n=3)
    assert signs.half_alpha().dtype == np.int8
    assert set(np.unique(signs.alpha).tolist()) == {-1.0, 0.0, 1.0}


def test_positive_beta_with_exchanged_corners_decides_every_surface_alike():
    # sign-valued alpha: beta = +-1, stored once as 1 after the exchange; a layout with
    # the corners of every other surface exchanged back and its beta negative (one per
    # surface) must give the same run, bit for bit
    f = patch(300, "sign", seed=2)
    q0 = f.template + np.random.default_rng(3).normal(0, 0.08, (f.n, 2))
    lay = run_layout(fl.AngleRestrictedLaw().compiled_terms(f, pairs=False))
    assert lay.surf_stride == 0 and lay.surf_beta.tolist() == [1.0]
    s = lay.surf_a.size
    back = np.arange(s) % 2 == 1
    b, c = lay.surf_b.copy(), lay.surf_c.copy()
    b[back], c[back] = lay.surf_c[back], lay.surf_b[back]
    other = lay._replace(surf_b=b, surf_c=c, surf_beta=np.where(back, -1.0, 1.0), surf_stride=1)
    kw = {"dt": 1e-3, "n_steps": 300, "save_every": 30}
    one, two = run_compiled(lay, q0, **kw), run_compiled(other, q0, **kw)
    assert one.status == two.status
    np.testing.assert_array_equal(one.x, two.x)
    np.testing.assert_array_equal(one.v, two.v)
    # angle-valued alpha: one positive beta per surface, and the numpy law's field
    g = patch(40, "angle", seed=4)
    lay2 = run_layout(fl.AngleRestrictedLaw().compiled_terms(g, pairs=False))
    assert lay2.surf_stride == 1 and lay2.surf_beta.size == lay2.surf_a.size
    assert np.all(lay2.surf_beta > 0)
    q = g.template + np.random.default_rng(5).normal(0, 0.08, (g.n, 2))
    a = fl.simulate(g, "angle-restricted", q, duration=0.3, save_every=50, backend="numba")
    ref = fl.simulate(g, "angle-restricted", q, duration=0.3, save_every=50, backend="numpy")
    assert a.status == ref.status == "success"
    assert np.any(a.sigma >= 0) and np.any(a.sigma < 0)  # restrictions on and off
    np.testing.assert_allclose(a.q, ref.q, rtol=0, atol=1e-10)


def test_a_formation_beyond_the_held_limit_holds_only_its_halves(monkeypatch):
    # the same lists, built at each access instead of kept; the same compiled run
    import formationlab.formation.spec as spec

    f = patch(300, "sign", seed=6)
    lists = (f.restricted_triples, f.restricted_alpha, *f.surfaces, f.restricted_sign)
    q0 = f.template + np.random.default_rng(7).normal(0, 0.08, (f.n, 2))
    kw = {"dt": 1e-3, "n_steps": 200, "save_every": 50}
    law = fl.AngleRestrictedLaw()
    kept = run_compiled(run_layout(law.compiled_terms(f, pairs=False)), q0, **kw)
    monkeypatch.setattr(spec, "HELD_LIMIT", 2 * len(f.restricted_halves) - 1)
    g = f.with_diameters(0.2)
    again = (g.restricted_triples, g.restricted_alpha, *g.surfaces, g.restricted_sign)
    for a, b in zip(lists, again, strict=True):
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
        assert not b.flags.writeable
    derived = ("_ordered_lists", "_surfaces_held", "_triple_surface")
    assert not set(derived) & set(vars(g)) and set(derived) <= set(vars(f))
    arrays = [v for v in vars(g).values() if isinstance(v, np.ndarray)]
    assert sum(a.nbytes for a in arrays) < sum(x.nbytes for x in lists[:2])
    built = run_compiled(run_layout(law.compiled_terms(g, pairs=False)), q0, **kw)
    assert built.status == kept.status
    np.testing.assert_array_equal(built.x, kept.x)
    # kept for a run of the numpy driver, dropped after it
    with g.holding():
        assert g.restricted_triples is g.restricted_triples
        assert set(derived[:1]) <= set(vars(g))
    assert not set(derived) & set(vars(g))
    res = fl.simulate(g, "angle-restricted", q0, duration=0.05, backend="numpy")
    ref = fl.simulate(f, "angle-restricted", q0, duration=0.05, backend="numpy")
    assert res.status == ref.status and not set(derived) & set(vars(g))
    np.testing.assert_array_equal(res.q, ref.q)


def test_switching_surfaces_beyond_the_one_key_range_are_the_same():
    # robot numbers whose cube overflows the int64 key take the three-column path; a
    # numbering that keeps the order gives the same surfaces, renumbered alike
    f = patch(120, "angle", seed=8)
    t, a = f.restricted_halves.astype(np.int64), f.half_alpha()
    big = 2_000_000 + 1_000 * t  # (the largest number exceeds 2**62 ** (1/3))
    want = switching_surfaces(t, a)
    got = switching_surfaces(big, a)
    np.testing.assert_array_equal(got[0], 2_000_000 + 1_000 * want[0])
    assert got[1].tobytes() == want[1].tobytes()
    np.testing.assert_array_equal(got[2], want[2])
