"""Speed of the batched kernel ``formationlab.studies.batch.run_batch`` (issue 5).

Targets, on 2 cores, explicit Euler in float64:

1. at least 1e8 trial-steps per second for the paper's three-robot
   angle-restricted law (k_c = 2, k_a = 3, theta = 0.5, simulation 2's alpha
   table, diameters 0.2), measured with early stopping switched off;
2. a million trials of the paper's triangle (uniform starts in [-3, 3]^2,
   overlapping draws rejected; 10 s, dt = 1e-3) in under a minute, with the
   default early stopping (check every 10 steps).

Also printed: how the cost per trial-step grows with the number of robots
(3, 4, 6, 10; complete graphs, template orientation, regular polygons of unit
side) and the memory used (peak resident set size and the arrays per trial).

Run ``python benchmarks/bench_batch.py`` (``--quick`` for a smaller run). The
machine's load average is printed with every figure: the figures mean something
only when the load is low.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import resource
import time

import numba
import numpy as np

import formationlab as fl
from formationlab.studies.batch import CHUNK, run_batch

SIM2 = {(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}
DT = 1e-3


def box_starts(formation: fl.Formation, count: int, half_width: float, seed: int) -> np.ndarray:
    """``count`` uniform draws in ``[-w, w]^2`` per robot, overlapping draws rejected."""
    rng = np.random.default_rng(seed)
    iu, ju = np.triu_indices(formation.n, k=1)
    a = formation.contact_matrix[iu, ju]
    kept: list[np.ndarray] = []
    have = 0
    while have < count:
        q = rng.uniform(-half_width, half_width, size=(count, formation.n, 2))
        ok = np.all(np.linalg.norm(q[:, ju] - q[:, iu], axis=-1) > a, axis=-1)
        kept.append(q[ok])
        have += int(ok.sum())
    return np.concatenate(kept)[:count]


def polygon(n: int) -> fl.Formation:
    """Regular n-gon of unit side, complete graph, orientation of the template (sign alpha)."""
    radius = 0.5 / math.sin(math.pi / n)
    ang = 2 * math.pi * np.arange(n) / n
    tpl = radius * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    return fl.Formation.from_template(tpl, edges="complete", diameters=0.2)


def load() -> str:
    return "load {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def timed(formation, law, q0, **kw):
    t0, c0 = time.perf_counter(), time.process_time()
    res = run_batch(formation, law, q0, **kw)
    return res, time.perf_counter() - t0, time.process_time() - c0


def throughput(formation, law, trials, steps, repeats, label):
    """Trial-steps per second with early stopping off (convergence tested at the end only)."""
    q0 = box_starts(formation, trials, 3.0, seed=1)
    rates = []
    for _ in range(repeats):
        before = load()
        res, wall, cpu = timed(
            formation, law, q0, dt=DT, duration=steps * DT, check_every=steps + 1
        )
        done = int(res.steps.sum())
        rates.append(done / wall)
        print(
            f"  {label}: {done:.3g} trial-steps in {wall:.2f} s wall ({cpu:.2f} s CPU): "
            f"{done / wall:.3g} trial-steps/s, {cpu / done * 1e9:.2f} CPU-ns per trial-step "
            f"[{before}]"
        )
    return max(rates), float(np.median(rates))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller runs (about 20 s)")
    parser.add_argument("--trials", type=int, default=None, help="trials of target 2")
    args = parser.parse_args()
    quick = args.quick
    n_million = args.trials or (100_000 if quick else 1_000_000)

    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs")
    print(f"numba {numba.__version__}, threads {numba.get_num_threads()}, numpy {np.__version__}")
    tri = fl.Formation.from_alpha_table(SIM2, n=3, distances=1.0, diameters=0.2)
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)

    t0 = time.perf_counter()
    run_batch(tri, law, box_starts(tri, 4, 3.0, seed=0), dt=DT, duration=0.01)
    print(f"first call (compile or load from numba's cache): {time.perf_counter() - t0:.2f} s")
    print(f"threading layer: {numba.threading_layer()}")

    print("\n[1] throughput, paper's triangle, angle-restricted law, early stopping off")
    best, median = throughput(
        tri, law, 50_000 if quick else 200_000, 1000, 2 if quick else 3, "N = 3"
    )
    verdict = "MET" if best >= 1e8 else "NOT MET"
    print(f"  best {best:.3g}, median {median:.3g} trial-steps/s; target 1e8: {verdict}")

    print(f"\n[2] {n_million:,} trials of the paper's triangle, 10 s, dt = 1e-3, early stopping")
    q0 = box_starts(tri, n_million, 3.0, seed=2)
    before = load()
    res, wall, cpu = timed(tri, law, q0, dt=DT, duration=10.0)
    counts = {o: int(np.sum(res.outcome == o)) for o in fl.OUTCOMES}
    print(
        f"  wall {wall:.1f} s (CPU {cpu:.1f} s) [{before}]; mean steps per trial "
        f"{res.steps.mean():.0f} of 10000; {res.steps.sum() / wall:.3g} trial-steps/s"
    )
    print(f"  outcomes: {counts}")
    scale = 1_000_000 / n_million
    verdict = "MET" if wall * scale < 60 else "NOT MET"
    print(f"  projected for 1e6 trials: {wall * scale:.1f} s; target < 60 s: {verdict}")
    arrays = (q0, res.q_final, res.u_final, res.outcome, res.max_distance_error)
    arrays += (res.converged_time, res.min_clearance, res.steps, res.net_speed)
    per_trial = sum(x.nbytes for x in arrays) / n_million
    scratch = (5 * 3 * 2 + 6) * 8 * CHUNK  # five (n, 2, chunk) buffers and six (chunk,)
    print(
        f"  arrays per trial (input and result): {per_trial:.0f} bytes, "
        f"{per_trial * n_million / 2**20:.0f} MiB in all; kernel scratch per chunk of "
        f"{CHUNK} trials: {scratch / 1024:.0f} KiB"
    )
    del res, q0

    print("\n[3] cost against the number of robots (complete graph, template orientation)")
    print("  CPU-ns per trial-step (trial-steps/s), early stopping off")
    print("  N  pairs  triples  distance law             angle-restricted law")
    for n in (3, 4, 6, 10):
        f = polygon(n)
        pairs, triples = n * (n - 1) // 2, int(f.restricted.sum())
        trials = {3: 100_000, 4: 50_000, 6: 20_000, 10: 4_000}[n] // (4 if quick else 1)
        q0 = box_starts(f, trials, 3.0, seed=n)
        cells = []
        for lw in (fl.DistanceLaw(k_c=2.0), law):
            res, wall, cpu = timed(f, lw, q0, dt=DT, duration=1.0, check_every=1001)
            done = int(res.steps.sum())
            cells.append(f"{cpu / done * 1e9:8.1f} ({done / wall:8.3g})")
        print(f"  {n:<2} {pairs:>5}  {triples:>7}  {cells[0]:<23}  {cells[1]:<23} [{load()}]")

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\n[4] peak resident set size of this process: {peak:.0f} MiB")


if __name__ == "__main__":
    main()
