"""The vectorised environment's compiled per-step work (formationlab.envs.stage) against the
numpy functions it replaces: observations (every sensing that is a function of the state),
the reward's errors, the law as policy; the starts drawn once per seed block; the buffer."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from formationlab.envs import vector_law_policy
from formationlab.envs.observations import flat_observations, observation_parts
from formationlab.envs.policy import law_actions
from formationlab.envs.rewards import Rewards, edge_errors, orientation_errors, robot_errors
from formationlab.envs.vector import FormationVectorEnv
from formationlab.io.scenario import load_scenario
from formationlab.sensing import BLOCK, Channel, Sensing
from formationlab.studies.sampling import model_initial_states, trial_initial_states

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TRIANGLE = EXAMPLES / "paper-simulation-1.toml"
NEAR = EXAMPLES / "paper-simulation-1-unicycle-near-identity.toml"
SENSINGS = {
    "paper": None,
    "local-range-mismatch": Sensing(frames="local", range=3.0, mismatch=0.02),
    "frame-error": Sensing(frame_error=0.3),
}


def numpy_observations(env: FormationVectorEnv) -> np.ndarray:
    """Every formation's observations by the numpy functions (the channel's field)."""
    x = env.state()
    which = np.arange(env.num_envs)
    z, seen = env._channel.field(x, which)
    seen = np.ones(z.shape[:-1], dtype=bool) if seen is None else seen
    parts = observation_parts(env.model, x, z, seen, env._channel.angles(x, which), env.others)
    return flat_observations(env.dict_space, parts, env.neighbours, np.float32)


@pytest.mark.parametrize("key", sorted(SENSINGS))
@pytest.mark.parametrize("path", [TRIANGLE, NEAR], ids=["single", "unicycle"])
def test_observations_and_errors_are_the_numpy_functions(path, key):
    sc = load_scenario(path)
    env = FormationVectorEnv(
        sc, num_envs=5, sensing=SENSINGS[key], rewards=Rewards(orientation=1.0)
    )
    obs, info = env.reset(seed=11)
    rng = np.random.default_rng(3)
    for _ in range(4):
        ref = numpy_observations(env)
        if path == TRIANGLE:  # the same operations: the same bits
            np.testing.assert_array_equal(obs, ref)
        else:  # frames of headings: the library's cos and sin, numpy's (an ulp)
            np.testing.assert_allclose(obs, ref, rtol=0, atol=1e-6)
        assert np.count_nonzero(obs != 0) > obs.size // 3  # (not a buffer of zeros)
        p = sc.model.points(env.state())  # (hand points: numpy's cos and sin)
        tol = {"rtol": 0, "atol": 0} if path == TRIANGLE else {"rtol": 1e-12, "atol": 1e-15}
        np.testing.assert_allclose(info["error"], robot_errors(sc.formation, p), **tol)
        top = np.max(edge_errors(sc.formation, p), axis=-1)
        np.testing.assert_allclose(env._worst, top, **tol)
        np.testing.assert_array_equal(env._wrong, orientation_errors(sc.formation, p))
        obs, _, _, _, info = env.step(rng.uniform(-1, 1, (5, 3, 2)))


@pytest.mark.parametrize("key", sorted(SENSINGS))
def test_law_policy_is_law_actions(key):
    sc = load_scenario(TRIANGLE)
    env = FormationVectorEnv(sc, num_envs=6, sensing=SENSINGS[key])
    obs, _ = env.reset(seed=2)
    policy = vector_law_policy(env)
    n, rows = 3, np.arange(3)[:, None]
    for _ in range(3):
        o = obs.astype(float)
        z = np.zeros((6, n, n, 2))
        seen = np.zeros((6, n, n), dtype=bool)
        z[:, rows, env.others] = o[..., env.parts["relative"]].reshape(6, n, n - 1, 2)
        seen[:, rows, env.others] = o[..., env.parts["seen"]] != 0
        want = law_actions(env.terms, env.model, z, seen, env.own_distance, None)
        got = policy(obs)
        np.testing.assert_array_equal(got, want)
        assert np.abs(got).max() > 0.1  # (the law acts)
        obs, *_ = env.step(got)


def test_starts_follow_the_seed_blocks():
    """Episodes past the first seed block (64 trials) start from the study's trials."""
    sc = load_scenario(NEAR)  # unicycles: headings drawn per block too
    env = FormationVectorEnv(sc, num_envs=2)
    env.reset(seed=[5, 8])
    initial = env.initial
    for e in (0, 63, 64, 130, 1):
        env.episodes[:] = e
        got = env.starts.states(env.seeds, env.episodes, np.arange(2))
        for b, s in enumerate([5, 8]):
            q = trial_initial_states(sc.formation, initial, s, [e])
            np.testing.assert_array_equal(
                got[b], model_initial_states(sc.formation, sc.model, q, s, [e])[0]
            )
    assert list(env.starts.block) == [0, 0]  # back to block 0 for episode 1


def test_copy_false_returns_the_buffer():
    sc = dataclasses.replace(load_scenario(TRIANGLE), duration=0.002)
    env = FormationVectorEnv(sc, num_envs=3, copy=False)
    obs, _ = env.reset(seed=0)
    again, *_ = env.step(np.zeros((3, 3, 2)))
    assert again is obs
    copied = FormationVectorEnv(sc, num_envs=3)
    first, _ = copied.reset(seed=0)
    second, *_ = copied.step(np.zeros((3, 3, 2)))
    assert second is not first
    np.testing.assert_array_equal(second, again)


def test_noise_delay_drops_are_the_channels_observations():
    """With noise, delay and drops each formation's observations are those of its own
    channel (Channel.observe, seeded as the study seeds the trial), step after step and
    across a block of draws (BLOCK steps)."""
    sensing = Sensing(frames="local", noise=0.01, delay=0.004, drop=0.3, mismatch=0.02)
    sc = load_scenario(TRIANGLE)
    B = 3
    env = FormationVectorEnv(sc, num_envs=B, sensing=sensing)
    obs, _ = env.reset(seed=[4, 7, 9])
    channels = [
        Channel(sensing, sc.formation, sc.law, sc.model, [(s, 0)], env.dt) for s in (4, 7, 9)
    ]
    one = np.zeros(1, dtype=np.intp)
    rng = np.random.default_rng(1)
    k = np.zeros(B, dtype=int)
    rejected = np.zeros(B, dtype=bool)
    for _ in range(BLOCK + 5):
        x = env.state()
        for b, ch in enumerate(channels):
            if not rejected[b]:
                z, seen = ch.observe(x[b : b + 1], one, int(k[b]))
                parts = observation_parts(sc.model, x[b : b + 1], z, seen, None, env.others)
                ref = flat_observations(env.dict_space, parts, env.neighbours, np.float32)
                np.testing.assert_array_equal(obs[b : b + 1], ref)
        obs, _, _, _, info = env.step(rng.uniform(-0.2, 0.2, (B, 3, 2)))
        rejected = info["rejected"]
        k += ~rejected
    assert k.min() > BLOCK  # (a second block of draws was used)
    np.testing.assert_array_equal(
        env.own_distance[:, None], np.stack([c.own_distance for c in channels])
    )
