"""The learned law and its training (docs/learning.md).

The network's forward pass (shapes, a stack of candidates = each alone), what the law's form
promises (each robot's command turns with its own frame; a mirror image with the desired
signs reversed gets the mirror command; relabelling robots relabels commands; the desired
shape is an equilibrium whatever the weights), the law = a plain loop over each robot's
measurements, CMA-ES improving the reward on a tiny seeded budget, ``formationlab train``
and a study of the file it wrote giving the fractions training's evaluation stored, and bad
parameters files refused by key.
"""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from _scenarios import clear_starts, triangle
from typer.testing import CliRunner, Result

import formationlab as fl
from formationlab.cli import _load_commands, app
from formationlab.controllers.network import (
    Network,
    forward,
    network_arrays,
    network_from_arrays,
    parameter_count,
)
from formationlab.controllers.policy import (
    FEATURES,
    OUTPUTS,
    PolicyLaw,
    neighbourhoods,
    policy_control,
    triple_commands,
)
from formationlab.errors import ParameterError, ScenarioError
from formationlab.io.policy import read_curve
from formationlab.io.scenario import load_scenario
from formationlab.learning import TrainingConfig, episode_reward, rollout, train
from formationlab.studies.batch import batch_backend
from formationlab.studies.config import BoxInitial
from formationlab.studies.sampling import trial_initial_states

_load_commands()
runner = CliRunner()

SIZES = (FEATURES, 8, 8, OUTPUTS)
#: the paper's triangle (alpha of simulation 2: clockwise 1-2-3) and the unit square with
#: both diagonals, counter-clockwise
TRIANGLE = fl.Formation.from_alpha_table(
    [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]], n=3, distances=1.0, diameters=0.2
)
SQUARE = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], diameters=0.2)

STUDY = '[study]\ntrials = 16\ninitial = { kind = "box", half_width = 3.0 }\n'


def scenario_text(law: str, parameters: str = "") -> str:
    """The paper's triangle under ``law`` (coarse step, 6 s) with a study of 16 trials;
    ``parameters``: the policy law's file, as TOML text."""
    text = triangle("learned-triangle", "6.0", STUDY).replace("dt = 1e-3", "dt = 0.005")
    gains = "k_c = 2.0\nk_a = 3.0\ntheta = 0.5\n"  # the paper's, which the learned law takes not
    text = text.replace(gains, gains if law != "policy" else "")
    return text.replace('law = "angle-restricted"', f'law = "{law}"\n{parameters}')


def invoke(*args: object) -> Result:
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


def random_network(seed: int = 0, scale: float = 0.7) -> Network:
    rng = np.random.default_rng(seed)
    return Network.from_flat(SIZES, scale * rng.normal(size=parameter_count(SIZES)))


def turn(angle: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 2, 2)``."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


# ----------------------------------------------------------------------------- the network


def test_the_forward_pass_maps_features_to_outputs_and_a_stack_runs_each_network() -> None:
    net = random_network()
    x = np.random.default_rng(1).normal(size=(5, 7, FEATURES))
    y = forward(net, x)
    assert net.sizes == SIZES and y.shape == (5, 7, OUTPUTS)
    # by hand: tanh hidden layers, a linear output
    h = np.tanh(np.tanh(x @ net.weights[0] + net.biases[0]) @ net.weights[1] + net.biases[1])
    np.testing.assert_allclose(y, h @ net.weights[2] + net.biases[2], rtol=0, atol=1e-12)
    flats = np.random.default_rng(2).normal(size=(3, parameter_count(SIZES)))
    stack = Network.from_flat(SIZES, flats)
    ys = forward(stack, np.broadcast_to(x, (3, *x.shape)))
    for p in range(3):
        alone = Network.from_flat(SIZES, flats[p])
        np.testing.assert_allclose(ys[p], forward(alone, x), rtol=0, atol=1e-12)
        np.testing.assert_array_equal(alone.flat(), flats[p])
    again = network_from_arrays(network_arrays(net))
    np.testing.assert_array_equal(again.flat(), net.flat())


def test_a_network_refuses_shapes_that_do_not_chain() -> None:
    with pytest.raises(ParameterError, match="layer 2 takes 3 inputs but layer 1 gives 4"):
        Network(weights=(np.zeros((6, 4)), np.zeros((3, 2))), biases=(np.zeros(4), np.zeros(2)))
    with pytest.raises(ParameterError, match="has 146 parameters, got 3"):
        Network.from_flat(SIZES, [1.0, 2.0, 3.0])


# ------------------------------------------------------------------- what the law promises


@pytest.mark.parametrize("formation", [TRIANGLE, SQUARE], ids=["triangle", "square"])
def test_turning_each_robots_frame_turns_its_command(formation: fl.Formation) -> None:
    net, hoods = random_network(3), neighbourhoods(formation)
    q = clear_starts(formation.n, 6, 4)
    args = (hoods.sign, hoods.d_ij, hoods.d_ik)
    r_ij = q[:, hoods.j] - q[:, hoods.i]
    r_ik = q[:, hoods.k] - q[:, hoods.i]
    world = triple_commands(net, r_ij, r_ik, *args)
    angles = np.random.default_rng(5).uniform(-np.pi, np.pi, (6, formation.n))
    frame = turn(-angles)[:, hoods.i]  # world -> robot i's frame, per triple of robot i
    own = triple_commands(
        net, np.einsum("btxy,bty->btx", frame, r_ij), np.einsum("btxy,bty->btx", frame, r_ik),
        *args,
    )  # fmt: skip
    back = np.einsum("btyx,bty->btx", frame, own)  # robot i's frame -> world
    assert np.abs(world).max() > 0.05  # not a comparison of zeros
    np.testing.assert_allclose(back, world, rtol=0, atol=1e-12)
    assert np.abs(own - world).max() > 1e-3  # the command really was in the robot's frame


def test_the_mirror_image_with_reversed_signs_gets_the_mirror_command() -> None:
    law = PolicyLaw.from_network(random_network(6))
    q = clear_starts(4, 5, 7)
    mirror = np.array([-1.0, 1.0])
    flipped = fl.Formation.from_template(
        [[0, 0], [-1, 0], [-1, 1], [0, 1]], diameters=0.2
    )  # the square's mirror image: every desired sign reversed
    u = law.control(SQUARE, q)
    np.testing.assert_allclose(law.control(flipped, q * mirror), u * mirror, rtol=0, atol=1e-12)
    # and the same positions under the reversed signs are commanded otherwise
    assert np.abs(law.control(flipped, q) - u).max() > 1e-3


def test_relabelling_the_robots_relabels_the_commands() -> None:
    law = PolicyLaw.from_network(random_network(8))
    template = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    perm = np.array([2, 0, 3, 1])
    relabelled = fl.Formation.from_template(template[perm], diameters=0.2)
    q = clear_starts(4, 5, 9)
    np.testing.assert_allclose(
        law.control(relabelled, q[:, perm]), law.control(SQUARE, q)[:, perm], rtol=0, atol=1e-12
    )


def test_the_law_is_each_robots_network_on_its_own_measurements() -> None:
    """The law against a plain loop over robots and their ordered pairs of neighbours."""
    net = random_network(10)
    law = PolicyLaw.from_network(net)
    q = clear_starts(4, 3, 11)
    u = law.control(SQUARE, q)
    for b in range(len(q)):
        for i in range(4):
            others = [j for j in range(4) if j != i]  # the complete graph
            expected = np.zeros(2)
            for j in others:
                for k in others:
                    if j == k:
                        continue
                    r_ij, r_ik = q[b, j] - q[b, i], q[b, k] - q[b, i]
                    c = r_ij[0] * r_ik[1] - r_ij[1] * r_ik[0]
                    s = float(SQUARE.desired_sign[i, j, k])
                    sin = c / (np.linalg.norm(r_ij) * np.linalg.norm(r_ik))
                    cos = r_ij @ r_ik / (np.linalg.norm(r_ij) * np.linalg.norm(r_ik))
                    d_ij, d_ik = SQUARE.distance_matrix[i, j], SQUARE.distance_matrix[i, k]
                    x = np.array([np.log(np.linalg.norm(r_ij) / d_ij),
                                  np.log(np.linalg.norm(r_ik) / d_ik),
                                  max(-s * sin, 0.0), cos, s * sin, abs(s)])  # fmt: skip
                    x0 = np.array([0.0, 0.0, 0.0, cos, s * sin, abs(s)])
                    a, bb = forward(net, x) - forward(net, x0)
                    g = r_ij / np.linalg.norm(r_ij)
                    expected += (a * g + s * bb * np.array([-g[1], g[0]])) / 2  # deg - 1 = 2
            np.testing.assert_allclose(u[b, i], expected, rtol=0, atol=1e-12)
    # translations change nothing
    np.testing.assert_allclose(
        law.control(SQUARE, q + np.array([5.0, -2.0])), u, rtol=0, atol=1e-12
    )


def test_the_desired_shape_is_an_equilibrium_and_its_mirror_need_not_be() -> None:
    law = PolicyLaw.from_network(random_network(12))
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    turned = square @ turn(np.array(0.7)).T + [3.0, 1.0]
    np.testing.assert_allclose(law.control(SQUARE, turned), 0.0, rtol=0, atol=1e-12)
    assert np.abs(law.control(SQUARE, turned * [-1.0, 1.0])).max() > 1e-3


# --------------------------------------------------------------------------------- training


def test_a_rollout_integrates_effort_and_peak_speed_and_freezes_a_collision() -> None:
    """Under a constant field every sum is by hand: q(T) = q0 + T u, effort T sum |u_i|^2."""
    q0 = np.array([[[0.0, 0.0], [1.0, 0.0], [0.5, 1.0]], [[0.0, 0.0], [0.3, 0.0], [0.5, 1.0]]])
    u = np.array([[0.5, 0.0], [-0.5, 0.0], [0.0, 0.2]])  # robots 1 and 2 close in at speed 1
    ended = rollout(lambda q: np.broadcast_to(u, q.shape).copy(), TRIANGLE, q0, dt=0.01,
                    steps=20)  # fmt: skip
    assert not ended.collided[0] and ended.collided[1]  # 0.3 - 0.2 = 0.1 closes in 0.1 s
    np.testing.assert_allclose(ended.q[0], q0[0] + 0.2 * u, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ended.effort[0], 0.2 * (0.25 + 0.25 + 0.04), rtol=1e-12)
    np.testing.assert_allclose(ended.peak_speed, 0.5, rtol=1e-12)
    gap = np.linalg.norm(ended.q[1, 1] - ended.q[1, 0])
    assert 0.19 <= gap <= 0.2 and ended.effort[1] < ended.effort[0]  # frozen at contact


def test_cma_training_improves_the_reward_on_a_tiny_seeded_budget() -> None:
    config = TrainingConfig(generations=8, population=8, batch=16, duration=4.0, dt=0.05, seed=1)
    a = train(TRIANGLE, BoxInitial(half_width=3.0), config)
    b = train(TRIANGLE, BoxInitial(half_width=3.0), config)
    np.testing.assert_array_equal(a.network.flat(), b.network.flat())  # seeded
    assert len(a.curve["centre"]) == 8 and a.curve["evaluations"][-1] == 64
    assert np.all(a.curve["best"] >= a.curve["mean"])
    # on starts it never saw (another seed), against the all-zero network CMA-ES starts
    # from, which leaves the robots where they are
    starts = trial_initial_states(TRIANGLE, BoxInitial(half_width=3.0), 99, np.arange(64))
    hoods, zero = neighbourhoods(TRIANGLE), Network.from_flat(config.sizes, 0.0 * a.network.flat())
    before, after = (
        episode_reward(
            TRIANGLE, rollout(partial(policy_control, net, hoods), TRIANGLE, starts, dt=0.05,
                              steps=80),
        ).mean()
        for net in (zero, a.network)
    )  # fmt: skip
    assert before < -1.0 and after > before + 1.0, (before, after)


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """``formationlab train`` on a tiny budget, its evaluation a study of 16 trials."""
    root = tmp_path_factory.mktemp("learn")
    scenario = root / "train.toml"
    scenario.write_text(scenario_text("distance"))
    out = root / "policies" / "tiny.npz"
    res = invoke("train", scenario, "--out", out, "-g", 3, "-p", 4, "-b", 8, "--seed", 2,
                 "--eval-trials", 16, "--eval-seed", 5, "--figure", root / "curve.png",
                 "--quiet")  # fmt: skip
    assert res.exit_code == 0, res.output
    return scenario, out


def test_train_writes_the_network_its_curve_and_the_evaluation(trained) -> None:
    _, out = trained
    curve, meta = read_curve(out)
    assert list(curve["generation"]) == [1.0, 2.0, 3.0]
    assert meta["training"]["population"] == 4 and meta["evaluation"]["seed"] == 5
    assert sum(meta["evaluation"]["fractions"].values()) == pytest.approx(1.0)
    csv = out.with_name("tiny-training.csv").read_text().splitlines()
    assert csv[0].startswith("generation,evaluations,best,mean,centre") and len(csv) == 4
    assert (out.parent.parent / "curve.png").stat().st_size > 1000
    assert PolicyLaw(parameters=str(out)).network.sizes == (FEATURES, 16, 16, OUTPUTS)


def test_a_study_of_the_saved_policy_gives_the_fractions_of_trainings_evaluation(
    trained, tmp_path: Path
) -> None:
    _, out = trained
    folder = tmp_path / "elsewhere"
    folder.mkdir()
    scenario = folder / "policy.toml"
    scenario.write_text(scenario_text("policy", f'parameters = "{out}"'))
    res = invoke("study", scenario, "--out", tmp_path / "study", "--seed", 5, "--quiet")
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "study" / "summary.json").read_text())
    (group,) = summary["groups"]
    _, meta = read_curve(out)
    assert group["law"] == "policy" and group["trials"] == 16
    assert group["fractions"] == meta["evaluation"]["fractions"]
    assert summary["backend_used"] == "numpy"


def test_a_relative_parameters_path_is_relative_to_the_scenario_file(trained, tmp_path) -> None:
    _, out = trained
    scenario = out.parent / "uses.toml"
    scenario.write_text(scenario_text("policy", 'parameters = "tiny.npz"'))
    law = load_scenario(scenario).law
    assert isinstance(law, PolicyLaw) and Path(law.parameters) == out
    assert law.digest and law.digest == PolicyLaw(parameters=str(out)).digest


def test_an_output_folder_keeps_the_policy_file_and_runs_again_from_there(trained, tmp_path):
    # the copied scenario names a copy of the file beside it, not the original's relative path
    _, out = trained
    scenario = out.parent / "uses-again.toml"
    scenario.write_text(scenario_text("policy", 'parameters = "tiny.npz"  # the network'))
    res = invoke("study", scenario, "--out", tmp_path / "study", "--seed", 5, "--quiet")
    assert res.exit_code == 0, res.output
    folder = tmp_path / "study"
    assert (folder / "tiny.npz").read_bytes() == out.read_bytes()
    copied = (folder / "scenario.toml").read_text()
    assert 'parameters = "tiny.npz"  # the network' in copied
    law = load_scenario(folder / "scenario.toml").law
    assert (
        Path(law.parameters) == folder / "tiny.npz"
        and law.digest == PolicyLaw(parameters=str(out)).digest
    )
    moved = tmp_path / "moved"
    folder.rename(moved)  # the folder carries what it needs
    res = invoke("run", moved / "scenario.toml", "--out", tmp_path / "again", "-q")
    assert res.exit_code in (0, 1), res.output  # (1: the tiny policy's robots may touch)
    assert (tmp_path / "again" / "trajectory.nc").exists()
    assert (tmp_path / "again" / "tiny.npz").read_bytes() == out.read_bytes()


def test_the_study_chooses_the_numpy_path_for_the_learned_law(trained) -> None:
    _, out = trained
    law = PolicyLaw(parameters=str(out))
    assert not law.compiles() and fl.get_law("distance").compiles()
    backend, note = batch_backend("numba", laws=[law])
    assert backend == "numpy" and "'policy'" in note
    backend, note = batch_backend("numba", laws=[fl.get_law("distance"), law])  # a study's
    assert backend == "numba" and "'policy'" in note and "other laws' on the compiled" in note
    assert batch_backend("numba", laws=[fl.get_law("distance")]) == ("numba", "")


# ------------------------------------------------------------------------------ bad input


def _bad_files(root: Path) -> dict[str, tuple[Path, str]]:
    text = root / "text.npz"
    text.write_text("not a zip")
    empty = root / "empty.npz"
    np.savez(empty, something=np.zeros(3))
    chain = root / "chain.npz"
    np.savez(chain, W1=np.zeros((6, 4)), b1=np.zeros(4), W2=np.zeros((3, 2)), b2=np.zeros(2))
    inputs = root / "inputs.npz"
    np.savez(inputs, W1=np.zeros((5, 2)), b1=np.zeros(2))
    return {
        "missing": (root / "nowhere.npz", "does not exist"),
        "folder": (root, "is a folder"),
        "not npz": (text, "is not a .npz"),
        "no network": (empty, "expected arrays W1, b1"),
        "shapes": (chain, "layer 2 takes 3 inputs"),
        "inputs": (inputs, "5 inputs and 2 outputs; the policy law's takes 6"),
    }


def test_bad_parameters_files_are_refused_with_the_key_named(tmp_path: Path) -> None:
    for path, message in _bad_files(tmp_path).values():
        scenario = tmp_path / "bad.toml"
        scenario.write_text(scenario_text("policy", f'parameters = "{path}"'))
        with pytest.raises(ScenarioError, match=message) as err:
            load_scenario(scenario)
        assert err.value.key == "controller.parameters"
        assert f"{scenario}: controller.parameters (line " in str(err.value)
    no_file = tmp_path / "none.toml"
    no_file.write_text(scenario_text("policy"))
    law = load_scenario(no_file).law  # built, but it refuses to run, naming the key
    with pytest.raises(ParameterError, match=r'parameters = "policy\.npz"') as err:
        law.control(TRIANGLE, clear_starts(3, 1, 0))
    assert err.value.key == "parameters"


def test_train_exit_codes(trained, tmp_path: Path) -> None:
    scenario, out = trained
    res = invoke("train", scenario, "--out", out, "-g", 1, "-p", 2, "-b", 2, "--eval-trials", 0)
    assert res.exit_code == 2 and "exists; use --force" in res.output
    res = invoke("train", tmp_path / "nowhere.toml", "--out", tmp_path / "p.npz")
    assert res.exit_code == 2 and "does not exist" in res.output
    res = invoke("train", scenario, "--out", tmp_path / "p.json", "-g", 1)
    assert res.exit_code == 2 and ".npz" in res.output
    res = invoke("train", scenario, "--out", tmp_path / "p.npz", "-p", 1)
    assert res.exit_code == 2  # typer's own check: population >= 2
    fresh = tmp_path / "p.npz"
    res = invoke("train", scenario, "--out", fresh, "-g", 1, "-p", 2, "-b", 2,
                 "--eval-trials", 0, "--quiet")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "evaluation" not in read_curve(fresh)[1]
