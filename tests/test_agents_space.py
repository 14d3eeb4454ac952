"""The PettingZoo environment with a formation in space: relative positions and actions of
three components, in each robot's own frame (a rotation of SO(3) with local frames)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

import formationlab as fl
from formationlab.envs import law_policy, parallel_env
from formationlab.errors import ParameterError
from formationlab.io.scenario import load_scenario
from formationlab.models import DoubleIntegrator
from formationlab.sensing import Sensing, measured

SPACE = Path(__file__).resolve().parents[1] / "examples" / "space"
LOCAL = Sensing(frames="local", noise=0.01, drop=0.1)


def tetrahedron(law="distance", model=None, duration=0.3):
    """The mirror tetrahedron under a law that robots can run on their own measurements."""
    sc = load_scenario(SPACE / "tetrahedron-mirror.toml")
    parts = {"law": fl.get_law(law), "duration": duration}
    if model is not None:
        parts["model"] = model
    return dataclasses.replace(sc, **parts)


def exact(sc, **kwargs):
    return parallel_env(sc, **{"observation": "dict", "dtype": np.float64, "jitter": 0.0} | kwargs)


def run(env, seed=0):
    obs, _ = env.reset(seed=seed)
    policy = law_policy(env)
    xs = [env.state()]
    while env.agents:
        obs = env.step(policy(obs))[0]
        xs.append(env.state())
    return np.array(xs)


def reference(sc, t_end, sensing=None):
    return fl.simulate(
        sc.formation, sc.law, sc.x0, duration=t_end, integrator=sc.integrator, model=sc.model,
        backend="numpy", sensing=sensing,
    )  # fmt: skip


def test_spaces_and_the_api_in_space():
    env = exact(tetrahedron(), sensing=LOCAL)
    parallel_api_test(env, num_cycles=30)
    obs, _ = env.reset(seed=2)
    assert env.observation_space("robot_1")["relative"].shape == (3, 3)
    assert env.action_space("robot_1").shape == (3,)
    assert env.state_space.shape == (4, 3)
    for agent in env.agents:
        assert env.observation_space(agent).contains(obs[agent])
    with pytest.raises(ParameterError, match=r"must have shape \(3,\)"):
        env.step({a: np.zeros(2) for a in env.agents})
    flat = parallel_env(tetrahedron(), jitter=0.0)
    assert flat.observation_space("robot_1").shape == (3 * 3 + 3 + 3,)


def test_relative_positions_are_in_each_robots_own_frame():
    """Without noise: robot i sees R_i^T (p_j - p_i), R_i its fixed random rotation, and
    every |z_ij| is the distance |p_j - p_i| (a rotation keeps lengths)."""
    sc = tetrahedron()
    env = exact(sc, sensing=Sensing(frames="local"))
    obs, _ = env.reset(seed=5)
    R = env.channel.frames(env.state()[None], np.array([0]))[0]  # (n, 3, 3)
    assert R.shape == (4, 3, 3)
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)  # fmt: skip
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    z = measured(env.state()[None], R[None])[0]
    p = env.state()
    for i in range(4):
        others = [j for j in range(4) if j != i]
        rel = obs[f"robot_{i + 1}"]["relative"]
        np.testing.assert_allclose(rel, z[i, others], atol=1e-12)
        lengths = np.linalg.norm(p[others] - p[i], axis=-1)
        np.testing.assert_allclose(np.linalg.norm(rel, axis=-1), lengths, atol=1e-12)
        assert np.abs(rel - (p[others] - p[i])).max() > 1e-3  # not the common frame
    # an action in a robot's own frame is R_i a in the common one
    a = {f"robot_{i + 1}": np.array([0.1 * (i + 1), 0.0, 0.0]) for i in range(4)}
    x0 = env.state()
    env.step(a)
    moved = (env.state() - x0) / sc.integrator.dt
    np.testing.assert_allclose(moved, [R[i] @ a[f"robot_{i + 1}"] for i in range(4)], atol=1e-9)


def test_the_law_policy_in_space_is_simulate():
    sc = tetrahedron()
    xs = run(exact(sc))
    assert xs.shape == (151, 4, 3)
    np.testing.assert_allclose(xs, reference(sc, 0.3).x, rtol=0, atol=1e-12)


def test_local_frames_in_space_are_simulate_with_the_same_seed():
    sc = tetrahedron()
    xs = run(exact(sc, sensing=LOCAL), seed=7)
    np.testing.assert_allclose(xs, reference(sc, 0.3, dataclasses.replace(LOCAL, seed=7)).x,
                               rtol=0, atol=1e-12)  # fmt: skip


def test_a_double_integrator_in_space_observes_its_velocity_in_its_frame():
    sc = tetrahedron()
    model = DoubleIntegrator()
    sc = dataclasses.replace(sc, model=model, x0=model.initial_state(sc.q0))
    env = exact(sc, sensing=Sensing(frames="local"))
    assert env.observation_space("robot_1")["velocity"].shape == (3,)
    xs = run(env, seed=4)
    assert xs.shape[-1] == 6
    np.testing.assert_allclose(
        xs, reference(sc, 0.3, Sensing(frames="local", seed=4)).x, rtol=0, atol=1e-12
    )
    env.reset(seed=4)
    env.step({a: np.ones(3) for a in env.agents})
    R = env.channel.frames(env.state()[None], np.array([0]))[0]
    w = env.state()[:, 3:]
    obs = env._observations()
    for i in range(4):
        np.testing.assert_allclose(obs[f"robot_{i + 1}"]["velocity"], R[i].T @ w[i], atol=1e-12)


def test_what_the_environment_cannot_do_in_space_is_refused_by_name():
    with pytest.raises(ParameterError, match=r"run the laws 'distance', 'squared-distance'; "
                       r".* not 'chirality-restricted': choose one of them"):  # fmt: skip
        exact(tetrahedron(law="chirality-restricted"))  # no local form in space (yet)
    with pytest.raises(ParameterError, match="draws formations in the plane"):
        parallel_env(tetrahedron(), render_mode="rgb_array")
