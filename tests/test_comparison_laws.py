"""The comparison laws: squared distance (Krick et al. 2009) and signed area (Anderson et al. 2017).

Checked against values derived by hand, finite differences of their potentials,
invariances, and Lyapunov decrease along simulated runs.
"""

import math

import numpy as np
import pytest

import formationlab as fl
from formationlab.controllers import LAWS, SignedAreaLaw, SquaredDistanceLaw, grad_phi
from formationlab.controllers.signed_area import desired_areas, signed_areas
from formationlab.errors import FormationError, ParameterError

SIM1 = {(1, 2, 3): -1, (3, 1, 2): -1, (2, 1, 3): 1}  # section 4, simulation 1
SIM2 = {(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}  # section 4, simulation 2
EQUILATERAL = math.sqrt(3) / 4  # area of the triangle with unit sides
SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def square_one_diagonal(orientation="template"):
    """Four robots, the ring 1-2-3-4 and diagonal 1-3: robots 2 and 4 are not neighbours."""
    edges = [[1, 2], [2, 3], [3, 4], [4, 1], [1, 3]]
    return fl.Formation.from_template(SQUARE, edges=edges, orientation=orientation)


def numerical_gradient(fun, q, eps=1e-6):
    g = np.zeros_like(q)
    for idx in np.ndindex(q.shape):
        e = np.zeros_like(q)
        e[idx] = eps
        g[idx] = (fun(q + e) - fun(q - e)) / (2 * eps)
    return g


def test_registered_by_name():
    assert LAWS["squared-distance"] is SquaredDistanceLaw
    assert LAWS["signed-area"] is SignedAreaLaw
    law = fl.get_law("signed-area", k_s=2.5)
    assert isinstance(law, SignedAreaLaw) and law.k_s == 2.5


@pytest.mark.parametrize(
    ("cls", "params"),
    [
        (SquaredDistanceLaw, {"k": 0.0}),
        (SquaredDistanceLaw, {"k_r": -1.0}),
        (SignedAreaLaw, {"k_s": -0.1}),
        (SignedAreaLaw, {"k": float("nan")}),
    ],
)
def test_invalid_gains_are_user_errors(cls, params):
    with pytest.raises(ParameterError, match="must be a finite number"):
        cls(**params)


def test_squared_distance_two_robots_by_hand():
    # V = 1/4 (r^2 - d^2)^2, grad_1 V = -(r^2 - d^2)(q_2 - q_1): with r = 2, d = 1,
    # u_1 = k (4 - 1) (2, 0) = (6k, 0) and u_2 = -u_1.
    f = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    u = SquaredDistanceLaw(k=1.5).control(f, np.array([[0.0, 0.0], [2.0, 0.0]]))
    np.testing.assert_allclose(u, [[9.0, 0.0], [-9.0, 0.0]], rtol=1e-14)
    assert SquaredDistanceLaw().potential(f, np.array([[0.0, 0.0], [2.0, 0.0]])) == 2.25


def test_repulsion_force_is_that_of_the_paper_laws():
    # Robots 2 and 4 of the square with one diagonal are not neighbours; with the
    # edges at their desired lengths only the repulsion acts, and with k_r = k_c it
    # must equal the distance law's (eq. 8, gamma_ij scaled by k_c).
    f = square_one_diagonal()
    q = SQUARE.copy()
    q[1] = [0.62, 0.38]  # robot 2 moved towards robot 4 along the line x + y = 1
    q[3] = [0.38, 0.62]
    gap = np.linalg.norm(q[3] - q[1]) - 0.2
    assert gap < 0.5  # inside the repulsion's influence
    u_sq = SquaredDistanceLaw(k_r=2.0).control(f, q) - SquaredDistanceLaw(k_r=0.0).control(f, q)
    rep = fl.Repulsion()
    u_paper = -2.0 * (grad_phi(f, q, rep) - grad_phi(f, q, None))  # k_c = 2
    np.testing.assert_allclose(u_sq, u_paper, atol=1e-12)
    # and by hand: gamma'(s) = -eta (1/s - 1/s0) / s^2, pushing robot 2 away from robot 4
    s, s0 = gap, 0.5
    push = 2.0 * (1 / s - 1 / s0) / s**2
    away = (q[1] - q[3]) / np.linalg.norm(q[1] - q[3])
    np.testing.assert_allclose(u_sq[1], push * away, rtol=1e-12)


@pytest.mark.parametrize("law", [SquaredDistanceLaw(k=0.7, k_r=1.3), SignedAreaLaw(k=0.7, k_s=2.0)])
def test_control_is_minus_k_times_gradient_of_potential(law, rng):
    f = square_one_diagonal()
    for _ in range(3):
        q = SQUARE + rng.normal(scale=0.15, size=(4, 2))
        grad = numerical_gradient(lambda x: float(law.potential(f, x)), q)
        np.testing.assert_allclose(law.control(f, q), -law.k * grad, rtol=1e-6, atol=1e-7)


def test_desired_areas_of_the_paper_tables():
    # The paper's alpha drives to sign(c_123) = -sign(alpha_123) (docs/conventions.md):
    # simulation 1 (alpha_123 = -1) wants the counter-clockwise triangle, simulation 2
    # the clockwise one; unit sides give |A*| = sqrt(3)/4 (Heron).
    for table, sign in ((SIM1, 1.0), (SIM2, -1.0)):
        f = fl.Formation.from_alpha_table(table, n=3, distances=1.0)
        tris, target = desired_areas(f)
        np.testing.assert_array_equal(tris, [[0, 1, 2]])
        np.testing.assert_allclose(target, [sign * EQUILATERAL], rtol=1e-14)


def test_desired_areas_from_a_template_and_its_mirror():
    tpl = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]])  # ccw, area 1
    f = fl.Formation.from_template(tpl)
    np.testing.assert_allclose(desired_areas(f)[1], [1.0])
    np.testing.assert_allclose(desired_areas(f.with_orientation("mirror"))[1], [-1.0])
    assert len(desired_areas(f.with_orientation("free"))[0]) == 0


def test_desired_area_from_angles_when_an_edge_is_missing():
    # Only edges 1-2 and 1-3: with angle-valued alpha the area is 1/2 d_12 d_13 sin(alpha).
    f = fl.Formation.from_alpha_table(
        {(1, 2, 3): -math.pi / 3},
        n=3,
        edges=[[1, 2], [1, 3]],
        distances=[2.0, 3.0],
        alpha_values="angle",
    )
    np.testing.assert_allclose(desired_areas(f)[1], [0.5 * 2 * 3 * math.sin(math.pi / 3)])
    g = fl.Formation.from_alpha_table({(1, 2, 3): -1}, n=3, edges=[[1, 2], [1, 3]])
    with pytest.raises(FormationError, match="desired area of triangle"):
        desired_areas(g)


def test_contradictory_orientations_are_rejected():
    # c_231 = c_123, so alpha_123 = 1 and alpha_231 = -1 ask for both orientations.
    f = fl.Formation.from_alpha_table({(1, 2, 3): 1, (2, 3, 1): -1}, n=3)
    with pytest.raises(FormationError, match="opposite orientations"):
        SignedAreaLaw().control(f, SQUARE[:3])


def test_signed_area_law_tells_a_triangle_from_its_mirror():
    f = fl.Formation.from_alpha_table(SIM1, n=3)  # wants counter-clockwise
    ccw = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, math.sqrt(3) / 2]])
    cw = ccw * [1.0, -1.0]
    sa, sq = SignedAreaLaw(k_s=1.0), SquaredDistanceLaw()
    np.testing.assert_allclose(sa.control(f, ccw), 0.0, atol=1e-14)
    np.testing.assert_allclose(sq.control(f, cw), 0.0, atol=1e-14)  # blind to orientation
    # at the mirror image only the area term acts: u_a = -k k_s (A - A*) 1/2 k x r_bc
    u = sa.control(f, cw)
    err = -EQUILATERAL - EQUILATERAL
    expected_1 = -err * 0.5 * np.array([-(cw[2, 1] - cw[1, 1]), cw[2, 0] - cw[1, 0]])
    np.testing.assert_allclose(u[0], expected_1, rtol=1e-12)
    assert sa.potential(f, cw) == pytest.approx(0.5 * err**2, rel=1e-12)


def test_signed_areas_match_triple_products():
    q = np.random.default_rng(3).normal(size=(5, 4, 2))
    tris = np.array([[0, 1, 2], [1, 2, 3]])
    c = fl.triple_products(q)
    np.testing.assert_allclose(
        signed_areas(tris, q), 0.5 * c[:, tris[:, 0], tris[:, 1], tris[:, 2]]
    )


@pytest.mark.parametrize("law", [SquaredDistanceLaw(), SignedAreaLaw()])
def test_invariances(law, rng):
    f = square_one_diagonal()
    q = SQUARE + rng.normal(scale=0.2, size=(4, 2))
    u = law.control(f, q)
    np.testing.assert_allclose(
        law.control(f, q + np.array([3.0, -1.0])), u, atol=1e-12
    )  # translation
    a = 0.7
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    np.testing.assert_allclose(law.control(f, q @ rot.T), u @ rot.T, atol=1e-12)  # rotation
    # batch axes: a stack of states gives the stack of controls
    np.testing.assert_allclose(law.control(f, np.stack([q, q + 1.0])), np.stack([u, u]), atol=1e-12)


@pytest.mark.parametrize("law", [SquaredDistanceLaw(), SignedAreaLaw(k_s=2.0)])
def test_potential_decreases_along_runs(law):
    f = fl.Formation.from_alpha_table(SIM2, n=3)  # wants clockwise
    q0 = np.array([[-1.5, 1.0], [1.2, 1.3], [0.3, -1.4]])
    assert fl.triangle_orientation(q0) == "cw"
    res = fl.simulate(f, law, q0, duration=3.0, integrator=fl.Euler(dt=1e-3))
    assert res.status == "success"
    assert np.all(np.diff(res.V) <= 1e-12)
    assert res.V[-1] < 1e-6 * res.V[0]
    assert res.outcome() == "desired"


def test_signed_area_keeps_a_distorted_mirror_minimum():
    # By hand: on equilateral triangles of side s with the wrong (ccw) orientation,
    # W(x = s^2) = 3/4 (x - 1)^2 + k_s 3/32 (x + 1)^2 is stationary at
    # x = (8 - k_s) / (8 + k_s); for k_s = 1, s^2 = 7/9 and W = 1/3. From a ccw start
    # the law stops there, and it is a local minimum of W (the Hessian has the three
    # zero eigenvalues of the rigid motions and three positive ones): an area penalty
    # this weak does not remove the mirror minimum, it only shrinks it.
    law = SignedAreaLaw(k_s=1.0)
    f = fl.Formation.from_alpha_table(SIM2, n=3)
    q0 = np.array([[-1.5, -1.0], [1.2, -1.3], [0.3, 1.4]])
    res = fl.simulate(f, law, q0, duration=8.0, integrator=fl.Euler(dt=1e-3))
    assert res.outcome() == "incorrect"
    q = res.final
    assert fl.triangle_orientation(q) == "ccw"
    np.testing.assert_allclose(fl.distance_errors(f, q) + 1.0, math.sqrt(7 / 9), rtol=1e-5)
    assert res.V[-1] == pytest.approx(1 / 3, rel=1e-6)
    eps = 1e-4
    hess = np.zeros((6, 6))
    grad = lambda x: -law.control(f, x.reshape(3, 2)).ravel() / law.k  # noqa: E731
    for m in range(6):
        e = np.zeros(6)
        e[m] = eps
        hess[:, m] = (grad(q.ravel() + e) - grad(q.ravel() - e)) / (2 * eps)
    eig = np.linalg.eigvalsh(0.5 * (hess + hess.T))
    np.testing.assert_allclose(eig[:3], 0.0, atol=1e-5)
    assert eig[3] > 1e-2


def test_signed_area_reaches_the_desired_orientation_where_squared_distance_does_not():
    # From a slightly clockwise start, the squared-distance law keeps the orientation
    # (the mirror of what simulation 1 wants); the area term flips it.
    f = fl.Formation.from_alpha_table(SIM1, n=3)
    q0 = np.array([[-0.6, 0.0], [0.6, 0.05], [0.1, -0.3]])
    assert fl.triangle_orientation(q0) == "cw"
    for law, outcome in ((SquaredDistanceLaw(), "mirror"), (SignedAreaLaw(k_s=5.0), "desired")):
        res = fl.simulate(f, law, q0, duration=8.0, integrator=fl.Euler(dt=1e-3))
        assert res.outcome() == outcome, law.name
