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
def minimal(q0, pi, pj, d, a, ti, tj, tk, ta, b_, c_, alpha, k_c, k_a, theta, dt, steps):
    """Explicit Euler of eq. (11) over the trials of ``q0`` ``(n, 2, B)``, chunks of 256."""
    n, _, B = q0.shape
    for c in prange((B + 255) // 256):
        lo, hi = c * 256, min(B, c * 256 + 256)
        q = q0[:, :, lo:hi].copy()
        u = np.empty_like(q)
        for _ in range(steps):
            u[:] = 0.0
            for p in range(pi.size):  # eq. (8): k_c phi'(r) / r r_ij
                i, j = pi[p], pj[p]
                for t in range(hi - lo):
                    dx, dy = q[j, 0, t] - q[i, 0, t], q[j, 1, t] - q[i, 1, t]
                    r = math.sqrt(dx * dx + dy * dy)
                    g = k_c * (1.0 / (d[p] - a[p]) - 1.0 / (r - a[p])) / r
                    u[i, 0, t] += g * dx
                    u[i, 1, t] += g * dy
                    u[j, 0, t] -= g * dx
                    u[j, 1, t] -= g * dy
            for m in range(ti.size):  # eqs. (13), (14), (23), per ordered triple
                i, j, k = ti[m], tj[m], tk[m]
                for t in range(hi - lo):
                    cab = (q[b_[m], 0, t] - q[ta[m], 0, t]) * (q[c_[m], 1, t] - q[ta[m], 1, t]) - (
                        q[b_[m], 1, t] - q[ta[m], 1, t]
                    ) * (q[c_[m], 0, t] - q[ta[m], 0, t])
                    w = k_a * alpha[m] if alpha[m] * cab + theta >= 0.0 else 0.0
                    u[i, 0, t] += w * (q[k, 1, t] - q[j, 1, t])
                    u[i, 1, t] -= w * (q[k, 0, t] - q[j, 0, t])
            for i in range(n):
                for t in range(hi - lo):
                    q[i, 0, t] += dt * u[i, 0, t]
                    q[i, 1, t] += dt * u[i, 1, t]
        q0[:, :, lo:hi] = q


def minimal_inputs(formation: fl.Formation) -> tuple:
    """Pairs (edges: complete graphs here) and ordered restricted triples of ``formation``."""
    e = formation.edges
    a = 0.5 * (formation.diameters[e[:, 0]] + formation.diameters[e[:, 1]])
    t = formation.restricted_triples
    srt = np.sort(t, axis=1)  # the sorted triangle, c_ijk = parity c_abc
    alpha = formation.restricted_alpha * fl.potentials.parity(t[:, 0], t[:, 1], t[:, 2])
    return (
        e[:, 0].astype(np.int64), e[:, 1].astype(np.int64), formation.distances.astype(float), a,
        *(t[:, m].astype(np.int64) for m in range(3)),
        *(srt[:, m].astype(np.int64) for m in range(3)), alpha.astype(float),
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
    args = minimal_inputs(formation)
    qm = np.ascontiguousarray(q0.transpose(1, 2, 0))
    minimal(qm[..., :8].copy(), *args, 2.0, 3.0, 0.5, DT, 2)  # compile or load
    run_batch(formation, law, q0[:8], dt=DT, duration=2 * DT)
    ours, ref = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = run_batch(formation, law, q0, dt=DT, duration=steps * DT, check_every=steps + 1)
        ours.append(int(res.steps.sum()) / (time.perf_counter() - t0))
        q = qm.copy()
        t0 = time.perf_counter()
        minimal(q, *args, 2.0, 3.0, 0.5, DT, steps)
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
