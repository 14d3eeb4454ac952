"""The paper's triangle (section 4, simulation 1) with every robot a PettingZoo agent.

Each robot's action is the paper's law computed from its own observation (its measured
relative positions of the other robots, in its own frame): formationlab.envs.law_policy.
The episode ends when the desired formation is reached.

    pip install formationlab[agents]
    python examples/agents/pettingzoo_paper_law.py
"""

from pathlib import Path

import numpy as np

from formationlab.envs import law_policy, parallel_env
from formationlab.outcomes.analysis import distance_errors, edge_labels
from formationlab.io.scenario import load_scenario

scenario = load_scenario(Path(__file__).resolve().parents[1] / "paper-simulation-1.toml")
env = parallel_env(scenario, jitter=0.0)  # the paper's start (default: a jittered one)
policy = law_policy(env)

observations, infos = env.reset(seed=0)
total = dict.fromkeys(env.agents, 0.0)
while env.agents:
    observations, rewards, terminations, truncations, infos = env.step(policy(observations))
    for agent, r in rewards.items():
        total[agent] += r

info = infos["robot_1"]
print(f"outcome: {info['outcome']} at t = {info['t']:.3f} s ({round(info['t'] / env.dt)} steps)")
errors = distance_errors(env.formation, env.model.points(env.state()))
for label, e in zip(edge_labels(env.formation), errors, strict=True):
    print(f"  r_{label} - d_{label} = {e:+.4f} m")
print("return per robot:", ", ".join(f"{a} {v:.1f}" for a, v in total.items()))
print("final positions (m):")
print(np.array2string(env.state()[:, :2], precision=3, suppress_small=True))
