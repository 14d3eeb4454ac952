"""Cost of an explicit-Euler step against the number of robots: the compiled single-run path.

A triangular lattice of N robots (spacing 1, diameter 0.2), Delaunay edges with their
template distances, a start perturbed by 0.05 (seed 1) so that Khatib's repulsion and the
switching surfaces are active; explicit Euler (dt = 1e-3) on the compiled path
(``integrators/compiled.py``), for the distance law and the angle-restricted law
(orientation from the lattice, collinear triples skipped). For each N it prints:

* ms per step inside the compiled loop on one thread and on numba's threads (the same
  numbers bit for bit), the CPU ms per step of the one-thread run (what a quiet machine
  would take), and what ``simulate`` chose by default (it measures both above
  ``PARALLEL_FROM`` robots);
* ns per robot-step (flat when the cost grows linearly in N) and the growth exponent
  between consecutive sizes;
* memory per robot: "run" is the peak that building the law's data and the compiled run
  add (kernel data, layout, close list, scratch, saved states: here 3 states); "simulate"
  the peak of the whole ``simulate`` call, post-processing (V, sigma) included;
  "formation" what the formation given to it holds after every call of the benchmark
  (its arrays and the lists it derived and kept: up to ``spec.HELD_LIMIT`` restricted
  triples it keeps them, beyond it holds only the halves); "total" the whole call with the
  formation, simulate + formation: the figure the memory target is about;
* one numpy evaluation of the law's field at the same N (the numpy driver's cost per step,
  measured in the same run, after a first one: the driver keeps what the formation
  derives for its run), and the 3-robot step through ``simulate`` against the numpy
  driver.

Then PASS/FAIL against the targets of the swarm issue. ``python
benchmarks/bench_swarm.py [--max 100000]``; the load average is printed at the start and
the end (the machine is shared: wall times grow with the load, CPU times much less).
"""

from __future__ import annotations

import argparse
import itertools
import os
import time
import tracemalloc

import numba
import numpy as np

import formationlab as fl
from formationlab.dynamics import System
from formationlab.integrators.compiled import compiled_terms, run_compiled
from formationlab.studies.paper import PAPER_Q0, paper_formation, paper_law

DT = 1e-3
LAWS = ("distance", "angle-restricted")


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (5 min {five:.2f}) on {os.cpu_count()} cores"


def swarm(n: int, law: str) -> tuple[fl.Formation, fl.Law, np.ndarray]:
    tpl = fl.lattice("triangular", n, 1.0)
    edges = fl.build_edges("delaunay", tpl)
    orient = "template" if law == "angle-restricted" else "free"
    f = fl.Formation.from_template(
        tpl, edges=edges, diameters=0.2, orientation=orient, one_based=False
    )
    q0 = tpl + np.random.default_rng(1).normal(0.0, 0.05, tpl.shape)
    return f, fl.get_law(law), q0


def formation_bytes(f: fl.Formation) -> int:
    """Bytes of every array the formation holds now, the lists it derived and kept included."""
    seen: dict[int, int] = {}

    def walk(v: object) -> None:
        if isinstance(v, np.ndarray):
            seen[id(v)] = v.nbytes
        elif isinstance(v, tuple | list):
            for x in v:
                walk(x)

    walk(list(vars(f).values()))
    return sum(seen.values())


def loop_cost(layout, q0, steps: int, parallel: bool) -> tuple[float, float, str]:
    """Wall and CPU seconds per step inside the compiled loop."""
    run_compiled(layout, q0, dt=DT, n_steps=2, save_every=2, parallel=parallel)  # warm
    c0 = time.process_time()
    out = run_compiled(layout, q0, dt=DT, n_steps=steps, save_every=steps, parallel=parallel)
    return out.wall / steps, (time.process_time() - c0) / steps, str(out.status)


def peak_bytes(fn) -> int:
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def three_robots() -> tuple[float, float]:
    """Seconds per step of ``simulate`` (whole call) for the paper's triangle: compiled, numpy."""
    f, law = paper_formation(2), paper_law()

    def per_step(steps: int, backend: str) -> float:
        t0 = time.perf_counter()
        fl.simulate(f, law, PAPER_Q0, duration=steps * DT, save_every=steps, backend=backend)
        return (time.perf_counter() - t0) / steps

    per_step(100, "numba")  # compiled and cached once
    return min(per_step(20_000, "numba") for _ in range(3)), per_step(2_000, "numpy")


def verdict(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max", type=int, default=100_000)
    args = parser.parse_args()
    threads = numba.get_num_threads()
    print(f"start: {load()}; numba threads {threads} ({numba.threading_layer()})")
    fast, slow = three_robots()
    print(f"3 robots (simulate, whole call per step): {fast * 1e6:.2f} us compiled, "
          f"{slow * 1e6:.1f} us numpy driver ({slow / fast:.0f}x)")  # fmt: skip
    sizes = [n for n in (100, 1_000, 10_000, 100_000) if n <= args.max]
    head = (f"{'N':>7} {'law':>16} {'1 thread':>9} {'cpu':>7} {f'{threads} thr':>8} "
            f"{'default':>8} {'ns/robot':>9} {'run':>6} {'simul.':>7} {'formn.':>7} "
            f"{'total':>6} {'numpy':>9}  status")  # fmt: skip
    print(
        "ms per step (1 thread, its CPU, threads, simulate's default); KB per robot "
        "(run, simulate, formation, total = simulate + formation); numpy: one field "
        "evaluation, ms"
    )
    print(head)
    best: dict[tuple[int, str], float] = {}
    cpu_cost: dict[tuple[int, str], float] = {}
    memory: dict[tuple[int, str], tuple[float, float, float]] = {}
    for n in sizes:
        steps = max(100, min(2000, 20_000_000 // n))
        for name in LAWS:
            f, law, q0 = swarm(n, name)
            layout = compiled_terms(System(formation=f, law=law), fl.Euler(dt=DT))
            one, cpu, status = loop_cost(layout, q0, steps, parallel=False)
            many = loop_cost(layout, q0, steps, parallel=True)[0] if threads > 1 else one
            res = fl.simulate(f, law, q0, duration=steps * DT, save_every=steps)
            default = res.stats["step_cost_s"]

            def run_part(f=f, law=law, q0=q0, steps=steps) -> None:
                lay = compiled_terms(System(formation=f, law=law), fl.Euler(dt=DT))
                run_compiled(lay, q0, dt=DT, n_steps=steps, save_every=steps // 2)

            def whole(f=f, law=law, q0=q0, steps=steps) -> None:
                fl.simulate(f, law, q0, duration=steps * DT, save_every=steps // 2)

            run_kb = peak_bytes(run_part) / n / 1e3
            sim_kb = peak_bytes(whole) / n / 1e3
            with f.holding():  # as the numpy driver runs: what it derives kept for the run
                law.control(f, q0)
                t0 = time.perf_counter()
                law.control(f, q0)
                ref = time.perf_counter() - t0
            form_kb = formation_bytes(f) / n / 1e3  # after every call: what it kept included
            best[n, name] = default
            cpu_cost[n, name] = cpu
            memory[n, name] = (run_kb, sim_kb, sim_kb + form_kb)
            print(f"{n:>7} {name:>16} {one * 1e3:9.3f} {cpu * 1e3:7.3f} {many * 1e3:8.3f} "
                  f"{default * 1e3:8.3f} {default / n * 1e9:9.1f} {run_kb:6.2f} {sim_kb:7.2f} "
                  f"{form_kb:7.2f} {sim_kb + form_kb:6.2f} {ref * 1e3:9.2f}  {status}, "
                  f"{res.stats['threads']} thr")  # fmt: skip
    print("linearity: growth exponent of the cost per step between consecutive sizes "
          "(1 = linear); CPU of the one-thread run, and wall of the default")  # fmt: skip
    exps = {}
    for name in LAWS:
        steps_ = list(itertools.pairwise(sizes))
        for label, table in (("cpu", cpu_cost), ("wall", best)):
            e = [np.log(table[b, name] / table[a, name]) / np.log(b / a) for a, b in steps_]
            if label == "cpu":
                exps[name] = [x for (a, _), x in zip(steps_, e, strict=True) if a >= 1_000]
            print(f"  {name:>16} {label:>4}: " + ", ".join(
                f"{a:.0e}->{b:.0e} {x:.2f}" for (a, b), x in zip(steps_, e, strict=True)
            ))  # fmt: skip
    print(f"end: {load()}")
    print("targets:")
    big = max(sizes)
    dist, ang = best[big, "distance"], best[big, "angle-restricted"]
    print(
        f"  {verdict(dist <= 5e-3)} {big:.0e} robots, distance law with repulsion: "
        f"{dist * 1e3:.2f} ms per step (target <= 5 ms{'' if big == 100_000 else ', at 1e5'})"
    )
    print(f"  {verdict(ang <= 15e-3)} {big:.0e} robots, angle-restricted: {ang * 1e3:.2f} ms "
          f"per step, {ang / dist:.1f}x the distance law (target <= 3 x 5 ms)")  # fmt: skip
    for name in LAWS:
        run_kb, sim_kb, total_kb = memory[big, name]
        print(f"  {verdict(total_kb <= 1.0)} memory, {name}: {total_kb:.2f} KB per robot for "
              f"the whole simulate call with the formation (target <= 1 KB): the call "
              f"{sim_kb:.2f} KB (the run {run_kb:.2f} KB) and the formation "
              f"{total_kb - sim_kb:.2f} KB")  # fmt: skip
    print(f"  {verdict(fast <= 5e-6)} 3 robots through simulate: {fast * 1e6:.2f} us per step "
          "(target <= 5 us)")  # fmt: skip
    worst = max(max(v, default=0.0) for v in exps.values())
    print(f"  {verdict(worst <= 1.15)} cost linear in N: largest growth exponent of the CPU "
          f"time per step from 1e3 on {worst:.2f} (PASS if <= 1.15)")  # fmt: skip


if __name__ == "__main__":
    main()
