"""Cost of an explicit-Euler step against the number of robots: the compiled single-run path.

A triangular lattice of N robots (spacing 1, diameter 0.2), Delaunay edges with their
template distances, a start perturbed by 0.05 (seed 1) so that Khatib's repulsion and the
switching surfaces are active; ``formationlab.simulate`` with ``Euler(dt=1e-3)`` for a few
steps on the compiled path (``integrators/compiled.py``), for the distance law and the
angle-restricted law (orientation from the lattice, collinear triples skipped). Prints ms
per step, ns per robot-step (flat when the cost grows linearly in N), the memory per robot
of the run's own arrays, and the 3-robot step against the numpy driver measured in the same
run. Run ``python benchmarks/bench_swarm.py [--max 100000]``; the load average is printed.
"""

from __future__ import annotations

import argparse
import os
import time
import tracemalloc

import numpy as np
from scipy.spatial import Delaunay

import formationlab as fl
from formationlab.paper import PAPER_Q0, paper_formation, paper_law


def lattice(count: int) -> np.ndarray:
    """``count`` points of a triangular lattice of spacing 1, row by row (a brick of rows)."""
    side = int(np.ceil(np.sqrt(count)))
    j, i = np.divmod(np.arange(count), side)
    return np.stack([i + 0.5 * (j % 2), j * np.sqrt(3) / 2], axis=-1).astype(float)


def delaunay_edges(points: np.ndarray) -> np.ndarray:
    """Delaunay edges of the lattice, without the long edges of boundary slivers."""
    tri = Delaunay(points).simplices
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    length = np.linalg.norm(points[e[:, 1]] - points[e[:, 0]], axis=1)
    return e[length < 1.5]


def per_step(formation, law, q0, steps: int, backend: str) -> tuple[float, float, str]:
    """Seconds per step inside the time loop, per step of the whole call, and the status."""
    t0 = time.perf_counter()
    res = fl.simulate(formation, law, q0, duration=steps * 1e-3, save_every=steps, backend=backend)
    whole = (time.perf_counter() - t0) / steps
    return res.stats.get("step_cost_s", whole), whole, str(res.status)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max", type=int, default=100_000)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    f3, law3 = paper_formation(2), paper_law()
    per_step(f3, law3, PAPER_Q0, 100, "numba")  # compile once
    fast = per_step(f3, law3, PAPER_Q0, 20000, "numba")[1]
    slow = per_step(f3, law3, PAPER_Q0, 2000, "numpy")[1]
    print(f"3 robots: {fast * 1e6:.2f} us per step compiled, {slow * 1e6:.1f} us numpy "
          f"({slow / fast:.0f}x); target <= 5 us")  # fmt: skip
    rng = np.random.default_rng(1)
    sizes = [n for n in (100, 1_000, 10_000, 100_000) if n <= args.max]
    print(f"{'N':>7} {'law':>17} {'ms/step':>9} {'ns/robot-step':>14} {'with setup':>11} "
          f"{'KB/robot':>9}  status")  # fmt: skip
    for n in sizes:
        tpl = lattice(n)
        edges = delaunay_edges(tpl)
        q0 = tpl + rng.normal(0.0, 0.05, tpl.shape)
        for name in ("distance", "angle-restricted"):
            orient = "template" if name == "angle-restricted" else "free"
            f = fl.Formation.from_template(
                tpl, edges=edges, diameters=0.2, orientation=orient, one_based=False
            )
            law = fl.get_law(name)
            steps = max(5, min(200, 2_000_000 // n))
            per_step(f, law, q0, 2, "numba")
            tracemalloc.start()
            t, whole, status = per_step(f, law, q0, steps, "numba")
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
            print(f"{n:>7} {name:>17} {t * 1e3:9.3f} {t / n * 1e9:14.1f} {whole * 1e3:9.2f}ms "
                  f"{peak / n / 1e3:9.2f}  {status}")  # fmt: skip
    print("targets at 1e5: distance <= 5 ms/step, angle-restricted <= 3x that, <= 1 KB/robot "
          "(ms/step: inside the compiled loop; 'with setup': the whole simulate call per step, "
          "building the kernel data and the post-processing included)")  # fmt: skip


if __name__ == "__main__":
    main()
