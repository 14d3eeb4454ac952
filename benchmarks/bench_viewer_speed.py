"""Simulated seconds per wall second of the live viewer at 1,000 robots: the compiled loop
against the numpy driver, measured in the same run.

Usage::

    python benchmarks/bench_viewer_speed.py                 # examples/lattice-1000.toml
    python benchmarks/bench_viewer_speed.py --seconds 5 --scenario examples/lattice-1000-angle.toml

The live session (``formationlab.viewer.LiveSession``) is driven as the page drives it:
``advance(wall_dt)`` and ``frame()`` once per display frame (at most 60 a second, the real
wall time between calls given), at speeds x1, x10 and x100, for ``--seconds`` of wall time
each. "x1 means real time" when the simulated seconds per wall second reach 1. The numpy
driver's figure is the same session with the compiled loop switched off (each step one
pass of ``integrators.driver.Stepping``, the path the viewer took for every formation
before). The first compiled segment compiles the loop (or loads it from numba's cache);
it is run before the clock starts.

``--counts 50,100,200,400`` measures instead where the live session should switch to the
compiled loop (``viewer.stepping.COMPILED_FROM``): the same lattice at each count (its
``count`` replaced), wall milliseconds per step of the compiled loop (forced on below the
switch) and of the numpy driver, taken in segments of steps as the page takes them, and
their ratio (numpy / compiled; above 1 the compiled loop is the faster).
"""

from __future__ import annotations

import argparse
import time
import tomllib
from pathlib import Path

from formationlab.integrators.compiled import compiled_terms
from formationlab.io.scenario import load_scenario
from formationlab.scenario import parse_scenario
from formationlab.viewer import LiveSession
from formationlab.viewer.stepping import COMPILED_FROM, CompiledSteps

ROOT = Path(__file__).resolve().parents[1]


def measure(session: LiveSession, speed: float, seconds: float) -> tuple[float, int]:
    """Simulated seconds per wall second while the session is advanced as the page does,
    and the steps taken."""
    session.set_speed(speed)
    t0, steps0 = session.t, session.steps
    start = last = time.perf_counter()
    while (now := time.perf_counter()) - start < seconds:
        session.advance(now - last)  # the wall time since the last frame, as the page's tick
        session.frame()  # and the frame it answers with (V, the errors, the active surfaces)
        last = now
        time.sleep(max(0.0, 1 / 60 - (time.perf_counter() - now)))  # the display's frame
    wall = time.perf_counter() - start
    return (session.t - t0) / wall, session.steps - steps0


def per_step(session: LiveSession, seconds: float) -> float:
    """Wall milliseconds per step of ``session`` over ``seconds``, in segments of 20 steps."""
    session.step(2)  # (compile or load the loop first)
    start, steps = time.perf_counter(), 0
    while time.perf_counter() - start < seconds:
        steps += session.step(20)
    return 1e3 * (time.perf_counter() - start) / max(steps, 1)


def switch(path: str, counts: list[int], seconds: float) -> None:
    """Per-step cost of each path at each count (module docstring)."""
    raw = tomllib.loads(Path(path).read_text())
    print(f"COMPILED_FROM = {COMPILED_FROM}; {seconds:g} s of wall time per case")
    print(f"{'robots':>7} {'compiled ms/step':>17} {'numpy ms/step':>14} {'numpy/compiled':>15}")
    for count in counts:
        raw["formation"]["template"]["count"] = count
        scenario = parse_scenario(raw, source=f"{path} (count = {count})")
        fast = LiveSession(scenario, seed=1)
        layout = compiled_terms(fast.system, fast.integrator)
        if layout is None:
            raise SystemExit(f"{count} robots: this scenario does not step on the compiled loop")
        fast._compiled = CompiledSteps(fast.system, fast.integrator, layout)  # (forced on)
        slow = LiveSession(scenario, seed=1)
        slow._compiled = None  # the driver's path
        a, b = per_step(fast, seconds), per_step(slow, seconds)
        print(f"{scenario.n:>7} {a:>17.3f} {b:>14.3f} {b / a:>15.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=str(ROOT / "examples" / "lattice-1000.toml"))
    parser.add_argument("--seconds", type=float, default=3.0, help="wall seconds per case")
    parser.add_argument("--counts", default="", help="e.g. 50,100,200,400: where to switch")
    args = parser.parse_args()
    if args.counts:
        switch(args.scenario, [int(c) for c in args.counts.split(",")], args.seconds)
        return
    scenario = load_scenario(args.scenario)
    compiled = LiveSession(scenario, seed=1)
    compiled.step(2)  # compile (or load) the loop before the clock starts
    if not compiled.frame().header["compiled"]:
        raise SystemExit(f"{scenario.name}: this scenario does not step on the compiled loop")
    numpy_path = LiveSession(scenario, seed=1)
    numpy_path._compiled = None  # the driver's path, as before (no compiled loop)
    numpy_path.step(2)
    print(f"{scenario.name}: {scenario.n} robots, dt = {compiled.integrator.dt:g} s, "
          f"{args.seconds:g} s of wall time per case")  # fmt: skip
    print(f"{'path':<10} {'asked':>6} {'reached (sim s / wall s)':>26} {'steps':>8}")
    for speed in (1.0, 10.0, 100.0):
        for name, session in (("compiled", compiled), ("numpy", numpy_path)):
            reached, steps = measure(session, speed, args.seconds)
            print(f"{name:<10} {f'x{speed:g}':>6} {reached:>26.3f} {steps:>8}")


if __name__ == "__main__":
    main()
