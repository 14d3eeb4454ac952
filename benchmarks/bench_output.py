"""Time and memory of a run's output against the number of robots: ``run`` and ``animate``.

For N robots on a triangular lattice (``template = { lattice = "triangular" }``, spacing 1,
Delaunay edges, start perturbed by 0.05, seed 1, distance law or ``--law angle-restricted``),
50 steps of explicit Euler (dt = 1e-3) stored every ``K`` steps, each in a fresh process:

* ``run``: what ``formationlab run`` does, phase by phase with the command's own functions
  (loading and checking the scenario, simulating, the post-processing inside ``simulate``
  beyond the compiled loop, writing ``trajectory.nc``, ``summary.json`` and the per-edge
  table, drawing the figures), the process's peak resident memory, its memory after the
  imports, and the size of what is saved (the arrays of ``trajectory.nc`` before
  compression); "memory bounded by what is saved" reads as: peak minus the memory of the
  setup grows with the saved size (plus at most ``chunked.BUDGET`` of scratch and the
  libraries the writing and the figures import), not with N times the steps; ``+sim`` and
  ``+write`` are what simulating and writing added to the peak;
* ``animate``: ``formationlab animate DIR --format gif --frames F`` on the run stored every
  step (51 states), wall time per frame and peak memory.

Prints the load average, and as a reference measured in the same run the wall time of
``python -c "import formationlab"`` (best of three), so that figures from a busy machine
can be scaled. Run ``python benchmarks/bench_output.py [--max 100000] [--animate-max 10000]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SCENARIO = """
name = "lattice-{n}"
[robots]
positions = {{ around = "template", sigma = 0.05, seed = 1 }}
diameters = 0.2
[formation]
template = {{ lattice = "triangular", count = {n}, spacing = 1.0 }}
edges = "delaunay"
orientation = "{orientation}"
[controller]
law = "{law}"
repulsion = {{ eta = 1.0, influence = 0.3 }}
[simulation]
integrator = "euler"
dt = 1e-3
duration = 0.05
"""


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: kB


def child_run(scenario: str, out: str, save_every: int) -> dict[str, float]:
    """One ``run``, phase by phase (in this process); returns the figures."""
    t0 = time.perf_counter()
    import formationlab as fl
    from formationlab.cli.run import _write_data, _write_figures
    from formationlab.io.files import prepare_output_dir
    from formationlab.io.scenario import load_scenario

    fig: dict[str, float] = {"import_s": time.perf_counter() - t0, "rss_import_mb": _rss_mb()}
    t = time.perf_counter()
    sc = load_scenario(scenario)
    fig["load_s"] = time.perf_counter() - t
    fig["rss_setup_mb"] = _rss_mb()
    t = time.perf_counter()
    res = fl.simulate(
        sc.formation, sc.law, sc.x0, duration=sc.duration, integrator=sc.integrator,
        save_every=save_every,
    )  # fmt: skip
    fig["simulate_s"] = time.perf_counter() - t
    fig["loop_s"] = float(res.stats["wall_time_s"])
    fig["rss_simulate_mb"] = _rss_mb()
    folder = prepare_output_dir(out)
    t = time.perf_counter()
    summary, written = _write_data(folder, sc, Path(scenario), res, save_every, quiet=True)
    fig["write_s"] = time.perf_counter() - t
    fig["rss_write_mb"] = _rss_mb()
    t = time.perf_counter()
    _write_figures(folder, sc, Path(scenario), res, summary, save_every, written, quiet=True)
    fig["figures_s"] = time.perf_counter() - t
    fig["rss_peak_mb"] = _rss_mb()
    saved = res.q.nbytes + res.u.nbytes + res.V.nbytes + res.sigma.nbytes + res.t.nbytes
    saved += 8 * len(res.t) * len(sc.formation.edges)  # distance_error
    fig["saved_mb"] = saved / 2**20
    fig["states"] = len(res.t)
    fig["edges"] = len(sc.formation.edges)
    fig["nc_mb"] = (folder / "trajectory.nc").stat().st_size / 2**20
    return fig


def child_animate(folder: str, frames: int) -> dict[str, float]:
    """``formationlab animate`` (GIF) in this process; returns wall time and peak memory."""
    t0 = time.perf_counter()
    from formationlab.cli import main

    t = time.perf_counter()
    try:
        main(["animate", folder, "--format", "gif", "--frames", str(frames), "--force"])
    except SystemExit as exc:
        if exc.code not in (0, None):
            raise
    return {
        "animate_s": time.perf_counter() - t,
        "import_s": t - t0,
        "rss_peak_mb": _rss_mb(),
    }


def _child(*args: str) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, __file__, "--child", *args], capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _reference() -> float:
    """Best of three: wall seconds of ``python -c "import formationlab"``."""
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import formationlab"], check=True)
        best = min(best, time.perf_counter() - t)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max", type=int, default=100_000, help="largest N of the runs")
    parser.add_argument("--animate-max", type=int, default=10_000, help="largest N animated")
    parser.add_argument("--law", default="distance", choices=("distance", "angle-restricted"))
    parser.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        kind, *rest = args.child
        fig = (
            child_run(rest[0], rest[1], int(rest[2]))
            if kind == "run"
            else child_animate(rest[0], int(rest[1]))
        )
        print(json.dumps(fig))
        return
    load = os.getloadavg()
    ref = _reference()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores; "
          f"reference: `python -c 'import formationlab'` {ref:.2f} s (best of 3)")  # fmt: skip
    print(f"law {args.law}; 50 steps of dt = 1e-3 stored every K steps")
    head = (f"{'N':>7} {'K':>2} {'saved':>6} {'edges':>7} {'load':>6} {'simulate':>8} "
            f"{'(loop)':>7} {'write':>6} {'figures':>7} {'saved MB':>8} {'nc MB':>6} "
            f"{'setup MB':>8} {'+sim MB':>7} {'+write MB':>9} {'peak MB':>7} "
            f"{'peak-setup':>10}")  # fmt: skip
    print(head)
    orientation = "template" if args.law == "angle-restricted" else "free"
    sizes = [n for n in (100, 1_000, 10_000, 100_000) if n <= args.max]
    with tempfile.TemporaryDirectory() as tmp:
        runs: dict[int, str] = {}
        for n in sizes:
            scenario = Path(tmp, f"lattice-{n}.toml")
            scenario.write_text(SCENARIO.format(n=n, law=args.law, orientation=orientation))
            for k in (5, 1):
                out = str(Path(tmp, f"run-{n}-{k}"))
                f = _child("run", str(scenario), out, str(k))
                print(f"{n:>7} {k:>2} {f['states']:>6.0f} {f['edges']:>7.0f} {f['load_s']:>6.2f} "
                      f"{f['simulate_s']:>8.2f} {f['loop_s']:>7.2f} {f['write_s']:>6.2f} "
                      f"{f['figures_s']:>7.2f} {f['saved_mb']:>8.1f} {f['nc_mb']:>6.1f} "
                      f"{f['rss_setup_mb']:>8.0f} "
                      f"{f['rss_simulate_mb'] - f['rss_setup_mb']:>7.0f} "
                      f"{f['rss_write_mb'] - f['rss_simulate_mb']:>9.0f} {f['rss_peak_mb']:>7.0f} "
                      f"{f['rss_peak_mb'] - f['rss_setup_mb']:>10.0f}", flush=True)  # fmt: skip
                runs[n] = out
        print("\nanimate (GIF), on the run stored every step:")
        print(f"{'N':>7} {'frames':>6} {'wall s':>7} {'s/frame':>8} {'peak MB':>8}")
        for n in sizes:
            if n > args.animate_max:
                continue
            frames = 50
            f = _child("animate", runs[n], str(frames))
            print(f"{n:>7} {frames:>6} {f['animate_s']:>7.2f} {f['animate_s'] / frames:>8.3f} "
                  f"{f['rss_peak_mb']:>8.0f}", flush=True)  # fmt: skip
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
