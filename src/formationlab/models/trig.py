"""Trigonometry of the unicycle kernel without calls of the C library.

A call of ``math.cos``, ``math.sin`` or ``math.atan2`` keeps the loop that holds it from
being vectorised and costs 20-40 ns on the machine measured (docs/robot-models.md), more
than a single integrator's whole step per robot. The compiled loop (:mod:`.stage`) therefore
keeps every unicycle's heading as the unit vector ``h = (cos theta, sin theta)`` as well
as the angle ``theta``, turns ``h`` after each Euler step by the step's angle (the
difference of the two stored angles, small) with :func:`turn_small`, and needs ``atan2``
only for the heading transform, as the branch-free rational approximation
:func:`atan2_poly`. Each function is plain arithmetic and selects, inlined into the
loops, which the compiler can vectorise. Both are within about an ulp of the library's
values; the kernel's results then equal the numpy driver's to rounding
(``tests/test_model_kernel.py``), and the accuracy itself is tested against numpy
(``tests/test_kernel_trig.py``).
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["SMALL_TURN", "atan2_poly", "turn_small", "two_sum"]

#: Largest ``|dt omega|`` that :func:`turn_small` takes: its series are then exact to
#: rounding (first term left out ``0.25^14 / 14! = 4e-20``); larger turns call the library.
SMALL_TURN = 0.25

# Cephes atan (S. L. Moshier, atan.c): atan(z) = z + z^3 P(z^2) / Q(z^2) for |z| <= 0.66,
# relative error 2.2e-16 in IEEE double; beyond, atan(a) = pi/4 + atan((a - 1) / (a + 1)).
_P0 = -8.750608600031904122785e-01
_P1 = -1.615753718733365076637e01
_P2 = -7.500855792314704667340e01
_P3 = -1.228866684490136173410e02
_P4 = -6.485021904942025371784e01
_Q0 = 2.485846490142306297962e01
_Q1 = 1.650270098316988542046e02
_Q2 = 4.328810604912902668951e02
_Q3 = 4.853903996359136964868e02
_Q4 = 1.945506571482613964425e02
_PIO4 = math.pi / 4  # k _PIO4 is fl(k pi/4) exactly for k = 0..4
_PIO4_LO = 3.061616997868383e-17  # pi/4 - _PIO4; k _PIO4_LO is k pi/4 - fl(k pi/4)


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def atan2_poly(y, x):
    """``atan2(y, x)`` in ``[-pi, pi]`` to about an ulp, branch-free (no library call).

    With ``lo, hi = min, max(|x|, |y|)``, ``atan(lo / hi) = t`` or, above 0.66,
    ``pi/4 + t`` with ``t = atan((lo - hi) / (lo + hi))`` (the difference is exact);
    ``t`` by Cephes' rational function. The octant (``|y| > |x|``: ``pi/2 - .``) and the
    half plane (sign bit of ``x``: ``pi - .``) make the result ``k pi/4 + sign t``,
    ``k`` in 0..4, added last with ``pi/4`` in two parts; then the sign of ``y``. Signed
    zeros as the library: ``atan2(+-0, +0) = +-0``, ``atan2(+-0, -0) = +-pi``. Finite
    arguments only (the kernel's infinite or NaN controls end the trial anyway).
    """
    ax = abs(x)
    ay = abs(y)
    lo = min(ax, ay)
    hi = max(ax, ay)
    mid = lo > 0.66 * hi
    num = lo - hi if mid else lo
    den = lo + hi if mid else (hi if hi > 0.0 else 1.0)
    z = num / den
    zz = z * z
    p = (((_P0 * zz + _P1) * zz + _P2) * zz + _P3) * zz + _P4
    q = ((((zz + _Q0) * zz + _Q1) * zz + _Q2) * zz + _Q3) * zz + _Q4
    t = z + z * (zz * p / q)  # atan(z), |z| <= 0.66
    k = 1.0 if mid else 0.0  # atan(lo / hi) = k pi/4 + t
    sign = 1.0
    steep = ay > ax  # atan(|y| / |x|) = pi/2 - atan(lo / hi)
    k = 2.0 - k if steep else k
    sign = -sign if steep else sign
    left = math.copysign(1.0, x) < 0.0  # atan2(|y|, x) = pi - atan(|y| / |x|)
    k = 4.0 - k if left else k
    sign = -sign if left else sign
    return math.copysign(k * _PIO4 + (k * _PIO4_LO + sign * t), y)


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def two_sum(a, b):
    """``a + b`` rounded and its rounding error, exactly (Knuth's TwoSum, no branch)."""
    total = a + b
    bb = total - a
    return total, (a - (total - bb)) + (b - bb)


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def turn_small(c, s, c_lo, s_lo, a):
    """``(cos, sin)`` of ``theta + a`` from those of ``theta``, ``|a|`` small; two parts each.

    ``cos theta = c + c_lo``, ``sin theta = s + s_lo`` (``c_lo``, ``s_lo``: what rounding
    left out, below half an ulp). Returns the same four numbers of ``theta + a``:
    ``h + (cos a - 1) h + sin a h_perp`` with the Taylor series of ``cos a - 1`` (to
    ``a^12``) and ``sin a`` (to ``a^13``), exact to rounding for ``|a| <= SMALL_TURN``
    (meaningless beyond: the caller takes the library's values there); the last sum is
    exact (:func:`two_sum`), so the rounding of each sum is carried to the next step
    instead of accumulating. What remains is the rounding of the products, about
    ``eps |a|`` per step, a random walk: measured over 100,000 steps, within 0.5 eps of
    the library's values for steps of 1e-3 rad, 2 eps for 0.02 rad, 40 eps for 0.25 rad.
    """
    a2 = a * a
    cm1 = -a2 * (
        1.0 / 2
        + a2 * (-1.0 / 24 + a2 * (1.0 / 720 + a2 * (-1.0 / 40320 + a2 * (
            1.0 / 3628800 + a2 * (-1.0 / 479001600)))))
    )  # fmt: skip
    sn = a * (
        1.0
        + a2 * (-1.0 / 6 + a2 * (1.0 / 120 + a2 * (-1.0 / 5040 + a2 * (1.0 / 362880 + a2 * (
            -1.0 / 39916800 + a2 * (1.0 / 6227020800))))))
    )  # fmt: skip
    c1, c1_lo = two_sum(c, (c * cm1 - s * sn) + c_lo)
    s1, s1_lo = two_sum(s, (s * cm1 + c * sn) + s_lo)
    return c1, s1, c1_lo, s1_lo
