"""The two layouts of a single compiled run against each other, by formation size.

A single run of at most ``formationlab.engine.layout.PAIRS_UP_TO`` robots takes the pairs
layout of batches (every pair), a larger one the lists layout (edges and a close-pair list
by robot). This prints, for triangular lattices of growing size under the distance law (or
``--law angle-restricted``), the cost per step of each layout on the compiled loop, one
thread, best of three runs of 3,000 steps in the same process, and their ratio: the ratio
crosses 1 where the choice should switch.

Run ``python benchmarks/bench_layouts.py [--law distance]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import formationlab as fl
from formationlab.engine.layout import PAIRS_UP_TO, run_layout
from formationlab.formation.graphs import delaunay_edges
from formationlab.formation.templates import lattice
from formationlab.integrators.compiled import run_compiled

SIZES = (3, 6, 12, 24, 32, 40, 48, 96, 192)


def per_step(make, q0, repeat: int = 3) -> float:
    best = float("inf")
    for _ in range(repeat):
        terms = make()
        t0 = time.perf_counter()
        out = run_compiled(terms, q0, dt=1e-3, n_steps=3000, save_every=100, parallel=False)
        best = min(best, (time.perf_counter() - t0) / max(out.steps, 1))
    return best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--law", default="distance")
    law = fl.get_law(ap.parse_args().law)
    rng = np.random.default_rng(1)
    print(f"PAIRS_UP_TO = {PAIRS_UP_TO}; law {law.name}; microseconds per step")
    print(f"{'robots':>6s} {'pairs':>9s} {'lists':>9s} {'pairs/lists':>12s}")
    for n in SIZES:
        tpl = lattice("triangular", n)
        f = fl.Formation.from_template(tpl, edges=delaunay_edges(tpl), one_based=False)
        q0 = tpl + 0.1 * rng.standard_normal(tpl.shape)
        pairs = per_step(lambda f=f: law.compiled_terms(f).writable(), q0)
        lists = per_step(lambda f=f: run_layout(law.compiled_terms(f, pairs=False)), q0)
        print(f"{n:6d} {pairs * 1e6:9.2f} {lists * 1e6:9.2f} {pairs / lists:12.2f}")


if __name__ == "__main__":
    main()
