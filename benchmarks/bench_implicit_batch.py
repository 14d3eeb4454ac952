"""Cost of settling with implicit Euler: the vectorised batch correction against one by one.

Builds the trials that the study kernel leaves ``not-converged`` on the unit
square with both diagonals (angle-restricted law, k_c = 2, k_a = 3,
theta = 0.5, starts uniform in [-3, 3]^2, seed 1, dt = 1e-3, 15 s: the
k_a = 3 group of ``examples/study-square.toml``), then settles them with
``formationlab.equilibria.settle`` and ``ImplicitEuler(dt=0.01)`` for up to
5 s, stopping at the study's speed tolerance (the study's ``[study.settle]``
defaults), in three ways:

1. the whole batch at once, with the step's vectorised correction of the
   members at one or two surfaces;
2. the whole batch at once, every corrected member solved one by one in Python
   (the vectorised correction switched off: the step as it was before);
3. one trial at a time, as the study runner settles them (``settle_trials``).

Prints the cost per settled trial of each, and checks that 1 and 2 end in the
same states and outcomes. Run ``python benchmarks/bench_implicit_batch.py``
(``--trials N``, default 2000; about 180 trials are settled). The load average
is printed: the figures mean something only when the load is low.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import formationlab as fl
from formationlab.analysis import Tolerances
from formationlab.equilibria import settle
from formationlab.integrators import ImplicitEuler
from formationlab.studies.batch import run_batch
from formationlab.studies.config import BoxInitial
from formationlab.studies.sampling import trial_initial_states

SEED, DT_KERNEL, DURATION_KERNEL = 1, 1e-3, 15.0
DT, DURATION = 0.01, 5.0


class OneByOne(ImplicitEuler):
    """The step with the vectorised correction switched off (every member by ``_correct``)."""

    def _correct_batch(self, system, q, sigma0, base, q_pred, rows, involved, dt, counters):
        return np.zeros(len(rows), bool), np.full(len(rows), -1)


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
    slow = run(OneByOne(dt=DT), q)
    timings["batch, one by one (before)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    single = [run(ImplicitEuler(dt=DT), q[b : b + 1]) for b in range(len(q))]
    timings["trial by trial, vectorised"] = time.perf_counter() - t0
    for label, seconds in timings.items():
        print(f"{label:30s} {seconds:7.2f} s  {1e3 * seconds / len(q):7.2f} ms per trial")
    print(f"max |q difference| between 1 and 2: {np.max(np.abs(fast.q - slow.q)):.1e}; "
          f"same outcomes: {bool(np.all(fast.outcome == slow.outcome))}")  # fmt: skip
    agree = np.mean([s.outcome[0] == o for s, o in zip(single, fast.outcome, strict=True)])
    labels, counts = np.unique(fast.outcome, return_counts=True)
    print(f"outcomes {dict(zip(labels.tolist(), counts.tolist(), strict=True))}; "
          f"trial by trial agrees with the batch on {100 * agree:.0f} %")  # fmt: skip


if __name__ == "__main__":
    main()
