"""Cost per robot-step of a swarm in space against one in the plane, on the compiled loop.

A face-centred cubic patch of N robots in space (``lattice("fcc", N)``, spacing 1) against
a triangular patch of N robots in the plane (``lattice("triangular", N)``), both with
Delaunay edges (in space the tetrahedralisation without its slivers) at their template
distances, diameter 0.2, a start perturbed by 0.05 per coordinate (seed 1), the distance
law (eq. 8, with Khatib's repulsion between close non-neighbours), single integrators,
explicit Euler (dt = 1e-3) on the compiled single run (``integrators/compiled.py``, the
lists layout: the loop ``engine/loop.py`` compiled once for each dimension). The two are
measured in the same run, one after the other, each on one thread and on numba's threads;
it prints ms per step, ns per robot-step and ns per edge-step of each (the whole step's time
over the edges), the ratio space / plane of the faster of each, and PASS/FAIL against the
target of the issue (at most 2x).

In space a robot has about twice the edges of the plane (an fcc point has 12 neighbours
and about 14 Delaunay edges against 6: 6.9 edges per robot against 3.0), and each edge
three coordinates instead of two: the ratio measures how much of that the loop absorbs.
The per-edge figure says where the rest lies: at the same cost per edge-step, the edges
alone make space 2.3 times the plane per robot-step.

``python benchmarks/bench_swarm_space.py [--n 100000] [--steps 200]``; the load average is
printed at the start and the end (the machine may be shared: wall times grow with the
load, CPU times much less).
"""

from __future__ import annotations

import argparse
import os
import time

import numba
import numpy as np

import formationlab as fl
from formationlab.dynamics import System
from formationlab.integrators.compiled import compiled_terms, run_compiled

DT = 1e-3
TARGET = 2.0


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (5 min {five:.2f}) on {os.cpu_count()} cores"


def swarm(kind: str, n: int) -> tuple[fl.Formation, np.ndarray]:
    """The lattice patch ``kind`` of ``n`` robots, its Delaunay graph and the start."""
    tpl = fl.lattice(kind, n, 1.0)
    edges = fl.build_edges("delaunay", tpl)
    f = fl.Formation.from_template(tpl, edges=edges, diameters=0.2, one_based=False)
    q0 = tpl + np.random.default_rng(1).normal(0.0, 0.05, tpl.shape)
    return f, q0


def per_step(layout, q0, steps: int, parallel: bool) -> tuple[float, float, str]:
    """Wall and CPU seconds per step inside the compiled loop (after a warm-up run)."""
    run_compiled(layout, q0, dt=DT, n_steps=2, save_every=2, parallel=parallel)
    c0 = time.process_time()
    out = run_compiled(layout, q0, dt=DT, n_steps=steps, save_every=steps, parallel=parallel)
    return out.wall / steps, (time.process_time() - c0) / steps, str(out.status)


def measure(kind: str, n: int, steps: int) -> tuple[float, float]:
    """Print one swarm's costs; returns its best ns per robot-step and per edge-step."""
    t0 = time.perf_counter()
    f, q0 = swarm(kind, n)
    built = time.perf_counter() - t0
    layout = compiled_terms(System(formation=f, law=fl.get_law("distance")), fl.Euler(dt=DT))
    assert layout is not None, "the compiled loop should take this swarm"
    best = np.inf
    rows = []
    for parallel in (False, True):
        if parallel and numba.get_num_threads() < 2:
            continue
        wall, cpu, status = per_step(layout, q0, steps, parallel)
        best = min(best, wall)
        threads = numba.get_num_threads() if parallel else 1
        rows.append(f"{threads} thr {1e3 * wall:7.3f} ms (cpu {1e3 * cpu:7.3f}), {status}")
    ns = 1e9 * best / n
    per_edge = 1e9 * best / len(f.edges)
    print(
        f"{kind:>10} {f.dim}-D  N = {n:>7}  edges {len(f.edges):>7} ({len(f.edges) / n:4.1f} "
        f"per robot)  built in {built:5.1f} s  |  " + "  |  ".join(rows) + f"  |  {ns:6.1f} ns "
        f"per robot-step, {per_edge:5.2f} ns per edge-step (best)"
    )
    return ns, per_edge


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100_000)
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args()
    print(f"start: {load()}; numba threads {numba.get_num_threads()}; {args.steps} steps")
    plane, plane_edge = measure("triangular", args.n, args.steps)
    space, space_edge = measure("fcc", args.n, args.steps)
    ratio = space / plane
    print(f"end: {load()}")
    verdict = "PASS" if ratio <= TARGET else "FAIL"
    print(
        f"  {verdict} {args.n} robots in space: {space:.1f} ns per robot-step against "
        f"{plane:.1f} in the plane, {ratio:.2f}x (target <= {TARGET:g}x)"
    )
    print(
        f"  per edge-step: {space_edge:.2f} ns in space against {plane_edge:.2f} in the plane, "
        f"{space_edge / plane_edge:.2f}x (the rest of the ratio is the edges per robot)"
    )


if __name__ == "__main__":
    main()
