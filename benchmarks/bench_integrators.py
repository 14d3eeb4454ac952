"""Switch counts and run times of each integrator on a sliding start and on simulation 2.

Usage::

    python benchmarks/bench_integrators.py                 # print the tables
    python benchmarks/bench_integrators.py --quick         # shorter, coarser runs
    python benchmarks/bench_integrators.py --figure docs/figures/integrators-sliding.png

Starts (section 4 gains k_c = 2, k_a = 3, theta = 0.5, diameters 0.2, d_ij = 1):

* ``sliding``: simulation 1's alpha table (desired c_123 > 0) with robot 1 far from
  robots 2 and 3 on the wrong side of their line, q0 = (5, -2), (-1.5, 0), (1.5, 0):
  the mechanism of the paper's figure 3; it slides along s (eq. 26) for ~0.87 s.
* ``simulation 2``: the paper's start and alpha table, exact and with x_1(0) shifted
  by 1e-6 (the exact start is trapped in the mirror-symmetric subspace).

"error vs filippov" is the largest final position difference to the Filippov run.
"""

from __future__ import annotations

import argparse

import numpy as np

import formationlab as fl
from formationlab.integrators import Filippov, ImplicitEuler

LAW = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
SIM1_TABLE = {(1, 2, 3): -1, (3, 1, 2): -1, (2, 1, 3): 1}
SIM2_TABLE = {(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}
SLIDING_Q0 = np.array([[5.0, -2.0], [-1.5, 0.0], [1.5, 0.0]])
PAPER_Q0 = np.array([[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]])


def integrators(quick: bool) -> dict[str, fl.Integrator]:
    out: dict[str, fl.Integrator] = {
        "euler dt=1e-2": fl.Euler(dt=1e-2),
        "euler dt=1e-3": fl.Euler(dt=1e-3),
        "rk4 dt=1e-3": fl.RK4(dt=1e-3),
        "implicit-euler dt=1e-2": ImplicitEuler(dt=1e-2),
        "implicit-euler dt=1e-3": ImplicitEuler(dt=1e-3),
        "filippov": Filippov(save_dt=1e-3),
    }
    if quick:
        out = {k: v for k, v in out.items() if "1e-3" not in k or k.startswith("implicit")}
    return out


def table(title: str, formation: fl.Formation, q0: np.ndarray, duration: float, quick: bool):
    print(f"\n{title}  (duration {duration:g} s)")
    head = (
        f"{'integrator':24s} {'wall s':>7s} {'steps':>7s} {'us/step':>8s} {'switches':>8s} "
        f"{'sliding s':>9s} {'slide end':>9s} {'max|sigma|':>10s} {'err vs fil':>10s}  outcome"
    )
    print(head)
    print("-" * len(head))
    results = {}
    for name, integ in integrators(quick).items():
        results[name] = fl.simulate(formation, LAW, q0, duration=duration, integrator=integ)
    ref = results["filippov"].final
    for name, res in results.items():
        d = res.stats
        err = float(np.max(np.abs(res.final - ref)))
        print(
            f"{name:24s} {d['wall_time_s']:7.2f} {d['steps']:7.0f} "
            f"{1e6 * d['step_cost_s']:8.1f} {d['switch_count']:8.0f} "
            f"{d['sliding_time']:9.3f} {d['sliding_end']:9.3f} {d['max_excursion']:10.2g} "
            f"{err:10.2g}  {res.outcome()}"
        )
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="skip the slow dt = 1e-3 runs")
    parser.add_argument("--figure", help="also write the docs figure of the sliding phase here")
    args = parser.parse_args()

    sim1 = fl.Formation.from_alpha_table(SIM1_TABLE, n=3, distances=1.0, diameters=0.2)
    sim2 = fl.Formation.from_alpha_table(SIM2_TABLE, n=3, distances=1.0, diameters=0.2)
    sliding = table("sliding three-robot start", sim1, SLIDING_Q0, 6.0, args.quick)
    table("simulation 2, exact start", sim2, PAPER_Q0, 20.0, args.quick)
    q0 = PAPER_Q0.copy()
    q0[0, 0] += 1e-6
    table("simulation 2, x_1(0) + 1e-6", sim2, q0, 20.0, args.quick)

    if args.figure:
        from formationlab.io.figures import save_figure
        from formationlab.plotting.integrators import sliding_figure

        shown = {
            "explicit Euler, dt = 1e-2": sliding["euler dt=1e-2"],
            "explicit Euler, dt = 1e-3": sliding.get("euler dt=1e-3"),
            "implicit Euler, dt = 1e-2": sliding["implicit-euler dt=1e-2"],
            "Filippov reference (DOP853, events)": sliding["filippov"],
        }
        shown = {k: v for k, v in shown.items() if v is not None}
        fig = sliding_figure(shown, window=(0.0, 1.2), ylim=(-2.0, 0.6))
        print(f"\nwrote {save_figure(fig, args.figure)}")


if __name__ == "__main__":
    main()
