"""Cost per trial-step of each robot model in the compiled kernel, against single integrators.

Target (issue 12): the unicycle (either transform) and the double integrator at most
2x the single integrator's cost per trial-step in the kernel. Measured on the paper's
triangle (simulation 2's alpha table, k_c = 2, k_a = 3, theta = 0.5) and the square
with both diagonals, explicit Euler dt = 1e-3, early stopping switched off (every trial
runs every step), box starts in [-3, 3]^2, the same starts for every model; the
reference (single integrators) is measured in the same run, interleaved.

Run ``python benchmarks/bench_models.py`` (``--quick`` for a smaller run). The load
average is printed: the figures mean something only when the load is low.

Measured (``--quick``, 2 shared cores at load 3-4.5, best of three runs per row):

=========================  ===========================  ============================
model                      cos/sin twice per step       cos/sin once per step
=========================  ===========================  ============================
unicycle, near-identity    3.2-4.0x                     2.1-2.4x
unicycle, heading          3.5-4.5x                     3.0-3.5x
double integrator          0.9-1.1x                     0.8-1.1x
=========================  ===========================  ============================

The target is met by the double integrator, not by the unicycles. What remains is the
C library: one ``sincos`` per robot and step (about 11 ns on one thread here) and, for
the heading transform, one ``atan2`` (about 13 ns), against about 9 ns for the single
integrator's whole step per robot (triangle or square); neither call is vectorised.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import formationlab as fl
from formationlab.analysis import Tolerances
from formationlab.models import DoubleIntegrator, SingleIntegrator, Unicycle
from formationlab.studies.batch import run_batch
from formationlab.studies.config import BoxInitial
from formationlab.studies.sampling import model_initial_states, trial_initial_states

MODELS = {
    "single-integrator": SingleIntegrator(),
    "unicycle near-identity": Unicycle(mapping="near-identity"),
    "unicycle heading": Unicycle(mapping="heading"),
    "double-integrator": DoubleIntegrator(),
    "unicycle near-identity, limits": Unicycle(max_speed=0.5, max_turn_rate=3.0),
    "double-integrator, limit": DoubleIntegrator(max_speed=0.5),
}
NEVER = Tolerances(speed=1e-300)  # no trial counts as stopped: every trial runs every step


def cost(formation, law, model, q0, steps, repeats):
    x0 = model_initial_states(formation, model, q0, 1, np.arange(len(q0)))
    run_batch(formation, law, x0[:64], dt=1e-3, duration=0.01, tolerances=NEVER, model=model)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        res = run_batch(
            formation, law, x0, dt=1e-3, duration=steps * 1e-3, tolerances=NEVER, model=model
        )
        wall = time.perf_counter() - start
        best = min(best, wall / max(int(res.steps.sum()), 1))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    trials, steps, repeats = (2048, 500, 3) if args.quick else (8192, 2000, 5)
    triangle = fl.Formation.from_alpha_table(
        [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]], n=3, distances=1.0, diameters=0.2
    )
    square = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], diameters=0.2)
    print(f"load average {os.getloadavg()}; {trials} trials x {steps} steps, best of {repeats}")
    worst = 0.0
    for shape, f in (("triangle", triangle), ("square", square)):
        q0 = trial_initial_states(f, BoxInitial(half_width=3.0), 1, np.arange(trials))
        for law in (fl.DistanceLaw(), fl.AngleRestrictedLaw()):
            ref = cost(f, law, MODELS["single-integrator"], q0, steps, repeats)
            print(f"\n{shape}, {law.name} law: single integrator {ref * 1e9:.2f} ns/trial-step")
            for name, model in MODELS.items():
                c = cost(f, law, model, q0, steps, repeats)
                ratio = c / ref
                if name in ("unicycle near-identity", "unicycle heading", "double-integrator"):
                    worst = max(worst, ratio)
                print(f"  {name:32s} {c * 1e9:7.2f} ns/trial-step  {ratio:5.2f}x")
    verdict = "met" if worst <= 2.0 else "NOT met"
    print(f"\nworst of unicycle / double integrator: {worst:.2f}x (target <= 2x: {verdict})")
    print(f"load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
