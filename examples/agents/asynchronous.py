"""The paper's triangle (section 4, simulation 1) with robots that do not share a clock.

Every robot is an asyncio task with its own control period (1, 2 and 5 ms) and a wake-up
jitter of 30 % of its period; the world integrates at dt = 1 ms. Prints how each run
ended and when it converged, against the synchronous run (``simulate``, explicit Euler,
every robot updating every step).

Run from the repository root:  python examples/agents/asynchronous.py
"""

from pathlib import Path

import formationlab as fl
from formationlab.agents import run_async
from formationlab.scenario import parse_scenario

HERE = Path(__file__).resolve().parent
scenario = parse_scenario((HERE.parent / "paper-simulation-1.toml").read_text())
formation, law, dt = scenario.formation, scenario.law, scenario.integrator.dt
q0 = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]
periods, jitter = [1e-3, 2e-3, 5e-3], 0.3

sync = fl.simulate(formation, law, q0, duration=scenario.duration, integrator=fl.Euler(dt=dt))
run = run_async(formation, law, q0, duration=scenario.duration, dt=dt, periods=periods,
                jitter=jitter, seed=0)  # fmt: skip


def line(name: str, result: fl.SimulationResult) -> str:
    t = result.converged_time()
    when = "never" if t is None else f"{t:.3f} s"
    return (
        f"{name:<13} outcome {result.outcome():<8} status {result.status:<8} "
        f"converged at {when:<9} final shape error {result.shape_error[-1]:.1e}"
    )


print(f"paper triangle, dt = {dt:g} s, {scenario.duration:g} s simulated")
print(line("synchronous", sync))
print(line("asynchronous", run))
print(
    "  periods " + ", ".join(f"{1e3 * T:g} ms" for T in run.periods)
    + f", jitter {jitter:.0%} of each period; updates per robot: "
    + ", ".join(str(k) for k in run.updates)
)  # fmt: skip
print(f"  {run.message}")
