"""The vectorised environment (formationlab.envs.vector): B formations equal B environments
of one formation, bit for bit; the PettingZoo environment's step; spaces, autoreset, every
robot model, sensing, faults, rewards, the law as policy, refusals."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import gymnasium
import numpy as np
import pytest

from formationlab.envs import parallel_env, vector_law_policy
from formationlab.envs.policy import law_policy
from formationlab.envs.rewards import Rewards, orientation_errors, robot_errors
from formationlab.envs.vector import VECTOR_ENV_ID, FormationVectorEnv
from formationlab.errors import ParameterError
from formationlab.io.scenario import load_scenario
from formationlab.outcomes.tolerances import OUTCOMES
from formationlab.sensing import Channel, Faults, Sensing
from formationlab.sensing.config import Stop

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TRIANGLE = EXAMPLES / "paper-simulation-1.toml"
MODELS = [
    "paper-simulation-1.toml",
    "paper-simulation-1-unicycle-near-identity.toml",
    "paper-simulation-1-unicycle-heading.toml",
    "paper-simulation-1-double-integrator.toml",
]
SENSINGS = {
    "local-mismatch-range": Sensing(frames="local", mismatch=0.02, range=4.0),
    "noise-delay-drop": Sensing(frames="local", noise=0.01, delay=0.01, drop=0.3),
}


def short(path: Path, duration: float = 0.03):
    """The scenario with a short episode, so that formations reset within a test."""
    sc = load_scenario(path)
    return dataclasses.replace(sc, duration=duration)


def run(env: FormationVectorEnv, seed, actions):
    """Observations, rewards, ends and outcomes of ``env`` under ``actions`` (T, B, n, 2)."""
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out += [obs, r, term, trunc, info["outcome"].astype(str), info["error"]]
        if "_final_obs" in info:
            out.append(info["final_obs"][info["_final_obs"]])
    return out


def assert_same(batch, singles):
    """``batch`` (lists of B-row arrays) equals the B ``singles``' rows, bit for bit."""
    for b, single in enumerate(singles):
        for got, one in zip(batch, single, strict=True):
            if got.ndim and got.shape[0] == len(singles) and one.shape[0] == 1:
                np.testing.assert_array_equal(got[b : b + 1], one)


@pytest.mark.parametrize("name", MODELS)
def test_batch_equals_single_environments_for_every_model(name):
    # 12 steps of a 10-step episode: every formation resets once, mid-test
    sc = short(EXAMPLES / name, duration=10 * 1e-3 if "simulation-1" in name else 0.05)
    B = 3
    env = FormationVectorEnv(sc, num_envs=B)
    rng = np.random.default_rng(5)
    acts = rng.uniform(-1, 1, (12, B, 3, 2))
    batch = run(env, 40, acts)
    singles = [
        run(FormationVectorEnv(sc, num_envs=1), 40 + b, acts[:, b : b + 1]) for b in range(B)
    ]
    assert_same(batch, singles)
    assert env.episodes.min() >= 1  # every formation started a second episode
    np.testing.assert_array_equal(env.seeds, [40, 41, 42])


@pytest.mark.parametrize("key", sorted(SENSINGS))
def test_batch_equals_single_environments_with_sensing(key):
    sc = short(EXAMPLES / "agents" / "robustness-triangle.toml", duration=0.05)
    sc = dataclasses.replace(sc, faults=None)
    B = 3
    env = FormationVectorEnv(sc, num_envs=B, sensing=SENSINGS[key])
    acts = np.random.default_rng(2).uniform(-1, 1, (13, B, 3, 2))
    batch = run(env, [7, 3, 11], acts)
    singles = [
        run(FormationVectorEnv(sc, num_envs=1, sensing=SENSINGS[key]), [s], acts[:, b : b + 1])
        for b, s in enumerate([7, 3, 11])
    ]
    assert_same(batch, singles)
    assert env.episodes.min() >= 1


@pytest.mark.parametrize("name", [*MODELS, "sensed"])
def test_step_is_the_pettingzoo_environments(name):
    """From the same state and channel, the PettingZoo environment's step and the vector
    environment's give the same observations and rewards (the compiled model stage's
    rates, the driver's to rounding: unicycles' cos and sin from two libraries)."""
    sensing = SENSINGS["local-mismatch-range"] if name == "sensed" else None
    sc = load_scenario(EXAMPLES / ("paper-simulation-1.toml" if name == "sensed" else name))
    venv = FormationVectorEnv(sc, num_envs=1, sensing=sensing)
    obs, _ = venv.reset(seed=9)
    pz = parallel_env(sc, sensing=sensing)
    pz.reset(seed=1)
    pz.channel = Channel(pz.sensing, sc.formation, sc.law, sc.model, [(9, 0)], pz.dt)
    pz._x = venv.state()[0]
    pz._observe()
    rng = np.random.default_rng(0)
    for _ in range(5):
        got = pz._observations()
        np.testing.assert_allclose(np.stack([got[a] for a in pz.agents]), obs[0], atol=1e-6)
        a = rng.uniform(-1, 1, (1, 3, 2))
        obs, r, *_ = venv.step(a)
        _, rp, *_ = pz.step({f"robot_{i + 1}": a[0, i] for i in range(3)})
        np.testing.assert_allclose(r[0], [rp[f"robot_{i + 1}"] for i in range(3)], rtol=1e-12)
        np.testing.assert_allclose(venv.state()[0], pz.state(), rtol=1e-13, atol=1e-15)


def test_spaces_autoreset_and_infos():
    sc = short(TRIANGLE, duration=5e-3)  # 5 steps
    env = FormationVectorEnv(sc, num_envs=4)
    assert env.metadata["autoreset_mode"] == gymnasium.vector.AutoresetMode.SAME_STEP
    assert env.single_observation_space.shape == (3, 8)  # 2 x 2 relative, 2 seen, 2 neighbour
    assert env.observation_space.shape == (4, 3, 8)
    assert env.action_space.shape == (4, 3, 2)
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    first = obs.copy()
    zero = np.zeros((4, 3, 2))
    for k in range(5):
        obs, r, term, trunc, info = env.step(zero)
        assert r.shape == (4, 3) and term.shape == trunc.shape == (4,)
        assert env.observation_space.contains(obs)
        assert trunc.all() == (k == 4) and not term.any()
    # at the 5th step each formation's episode 1 starts (trial 1 of its study), and the
    # last observation of episode 0 is in final_obs: with no motion, its first one
    assert info["_final_obs"].all()
    np.testing.assert_array_equal(info["final_obs"], first)
    assert list(env.episodes) == [1, 1, 1, 1] and not np.array_equal(obs, first)
    assert set(info["outcome"]) <= {"not-converged", "incorrect", "mirror", "drifting"}
    np.testing.assert_array_equal(info["t"], 5 * 1e-3)  # (the time of the last state)


def test_starts_are_the_studys_trials():
    from formationlab.studies.config import parse_study
    from formationlab.studies.sampling import trial_initial_states

    sc = load_scenario(TRIANGLE)
    env = FormationVectorEnv(sc, num_envs=2)
    env.reset(seed=[4, 9])
    initial = parse_study(sc.study).initial
    for b, s in enumerate([4, 9]):
        q = trial_initial_states(sc.formation, initial, s, [0])[0]
        np.testing.assert_array_equal(env.state()[b], q)


def test_registered_with_gymnasium():
    env = gymnasium.make_vec(VECTOR_ENV_ID, num_envs=2, scenario=TRIANGLE)
    assert isinstance(env.unwrapped, FormationVectorEnv) and env.num_envs == 2
    obs, _ = env.reset(seed=1)
    assert obs.shape == (2, 3, 8)


def test_law_as_policy_equals_pettingzoo_policy_and_converges():
    sc = load_scenario(TRIANGLE)
    env = FormationVectorEnv(sc, num_envs=2)
    policy = vector_law_policy(env)
    obs, _ = env.reset(seed=3)
    pz = parallel_env(sc)
    pz.reset(seed=0)
    pz_policy = law_policy(pz)
    got = pz_policy({f"robot_{i + 1}": obs[0, i] for i in range(3)})
    np.testing.assert_array_equal(
        policy(obs)[0], np.stack([got[f"robot_{i + 1}"] for i in range(3)])
    )
    e0 = robot_errors(sc.formation, env.state()[..., :2]).sum()
    for _ in range(300):
        obs, _, term, trunc, _ = env.step(policy(obs))
        assert not term.any() and not trunc.any()
    assert robot_errors(sc.formation, env.state()[..., :2]).sum() < 0.5 * e0


def test_rewards_terms():
    sc = load_scenario(TRIANGLE)
    f = sc.formation
    q = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.5]])
    mirror = q * [1.0, -1.0]
    wrong = orientation_errors(f, np.stack([q, mirror]))
    # each robot holds one restricted triple of the triangle: all right or all wrong
    assert sorted({tuple(wrong[0]), tuple(wrong[1])}) == [(0.0, 0.0, 0.0), (1.0, 1.0, 1.0)]
    e = robot_errors(f, q[None])[0]
    r12, r13 = 1.0, np.hypot(0.5, 0.5)
    assert e[0] == pytest.approx(abs(r12 - 1.0) + abs(r13 - 1.0))  # d_ij = 1 (the paper's)
    u = np.array([[[3.0, 4.0], [0.0, 0.0], [1.0, 0.0]]])
    r = Rewards(distance=0.0, effort=2.0, collision=7.0).of(f, q[None], u, np.array([True]))
    np.testing.assert_allclose(r, [[-50.0 - 7.0, -7.0, -2.0 - 7.0]])
    with pytest.raises(ParameterError) as err:
        Rewards(effort=-1.0)
    assert err.value.key == "rewards.effort"


def test_a_stopped_robot_stays():
    sc = dataclasses.replace(load_scenario(TRIANGLE), faults=Faults(stop=(Stop(robot=2, at=0.0),)))
    env = FormationVectorEnv(sc, num_envs=2)
    env.reset(seed=0)
    x0 = env.state()
    env.step(np.ones((2, 3, 2)))
    x1 = env.state()
    np.testing.assert_array_equal(x1[:, 1], x0[:, 1])
    assert np.all(x1[:, [0, 2]] != x0[:, [0, 2]])


@pytest.mark.parametrize(
    ("name", "key"),
    [("square-marching.toml", "marching"), ("square-safety.toml", "safety")],
)
def test_refuses_what_it_does_not_step(name, key):
    with pytest.raises(ParameterError, match="PettingZoo environment") as err:
        FormationVectorEnv(EXAMPLES / name, num_envs=2)
    assert err.value.key == key


def test_refuses_bad_input():
    sc = load_scenario(TRIANGLE)
    with pytest.raises(ParameterError) as err:
        FormationVectorEnv(sc, num_envs=0)
    assert err.value.key == "num_envs"
    env = FormationVectorEnv(sc, num_envs=2)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros((2, 3, 2)))
    env.reset(seed=0)
    with pytest.raises(ParameterError, match=r"shape \(2, 3, 2\)") as err:
        env.step(np.zeros((3, 2)))
    assert err.value.key == "actions"
    with pytest.raises(ParameterError, match="2 seeds"):
        env.reset(seed=[1, 2, 3])


def test_torchrl_adapter():
    pytest.importorskip("torchrl")  # the optional 'torch' extra (not in the test extra)
    from formationlab.envs.torchrl import outcome_codes, torchrl_env

    env = torchrl_env(TRIANGLE, num_envs=4)
    assert tuple(env.batch_size) == (4,)
    td = env.rollout(3)
    assert tuple(td["observation"].shape) == (4, 3, 3, 8)
    # every robot's own reward (not one per formation broadcast), (B, T, n, 1)
    reward = td["next", "reward"].numpy()
    assert reward.shape == (4, 3, 3, 1) and np.isfinite(reward).all()
    assert np.any(reward[..., 0, 0] != reward[..., 1, 0])
    # the steps chain: the next observation is the following step's (no episode ended)
    codes = td["next", "outcome_code"].numpy()
    assert codes.shape == (4, 3) and np.all(codes == -1)
    np.testing.assert_array_equal(td["next", "observation"][:, :-1].numpy(),
                                  td["observation"][:, 1:].numpy())  # fmt: skip
    assert list(outcome_codes(np.array(["", "desired", "collision"], dtype=object))) == [
        -1, OUTCOMES.index("desired"), OUTCOMES.index("collision")]  # fmt: skip
