"""The laws (8) and (11)-(14) against finite differences, eq. (23), invariances, eq. (25)."""

import numpy as np
import pytest

import formationlab as fl
from formationlab.controllers import grad_phi, grad_psi, phi_sum, psi_sum
from formationlab.controllers.potentials import khatib, phi, psi, triple_products

H = 1e-6


def _fd_grad(fun, q, i):
    g = np.zeros(2)
    for ax in range(2):
        dq = np.zeros_like(q)
        dq[i, ax] = H
        g[ax] = (fun(q + dq) - fun(q - dq)) / (2 * H)
    return g


def _phi_i(f, law, q, i):
    """phi_i of eq. (12), written out pair by pair (independent of the vectorised code)."""
    total = 0.0
    for j in range(f.n):
        if j == i:
            continue
        r = np.linalg.norm(q[j] - q[i])
        a = f.contact_matrix[i, j]
        if f.adjacency[i, j]:
            total += phi(r, f.distance_matrix[i, j], a)
        else:
            total += khatib(r - a, law.repulsion.eta, law.repulsion.influence)
    return float(total)


def _psi_i(f, q, theta, i):
    """psi_i of eq. (13) over ordered pairs, written out."""
    total = 0.0
    for j in range(f.n):
        for k in range(f.n):
            if f.triples[i, j, k]:
                rij, rik = q[j] - q[i], q[k] - q[i]
                c = rij[0] * rik[1] - rij[1] * rik[0]
                total += psi(f.alpha[i, j, k], c, theta)
    return float(total)


@pytest.fixture
def square_incomplete():
    """Four robots, a cycle without one diagonal: one non-neighbour pair (Khatib acts)."""
    tpl = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    return fl.Formation.from_template(
        tpl, edges=[[1, 2], [2, 3], [3, 4], [4, 1], [1, 3]], diameters=0.3, alpha_values="angle"
    )


def test_distance_law_is_minus_kc_grad_phi_i(square_incomplete, rng):
    f = square_incomplete
    law = fl.DistanceLaw(k_c=1.7, repulsion=fl.Repulsion(eta=0.8, influence=0.6))
    q = f.template + 0.15 * rng.normal(size=(4, 2))
    q[3] = q[1] + np.array([0.5, 0.1])  # robots 2 and 4 (non-neighbours) close: gamma active
    assert np.linalg.norm(q[3] - q[1]) - 0.3 < 0.6
    u = law.control(f, q)
    for i in range(f.n):
        g = _fd_grad(lambda x, i=i: _phi_i(f, law, x, i), q, i)
        np.testing.assert_allclose(u[i], -law.k_c * g, rtol=1e-6, atol=1e-7)  # eq. (8)
    # V = sum_i phi_i (eq. 9) has gradient 2 grad_i phi_i: u = -(k_c/2) grad V
    for i in range(f.n):
        gV = _fd_grad(lambda x: float(law.potential(f, x)), q, i)
        np.testing.assert_allclose(u[i], -0.5 * law.k_c * gV, rtol=1e-6, atol=1e-7)


def test_grad_psi_eq23_and_finite_differences(rng):
    tpl = np.array([[0.0, 0.0], [1.0, 0.2], [0.4, 1.1], [-0.6, 0.7]])
    f = fl.Formation.from_template(tpl, diameters=0.1, orientation="mirror", alpha_values="angle")
    theta = 0.3
    q = tpl + 0.05 * rng.normal(size=(4, 2))
    g = grad_psi(f, q, theta)
    c = triple_products(q)
    for i in range(f.n):
        # eq. (23): grad_i psi_ijk = alpha_ijk k x r_jk where active, summed over ordered pairs
        expected = np.zeros(2)
        for j in range(f.n):
            for k in range(f.n):
                if f.triples[i, j, k] and f.alpha[i, j, k] * c[i, j, k] + theta > 0:
                    r_jk = q[k] - q[j]
                    expected += f.alpha[i, j, k] * np.array([-r_jk[1], r_jk[0]])
        np.testing.assert_allclose(g[i], expected, rtol=1e-12, atol=1e-12)
        fd = _fd_grad(lambda x, i=i: _psi_i(f, x, theta, i), q, i)
        np.testing.assert_allclose(g[i], fd, rtol=1e-6, atol=1e-7)


def test_eq23_gradient_of_c_at_every_robot(rng):
    q = rng.normal(size=(3, 2))

    def c(x):
        return float(triple_products(x)[0, 1, 2])

    perp = lambda v: np.array([-v[1], v[0]])  # noqa: E731
    i, j, k = 0, 1, 2
    np.testing.assert_allclose(_fd_grad(c, q, i), perp(q[k] - q[j]), atol=1e-8)  # k x r_jk
    np.testing.assert_allclose(_fd_grad(c, q, j), perp(q[i] - q[k]), atol=1e-8)  # k x r_ki
    np.testing.assert_allclose(_fd_grad(c, q, k), perp(q[j] - q[i]), atol=1e-8)  # k x r_ij


def test_angle_law_is_descent_of_own_potentials(rng):
    f = fl.Formation.from_template(
        [[0, 0], [1, 0], [0.5, 0.9]], diameters=0.2, orientation="mirror"
    )
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    q = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.9]]) + 0.05 * rng.normal(size=(3, 2))
    assert law.active(f, q)[f.restricted].all()
    u = law.control(f, q)
    for i in range(3):
        gphi = _fd_grad(lambda x, i=i: _phi_i(f, law, x, i), q, i)
        gpsi = _fd_grad(lambda x, i=i: _psi_i(f, x, law.theta, i), q, i)
        np.testing.assert_allclose(u[i], -2.0 * gphi - 3.0 * gpsi, rtol=1e-6, atol=1e-6)  # eq. (11)


def test_ordered_pairs_count_each_unordered_pair_twice():
    f = fl.Formation.from_alpha_table({(1, 2, 3): 1}, n=3)
    q = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])  # c_123 = 1
    # only alpha_123 (and alpha_132 = -alpha_123) given: psi_1 = psi_123 + psi_132 = 1 + 1
    assert psi_sum(f, q, 0.5) == pytest.approx(2.0)
    g = grad_psi(f, q, 0.5)
    # grad_1 psi_1 = 2 alpha_123 k x r_23 with r_23 = (-1, 1): k x r_23 = (-1, -1)
    np.testing.assert_allclose(g[0], 2 * np.array([-1.0, -1.0]))


def _random_state(rng, n=4):
    tpl = rng.normal(size=(n, 2)) * 1.5
    f = fl.Formation.from_template(tpl, diameters=0.05, alpha_values="angle")
    q = tpl + 0.3 * rng.normal(size=(n, 2))
    return f, q


@pytest.mark.parametrize("law", [fl.DistanceLaw(), fl.AngleRestrictedLaw(theta=0.4)])
def test_translation_and_rotation_equivariance(law, rng):
    f, q = _random_state(rng)
    u = law.control(f, q)
    np.testing.assert_allclose(law.control(f, q + np.array([3.0, -7.0])), u, atol=1e-10)
    ang = 0.7
    R = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    np.testing.assert_allclose(law.control(f, q @ R.T), u @ R.T, atol=1e-10)


@pytest.mark.parametrize("law", [fl.DistanceLaw(), fl.AngleRestrictedLaw(theta=0.4)])
def test_relabelling_equivariance(law, rng):
    f, q = _random_state(rng)
    perm = np.array([2, 0, 3, 1])
    fp = fl.Formation.from_template(
        f.template[perm], diameters=f.diameters[perm], alpha_values="angle"
    )
    np.testing.assert_allclose(law.control(fp, q[perm]), law.control(f, q)[perm], atol=1e-10)


def test_mirror_flips_every_c_and_the_template_alpha(rng):
    q = rng.normal(size=(5, 2))
    m = q * np.array([-1.0, 1.0])
    c, cm = triple_products(q), triple_products(m)
    np.testing.assert_allclose(cm, -c, atol=1e-12)
    tpl = rng.normal(size=(4, 2))
    f = fl.Formation.from_template(tpl)
    fm = f.with_orientation("mirror")
    np.testing.assert_array_equal(fm.alpha, -f.alpha)
    # the law on the mirror formation at the mirrored state is the mirrored law
    law = fl.AngleRestrictedLaw(theta=0.2)
    np.testing.assert_allclose(
        law.control(fm, tpl * [-1, 1]), law.control(f, tpl) * [-1, 1], atol=1e-10
    )


def test_distance_law_controls_sum_to_zero(rng):
    """Pair forces are equal and opposite, so the centroid does not move."""
    f, q = _random_state(rng, n=6)
    u = fl.DistanceLaw().control(f, q)
    np.testing.assert_allclose(u.sum(axis=0), 0.0, atol=1e-12)


def test_batched_control_equals_one_by_one(rng):
    f, _ = _random_state(rng)
    law = fl.AngleRestrictedLaw(theta=0.4)
    qs = f.template + 0.3 * rng.normal(size=(5, 4, 4, 2))
    ub = law.control(f, qs)
    for idx in np.ndindex(5, 4):
        np.testing.assert_allclose(ub[idx], law.control(f, qs[idx]), atol=1e-13)


def test_eq25_holds_for_sign_alpha():
    """dV_n/dt = -(2/k_c) sum |u|^2 when every restriction is active and alpha are signs."""
    tpl = np.array([[0.0, 0.0], [1.0, 0.0], [0.3, 0.9]])
    f = fl.Formation.from_template(tpl, orientation="mirror", alpha_values="sign")
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    q = tpl + np.array([[0.05, -0.02], [0.0, 0.07], [-0.04, 0.03]])
    assert law.active(f, q)[f.restricted].all()
    u = law.control(f, q)
    vdot = (law.potential(f, q + H * u) - law.potential(f, q - H * u)) / (2 * H)
    assert vdot == pytest.approx(-(2 / law.k_c) * np.sum(u**2), rel=1e-7)


def test_eq25_fails_for_angle_alpha():
    """Erratum: with angle-valued alpha, lambda pi k_c = 2 k_a does not give eq. (25).

    The cyclic sum in (24) multiplies k x r_jk by +-pi, which is pi times the
    *sign* of alpha_ljk, not pi times alpha_ljk; so the identity needs |alpha| = 1.
    """
    tpl = np.array([[0.0, 0.0], [1.0, 0.0], [0.3, 0.9]])
    f = fl.Formation.from_template(tpl, orientation="mirror", alpha_values="angle")
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    q = tpl + np.array([[0.05, -0.02], [0.0, 0.07], [-0.04, 0.03]])
    assert law.active(f, q)[f.restricted].all()
    u = law.control(f, q)
    vdot = (law.potential(f, q + H * u) - law.potential(f, q - H * u)) / (2 * H)
    predicted = -(2 / law.k_c) * np.sum(u**2)
    assert abs(vdot - predicted) > 0.05 * abs(predicted)


def test_lambda_of_eq25():
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0)
    fs = fl.Formation.from_template([[0, 0], [1, 0], [0, 1]], alpha_values="sign")
    fa = fl.Formation.from_template([[0, 0], [1, 0], [0, 1]], alpha_values="angle")
    assert law.lam(fs) == pytest.approx(2 * 3 / (3 * 2))
    assert law.lam(fa) == pytest.approx(2 * 3 / (np.pi * 2))


def test_switching_surfaces_dedupe_cyclic_sign_triples():
    fs = fl.Formation.from_template([[0, 0], [1, 0], [0, 1]], alpha_values="sign")
    fa = fl.Formation.from_template([[0, 0], [1, 0], [0.2, 1]], alpha_values="angle")
    assert len(fs.surfaces[0]) == 1  # alpha_123 c_123 = alpha_231 c_231 = alpha_312 c_312
    assert len(fa.surfaces[0]) == 3  # different angles: three surfaces
    law = fl.AngleRestrictedLaw(theta=0.5)
    q = np.array([[0.0, 0.0], [1.0, 0.0], [0.3, -0.4]])
    full = law.control(fa, q)
    steps = (law.switching(fa, q) >= 0).astype(float)
    np.testing.assert_allclose(law.control_with(fa, q, steps), full, atol=1e-14)
    # every step off: the distance law
    np.testing.assert_allclose(
        law.control_with(fa, q, 0 * steps), fl.DistanceLaw().control(fa, q), atol=1e-14
    )


def test_sums_match_written_out_potentials(square_incomplete, rng):
    f = square_incomplete
    law = fl.AngleRestrictedLaw(theta=0.3, repulsion=fl.Repulsion(eta=0.8, influence=0.6))
    q = f.template + 0.1 * rng.normal(size=(4, 2))
    expected_phi = sum(_phi_i(f, law, q, i) for i in range(4))
    assert phi_sum(f, q, law.repulsion) == pytest.approx(expected_phi, rel=1e-12)
    expected_psi = sum(_psi_i(f, q, 0.3, i) for i in range(4))
    assert psi_sum(f, q, 0.3) == pytest.approx(expected_psi, rel=1e-12, abs=1e-12)
    g = grad_phi(f, q, law.repulsion)
    assert g.shape == (4, 2)
