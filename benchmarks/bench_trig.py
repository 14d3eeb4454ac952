"""Can a vectorised sine and cosine equal the C library's bit for bit, and cost less?

A record of an alternative that was not taken. The batch kernel's unicycles used to call
the C library's ``sincos`` once per robot and step (a call keeps its loop from being
vectorised, and numba's vectorised transcendental functions, Intel SVML, are gone since
numba 0.62); the kernel now carries the headings from step to step without calls and
approximates ``atan2`` to about an ulp (``models/trig.py``, docs/robot-models.md),
which the kernel's agreement with the driver to rounding tolerates. Before that, exact
equality with the library was the aim; this script measures the best exact alternative
found:

* a branch-free sine and cosine that the compiler vectorises: Cody-Waite reduction by
  pi/2 (two 33-bit parts and a third, exact products), a table of sin and cos of
  ``j / 128`` in double-double, short Taylor series of the remainder (``|t| <= 1/256``)
  and the sums in double-double (the products' errors by ``fma``), so that ``hi + lo``
  is the exact value to about 2^-60 relative;
* a certificate: where ``|lo| < 0.446 ulp(hi)`` (``hi + 1.12 lo == hi``), any result
  within 0.548 ulp of the exact value is ``hi``; glibc documents at most 0.548 ulp for
  ``sin`` and ``cos`` (``sysdeps/ieee754/dbl-64/s_sin.c``), so the library returns ``hi``
  there. The other arguments (about one in five: the two values' uncertain bands, near
  multiples of pi/2, huge or tiny arguments) call the library.

Printed: mismatches against ``math.cos`` and ``math.sin`` among the certified values (0
means bit for bit), the fraction certified, and the cost per value of the vectorised part,
of the whole (vectorised part and the library calls of the rest) and of the library's
``sincos`` in the same run, one thread, best of the rounds, with the load. The result
decides whether the kernel should use it: only if "whole" is well below the library's.

Run ``python benchmarks/bench_trig.py`` (``--values N`` per range for the check).
"""

from __future__ import annotations

import argparse
import math
import os
import time
from decimal import Decimal, getcontext

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

getcontext().prec = 60
EPS = Decimal(10) ** -58


def _atan_inv(x: int) -> Decimal:
    total, term, n, sign = Decimal(0), 1 / Decimal(x), 1, 1
    while term / n > EPS:
        total += sign * term / n
        term, n, sign = term / (x * x), n + 2, -sign
    return total


PI = 16 * _atan_inv(5) - 4 * _atan_inv(239)  # Machin


def _sin_cos(x: Decimal) -> tuple[Decimal, Decimal]:
    s, c, term, n = Decimal(0), Decimal(0), Decimal(1), 0
    while n < 3 or abs(term) > EPS:
        if n % 2 == 0:
            c += term if n % 4 == 0 else -term
        else:
            s += term if n % 4 == 1 else -term
        n += 1
        term = term * x / n
    return s, c


def _two(d: Decimal) -> tuple[float, float]:
    hi = float(d)
    return hi, float(d - Decimal(hi))


def _bits(d: Decimal, nbits: int) -> float:
    """``d`` rounded to ``nbits`` significant bits (so that small multiples are exact)."""
    scale = Decimal(2) ** (nbits - math.frexp(float(d))[1])
    return float((d * scale).to_integral_value() / scale)


HALF_PI = PI / 2
P1 = _bits(HALF_PI, 33)
P2 = _bits(HALF_PI - Decimal(P1), 33)
P3 = float(HALF_PI - Decimal(P1) - Decimal(P2))
TWO_OVER_PI = float(2 / PI)
N = 128  # table points per radian
JMAX = 103  # |j| <= 0.786 N
TABLE = np.array([[*_two(s), *_two(c)] for s, c in
                  (_sin_cos(Decimal(j) / N) for j in range(-JMAX, JMAX + 1))])  # fmt: skip
KAPPA = 1.12  # hi + KAPPA lo == hi  <=>  |lo| < 0.446 ulp(hi)


@intrinsic
def fma(typingctx, a, b, c):
    """``a b + c`` rounded once (``llvm.fma``)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=False, fastmath=False, error_model="numpy")
def certified(theta, cos_out, sin_out, ok):
    """Vectorised cos and sin of ``theta``; ``ok[b] = 1`` where they are the library's."""
    tab = TABLE  # a global constant: its loads alias no store, so the loop is vectorised
    for b in range(theta.shape[0]):
        x = theta[b]
        k = np.floor(x * TWO_OVER_PI + 0.5)
        a = x - k * P1  # exact
        kb = k * P2  # exact
        s0 = a - kb  # two_sum: s0 + e0 = a - kb
        z = s0 - a
        e0 = (a - (s0 - z)) + (-kb - z)
        lo = e0 - k * P3
        rh = s0 + lo  # r = rh + rl = x - k pi / 2
        rl = lo - (rh - s0)
        jf = np.floor(rh * N + 0.5)
        t = rh - jf * (1.0 / N)  # exact
        row = int(jf) + JMAX
        sh, sl, ch, cl = tab[row, 0], tab[row, 1], tab[row, 2], tab[row, 3]
        t2 = t * t
        st = rl + t * t2 * (-1.0 / 6.0 + t2 * (1.0 / 120.0))  # sin(t + rl) - t
        cm = t2 * (-0.5 + t2 * (1.0 / 24.0 - t2 * (1.0 / 720.0))) - t * rl  # cos(t + rl) - 1
        ph = ch * t  # sin(r) = sh + ch t + (sl + cl t + sh cm + ch st)
        pl = fma(ch, t, -ph)
        u = sh + ph
        z = u - sh
        lo_s = (((sh - (u - z)) + (ph - z)) + pl) + (sl + cl * t + sh * cm + ch * st)
        sr = u + lo_s
        sr_lo = lo_s - (sr - u)
        qh = sh * t  # cos(r) = ch - sh t + (cl - sl t + ch cm - sh st)
        ql = fma(sh, t, -qh)
        v = ch - qh
        z = v - ch
        lo_c = (((ch - (v - z)) + (-qh - z)) - ql) + (cl - sl * t + ch * cm - sh * st)
        cr = v + lo_c
        cr_lo = lo_c - (cr - v)
        # quadrant q: (sin, cos) = (s, c), (c, -s), (-s, -c), (-c, s) of r
        q = k - 4.0 * np.floor(k * 0.25)
        odd = (q == 1.0) | (q == 3.0)
        sv, sv_lo = (cr, cr_lo) if odd else (sr, sr_lo)
        cv, cv_lo = (sr, sr_lo) if odd else (cr, cr_lo)
        sin_out[b] = -sv if q >= 2.0 else sv
        cos_out[b] = -cv if (q == 1.0) | (q == 2.0) else cv
        good = (abs(rh) >= 2.0**-30) & (abs(x) <= 2.0**20)
        good = good & (sv + sv_lo * KAPPA == sv) & (cv + cv_lo * KAPPA == cv)
        ok[b] = 1.0 if good else 0.0


@njit(cache=False, fastmath=False, error_model="numpy")
def library_rest(theta, cos_out, sin_out, ok, rest, args):
    """The library's values where ``certified`` could not decide.

    Those arguments are gathered first, then the library called on them in a plain loop
    (with the calls under a condition the compiler may call for every argument and select,
    the calls having no side effects) and the values scattered back.
    """
    m = 0
    for b in range(theta.shape[0]):
        rest[m] = b
        args[m] = theta[b]
        m += ok[b] == 0.0
    for r in range(m):
        x = args[r]
        cos_out[rest[r]] = math.cos(x)
        sin_out[rest[r]] = math.sin(x)


@njit(cache=False, fastmath=False, error_model="numpy")
def library(theta, cos_out, sin_out):
    for b in range(theta.shape[0]):
        cos_out[b] = math.cos(theta[b])
        sin_out[b] = math.sin(theta[b])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--values", type=int, default=2_000_000, help="per range, for the check")
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()}")
    rng = np.random.default_rng(0)
    print("check against math.cos and math.sin (and the numpy driver's np.cos, np.sin):")
    for half in (0.8, math.pi, 50.0, 1e5):
        x = rng.uniform(-half, half, args.values)
        c, s, ok = np.empty_like(x), np.empty_like(x), np.empty_like(x)
        certified(x, c, s, ok)
        good = ok == 1.0
        lib_c = np.array([math.cos(v) for v in x])
        lib_s = np.array([math.sin(v) for v in x])
        bad = int(np.sum(good & ((c != lib_c) | (s != lib_s))))
        same = np.mean((np.cos(x) == lib_c) & (np.sin(x) == lib_s))
        print(f"  |theta| <= {half:<9g} certified {good.mean():6.1%}, mismatches among them "
              f"{bad}; numpy equals math on {same:.1%}")  # fmt: skip
    y, x = rng.standard_normal((2, args.values))
    lib_a = np.array([math.atan2(b, a) for b, a in zip(y, x, strict=True)])
    print(f"  np.arctan2 equals math.atan2 on {np.mean(np.arctan2(y, x) == lib_a):.1%} of "
          f"{args.values} normal pairs")  # fmt: skip
    theta = rng.uniform(-math.pi, math.pi, 768)  # a chunk of headings
    c, s, ok = np.empty_like(theta), np.empty_like(theta), np.empty_like(theta)
    rest, args_rest = np.empty(theta.size, dtype=np.int64), np.empty(theta.size)
    certified(theta, c, s, ok)
    runs = {
        "vectorised part": lambda: certified(theta, c, s, ok),
        "library for the rest (per value of the chunk)": lambda: library_rest(
            theta, c, s, ok, rest, args_rest
        ),
        "library sincos": lambda: library(theta, c, s),
    }
    reps = 500
    best = dict.fromkeys(runs, np.inf)
    for run in runs.values():
        run()
    for _ in range(args.rounds):
        for name, run in runs.items():
            start = time.perf_counter()
            for _ in range(reps):
                run()
            best[name] = min(best[name], (time.perf_counter() - start) / (reps * theta.size))
    print(f"cost per value, |theta| <= pi, one thread, best of {args.rounds}:")
    for name, cost in best.items():
        print(f"  {name:46s} {cost * 1e9:6.1f} ns")
    whole = best["vectorised part"] + best["library for the rest (per value of the chunk)"]
    print(f"  {'whole (the two first)':46s} {whole * 1e9:6.1f} ns, "
          f"{whole / best['library sincos']:.2f}x the library's")  # fmt: skip
    print(f"load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
