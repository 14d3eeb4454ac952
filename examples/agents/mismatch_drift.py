"""Drift of a formation whose neighbours disagree about distances, against the mismatch.

Mou, Belabbas, Morse, Sun and Anderson, "Undirected rigid formations are problematic",
IEEE Transactions on Automatic Control 61(10), 2016: when the two robots of an edge
hold slightly different desired distances, the formation ends in a distorted shape
that rotates at a constant angular velocity about a fixed point. This script measures
the steady angular velocity ``|omega|`` and centroid speed against the standard
deviation ``sigma`` of the robots' errors (``Sensing(mismatch=sigma, seed=...)``) for
Krick et al.'s squared-distance law and the paper's distance and angle-restricted
laws, on the paper's triangle and on the square with both diagonals, from
:func:`formationlab.agents.measure_drift` (the steady motion solved for, no
simulation), checks one realisation per law against a simulated run, prints a table
and writes a figure.

Usage::

    python examples/agents/mismatch_drift.py [FIGURE.png] [--seeds N]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import formationlab as fl
from formationlab.agents import measure_drift, own_distances, steady_motion
from formationlab.plotting.fonts import font_context
from formationlab.outcomes.rigid_motion import rigid_motion
from formationlab.scenario import parse_scenario
from formationlab.sensing import Sensing

EXAMPLES = Path(__file__).resolve().parent.parent
SCENARIOS = {"triangle": "paper-simulation-1.toml", "square": "square-with-diagonals.toml"}
SIGMAS = [0.0, 0.01, 0.02, 0.05, 0.1]
CHECK_SIGMA, CHECK_SEED = 0.05, 0


def laws(scenario):
    """Krick et al.'s law, and the paper's distance and angle-restricted laws with its gains."""
    paper = scenario.law
    return {
        "squared-distance": fl.get_law("squared-distance"),
        "distance": fl.get_law("distance", k_c=paper.k_c, repulsion=paper.repulsion),
        "angle-restricted": paper,
    }


def simulated_omega(scenario, law, seed):
    """``omega`` of a run from the scenario's start over its last second, and its end state."""
    res = fl.simulate(
        scenario.formation, law, scenario.q0, duration=60.0,
        sensing=Sensing(mismatch=CHECK_SIGMA, seed=seed), integrator=fl.RK4(dt=0.01),
    )  # fmt: skip
    i0 = np.searchsorted(res.t, res.t[-1] - 1.0 - 1e-9)
    fit = rigid_motion(res.q[i0], res.q[-1], res.t[-1] - res.t[i0])
    return float(fit.omega), res.q[-1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("figure", nargs="?", default="mismatch-drift.png")
    parser.add_argument("--seeds", type=int, default=50, help="realisations per sigma")
    args = parser.parse_args()
    seeds = list(range(args.seeds))
    tables, checks = {}, []
    for shape, file in SCENARIOS.items():
        scenario = parse_scenario((EXAMPLES / file).read_text(), source=file)
        for name, law in laws(scenario).items():
            tables[shape, name] = table = measure_drift(scenario.formation, law, SIGMAS, seeds)
            if not table.converged.all():
                print(
                    f"warning: {shape} {name}: {np.sum(~table.converged)} solves did not converge"
                )
            own = own_distances(scenario.formation, law, CHECK_SIGMA, [CHECK_SEED])[0]
            sim, q_end = simulated_omega(scenario, law, CHECK_SEED)
            solved = steady_motion(scenario.formation, law, own, guess=q_end).omega
            checks.append((shape, name, solved, sim))

    print(f"steady drift against mismatch sigma, {len(seeds)} realisations each: mean (std)")
    head = f"{'formation':<9} {'law':<17} {'sigma':>5}  {'|omega| rad/s':>17}  "
    print(head + f"{'centroid m/s':>17}  {'max |r - d| m':>17}  slope")
    for (shape, name), t in tables.items():
        s = t.summary()
        for a, sigma in enumerate(t.mismatch):
            cells = [f"{s[k + '_mean'][a]:.4f} ({s[k + '_std'][a]:.4f})"
                     for k in ("omega", "speed", "distortion")]  # fmt: skip
            slope = f"{t.slope():.3f}" if a == 0 else ""
            print(f"{shape:<9} {name:<17} {sigma:5.2f}  " + "  ".join(f"{c:>17}" for c in cells)
                  + f"  {slope}")  # fmt: skip
    print(f"\ncheck: sigma = {CHECK_SIGMA}, seed {CHECK_SEED}, simulated from the scenario's start")
    for shape, name, solved, sim in checks:
        print(f"{shape:<9} {name:<17} solved omega {solved:+.6f}  simulated {sim:+.6f}  "
              f"relative difference {abs(sim - solved) / abs(solved):.1e}")  # fmt: skip

    colours = {"squared-distance": "tab:blue", "distance": "tab:orange",
               "angle-restricted": "tab:green"}  # fmt: skip
    styles = {"triangle": ("o", "-"), "square": ("s", "--")}
    with font_context():
        fig, axes = plt.subplots(1, 2, figsize=(10.0, 4.2), layout="constrained")
        for (shape, name), t in tables.items():
            marker, line = styles[shape]
            for ax, values in zip(axes, (np.abs(t.omega), t.speed), strict=True):
                mean = values.mean(axis=1)
                if name == "angle-restricted":  # its restrictions are off: it is the distance law
                    ax.plot(t.mismatch, mean, marker=marker, linestyle="none", markersize=8,
                            markerfacecolor="none", color=colours[name],
                            label=f"{name}, {shape} (= distance)")  # fmt: skip
                    continue
                lo, hi = np.percentile(values, [16, 84], axis=1)
                ax.plot(t.mismatch, mean, marker=marker, linestyle=line, color=colours[name],
                        markersize=4, label=f"{name}, {shape}")  # fmt: skip
                ax.fill_between(t.mismatch, lo, hi, color=colours[name], alpha=0.12, linewidth=0)
        sig = np.linspace(0, max(SIGMAS), 50)
        paper = parse_scenario((EXAMPLES / SCENARIOS["triangle"]).read_text()).law
        d, a = 1.0, 0.2  # the paper's triangle: d = 1, diameters 0.2
        for name, kappa in (("squared-distance", 2.0 * d),
                            ("distance", paper.k_c / ((d - a) ** 2 * d))):  # fmt: skip
            axes[0].plot(sig, kappa * sig / np.sqrt(np.pi), color=colours[name], linewidth=0.9,
                         linestyle=":", label=rf"first order, {name}, triangle: "
                         rf"$\kappa\sigma/\sqrt{{\pi}}$, $\kappa$ = {kappa:.3g}")  # fmt: skip
        axes[0].set_ylabel(r"steady $|\omega|$ (rad/s)")
        axes[1].set_ylabel("steady centroid speed (m/s)")
        for ax in axes:
            ax.set_xlabel(r"mismatch $\sigma$ (m)")
            ax.grid(alpha=0.3)
        axes[0].legend(fontsize=6.5)
        axes[1].set_title("lines: mean over the realisations; bands: 16th-84th percentile",
                          fontsize=8)  # fmt: skip
        fig.suptitle("Neighbours that disagree about distances: the formation keeps turning "
                     "(Mou et al. 2016)", fontsize=10)  # fmt: skip
        fig.savefig(args.figure, dpi=150)
    print(f"\nwrote {args.figure}")


if __name__ == "__main__":
    main()
