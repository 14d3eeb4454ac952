"""The PettingZoo environment of the robots as agents, and the law as every agent's policy.

The environment driven by the law's decentralized policy is ``simulate`` with explicit
Euler at the same ``dt``: state by state to rounding without sensing faults, and with
noise, delay, drops, range and local frames when the channel has the same seed.
"""

import dataclasses
import importlib
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

import formationlab as fl
from formationlab.envs import law_policy, parallel_env
from formationlab.errors import ParameterError, ScenarioError
from formationlab.io.scenario import load_scenario
from formationlab.scenario import parse_scenario
from formationlab.sensing import Faults, Sensing, Stop

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
NOISY = Sensing(frames="local", noise=0.02, drop=0.2)
SENSED = Sensing(frames="local", noise=0.01, delay=0.002, drop=0.1, range=9.0)


def exact(sc, **kwargs):
    """The environment in float64 ``Dict`` observations from the scenario's own start (the
    form compared with ``simulate`` to rounding)."""
    return parallel_env(sc, **{"observation": "dict", "dtype": np.float64, "jitter": 0.0} | kwargs)


def scenario(name: str, duration: float | None = None):
    sc = load_scenario(EXAMPLES / f"{name}.toml")
    return sc if duration is None else dataclasses.replace(sc, duration=duration)


def run(env, policy=None, seed=0):
    """One episode: the states, observations and the last step's returns."""
    obs, info = env.reset(seed=seed)
    policy = policy or law_policy(env)
    xs, seen = [env.state()], [obs]
    while env.agents:
        obs, rew, term, trunc, info = env.step(policy(obs))
        xs.append(env.state())
        seen.append(obs)
    return np.array(xs), seen, (rew, term, trunc, info)


def reference(sc, t_end, sensing=None):
    return fl.simulate(
        sc.formation, sc.law, sc.x0, duration=t_end, integrator=sc.integrator, model=sc.model,
        backend="numpy", sensing=sensing,
    )  # fmt: skip


CASES = [
    ("paper-simulation-1", None),
    ("paper-simulation-1", NOISY),
    ("paper-simulation-1-unicycle-near-identity", None),
    ("paper-simulation-1-unicycle-near-identity", NOISY),
]


@pytest.mark.parametrize(("name", "sensing"), CASES)
def test_pettingzoo_api_and_seed_tests_pass(name, sensing):
    sc = scenario(name)
    env = exact(sc, sensing=sensing)
    parallel_api_test(env, num_cycles=60)
    parallel_seed_test(lambda: exact(sc, sensing=sensing), num_cycles=60)
    obs, _ = env.reset(seed=3)
    for agent in env.agents:  # what the spaces promise
        assert env.observation_space(agent).contains(obs[agent])
        assert env.action_space(agent).contains(env.action_space(agent).sample())


def test_the_law_policy_reaches_the_triangle_and_is_simulate():
    """Paper's simulation 1: desired formation, and simulate's states to rounding."""
    sc = scenario("paper-simulation-1")
    env = exact(sc)
    xs, _, (rew, term, trunc, info) = run(env)
    assert all(term.values()) and not any(trunc.values())
    assert {i["outcome"] for i in info.values()} == {"desired"}
    assert env.agents == [] and env.t < sc.duration
    errors = fl.outcomes.analysis.distance_errors(sc.formation, xs[-1])
    assert np.abs(errors).max() <= fl.outcomes.analysis.Tolerances().distance
    first = fl.outcomes.analysis.distance_errors(sc.formation, xs[-2])
    assert np.abs(first).max() > 1e-2  # first time
    # the reward is the negative local error: robot 1's edges are 1-2 and 1-3
    for robot, (e, f) in {"robot_1": (0, 1), "robot_2": (0, 2), "robot_3": (1, 2)}.items():
        assert rew[robot] == pytest.approx(-(abs(errors[e]) + abs(errors[f])), abs=1e-15)
    res = reference(sc, env.t)
    assert res.x.shape == xs.shape
    np.testing.assert_allclose(xs, res.x, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "name",
    [
        "paper-simulation-1-unicycle-near-identity",
        "paper-simulation-1-unicycle-heading",
        "paper-simulation-1-double-integrator",
    ],
)
def test_the_law_policy_on_other_models_is_simulate(name):
    """(v, omega) of unicycles and accelerations of double integrators; truncated at 0.8 s."""
    sc = scenario(name, duration=0.8)
    env = exact(sc)
    xs, _, (_, term, trunc, info) = run(env)
    assert all(trunc.values()) and not any(term.values())
    assert len(xs) == 801 and info["robot_2"]["outcome"] == "not-converged"
    np.testing.assert_allclose(xs, reference(sc, 0.8).x, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["triangle-obstacle", "square-marching", "square-safety"])
def test_obstacles_marching_and_a_safety_filter_act_on_the_agents_commands(name):
    """The closed loop adds repulsion and marching and filters the agents' commands."""
    sc = scenario(name, duration=0.3)
    xs, _, _ = run(exact(sc))
    res = fl.simulate(
        sc.formation, sc.law, sc.x0, duration=0.3, integrator=sc.integrator, model=sc.model,
        marching=sc.marching, obstacles=sc.obstacles, safety=sc.safety, backend="numpy",
    )  # fmt: skip
    np.testing.assert_allclose(xs, res.x, rtol=0, atol=1e-12)


def test_a_sensed_episode_is_simulate_with_the_same_seed():
    """Local frames, noise, delay, drops and range: the episode's seed is the channel's."""
    sc = scenario("paper-simulation-1", duration=0.5)
    env = exact(sc, sensing=SENSED)
    xs, _, _ = run(env, seed=11)
    res = reference(sc, 0.5, dataclasses.replace(SENSED, seed=11))
    np.testing.assert_allclose(xs, res.x, rtol=0, atol=1e-12)
    other, _, _ = run(env, seed=12)
    assert np.abs(other - xs).max() > 1e-4  # another seed, another run


def test_same_seed_same_episode_and_another_seed_other_noise():
    sc = scenario("paper-simulation-1")
    env = exact(sc, sensing=NOISY, jitter=0.05)

    def episode(seed):
        obs, info = env.reset(seed=seed)
        for i, agent in enumerate(env.agents):
            env.action_space(agent).seed(100 + i)
        out = [obs]
        for _ in range(30):
            obs = env.step({a: env.action_space(a).sample() for a in env.agents})[0]
            out.append(obs)
        return env.state(), np.array([[o[a]["relative"] for a in o] for o in out]), info

    x1, o1, i1 = episode(5)
    x2, o2, _ = episode(5)
    x3, o3, _ = episode(6)
    assert i1["robot_1"]["seed"] == 5 and np.array_equal(x1, x2) and np.array_equal(o1, o2)
    assert np.abs(o3 - o1).max() > 1e-3 and not np.array_equal(x3, x1)
    env.reset(seed=5)
    _, info = env.reset()  # the next episode of seed 5: another one
    assert info["robot_1"]["seed"] == (5, 1)


def test_observations_are_each_robots_measurements_in_its_frame():
    sc = scenario("paper-simulation-1")
    obs, info = exact(sc).reset(seed=0)
    # robot 1 at (-3, -3) sees robot 2 at (3, -3) and robot 3 at (0, 3)
    np.testing.assert_array_equal(obs["robot_1"]["relative"], [[6.0, 0.0], [3.0, 6.0]])
    np.testing.assert_array_equal(obs["robot_3"]["relative"], [[-3.0, -6.0], [3.0, -6.0]])
    assert obs["robot_2"]["seen"].tolist() == [1, 1] == obs["robot_2"]["neighbour"].tolist()
    assert info["robot_1"]["error"] == pytest.approx(5.0 + math.sqrt(45.0) - 1.0, abs=1e-14)
    assert info["robot_3"]["error"] == pytest.approx(2 * (math.sqrt(45.0) - 1.0), abs=1e-14)
    local = exact(sc, sensing=Sensing(frames="local", range=7.0)).reset(seed=0)[0]
    rel = local["robot_1"]["relative"]  # a rotation keeps the lengths; 3 is within 7 m
    np.testing.assert_allclose(np.linalg.norm(rel, axis=-1), [6.0, math.sqrt(45.0)], atol=1e-12)
    uni = scenario("paper-simulation-1-unicycle-near-identity")
    theta = uni.x0[:, 2]
    g = exact(uni).reset(seed=0)[0]
    np.testing.assert_allclose(g["robot_2"]["heading"], [math.cos(theta[1]), math.sin(theta[1])])
    h = exact(uni, sensing=Sensing(frames="local")).reset(seed=0)[0]
    np.testing.assert_allclose(h["robot_2"]["heading"], [1.0, 0.0], atol=1e-15)
    delayed = exact(sc, sensing=Sensing(delay=0.002)).reset(seed=0)[0]
    assert delayed["robot_1"]["seen"].tolist() == [0, 0]  # nothing has arrived at t = 0
    assert delayed["robot_1"]["relative"].tolist() == [[0.0, 0.0], [0.0, 0.0]]


def test_each_agents_action_uses_its_own_observation_only():
    env = exact(scenario("paper-simulation-1"))
    obs, _ = env.reset(seed=0)
    policy = law_policy(env)
    before = policy(obs)
    obs["robot_2"]["relative"] = obs["robot_2"]["relative"] + 0.3
    after = policy(obs)
    np.testing.assert_array_equal(before["robot_1"], after["robot_1"])
    np.testing.assert_array_equal(before["robot_3"], after["robot_3"])
    assert np.abs(before["robot_2"] - after["robot_2"]).max() > 1e-3


TWO = """
[robots]
positions = [[0.0, 0.0], [0.6, 0.0]]
diameters = 0.2
[formation]
edges = "complete"
distances = 1.0
[controller]
law = "distance"
[simulation]
integrator = "euler"
dt = 0.01
duration = 1.0
"""


@pytest.mark.parametrize(
    ("speed", "steps", "status"), [(5.0, 3, "step-collision"), (100.0, 0, "step-too-large")]
)
def test_contact_ends_the_episode_with_the_penalty(speed, steps, status):
    """Two robots 0.6 m apart driven at each other, a = 0.2: each step closes 2 speed dt."""
    env = exact(TWO, contact_penalty=50.0)
    env.reset(seed=0)
    push = {"robot_1": np.array([speed, 0.0]), "robot_2": np.array([-speed, 0.0])}
    for _ in range(steps):
        rew, term = env.step(push)[1:3]
        assert not any(term.values())
    _, rew, term, _, info = env.step(push)
    assert all(term.values()) and env.agents == []
    assert info["robot_1"]["status"] == status and info["robot_1"]["outcome"] == "collision"
    r = 0.6 - 2 * speed * 0.01 * steps  # the last accepted state is kept
    assert np.linalg.norm(np.diff(env.state(), axis=0)) == pytest.approx(r, abs=1e-12)
    assert rew["robot_1"] == pytest.approx(-abs(r - 1.0) - 50.0, abs=1e-12)
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(push)


def test_a_stopped_robot_ignores_its_action_and_truncation_comes_at_the_duration():
    env = exact(TWO, faults=Faults(stop=[Stop(robot=2, at=0.0)]))
    env.reset(seed=0)
    out = None
    for _ in range(100):
        out = env.step({"robot_1": np.array([-0.1, 0.0]), "robot_2": np.array([1.0, 1.0])})
    np.testing.assert_allclose(env.state(), [[-0.1, 0.0], [0.6, 0.0]], atol=1e-12)
    assert all(out[3].values()) and not any(out[2].values()) and env.t == pytest.approx(1.0)


def test_render_modes():
    env = exact(scenario("paper-simulation-1-unicycle-near-identity"), render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 3  # robots drawn, not a blank page
    # the kept figure draws what a new one draws (the first frame fits the view to both)
    from formationlab.plotting.agent_frame import agent_frame
    from formationlab.plotting.colors import robot_colors

    fresh = agent_frame(env.formation, env.state(), model=env.model, t=0.0)
    assert np.mean(np.any(frame != fresh, axis=-1)) < 1e-3
    colours = np.round(np.array(robot_colors(3))[:, :3] * 255).astype(int)

    def has(image, colour):
        return bool(np.any(np.all(np.abs(image.astype(int) - colour) <= 2, axis=-1)))

    for far in (1, 40):  # a step in the view, and one that carries robot 1 far out of it
        env.step({"robot_1": np.array([far, 0.0]), "robot_2": np.zeros(2), "robot_3": np.zeros(2)})
        later = env.render()
        assert later.shape == frame.shape and not np.array_equal(later, frame)
        assert all(has(later, c) for c in colours)  # every robot is in the picture
        frame = later
    none = exact(scenario("paper-simulation-1"))
    none.reset(seed=0)
    assert none.render() is None


def test_bad_arguments_are_parameter_errors():
    sc = scenario("paper-simulation-1")
    cases = [
        (lambda: exact(sc, render_mode="human"), "render_mode"),
        (lambda: exact(sc, contact_penalty=-1.0), "contact_penalty must be"),
        (lambda: exact(sc, max_command=0.0), "max_command must be a finite number > 0"),
        (lambda: exact(sc, jitter=float("nan")), "jitter must be"),
        (lambda: exact(sc, sensing="local"), "sensing must be a Sensing"),
        (lambda: exact(sc).observation_space("robot_4"), "robot_1 to robot_3"),
        (lambda: exact(sc).reset(seed=-1), "seed must be"),
    ]
    for make, message in cases:
        with pytest.raises(ParameterError, match=message):
            make()
    for bad, message in [(42, "a scenario is a Scenario"), ("[formation", "neither a scenario")]:
        with pytest.raises(ScenarioError, match=message):
            parallel_env(bad)
    for key, value in [("observation", "image"), ("dtype", np.int32), ("dtype", "nonsense")]:
        with pytest.raises(ParameterError, match=f"{key} must be"):
            parallel_env(sc, **{key: value})
    env = exact(sc)
    env.reset(seed=0)
    ok = {a: np.zeros(2) for a in env.agents}
    for actions, message in [
        ({"robot_1": np.zeros(2)}, r"no action for \['robot_2', 'robot_3'\]"),
        ({**ok, "robot_9": np.zeros(2)}, "unknown agents"),
        ({**ok, "robot_2": np.zeros(3)}, r"robot_2 must have shape \(2,\)"),
        ([np.zeros(2)] * 3, "dict of actions"),
    ]:
        with pytest.raises(ParameterError, match=message):
            env.step(actions)
    heading = parse_scenario(
        (EXAMPLES / "paper-simulation-1-unicycle-heading.toml").read_text()
        + "\n[marching]\nvelocity = [0.1, 0.0]\n"
    )
    with pytest.raises(ParameterError, match="near-identity"):
        exact(heading)


def test_a_missing_pettingzoo_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pettingzoo", None)
    monkeypatch.delitem(sys.modules, "formationlab.envs.pettingzoo")
    with pytest.raises(ImportError, match=r"pip install formationlab\[agents\]"):
        importlib.import_module("formationlab.envs.pettingzoo")


def test_the_example_reaches_the_desired_formation(capsys):
    import runpy

    runpy.run_path(str(EXAMPLES / "agents" / "pettingzoo_paper_law.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert out.startswith("outcome: desired at t = ")
    errors = [float(e) for e in re.findall(r"= ([+-]\d\.\d+) m", out)]
    assert len(errors) == 3 and max(map(abs, errors)) <= fl.outcomes.analysis.Tolerances().distance


def test_the_environments_former_address_still_answers_and_warns():
    import formationlab.agents as agents
    import formationlab.envs as envs

    for name in ("parallel_env", "FormationEnv", "law_policy"):
        with pytest.warns(DeprecationWarning, match=rf"formationlab\.envs\.{name}"):
            assert getattr(agents, name) is getattr(envs, name)
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        agents.nothing  # noqa: B018


# --------------------------------------------------------------------------- fitting the tooling


@pytest.mark.parametrize("observation", ["flat", "dict"])
def test_pettingzoo_api_test_passes_on_both_observation_forms(observation):
    env = parallel_env(EXAMPLES / "paper-simulation-1-unicycle-near-identity.toml",
                       observation=observation)  # fmt: skip
    parallel_api_test(env, num_cycles=30)
    obs, _ = env.reset(seed=1)
    space = env.observation_space("robot_2")
    assert space.contains(obs["robot_2"])
    if observation == "flat":  # gymnasium's flattening of the Dict, in float32
        assert obs["robot_2"].dtype == np.float32 and obs["robot_2"].shape == (2 + 2 + 4 + 2,)
        parts = env.as_dict(obs["robot_2"])
        np.testing.assert_array_equal(parts["neighbour"], [1, 1])
        np.testing.assert_allclose(np.linalg.norm(parts["heading"]), 1.0, rtol=1e-6)
    else:
        assert obs["robot_2"]["relative"].dtype == np.float32
    assert env.action_space("robot_2").dtype == np.float32
    wide = parallel_env(EXAMPLES / "paper-simulation-1.toml", dtype=np.float64)
    assert wide.reset(seed=0)[0]["robot_1"].dtype == np.float64


def test_a_path_a_string_path_toml_text_and_a_scenario_make_the_same_environment():
    from formationlab.viewer.sources import open_session

    path = EXAMPLES / "paper-simulation-1.toml"
    firsts = [
        parallel_env(given).reset(seed=5)[0]["robot_3"]
        for given in (path, str(path), path.read_text(), load_scenario(path))
    ]
    for other in firsts[1:]:
        np.testing.assert_array_equal(other, firsts[0])
    # the viewer reads its argument with the same function: TOML text too
    session = open_session(path.read_text())
    np.testing.assert_array_equal(session.scenario.x0, load_scenario(path).x0)


def test_seeds_change_the_start_and_the_same_seed_repeats_it():
    env = parallel_env(EXAMPLES / "paper-simulation-1.toml", observation="dict", dtype=np.float64)
    sc = env.scenario
    starts = []
    for seed in (0, 1, 0):
        env.reset(seed=seed)
        starts.append(env.state()[:, :2])
    assert not np.allclose(starts[0], starts[1])
    np.testing.assert_array_equal(starts[0], starts[2])
    spread = np.concatenate([s - sc.x0[:, :2] for s in starts[:2]]).std()
    jitter = 0.05 * sc.formation.distances.min()  # the documented default
    assert env.jitter == pytest.approx(jitter) and 0.2 * jitter < spread < 5 * jitter
    still = parallel_env(sc, jitter=0.0)
    still.reset(seed=7)
    np.testing.assert_array_equal(still.state(), sc.x0)


def test_supersuit_flattens_and_vectorises_the_flat_environment():
    import supersuit as ss

    path = EXAMPLES / "paper-simulation-1.toml"
    flat = ss.flatten_v0(parallel_env(path))
    obs, _ = flat.reset(seed=0)
    assert obs["robot_1"].shape == (8,) and obs["robot_1"].dtype == np.float32
    vec = ss.concat_vec_envs_v1(
        ss.pettingzoo_env_to_vec_env_v1(parallel_env(path)), 2, num_cpus=0,
        base_class="gymnasium",
    )  # fmt: skip
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (6, 8) and obs.dtype == np.float32  # 2 environments x 3 robots
    assert not np.array_equal(obs[:3], obs[3:])  # two environments, two seeds, two starts
    obs, rewards, *_ = vec.step(np.zeros((6, 2), dtype=np.float32))
    assert obs.shape == (6, 8) and rewards.shape == (6,) and np.all(rewards < 0)


def test_pettingzoo_make_builds_the_registered_environment():
    import pettingzoo

    from formationlab.envs import pettingzoo as module

    path = EXAMPLES / "paper-simulation-1.toml"
    made = pettingzoo.make("parallel", module.ENV_ID, scenario=path, observation="dict")
    assert isinstance(made, module.FormationEnv) and made.observation == "dict"
    assert module.FormationEnv.metadata["name"] == "formationlab_v0"
    aec = pettingzoo.make("aec", module.ENV_ID, scenario=path)
    aec.reset(seed=0)
    assert aec.agent_selection == "robot_1" and aec.observe("robot_1").shape == (8,)
