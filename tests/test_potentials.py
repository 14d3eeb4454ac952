"""Eqs. (5)-(7), Khatib's potential, and the collinear minimiser of eqs. (17)-(19)."""

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from formationlab.controllers.potentials import (
    collinear_minimizer,
    dkhatib_ds,
    dphi_dr,
    khatib,
    perp,
    phi,
    psi,
    triple_products,
)


def test_phi_properties_eq6():
    d, a = 2.0, 1.0  # the paper's figure 2
    r = np.linspace(1.0001, 10.0, 20001)
    v = phi(r, d, a)
    assert np.all(v >= 0)  # eq. (6): phi >= 0
    assert phi(d, d, a) == 0.0  # zero at r = d
    assert np.all(v[np.abs(r - d) > 1e-3] > 0)  # ... and only there
    assert phi(1.0 + 1e-12, d, a) > 25  # -> +inf at contact
    assert np.isinf(phi(a, d, a)) and np.isinf(phi(0.5, d, a))  # undefined below contact
    # hand value: r = 3: (3-2)/(2-1) - log((3-1)/(2-1)) = 1 - log 2
    assert phi(3.0, d, a) == pytest.approx(1 - np.log(2), rel=1e-15)


def test_dphi_dr_eq7_against_finite_differences():
    d, a, h = 1.0, 0.2, 1e-6
    r = np.linspace(0.25, 5.0, 50)
    fd = (phi(r + h, d, a) - phi(r - h, d, a)) / (2 * h)
    np.testing.assert_allclose(dphi_dr(r, d, a), fd, rtol=1e-6, atol=1e-8)
    assert dphi_dr(d, d, a) == 0.0


def test_khatib_values_and_derivative():
    eta, s0 = 2.0, 0.5
    assert khatib(0.25, eta, s0) == pytest.approx(0.5 * 2.0 * (4 - 2) ** 2)
    assert khatib(0.5, eta, s0) == 0 and khatib(3.0, eta, s0) == 0
    s, h = np.linspace(0.05, 0.49, 30), 1e-7
    fd = (khatib(s + h, eta, s0) - khatib(s - h, eta, s0)) / (2 * h)
    np.testing.assert_allclose(dkhatib_ds(s, eta, s0), fd, rtol=1e-6)
    # continuous with zero slope at the edge of its influence
    assert khatib(s0 - 1e-9, eta, s0) < 1e-15 and abs(dkhatib_ds(s0 - 1e-9, eta, s0)) < 1e-6


def test_triple_product_is_twice_signed_area():
    q = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]])
    c = triple_products(q)
    assert c[0, 1, 2] == pytest.approx(2.0)  # ccw, area 1
    assert c[0, 2, 1] == pytest.approx(-2.0)  # odd in j <-> k
    assert c[1, 2, 0] == pytest.approx(2.0) and c[2, 0, 1] == pytest.approx(2.0)  # cyclic
    assert perp(np.array([1.0, 0.0])).tolist() == [0.0, 1.0]  # k x e_x = e_y


def test_psi_step_and_jump():
    theta = 0.5
    assert psi(1.0, 2.0, theta) == 2.0  # active
    assert psi(1.0, -0.6, theta) == 0.0  # inactive beyond the surface
    assert psi(1.0, -0.5, theta) == -0.5  # Upsilon(0) = 1: psi = -theta on the surface
    # the jump across the surface is theta (NOTES: V_n is discontinuous)
    assert psi(1.0, -0.5 + 1e-12, theta) - psi(1.0, -0.5 - 1e-12, theta) == pytest.approx(-theta)


def _sum_on_line(x, L, d_ij, d_ik, a_ij, a_ik):
    return phi(abs(x), d_ij, a_ij) + phi(abs(L - x), d_ik, a_ik)


@pytest.mark.parametrize(
    ("L", "d_ij", "d_ik", "rho"),
    [
        (3.0, 1.0, 1.0, (0.2, 0.2, 0.2)),
        (1.5, 1.0, 2.0, (0.1, 0.3, 0.2)),
        (0.8, 1.0, 1.0, (0.2, 0.2, 0.2)),
        (5.0, 1.2, 0.7, (0.4, 0.1, 0.05)),
        (1.0, 1.0, 1.0, (0.2, 0.2, 0.2)),
    ],
)
def test_collinear_minimizer_matches_numerical(L, d_ij, d_ik, rho):
    """Our closed form for eq. (18): argmin of phi_ij + phi_ik with q_i on the line q_j q_k."""
    rho_i, rho_j, rho_k = rho
    a_ij, a_ik = (rho_i + rho_j) / 2, (rho_i + rho_k) / 2
    qj, qk = np.array([1.0, -2.0]), np.array([1.0, -2.0]) + L * np.array([0.6, 0.8])
    x_best, value = collinear_minimizer(qj, qk, d_ij, d_ik, a_ij, a_ik)
    # numerical: minimise on each of the three open intervals of the line
    cands = []
    for lo, hi in ((-L - 10, -a_ij), (a_ij, L - a_ik), (L + a_ik, 2 * L + 10)):
        if hi - lo <= 1e-12:
            continue
        res = minimize_scalar(
            _sum_on_line,
            bounds=(lo + 1e-12, hi - 1e-12),
            args=(L, d_ij, d_ik, a_ij, a_ik),
            method="bounded",
            options={"xatol": 1e-12},
        )
        cands.append((res.fun, res.x))
    fun, _ = min(cands)
    e = (qk - qj) / L
    off = x_best - qj
    assert abs(off[0] * e[1] - off[1] * e[0]) < 1e-12  # on the line
    x_ours = float(off @ e)
    # the minimum value (the minimiser may be one of two symmetric points)
    assert value == pytest.approx(fun, abs=1e-10)
    assert _sum_on_line(x_ours, L, d_ij, d_ik, a_ij, a_ik) == pytest.approx(fun, abs=1e-10)
    assert value > 0  # eq. (17) whenever the three cannot be collinear at the desired distances


def _printed_eq19(qj, qk, r_ij, r_ik, rho_j, rho_k):
    """Eqs. (18)-(19) as printed in the paper."""
    r_jk = np.linalg.norm(qk - qj)
    d = 0.5 * (rho_j + rho_k)
    r_d = (r_ij - d) * (r_ik - d) / (r_ij + r_ik - 2 * d)
    r_p = r_jk + 0.5 * (rho_k - rho_j)
    x = r_d + np.sqrt(r_d**2 + r_p**2)
    lam_j, lam_k = 0.5 * (1 + x / r_jk), 0.5 * (1 - x / r_jk)
    return lam_j * qj + lam_k * qk


def test_printed_eq19_is_not_the_minimiser():
    """Erratum: the printed (19) does not give the minimiser (it does not even depend on d_ij)."""
    qj, qk = np.array([0.0, 0.0]), np.array([3.0, 0.0])
    rho = 0.2
    a = rho
    for d_ij, d_ik in ((1.0, 1.0), (1.0, 2.5)):
        best, value = collinear_minimizer(qj, qk, d_ij, d_ik, a, a)
        # read r_ij, r_ik as the distances at the true minimiser (most favourable reading)
        r_ij, r_ik = np.linalg.norm(best - qj), np.linalg.norm(best - qk)
        printed = _printed_eq19(qj, qk, min(r_ij, r_ik), max(r_ij, r_ik), rho, rho)
        assert np.linalg.norm(printed - best) > 0.1
        x = printed[0]
        assert _sum_on_line(x, 3.0, d_ij, d_ik, a, a) > value + 1e-3
