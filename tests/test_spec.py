"""Formation specification: builders, the alpha conventions, validation messages."""

import numpy as np
import pytest

import formationlab as fl
from formationlab import FormationError


def test_paper_table_completion_and_desired_orientation():
    f = fl.Formation.from_alpha_table({(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}, n=3)
    a = f.alpha
    assert a[0, 1, 2] == 1 and a[0, 2, 1] == -1  # eq. (3)
    assert a[1, 2, 0] == 1 and a[2, 0, 1] == 1  # alpha_231 = -alpha_213
    # the law drives to sign(c_ijk) = -sign(alpha_ijk): simulation 2 wants clockwise
    assert f.desired_sign[0, 1, 2] == -1


def test_template_alpha_follows_paper_sign_convention():
    tpl = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]])  # ccw equilateral
    f = fl.Formation.from_template(tpl, alpha_values="angle")
    # ccw angle from r_12 to r_13 is +60 degrees; the paper's alpha carries the opposite sign
    assert f.alpha[0, 1, 2] == pytest.approx(-np.pi / 3)
    # eq. (4) in magnitude: the three angles of the triangle sum to pi
    assert abs(f.alpha[0, 1, 2] + f.alpha[1, 2, 0] + f.alpha[2, 0, 1]) == pytest.approx(np.pi)
    np.testing.assert_allclose(f.distances, 1.0)
    assert fl.Formation.from_template(tpl).alpha[0, 1, 2] == -1.0
    assert fl.Formation.from_template(tpl, orientation="mirror").alpha[0, 1, 2] == 1.0
    assert fl.Formation.from_template(tpl, orientation="free").alpha is None


def test_distances_follow_user_edge_order():
    f = fl.Formation.from_distances(3, edges=[[2, 3], [1, 2]], distances=[2.0, 1.5])
    assert f.edges.tolist() == [[0, 1], [1, 2]]
    assert f.distances.tolist() == [1.5, 2.0]


def test_rigidity_and_connectivity():
    assert fl.Formation.from_distances(4).is_rigid
    assert not fl.Formation.from_distances(4, edges=[[1, 2], [2, 3], [3, 4], [4, 1]]).is_rigid
    assert not fl.Formation.from_distances(4, edges=[[1, 2], [3, 4]]).is_connected


@pytest.mark.parametrize(
    ("build", "fragment"),
    [
        (
            lambda: fl.Formation.from_distances(3, distances=0.1, diameters=0.2),
            "must exceed the contact",
        ),
        (lambda: fl.Formation.from_distances(3, edges=[[1, 4]]), "names robot 4"),
        (lambda: fl.Formation.from_distances(3, edges=[[2, 2]]), "to itself"),
        (lambda: fl.Formation.from_distances(3, edges=[[1, 2], [2, 1]]), "given twice"),
        (lambda: fl.Formation.from_distances(3, distances=[1.0, np.nan, 1.0]), "finite"),
        (lambda: fl.Formation.from_distances(3, diameters=[0.1, 0.2]), "one per robot"),
        (lambda: fl.Formation.from_template([[0, 0], [1, 0], [2, 0]]), "collinear"),
        (lambda: fl.Formation.from_alpha_table({(1, 2, 3): 1, (1, 3, 2): 1}, n=3), "twice"),
        (lambda: fl.Formation.from_alpha_table({(1, 2, 2): 1}, n=3), "three different"),
        (
            lambda: fl.Formation.from_alpha_table({(1, 2, 3): 1}, n=3, edges=[[1, 2], [2, 3]]),
            "not both neighbours",
        ),
    ],
)
def test_validation_messages(build, fragment):
    with pytest.raises(FormationError, match=fragment):
        build()


def test_check_positions_names_overlapping_pair():
    f = fl.Formation.from_distances(3, diameters=0.4)
    with pytest.raises(FormationError, match="robots 2 and 3 overlap"):
        f.check_positions([[0, 0], [2, 0], [2.3, 0]])
    with pytest.raises(FormationError, match="NaN"):
        f.check_positions([[0, 0], [2, 0], [np.nan, 0]])
    with pytest.raises(FormationError, match="shape"):
        f.check_positions([[0, 0], [2, 0]])


def test_connectivity_is_decided_in_one_place_for_matrices_and_edge_lists():
    from formationlab.formation.graph import edges_connected, is_connected

    rng = np.random.default_rng(4)
    for _ in range(50):
        n = int(rng.integers(2, 9))
        a = np.triu(rng.random((n, n)) < 0.3, k=1)
        edges = np.argwhere(a)
        # a graph is connected when a search from robot 1 reaches every robot
        seen, todo = {0}, [0]
        while todo:
            i = todo.pop()
            for j in np.flatnonzero(a[i] | a[:, i]):
                if int(j) not in seen:
                    seen.add(int(j))
                    todo.append(int(j))
        assert is_connected(a | a.T) == edges_connected(edges, n) == (len(seen) == n)


def test_index_arrays_are_int32_and_the_kernels_still_get_int64():
    """Edges, restricted triples and surfaces in int32 (half the bytes); the same values as
    the int64 lists they are made from; every array of the law's kernel data int64."""
    from formationlab.formation.orientation import alpha_from_shape, switching_surfaces

    tpl = fl.lattice("triangular", 150, 1.0)
    edges = fl.build_edges("delaunay", tpl)
    f = fl.Formation.from_template(tpl, edges=edges, diameters=0.2, one_based=False)
    tris, _, surface = f.surfaces
    for arr in (f.edges, f.restricted_triples, tris, surface):
        assert arr.dtype == np.int32
    assert f.restricted_triples.nbytes == 12 * len(f.restricted_triples)
    assert not f.edges.flags.writeable and not f.restricted_triples.flags.writeable
    # the same numbers as the int64 lists they come from
    t64, a64, _ = alpha_from_shape(tpl, np.asarray(edges, np.int64), "sign")
    order = np.lexsort((t64[:, 2], t64[:, 1], t64[:, 0]))  # the formation's sorted order
    t64, a64 = t64[order], a64[order]
    np.testing.assert_array_equal(f.restricted_triples, t64)
    np.testing.assert_array_equal(f.restricted_alpha, a64)
    want = switching_surfaces(t64, a64)
    for got, ref in zip(f.surfaces, want, strict=True):
        np.testing.assert_array_equal(got, ref)
    # rebuilt from its own int32 lists, a formation is the same
    g = f.with_diameters(0.3)
    np.testing.assert_array_equal(g.restricted_triples, f.restricted_triples)
    assert g.restricted_triples.dtype == np.int32
    terms = fl.AngleRestrictedLaw().kernel_terms(f)
    ints = {k: v.dtype for k, v in terms._asdict().items()
            if isinstance(v, np.ndarray) and v.dtype.kind == "i"}  # fmt: skip
    assert ints and set(ints.values()) == {np.dtype(np.int64)}, ints
    # for the compiled single run (no pair arrays), which lays them out as int32 anyway
    lean = fl.AngleRestrictedLaw().kernel_terms(f, pairs=False)
    for name in ("edge_i", "edge_j", "surface_a", "term_i", "term_k", "term_surface"):
        assert getattr(lean, name).dtype == np.int32, name
        np.testing.assert_array_equal(getattr(lean, name), getattr(terms, name))
