"""Speed of sensed batches: the compiled loop's sensing stage, the numpy driver, the plain field.

``run_batch(..., sensing=...)`` under explicit Euler runs on the engine's compiled
loop with its sensing stage (``formationlab.sensing.stage``); ``backend="numpy"`` is the
stepping driver with its measurement channel, the reference the loop is tested against.
Printed, for the paper's triangle (simulation 2's alpha table, angle-restricted law
k_c = 2, k_a = 3, theta = 0.5, diameters 0.2) and the unit square with both diagonals,
dt = 5 ms as in the robustness studies, early stopping off (every trial runs every step):

* trial-steps per second of the sensed numba path, of the numpy driver path (same
  sensing, the same batch of trials, a fifth of the steps) and of the plain compiled
  kernel (the paper's sensing), measured in the same run, and the ratios;
* for sensing models: local frames alone; local frames with noise 0.01 m; local frames
  with delay 20 ms and 20 % losses; every key at once (frames, noise, range, delay,
  drops, mismatch) and a robot that stops.

Run ``python benchmarks/bench_sensing.py`` (``--quick`` for smaller runs). The load
average is printed with every figure: the figures mean something only when it is low.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numba
import numpy as np

import formationlab as fl
from formationlab.scenario import parse_scenario
from formationlab.sensing import Faults, Sensing, Stop
from formationlab.studies.batch import run_batch

SIM2 = {(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}
DT = 5e-3
SQUARE_FILE = Path(__file__).parents[1] / "examples/square-with-diagonals.toml"

SETTINGS = {
    "frames": (Sensing(frames="local"), None),
    "frames + noise": (Sensing(frames="local", noise=0.01), None),
    "frames + delay + drop": (Sensing(frames="local", delay=0.02, drop=0.2), None),
    "all keys + stop": (
        Sensing(frames="local", noise=0.01, range=3.0, delay=0.02, drop=0.2, mismatch=0.01),
        Faults(stop=[Stop(robot=2, at=5.0)]),
    ),
}


def load() -> str:
    return "load {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def box_starts(formation: fl.Formation, count: int, half_width: float, seed: int) -> np.ndarray:
    """``count`` uniform draws in ``[-w, w]^2`` per robot, overlapping draws rejected."""
    rng = np.random.default_rng(seed)
    iu, ju = np.triu_indices(formation.n, k=1)
    a = formation.contact_matrix[iu, ju]
    kept: list[np.ndarray] = []
    have = 0
    while have < count:
        q = rng.uniform(-half_width, half_width, size=(count, formation.n, 2))
        ok = np.all(np.linalg.norm(q[:, ju] - q[:, iu], axis=-1) > a, axis=-1)
        kept.append(q[ok])
        have += int(ok.sum())
    return np.concatenate(kept)[:count]


def rate(formation, law, trials, steps, **kw) -> tuple[float, str]:
    """Trial-steps per second of one batch, early stopping off (tested at the end only)."""
    q0 = box_starts(formation, trials, 3.0, seed=1)
    seeds = [(0, t) for t in range(trials)]
    if kw.get("sensing") is None and kw.get("faults") is None:
        seeds = None
    before = load()
    t0 = time.perf_counter()
    res = run_batch(formation, law, q0, dt=DT, duration=steps * DT, check_every=steps + 1,
                    seeds=seeds, **kw)  # fmt: skip
    wall = time.perf_counter() - t0
    return float(res.steps.sum()) / wall, before


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller runs (about a minute)")
    args = parser.parse_args()
    scale = 0.25 if args.quick else 1.0
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs")
    print(f"numba {numba.__version__}, threads {numba.get_num_threads()}, numpy {np.__version__}")
    tri = fl.Formation.from_alpha_table(SIM2, n=3, distances=1.0, diameters=0.2)
    square = parse_scenario(SQUARE_FILE.read_text()).formation
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)

    t0 = time.perf_counter()
    for sensing, faults in SETTINGS.values():  # compile, or load from numba's cache
        run_batch(tri, law, box_starts(tri, 2, 3.0, 0), dt=DT, duration=2 * DT,
                  sensing=sensing, faults=faults, seeds=[0, 1])  # fmt: skip
    run_batch(tri, law, box_starts(tri, 2, 3.0, 0), dt=DT, duration=2 * DT)
    print(f"first calls (compile or load from numba's cache): {time.perf_counter() - t0:.2f} s")
    steps = 2000  # 10 s at dt = 5 ms
    for label, formation in (("triangle", tri), ("square", square)):
        plain, plain_load = rate(formation, law, int(20_000 * scale), steps)
        print(f"\n{label}: plain kernel {plain:.3g} trial-steps/s [{plain_load}]")
        print(f"  {'sensing':<24}{'sensed numba':>14}{'numpy driver':>14}"
              f"{'numba/numpy':>13}{'plain/sensed':>14}")  # fmt: skip
        for name, (sensing, faults) in SETTINGS.items():
            kw = {"sensing": sensing, "faults": faults}
            fast, fast_load = rate(formation, law, int(2000 * scale), steps, backend="numba", **kw)
            # the driver is vectorised over trials: the same batch, fewer steps
            slow, slow_load = rate(formation, law, int(2000 * scale), steps // 5,
                                   backend="numpy", **kw)  # fmt: skip
            print(f"  {name:<24}{fast:>14.3g}{slow:>14.3g}{fast / slow:>12.0f}x"
                  f"{plain / fast:>13.1f}x   [{fast_load}; {slow_load}]")  # fmt: skip


if __name__ == "__main__":
    main()
