"""Environment steps per second of the vectorised environment, against the PettingZoo one.

One step of ``B`` formations counts ``B`` environment steps. For the paper's triangle
(``examples/paper-simulation-1.toml``) at ``B`` = 1, 64, 1,024 and 16,384 and for ``B`` =
256 formations of 100 robots (a triangular lattice with Delaunay edges, Gaussian starts
around it), with random actions (uniform in the action box, drawn each step, inside the
timing) and with the paper's law as the policy (``vector_law_policy``: every robot's
command from its own observation, on the whole batch), this prints the environment steps
per second of :class:`formationlab.envs.vector.FormationVectorEnv`, and the same step
through the PettingZoo single-formation API (``parallel_env``, dicts of agents, and
``law_policy``) measured in the same run, with their ratio. Formations that end (a
collision under random actions) start again inside the timing, as in training. The
target of issue 29: at least 1e6 environment steps per second for triangles at
``B = 16,384``, printed as PASS or FAIL for each policy, beside the rate of the engine's
compiled step alone on the same states (what the environment adds to it: observations,
rewards, ends, resets and the policy). Best of three timings each.

Run ``python benchmarks/bench_vector_env.py [--quick]`` (``--quick``: fewer steps).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from formationlab.engine.commanded import commanded_rates, commanded_step
from formationlab.envs import law_policy, parallel_env, vector_law_policy
from formationlab.envs.vector import FormationVectorEnv
from formationlab.io.scenario import load_scenario, resolve_scenario

TRIANGLE = Path(__file__).resolve().parents[1] / "examples" / "paper-simulation-1.toml"
HUNDRED = """
name = "lattice-100"
[robots]
positions = { around = "template", sigma = 0.05, seed = 1 }
diameters = 0.2
[formation]
template = { lattice = "triangular", count = 100, spacing = 1.0 }
edges = "delaunay"
orientation = "free"
[controller]
law = "distance"
k_c = 2.0
repulsion = { eta = 1.0, influence = 0.3 }
[simulation]
integrator = "euler"
dt = 1e-3
duration = 15.0
[study]
initial = { kind = "gaussian", sigma = 0.05 }
"""
TARGET = 1e6  # environment steps per second, triangles at B = 16,384


def best(run: Callable[[], float], repeat: int = 3) -> float:
    """The best of ``repeat`` timings (seconds)."""
    return min(run() for _ in range(repeat))


def vector_rate(scenario, B: int, policy: str, steps: int) -> float:
    """Environment steps per second of ``B`` formations under ``policy``."""
    env = FormationVectorEnv(scenario, num_envs=B)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    hi = env.single_action_space.high
    law = vector_law_policy(env)
    act = (lambda o: rng.uniform(-hi, hi, (B, *hi.shape))) if policy == "random" else law
    obs, *_ = env.step(act(obs))  # (first call: compiled kernels loaded)

    def timed() -> float:
        nonlocal obs
        t0 = time.perf_counter()
        for _ in range(steps):
            obs, *_ = env.step(act(obs))
        return time.perf_counter() - t0

    return B * steps / best(timed)


def compiled_step_rate(scenario, B: int, steps: int) -> float:
    """Environment steps per second of the engine's compiled step alone (the model stage's
    rates and the judged Euler step, :mod:`formationlab.engine.commanded`) on the states of
    ``B`` formations: what the environment's step costs at the least."""
    env = FormationVectorEnv(scenario, num_envs=B)
    env.reset(seed=0)
    x = env.state().transpose(1, 2, 0).copy()  # the loop's layout (n, k, B)
    u = np.zeros((x.shape[0], 2, B))
    f, xn, code = np.empty_like(x), np.empty_like(x), np.zeros(B, dtype=np.int8)

    def timed() -> float:
        t0 = time.perf_counter()
        for _ in range(steps):
            commanded_rates(x, u, f, env._model_terms)
            commanded_step(x, f, xn, env.dt, env._terms, code)
        return time.perf_counter() - t0

    timed()
    return B * steps / best(timed)


def pettingzoo_rate(scenario, policy: str, steps: int) -> float:
    """Environment steps per second of one formation through the PettingZoo API."""
    env = parallel_env(scenario)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    law = law_policy(env)
    spaces = {a: env.action_space(a) for a in env.possible_agents}

    def act(o):
        if policy == "random":
            return {a: rng.uniform(spaces[a].low, spaces[a].high) for a in o}
        return law(o)

    def timed() -> float:
        nonlocal obs
        t0 = time.perf_counter()
        for _ in range(steps):
            obs, *_ = env.step(act(obs))
            if not env.agents:
                obs, _ = env.reset()
        return time.perf_counter() - t0

    return steps / best(timed)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer steps per timing")
    args = ap.parse_args()
    scale = 0.2 if args.quick else 1.0
    triangle, hundred = load_scenario(TRIANGLE), resolve_scenario(HUNDRED)
    cases = [("triangle", triangle, B) for B in (1, 64, 1024, 16384)]
    cases.append(("100 robots", hundred, 256))
    print("environment steps per second (one step of B formations counts B)")
    alone = compiled_step_rate(triangle, 16384, max(20, int(200 * scale)))
    print(f"\ncompiled step alone (engine.commanded), triangle, B = 16,384: {alone:,.0f}")
    for policy in ("random", "law"):
        pz = {
            "triangle": pettingzoo_rate(triangle, policy, max(20, int(2000 * scale))),
            "100 robots": pettingzoo_rate(hundred, policy, max(5, int(100 * scale))),
        }
        print(f"\npolicy: {policy}")
        print(f"  PettingZoo, one formation: triangle {pz['triangle']:,.0f}, "
              f"100 robots {pz['100 robots']:,.0f}")  # fmt: skip
        for name, sc, B in cases:
            n = sc.formation.n
            steps = max(3, int(scale * min(2000, 2e6 / (B * n * n))))
            rate = vector_rate(sc, B, policy, steps)
            line = f"  vector, {name}, B = {B:>6,}: {rate:>14,.0f}"
            line += f"  ({rate / pz[name]:>8,.1f} x PettingZoo)"
            if name == "triangle" and B == 16384:
                verdict = "PASS" if rate >= TARGET else "FAIL"
                line += f"   target >= {TARGET:,.0f}: {verdict}"
                line += f"; the step alone is {alone / rate:.1f} x faster"
            print(line)


if __name__ == "__main__":
    main()
