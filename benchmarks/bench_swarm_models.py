"""Swarms of every robot model on the compiled loop: the cost of a step against the numpy
driver and against single integrators.

A triangular lattice of N robots (spacing 1, diameter 0.2, Delaunay edges, the distance
law), the start perturbed by 0.05 (seed 1) so that Khatib's repulsion acts; explicit Euler
with dt = 1e-3 through ``simulate`` (``backend="numba"``: the engine's loop on its lists
layout; ``backend="numpy"``: the stepping driver). The cost of a step is the difference of
a long and a short run divided by the difference of their steps (what a run costs beyond
its set-up and post-processing), best of ``--repeat``. It prints, per model, ms per step
compiled and in the numpy driver, their ratio, and the compiled cost against single
integrators' measured in the same run, and the same for single integrators with one
obstacle (a circle of radius 2 beside the lattice) and the decentralized filter (safety
distance 0.3, sensing radius 1.5: a swarm sets one, else every pair is a constraint); then
PASS/FAIL against the engine issue's targets: unicycles (heading mapping), and single
integrators with the obstacle and the filter, at least 10x faster compiled than in the
numpy driver, and unicycles within 2x of single integrators compiled.

``python benchmarks/bench_swarm_models.py [--n 10000] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import formationlab as fl
from formationlab.models import DoubleIntegrator, SingleIntegrator, Unicycle
from formationlab.safety import SafetyFilter
from formationlab.safety.obstacles import Circle

DT = 1e-3
MODELS = {
    "single integrator": SingleIntegrator(),
    "single, speed limit 0.5": SingleIntegrator(max_speed=0.5),
    "unicycle (heading)": Unicycle(mapping="heading"),
    "unicycle (near-identity)": Unicycle(mapping="near-identity"),
    "double integrator": DoubleIntegrator(),
}


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (5 min {five:.2f}) on {os.cpu_count()} cores"


def per_step(f, q0, model, backend: str, steps: tuple[int, int], repeat: int, **env) -> float:
    """Seconds per step beyond a run's fixed costs (long run minus short run); ``env``:
    obstacles and safety."""
    best = np.inf
    for _ in range(repeat):
        took = []
        for k in steps:
            began = time.perf_counter()
            res = fl.simulate(
                f, "distance", q0, model=model, duration=k * DT, save_every=k,
                backend=backend, **env,
            )  # fmt: skip
            took.append(time.perf_counter() - began)
            assert res.status == "success", res.message
        best = min(best, (took[1] - took[0]) / (steps[1] - steps[0]))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=10_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    n = args.n
    tpl = fl.lattice("triangular", n, 1.0)
    f = fl.Formation.from_template(
        tpl, edges=fl.build_edges("delaunay", tpl), diameters=0.2, one_based=False
    )
    q0 = tpl + np.random.default_rng(1).normal(0.0, 0.05, tpl.shape)
    print(f"start: {load()}; {n} robots on a triangular lattice, distance law, dt = {DT:g}")
    for model in MODELS.values():  # compiled once before anything is timed
        fl.simulate(f, "distance", q0, model=model, duration=2 * DT, backend="numba")
    print(f"{'model':>26} {'compiled':>9} {'numpy':>9} {'numpy/compiled':>15} {'/single':>8}")
    compiled: dict[str, float] = {}
    ratio: dict[str, float] = {}
    for name, model in MODELS.items():
        c = per_step(f, q0, model, "numba", (50, 550), args.repeat)
        p = per_step(f, q0, model, "numpy", (5, 25), args.repeat)
        compiled[name], ratio[name] = c, p / c
        rel = c / compiled["single integrator"]
        print(f"{name:>26} {c * 1e3:8.3f}ms {p * 1e3:8.2f}ms {p / c:14.1f}x {rel:7.2f}x")
    env = {
        "obstacles": (Circle(center=[float(tpl[:, 0].mean()), float(tpl[:, 1].min()) - 3.0],
                             radius=2.0),),
        "safety": SafetyFilter(filter="barrier-decentralized", distance=0.3, sensing_radius=1.5),
    }  # fmt: skip
    fl.simulate(f, "distance", q0, duration=2 * DT, backend="numba", **env)
    # (a run among obstacles under a filter has fixed costs of seconds at this size, which
    # vary by seconds: the steps between the two runs must cost more than that)
    c = per_step(f, q0, SingleIntegrator(), "numba", (100, 2100), 2, **env)
    p = per_step(f, q0, SingleIntegrator(), "numpy", (10, 110), 2, **env)
    rel = c / compiled["single integrator"]
    name = "single, obstacle + filter"
    print(f"{name:>26} {c * 1e3:8.3f}ms {p * 1e3:8.2f}ms {p / c:14.1f}x {rel:7.2f}x")
    safe = p / c
    uni = "unicycle (heading)"
    rel = compiled[uni] / compiled["single integrator"]
    print(f"end: {load()}")
    print(f"{'PASS' if ratio[uni] >= 10 else 'FAIL'}: unicycles compiled vs numpy driver "
          f"{ratio[uni]:.1f}x (target >= 10x)")  # fmt: skip
    print(
        f"{'PASS' if safe >= 10 else 'FAIL'}: single integrators with an obstacle and the "
        f"decentralized filter, compiled vs numpy driver {safe:.1f}x (target >= 10x)"
    )
    print(f"{'PASS' if rel <= 2 else 'FAIL'}: unicycles vs single integrators compiled "
          f"{rel:.2f}x (target <= 2x)")  # fmt: skip


if __name__ == "__main__":
    main()
