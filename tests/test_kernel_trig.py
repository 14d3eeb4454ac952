"""The unicycle kernel's trigonometry without library calls (models/trig.py).

``atan2_poly`` against numpy's ``arctan2`` over the whole range of finite arguments,
``turn_small`` against the library's ``cos`` and ``sin`` of headings stepped many times,
and the kernel where a step turns a robot by more than the series take (it falls back to
the library) against the stepping driver.
"""

import math

import numpy as np
import pytest
from numba import njit

import formationlab as fl
from formationlab.models import Unicycle
from formationlab.models.trig import SMALL_TURN, atan2_poly, turn_small
from formationlab.studies.batch import run_batch
from formationlab.studies.config import BoxInitial
from formationlab.studies.sampling import model_initial_states, trial_initial_states


@njit(cache=False)
def _atan2_all(y, x, out):
    for i in range(y.size):
        out[i] = atan2_poly(y[i], x[i])


@njit(cache=False)
def _carry(theta0, steps, out):
    """Headings stepped as the kernel does: theta += a, h turned by the exact difference."""
    th = theta0
    c, s, c_lo, s_lo = math.cos(th), math.sin(th), 0.0, 0.0
    for k in range(steps.size):
        nxt = th + steps[k]
        c, s, c_lo, s_lo = turn_small(c, s, c_lo, s_lo, nxt - th)
        th = nxt
        out[k, 0] = c - math.cos(th)
        out[k, 1] = s - math.sin(th)


def _atan2(y, x):
    y, x = np.broadcast_arrays(np.asarray(y, float), np.asarray(x, float))
    out = np.empty(y.size)
    _atan2_all(np.ascontiguousarray(y.ravel()), np.ascontiguousarray(x.ravel()), out)
    return out.reshape(y.shape)


def test_atan2_poly_is_numpys_arctan2_to_an_ulp_or_two_over_the_whole_range():
    rng = np.random.default_rng(7)
    size = 400_000
    y = rng.choice([-1.0, 1.0], size) * 10.0 ** rng.uniform(-300, 300, size)
    x = rng.choice([-1.0, 1.0], size) * y * 10.0 ** rng.uniform(-3, 3, size)  # every angle
    x[:1000] = y[:1000] * rng.uniform(0.6, 0.7, 1000)  # around the switch at 0.66
    x[1000:2000] = y[1000:2000]  # the diagonals
    ref = np.arctan2(y, x)
    ulps = np.abs(_atan2(y, x) - ref) / np.spacing(np.abs(ref))
    assert ulps.max() <= 2.0
    assert ulps.mean() <= 0.15  # most results are the library's (measured 0.085)
    assert np.ptp(ref) > 6.2  # the whole circle


@pytest.mark.parametrize(
    ("y", "x"),
    [(0.0, 0.0), (-0.0, 0.0), (0.0, -0.0), (-0.0, -0.0), (1.0, 0.0), (-1.0, 0.0), (0.0, -1.0),
     (-0.0, -1.0), (1.0, -0.0), (1.0, 1.0), (-1.0, -1.0), (1e-300, 1.0), (1.0, 1e-300)],
)  # fmt: skip
def test_atan2_poly_on_the_axes_diagonals_and_signed_zeros(y, x):
    got, ref = _atan2(y, x)[()], np.arctan2(y, x)
    assert got == ref and math.copysign(1.0, got) == math.copysign(1.0, ref)


@pytest.mark.parametrize("size", [1e-3, 0.02, SMALL_TURN])
def test_a_carried_heading_stays_the_librarys_over_many_steps(size):
    rng = np.random.default_rng(3)
    steps = rng.uniform(-size, size, 100_000) + size / 3  # spins many times round
    out = np.empty((steps.size, 2))
    _carry(0.3, steps, out)
    # the rounding of each sum is carried, not accumulated; what is left is the rounding of
    # the products, about eps |a| per step, a random walk: eps (1 + |a| sqrt(steps)) bounds
    # it (measured: 0.5, 2 and 40 eps for the three sizes, 1 + |a| sqrt(steps) = 1.3, 7.3, 80)
    assert np.abs(out).max() <= np.finfo(float).eps * (1.0 + size * np.sqrt(steps.size))


def test_turns_wider_than_the_series_fall_back_to_the_library_in_the_kernel():
    # hand points 1 cm ahead: omega = u . h_perp / l reaches 1,500 rad/s, so steps of
    # 0.01 s turn robots by more than SMALL_TURN; the kernel takes the library's cos and
    # sin there and still equals the driver (longer runs at such steps are chaotic: the
    # kernel before this change differed from the driver as much)
    model = Unicycle(offset=0.01)
    f = fl.Formation.from_template([[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]], diameters=0.1)
    law = fl.get_law("distance")
    idx = np.arange(40)
    q0 = trial_initial_states(f, BoxInitial(half_width=1.5), 4, idx)
    x0 = model_initial_states(f, model, q0, 4, idx)
    dt = 0.01
    _, omega = model.commands(x0, law.control(f, model.points(x0)))
    assert np.abs(omega * dt).max(axis=-1).min() > SMALL_TURN  # every trial starts wide
    a, b = (
        run_batch(f, law, x0, dt=dt, duration=0.5, backend=backend, model=model)
        for backend in ("numba", "numpy")
    )
    np.testing.assert_array_equal(a.status, b.status)
    np.testing.assert_array_equal(a.steps, b.steps)
    np.testing.assert_allclose(a.x_final, b.x_final, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.u_final, b.u_final, rtol=0, atol=1e-8)
    _, omega = model.commands(b.x_final, b.u_final)
    assert np.median(np.abs(omega * dt)) < SMALL_TURN  # and most end with small ones
