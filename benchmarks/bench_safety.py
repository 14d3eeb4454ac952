"""Cost per step of each safety filter against the law's own step, for 10 to 1,000 robots.

Usage::

    python benchmarks/bench_safety.py            # N = 10, 100, 1000
    python benchmarks/bench_safety.py --quick    # fewer repeats

Setup: a triangular lattice of N points (spacing 1), each point moved uniformly by up
to 0.15 in x and y (seeded); the formation's graph is the Delaunay triangulation of the
unperturbed lattice (``scipy.spatial.Delaunay``), desired distances the unperturbed
edge lengths, diameters 0.2. The law is the paper's distance law (eq. 8,
``DistanceLaw.control``, gains k_c = 2), which today evaluates every pair densely
(``n x n`` arrays). Filters: D_s = 0.6, gamma = 100 (the default), sensing radius 2.

Two commands are filtered:

* ``law``: the law's own command at the perturbed lattice (few constraints bind);
* ``squeeze``: the law's command plus a contraction ``-2 (q_i - mean q)``, which drives
  neighbours together so that many constraints bind (the stress case).

Each cost is the median over repeats of one call, measured in the same run as the
law's step. ``step ms`` is what the closed loop pays per step, ``SafetyFilter.command``
(the filtered command alone); ``apply ms`` is ``SafetyFilter.apply`` with statuses and
the active set. ``/law`` = step / law, ``/edge`` = step / edge; ``changed`` counts robots
whose command the filter changed. The ``g=1`` rows use gamma = 1, under which most
constraints bind (the stress case for the solvers); ``+speed`` adds max_speed = 1
(octagon).

Beyond 64 robots ``DistanceLaw.control`` sums over the edges and the close non-edges (a
k-d tree query). ``edge ms`` is the sparse reference measured beside it: the same eq.
(8) on the edge list only (no repulsion between non-neighbours, no pair search);
``/edge`` is the filter's step over that.

Target (issue 15): the decentralized filter adds at most 2x the law's step at 1,000
robots. The last lines say PASS or FAIL against the edge-list law (the stricter of the
two references) for the filter as configured by default (gamma = 100, no speed limit),
worst over its two commands, and the worst of the stress rows (speed limit, gamma = 1).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import numpy as np
from scipy.spatial import Delaunay

from formationlab.controllers import DistanceLaw
from formationlab.controllers.potentials import dphi_dr
from formationlab.formation.spec import Formation
from formationlab.safety import SafetyFilter, sensed_pairs


def lattice(n: int, rng: np.random.Generator) -> tuple[Formation, np.ndarray]:
    """A perturbed triangular lattice of ``n`` robots and its Delaunay formation."""
    cols = int(np.ceil(np.sqrt(n)))
    i = np.arange(n)
    row, col = i // cols, i % cols
    base = np.column_stack([col + 0.5 * (row % 2), row * np.sqrt(3) / 2])
    tri = Delaunay(base)
    edges = np.unique(
        np.sort(
            np.concatenate([tri.simplices[:, [0, 1]], tri.simplices[:, [1, 2]],
                            tri.simplices[:, [0, 2]]]), axis=1),
        axis=0,
    )  # fmt: skip
    length = np.linalg.norm(base[edges[:, 1]] - base[edges[:, 0]], axis=1)
    keep = length < 1.5  # drop the long hull edges of the triangulation
    formation = Formation(diameters=np.full(n, 0.2), edges=edges[keep], distances=length[keep])
    return formation, base + rng.uniform(-0.15, 0.15, base.shape)


def edge_law(formation: Formation, q: np.ndarray, k_c: float = 2.0) -> np.ndarray:
    """Eq. (8) summed over the edges only: ``u_i = k_c sum_j phi'(r_ij) r_ij / r_ij``; (n, 2)."""
    e = formation.edges
    r = q[e[:, 1]] - q[e[:, 0]]
    dist = np.sqrt(np.einsum("mk,mk->m", r, r))
    a = 0.5 * (formation.diameters[e[:, 0]] + formation.diameters[e[:, 1]])
    slope = dphi_dr(dist, formation.distances, a)  # eq. (7)
    f = (k_c * slope / dist)[:, None] * r
    u = np.zeros_like(q)
    np.add.at(u, e[:, 0], f)
    np.add.at(u, e[:, 1], -f)
    return u


def median_time(fn: Callable[[], object], repeats: int) -> float:
    fn()  # warm-up (numba compilation, caches)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    parser.add_argument("--sizes", type=int, nargs="*", default=[10, 100, 1000])
    args = parser.parse_args()
    rng = np.random.default_rng(2026)
    law = DistanceLaw()
    filters = {
        "decentralized": SafetyFilter(
            filter="barrier-decentralized", distance=0.6, gamma=100.0, sensing_radius=2.0
        ),
        "decentral.+speed": SafetyFilter(
            filter="barrier-decentralized", distance=0.6, gamma=100.0, sensing_radius=2.0,
            max_speed=1.0,
        ),
        "centralized": SafetyFilter(
            filter="barrier", distance=0.6, gamma=100.0, sensing_radius=2.0
        ),
        "decentral. g=1": SafetyFilter(
            filter="barrier-decentralized", distance=0.6, gamma=1.0, sensing_radius=2.0
        ),
        "centralized g=1": SafetyFilter(
            filter="barrier", distance=0.6, gamma=1.0, sensing_radius=2.0
        ),
    }  # fmt: skip
    print(f"load average (1, 5, 15 min) at start: {os.getloadavg()}")
    head = f"{'N':>5} {'pairs':>6} {'law ms':>8} {'edge ms':>8}  {'filter':<17} {'command':<8}"
    print(head + f" {'step ms':>9} {'/law':>7} {'/edge':>7} {'apply ms':>9} {'changed':>8}")
    verdict = []
    for n in args.sizes:
        formation, q = lattice(n, rng)
        pairs = len(sensed_pairs(q, 2.0))
        reps = 3 if args.quick else (50 if n <= 100 else 15)
        t_law = median_time(lambda: law.control(formation, q), reps)  # noqa: B023
        u_law = law.control(formation, q)
        t_edge = median_time(lambda: edge_law(formation, q), reps)  # noqa: B023
        if n <= 100:  # the sparse reference is the same law where no non-neighbour is near
            assert np.allclose(edge_law(formation, q), u_law)
        commands = {"law": u_law, "squeeze": u_law - 2.0 * (q - q.mean(axis=0))}
        for name, cfg in filters.items():
            for cname, u_hat in commands.items():
                reps_f = 3 if name.startswith("centralized") and n >= 1000 else reps
                t_c = median_time(lambda: cfg.command(q, u_hat), reps_f)  # noqa: B023
                t_a = median_time(lambda: cfg.apply(q, u_hat), reps_f)  # noqa: B023
                res = cfg.apply(q, u_hat)
                changed = int(np.count_nonzero(np.any(res.u != u_hat, axis=-1)))
                print(
                    f"{n:>5} {pairs:>6} {1e3 * t_law:>8.3f} {1e3 * t_edge:>8.3f}  {name:<17}"
                    f" {cname:<8} {1e3 * t_c:>9.3f} {t_c / t_law:>7.2f} {t_c / t_edge:>7.2f}"
                    f" {1e3 * t_a:>9.3f} {changed:>8}"
                )
                if n == 1000 and name.startswith("decentral"):
                    verdict.append((name, cname, t_c / t_edge, t_c / t_law))
    print(f"load average (1, 5, 15 min) at end: {os.getloadavg()}")
    if verdict:
        default = [v for v in verdict if v[0] == "decentralized"]
        worst = max(default, key=lambda v: v[2])
        ok = worst[2] <= 2.0
        print(
            f"{'PASS' if ok else 'FAIL'}: at 1,000 robots the decentralized filter (gamma = 100, "
            f"no speed limit) costs at most {worst[2]:.2f}x the edge-list law's step "
            f"({worst[1]} command; {worst[3]:.2f}x DistanceLaw.control); target <= 2x"
        )
        stress = max(verdict, key=lambda v: v[2])
        print(
            f"stress rows (not the target): at most {stress[2]:.2f}x the edge-list law "
            f"({stress[0]}, {stress[1]}; {stress[3]:.2f}x DistanceLaw.control)"
        )


if __name__ == "__main__":
    main()
