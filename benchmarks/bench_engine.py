"""The engine's batch loop against a minimal kernel of the same law (issue 24's targets).

Target: on the paper's triangle and on the square with both diagonals, angle-restricted
law (k_c = 2, k_a = 3, theta = 0.5), explicit Euler, early stopping off, the package's
batch loop (``studies.batch.run_batch``, which also decides contact, keeps the least
clearance and tests the stop rule at the end) steps at least as many trial-steps per second
as :func:`minimal`, a plain numba kernel of the same law written here (trials innermost, no
contact rule, no stop rule): ratio >= 1.0.

Both are timed in the same run, alternately, on the same starts; the ratio of the best of
``--repeats`` runs is printed with the machine's load. Run
``python benchmarks/bench_engine.py`` (``--quick`` for a shorter run).
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numba
import numpy as np
from numba import njit, prange

import formationlab as fl
from formationlab.studies.batch import run_batch

DT = 1e-3


@njit(cache=True, parallel=True, error_model="numpy")
def minimal(q0, pi, pj, d, a, sa, sb, sc, beta, start, ti, tj, tk, w, k_c, theta, dt, steps):
    """Explicit Euler of eq. (11) over the trials of ``q0`` ``(n, 2, B)``, chunks of 256.

    Pairs ``(pi, pj)`` with desired distance ``d`` and contact ``a``; switching surfaces
    ``beta c_abc + theta`` (one per triangle), each with its terms ``start[s]:start[s+1]``
    ``(i, j, k)`` of weight ``w = 2 k_a alpha_ijk`` (the ordered pairs ``(j, k)``, ``(k, j)``).
    """
    n, _, B = q0.shape
    for c in prange((B + 255) // 256):
        lo, hi = c * 256, min(B, c * 256 + 256)
        q = q0[:, :, lo:hi].copy()
        u = np.empty_like(q)
        on = np.empty(hi - lo)
        for _ in range(steps):
            u[:] = 0.0
            for p in range(pi.size):  # eq. (8): k_c phi'(r) / r r_ij
                i, j, inv = pi[p], pj[p], 1.0 / (d[p] - a[p])
                for t in range(hi - lo):
                    dx, dy = q[j, 0, t] - q[i, 0, t], q[j, 1, t] - q[i, 1, t]
                    r = math.sqrt(dx * dx + dy * dy)
                    g = k_c * (inv - 1.0 / (r - a[p])) / r
                    u[i, 0, t] += g * dx
                    u[i, 1, t] += g * dy
                    u[j, 0, t] -= g * dx
                    u[j, 1, t] -= g * dy
            for s in range(sa.size):  # eqs. (13), (14), (23)
                ia, ib, ic = sa[s], sb[s], sc[s]
                for t in range(hi - lo):
                    cab = (q[ib, 0, t] - q[ia, 0, t]) * (q[ic, 1, t] - q[ia, 1, t]) - (
                        q[ib, 1, t] - q[ia, 1, t]
                    ) * (q[ic, 0, t] - q[ia, 0, t])
                    on[t] = 1.0 if beta[s] * cab + theta >= 0.0 else 0.0
                for m in range(start[s], start[s + 1]):
                    i, j, k = ti[m], tj[m], tk[m]
                    for t in range(hi - lo):
                        u[i, 0, t] += w[m] * on[t] * (q[k, 1, t] - q[j, 1, t])
                        u[i, 1, t] -= w[m] * on[t] * (q[k, 0, t] - q[j, 0, t])
            for i in range(n):
                for t in range(hi - lo):
                    q[i, 0, t] += dt * u[i, 0, t]
                    q[i, 1, t] += dt * u[i, 1, t]
        q0[:, :, lo:hi] = q


def minimal_inputs(formation: fl.Formation, law: fl.AngleRestrictedLaw) -> tuple:
    """The law's pairs (complete graphs here: every pair an edge), surfaces and terms."""
    t = law.kernel_terms(formation)
    return (
        t.pair_i, t.pair_j, t.pair_distance, t.pair_contact, t.surface_a, t.surface_b,
        t.surface_c, t.surface_beta, t.term_start, t.term_i, t.term_j, t.term_k,
        t.term_weight,
    )  # fmt: skip


def starts(formation: fl.Formation, count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out = []
    while sum(len(x) for x in out) < count:
        q = rng.uniform(-3, 3, size=(count, formation.n, 2))
        r = np.linalg.norm(q[:, :, None] - q[:, None], axis=-1) + 10 * np.eye(formation.n)
        out.append(q[(r > 0.5).all(axis=(1, 2))])
    return np.concatenate(out)[:count]


def compare(name: str, formation: fl.Formation, trials: int, steps: int, repeats: int) -> float:
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    q0 = starts(formation, trials, seed=1)
    args = minimal_inputs(formation, law)
    qm = np.ascontiguousarray(q0.transpose(1, 2, 0))
    minimal(qm[..., :8].copy(), *args, 2.0, 0.5, DT, 2)  # compile or load
    run_batch(formation, law, q0[:8], dt=DT, duration=2 * DT)
    ours, ref = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = run_batch(formation, law, q0, dt=DT, duration=steps * DT, check_every=steps + 1)
        ours.append(int(res.steps.sum()) / (time.perf_counter() - t0))
        q = qm.copy()
        t0 = time.perf_counter()
        minimal(q, *args, 2.0, 0.5, DT, steps)
        ref.append(trials * steps / (time.perf_counter() - t0))
    load = "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())
    ratio = max(ours) / max(ref)
    print(
        f"{name:<28} engine {max(ours):9.3g} trial-steps/s   minimal kernel {max(ref):9.3g}   "
        f"ratio {ratio:5.2f} (target >= 1.0: {'MET' if ratio >= 1.0 else 'NOT MET'})   "
        f"[load {load}]"
    )
    return ratio


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    trials = 20_000 if args.quick else 100_000
    print(f"numba {numba.__version__}, {numba.get_num_threads()} threads; {trials} trials, "
          "1000 steps of dt = 1e-3, early stopping off")  # fmt: skip
    tri = fl.Formation.from_alpha_table(
        {(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}, n=3, distances=1.0, diameters=0.2
    )
    square = fl.Formation.from_template(
        [[0, 0], [1, 0], [1, 1], [0, 1]], edges="complete", diameters=0.2
    )
    compare("paper's triangle", tri, trials, 1000, args.repeats)
    compare("square with both diagonals", square, trials // 2, 1000, args.repeats)


if __name__ == "__main__":
    main()
