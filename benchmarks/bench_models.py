"""Cost per trial-step of each robot model in the compiled kernel, against single integrators.

Target (issue 12): the unicycle (either transform) and the double integrator at most
2x the single integrator's cost per trial-step in the kernel. Measured on the paper's
triangle (simulation 2's alpha table, k_c = 2, k_a = 3, theta = 0.5) and the square
with both diagonals, explicit Euler dt = 1e-3, early stopping switched off (every trial
runs every step), box starts in [-3, 3]^2 (unicycles: headings uniform on the circle),
the same starts for every model. The compiled loop (``engine.trials.run_trials``, as ``run_batch``
calls it) runs on one thread and is timed in CPU time of the process
(``time.process_time``), so that a cost is CPU time per trial-step and waiting for a
shared core is not counted; the rounds interleave the models, each figure is the best of
the rounds, and the reference (single integrators) is measured in the same rounds.
"met" / "NOT met" is each model's ratio against the target.

A unicycle's step calls no library function in its loops over trials (its headings are
carried from step to step and the heading transform's ``atan2`` is a rational
approximation, :mod:`formationlab.models.trig`); what it costs beyond a single
integrator is the third state column, the hand points or the angle, and the limits.

Run ``python benchmarks/bench_models.py`` (``--quick`` for a smaller run, ``--rounds N``).
The load average is printed: on a shared machine absolute figures drift with it, the
ratios less so.
"""

from __future__ import annotations

import argparse
import os
import time

import numba
import numpy as np

import formationlab as fl
from formationlab.engine.trials import run_trials
from formationlab.models import DoubleIntegrator, SingleIntegrator, Unicycle
from formationlab.outcomes.analysis import Tolerances
from formationlab.studies.config import BoxInitial
from formationlab.studies.sampling import model_initial_states, trial_initial_states

MODELS = {
    "single-integrator": SingleIntegrator(),
    "unicycle near-identity": Unicycle(mapping="near-identity"),
    "unicycle heading": Unicycle(mapping="heading"),
    "double-integrator": DoubleIntegrator(),
    "unicycle near-identity, limits": Unicycle(max_speed=0.5, max_turn_rate=3.0),
    "unicycle heading, limits": Unicycle(mapping="heading", max_speed=0.5, max_turn_rate=3.0),
    "double-integrator, limit": DoubleIntegrator(max_speed=0.5),
}
TARGET = 2.0
CHUNK = 256  # trials per chunk, as run_batch chooses for a few thousand trials
DT = 1e-3


def kernel_cost(formation, law, model, x0, steps) -> float:
    """Seconds per trial-step of one run of ``x0`` on the compiled loop (no trial stops early)."""
    start = time.process_time()
    run = run_trials(
        formation,
        law,
        model,
        x0,
        dt=DT,
        n_steps=steps,
        check_every=10,
        tol=Tolerances(speed=1e-300),
        chunk=CHUNK,
    )  # speed 1e-300: no trial counts as stopped, every trial runs every step
    cpu = time.process_time() - start
    return cpu / max(int(run.steps.sum()), 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1024 trials x 300 steps")
    parser.add_argument("--rounds", type=int, default=5, help="best of this many rounds")
    args = parser.parse_args()
    trials, steps = (1024, 300) if args.quick else (4096, 1000)
    numba.set_num_threads(1)
    triangle = fl.Formation.from_alpha_table(
        [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]], n=3, distances=1.0, diameters=0.2
    )
    square = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], diameters=0.2)
    print(f"load average {os.getloadavg()}; {trials} trials x {steps} steps, one thread, "
          f"best of {args.rounds} rounds")  # fmt: skip
    worst: dict[str, float] = {}
    for shape, f in (("triangle", triangle), ("square", square)):
        q0 = trial_initial_states(f, BoxInitial(half_width=3.0), 1, np.arange(trials))
        for law in (fl.DistanceLaw(), fl.AngleRestrictedLaw()):
            starts = {
                name: np.ascontiguousarray(model_initial_states(f, m, q0, 1, np.arange(trials)))
                for name, m in MODELS.items()
            }
            for name, m in MODELS.items():  # compile
                kernel_cost(f, law, m, starts[name][:64], 2)
            best = dict.fromkeys(MODELS, np.inf)
            for _ in range(args.rounds):
                for name, m in MODELS.items():
                    best[name] = min(best[name], kernel_cost(f, law, m, starts[name], steps))
            ref = best["single-integrator"]
            print(f"\n{shape}, {law.name} law: single integrator {ref * 1e9:.1f} ns/trial-step")
            print(f"  {'model':31s} {'ns/trial-step':>13s} {'ratio':>6s}  target <= {TARGET:g}x")
            for name in MODELS:
                ratio = best[name] / ref
                verdict = ""
                if name != "single-integrator":
                    verdict = "met" if ratio <= TARGET else "NOT met"
                    worst[name] = max(worst.get(name, 0.0), ratio)
                print(f"  {name:31s} {best[name] * 1e9:13.1f} {ratio:5.2f}x  {verdict}")
    print("\nworst ratio over the formations and laws:")
    for name, ratio in worst.items():
        print(f"  {name:32s} {ratio:5.2f}x  {'met' if ratio <= TARGET else 'NOT met'}")
    print(f"load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
