"""What the study runner adds to the batched kernel: sampling, chunks, tables, files.

Runs the same trials of the paper's triangle (angle-restricted law, k_c = 2,
k_a = 3, theta = 0.5, simulation 2's alpha table, starts uniform in [-3, 3]^2,
10 s, dt = 1e-3) twice:

1. ``run_batch`` alone on initial states drawn beforehand;
2. ``run_study`` (drawing the states, chunking, building the trials table and
   writing every chunk to parquet in a temporary folder, as the command does);

and prints the trial-steps per second of each, the runner's overhead and the
cost of drawing initial states per trial. Also checks that both give the same
outcomes. Run ``python benchmarks/bench_study.py`` (``--trials N``, default
100000). The load average is printed: the figures mean something only when the
load is low.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

import formationlab as fl
from formationlab.io.trials import ChunkFolder
from formationlab.studies import parse_study, run_study, study_groups
from formationlab.studies.batch import run_batch
from formationlab.studies.config import BoxInitial
from formationlab.studies.runner import study_identity
from formationlab.studies.sampling import trial_initial_states

SIM2 = {(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}
DT, DURATION, SEED = 1e-3, 10.0, 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=100_000)
    parser.add_argument("--chunk-size", type=int, default=10_000)
    args = parser.parse_args()
    n = args.trials
    formation = fl.Formation.from_alpha_table(SIM2, n=3, distances=1.0, diameters=0.2)
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; {n} trials")

    run_batch(formation, law, trial_initial_states(formation, BoxInitial(), 0, range(64)),
              dt=DT, duration=DURATION)  # fmt: skip  # compile (or load the cache) first

    t0 = time.perf_counter()
    q0 = trial_initial_states(formation, BoxInitial(half_width=3.0), SEED, range(n))
    t_sample = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = run_batch(formation, law, q0, dt=DT, duration=DURATION)
    t_batch = time.perf_counter() - t0
    steps = int(res.steps.sum())

    config = parse_study({"trials": n, "chunk_size": args.chunk_size})
    with tempfile.TemporaryDirectory() as tmp:
        groups = study_groups(formation, law, config)
        ident = study_identity(groups, config, seed=SEED, dt=DT, duration=DURATION)
        store = ChunkFolder(tmp, ident)
        store.start()
        t0 = time.perf_counter()
        study = run_study(formation, law, config, seed=SEED, dt=DT, duration=DURATION, store=store)
        t_study = time.perf_counter() - t0
    same = np.array_equal(study.trials["outcome"].to_numpy(str), res.outcome.astype(str))
    print(f"drawing the initial states: {t_sample:.2f} s ({1e6 * t_sample / n:.2f} us/trial)")
    print(f"run_batch alone:  {t_batch:6.2f} s  {steps / t_batch:.3g} trial-steps/s")
    overhead = 100 * (t_study / t_batch - 1)
    print(f"run_study:        {t_study:6.2f} s  {steps / t_study:.3g} trial-steps/s")
    print(f"runner overhead:  {overhead:.0f} % (sampling, chunks, table, parquet chunk files)")
    print(f"trial-steps: {steps:,} ({steps / n:.0f} per trial); same outcomes: {same}")


if __name__ == "__main__":
    main()
