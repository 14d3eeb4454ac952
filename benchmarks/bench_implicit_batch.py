"""Cost of settling with implicit Euler: the vectorised batch correction against one by one.

Builds the trials that the study kernel leaves ``not-converged`` on the unit
square with both diagonals (angle-restricted law, k_c = 2, k_a = 3,
theta = 0.5, starts uniform in [-3, 3]^2, seed 1, dt = 1e-3, 15 s: the
k_a = 3 group of ``examples/study-square.toml``), then settles them with
``formationlab.equilibria.settle`` and ``ImplicitEuler(dt=0.01)`` for up to
5 s, stopping at the study's speed tolerance (the study's ``[study.settle]``
defaults), in two ways:

1. the whole batch at once (one vectorised correction of the members at a
   surface per step);
2. one trial at a time (a batch of one each: the same implementation).

Prints the cost per settled trial of each, and how far the two end states are
apart (the step is the same arithmetic member by member). Run
``python benchmarks/bench_implicit_batch.py``
(``--trials N``, default 2000; about 180 trials are settled). The load average
is printed: the figures mean something only when the load is low.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import formationlab as fl
from formationlab.equilibria import settle
from formationlab.integrators import ImplicitEuler
from formationlab.outcomes.analysis import Tolerances
from formationlab.studies.batch import run_batch
from formationlab.studies.config import BoxInitial
from formationlab.studies.sampling import trial_initial_states

SEED, DT_KERNEL, DURATION_KERNEL = 1, 1e-3, 15.0
DT, DURATION = 0.01, 5.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=2000)
    args = parser.parse_args()
    square = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], diameters=0.2)
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    tol = Tolerances()
    q0 = trial_initial_states(square, BoxInitial(half_width=3.0), SEED, range(args.trials))
    res = run_batch(square, law, q0, dt=DT_KERNEL, duration=DURATION_KERNEL, tolerances=tol)
    q = res.q_final[res.outcome == "not-converged"]
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          f"{len(q)} of {args.trials} trials not converged")  # fmt: skip

    def run(integ, states):
        return settle(square, law, states, duration=DURATION, integrator=integ,
                      speed=tol.speed, tolerances=tol)  # fmt: skip

    timings = {}
    t0 = time.perf_counter()
    fast = run(ImplicitEuler(dt=DT), q)
    timings["batch, vectorised"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    single = [run(ImplicitEuler(dt=DT), q[b : b + 1]) for b in range(len(q))]
    timings["trial by trial"] = time.perf_counter() - t0
    for label, seconds in timings.items():
        print(f"{label:30s} {seconds:7.2f} s  {1e3 * seconds / len(q):7.2f} ms per trial")
    gap = max(float(np.max(np.abs(s.q_final[0] - fast.q_final[b]))) for b, s in enumerate(single))
    print(f"max |q difference| between 1 and 2: {gap:.1e}")
    agree = np.mean([s.outcome[0] == o for s, o in zip(single, fast.outcome, strict=True)])
    labels, counts = np.unique(fast.outcome, return_counts=True)
    print(f"outcomes {dict(zip(labels.tolist(), counts.tolist(), strict=True))}; "
          f"trial by trial agrees with the batch on {100 * agree:.0f} %")  # fmt: skip


if __name__ == "__main__":
    main()
