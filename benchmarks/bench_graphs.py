"""Cost of lattice templates, graph builders, the rigidity check and ``validate`` at scale.

Target (issue 11): every step that ``formationlab validate`` takes for a swarm grows about
linearly with the number of robots and none builds an n x n matrix, so that a
100,000-robot scenario validates in a few seconds. Each figure is measured at 10,000 and at
100,000 points in the same run; the ratio of the two costs is printed beside it (10 means
linear growth, 100 quadratic). Also printed: the peak resident memory, and as the reference
for the machine's speed, one ``scipy.spatial.cKDTree`` build and query of the same points.

Run ``python benchmarks/bench_graphs.py`` (``--quick``: 1,000 and 10,000 points). The
load average is printed: the figures mean something only when the load is low.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from formationlab.formation.graph import is_rigid
from formationlab.formation.graphs import (
    delaunay_edges,
    henneberg_edges,
    knn_edges,
    overlapping_pairs,
    within_edges,
)
from formationlab.formation.templates import lattice
from formationlab.scenario import parse_scenario

SCENARIO = (Path(__file__).resolve().parents[1] / "examples" / "lattice-1000.toml").read_text(
    encoding="utf-8"
)


def best(f: Callable[[], object], repeat: int = 2) -> float:
    """The best of ``repeat`` wall times of ``f()``, seconds."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times)


def hinged(pts: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Two minimally rigid halves joined by two bars, plus one redundant edge: ``2n - 3``
    edges, yet not rigid (the halves turn about a point), so the count does not decide."""
    left = pts[:, 0] < 0
    parts = []
    for side in (left, ~left):
        idx = np.flatnonzero(side)
        parts.append(idx[henneberg_edges(pts[idx])])
    across = e[left[e[:, 0]] != left[e[:, 1]]][:2]
    have = {tuple(x) for x in parts[0].tolist()}
    inside = e[left[e[:, 0]] & left[e[:, 1]]]
    extra = next(x for x in inside.tolist() if tuple(x) not in have)
    out = np.concatenate([*parts, across, [extra]])
    assert len(out) == 2 * len(pts) - 3
    return out


def measure(n: int) -> dict[str, float]:
    pts = lattice("triangular", n, 1.0)
    q0 = pts + np.random.default_rng(1).normal(scale=0.05, size=pts.shape)
    e = delaunay_edges(pts)
    h = henneberg_edges(pts)
    g = hinged(pts, e)
    assert is_rigid(e, n) and is_rigid(h, n) and not is_rigid(g, n)
    text = SCENARIO.replace("count = 1000", f"count = {n}")
    is_rigid(e[:10], 11)  # compile the pebble game outside the timings
    return {
        "reference: cKDTree build + 2-NN query": best(lambda: cKDTree(pts).query(pts, k=2)),
        "lattice (triangular)": best(lambda: lattice("triangular", n, 1.0)),
        "delaunay_edges": best(lambda: delaunay_edges(pts)),
        "knn_edges (k = 6)": best(lambda: knn_edges(pts, 6)),
        "within_edges (r = 1.5)": best(lambda: within_edges(pts, 1.5)),
        "henneberg_edges": best(lambda: henneberg_edges(pts)),
        "is_rigid (Delaunay)": best(lambda: is_rigid(e, n)),
        "is_rigid (Henneberg)": best(lambda: is_rigid(h, n)),
        "is_rigid (two halves, two bars: not rigid)": best(lambda: is_rigid(g, n)),
        "overlapping_pairs (start)": best(lambda: overlapping_pairs(q0, np.full(n, 0.2))),
        "parse_scenario + is_rigid (validate)": best(
            lambda: parse_scenario(text).formation.is_rigid, repeat=1
        ),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1,000 and 10,000 points")
    args = parser.parse_args()
    small, large = (1_000, 10_000) if args.quick else (10_000, 100_000)
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    a, b = measure(small), measure(large)
    print(f"\n| step | {small:,} points (s) | {large:,} points (s) | ratio |")
    print("| --- | --- | --- | --- |")
    for key in a:
        print(f"| {key} | {a[key]:.3f} | {b[key]:.3f} | {b[key] / a[key]:.1f} |")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\npeak resident memory {peak:.0f} MB; load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
