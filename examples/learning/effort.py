"""Control effort and peak speed of every law of a scenario's study, on the study's starts.

    python examples/learning/effort.py examples/learning/triangle-policy.toml --trials 100 --seed 1

The study's trials 0 .. TRIALS-1 of SEED (the starts `formationlab study --seed SEED`
draws), stepped with explicit Euler at the study's dt for its duration under each law's
own control (numpy, all trials at once: formationlab.learning.rollout). Prints, per law,
the median over the trials that did not collide of the effort int sum_i |u_i|^2 dt and of
the peak speed max_t max_i |u_i| (docs/learning.md).
"""

from __future__ import annotations

import argparse
import math
from functools import partial

import numpy as np

from formationlab.io.scenario import load_scenario
from formationlab.learning import rollout
from formationlab.studies import parse_study
from formationlab.studies.runner import StudySetup
from formationlab.studies.sampling import trial_initial_states


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario")
    parser.add_argument("--trials", type=int, default=100)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    sc = load_scenario(args.scenario)
    config = parse_study(sc.study, source=sc.source, text=sc.text, trials=args.trials)
    setup = StudySetup.from_scenario(sc, config)
    steps = math.ceil(round(setup.duration / setup.dt, 9))
    print("| law | effort (median) | peak speed (median) | collided |")
    print("| --- | ---: | ---: | ---: |")
    for g in setup.groups:
        q0 = trial_initial_states(g.formation, setup.config.initial, args.seed,
                                  np.arange(args.trials))  # fmt: skip
        field = partial(g.law.control, g.formation)
        ended = rollout(field, g.formation, q0, dt=setup.dt, steps=steps)
        ok = ~ended.collided
        print(f"| {g.law.name} | {np.median(ended.effort[ok]):.2f} | "
              f"{np.median(ended.peak_speed[ok]):.2f} | {int(ended.collided.sum())} |")  # fmt: skip


if __name__ == "__main__":
    main()
