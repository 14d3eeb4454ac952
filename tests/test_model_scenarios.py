"""Scenario keys of the robot models and of [marching]; the examples that use them run.

Every bad value names its key and line; keys of another model (or of the other
unicycle transform) are warnings with the key's line; the examples reach what their
comments say (docs/robot-models.md).
"""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import formationlab as fl
from formationlab.cli import _load_commands, app
from formationlab.errors import IgnoredKeyWarning, ScenarioError
from formationlab.io.scenario import load_scenario
from formationlab.marching import Marching, MotionParameters
from formationlab.scenario import parse_scenario

EXAMPLES = Path(__file__).parent.parent / "examples"

BASE = """
[robots]
positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]
model = "unicycle"
headings = [0.0, 1.5708, 3.1416]
mapping = "near-identity"
offset = 0.1
max_turn_rate = 3.0
[formation]
distances = 1.0
[controller]
law = "distance"
[simulation]
duration = 5.0
[marching]
velocity = [0.2, 0.0]
leader = 1
"""


def test_the_keys_build_the_model_the_state_and_the_marching():
    sc = parse_scenario(BASE)
    assert sc.model == fl.models.Unicycle(offset=0.1, max_turn_rate=3.0)
    np.testing.assert_array_equal(sc.x0[:, 2], [0.0, 1.5708, 3.1416])
    assert isinstance(sc.marching, Marching) and sc.marching.leader == 1
    np.testing.assert_array_equal(sc.marching.reference(3.0), [0.2, 0.0])
    assert sc.parameters["model"]["name"] == "unicycle"
    di = parse_scenario(
        BASE.replace('model = "unicycle"', 'model = "double-integrator"\ndamping = 3.0')
        .replace("headings = [0.0, 1.5708, 3.1416]", "velocities = [0.1, 0.2]")
        .replace('mapping = "near-identity"\noffset = 0.1\nmax_turn_rate = 3.0\n', "")
    )
    assert di.model == fl.models.DoubleIntegrator(damping=3.0)
    np.testing.assert_array_equal(di.x0[:, 2:], [[0.1, 0.2]] * 3)


@pytest.mark.parametrize(("old", "new", "key", "words"), [
    ("headings = [0.0, 1.5708, 3.1416]", "headings = [0.0, 1.5708]", "robots.headings",
     "one per robot: there are 3 positions but 2"),
    ("headings = [0.0, 1.5708, 3.1416]", "headings = [0.0, nan, 1.0]", "robots.headings",
     "finite"),
    ("headings = [0.0, 1.5708, 3.1416]", 'headings = "north"', "robots.headings", "radians"),
    ("offset = 0.1", "offset = 0.0", "robots.offset", "> 0"),
    ("headings = [0.0, 1.5708, 3.1416]\nmapping = \"near-identity\"\noffset = 0.1",
     "headings = [0.0, 3.1416, 0.0]\nmapping = \"near-identity\"\noffset = 3.0",
     "robots.headings", "hand points"),
    ('mapping = "near-identity"', 'mapping = "near"', "robots.mapping", "near-identity"),
    ('model = "unicycle"', 'model = "unicycel"', "robots.model", "did you mean 'unicycle'"),
    ("max_turn_rate = 3.0", "max_turn_rat = 3.0", "robots.max_turn_rat", "'max_turn_rate'"),
    ("max_turn_rate = 3.0", "k_c = 2.0", "robots.k_c", "[controller]"),
    ("leader = 1", "leader = 4", "marching.leader", "not a robot"),
    ("leader = 1", "leader = 0", "marching.leader", "a robot number (1-based)"),
    ("leader = 1", "leader = [1, 1]", "marching.leader", "each robot once"),
    ("leader = 1", "leader = [1, 7]", "marching.leader", "leader 7 is not a robot"),
    ("velocity = [0.2, 0.0]", "velocity = [0.2]", "marching.velocity", "[vx, vy]"),
    ("leader = 1", "angular_velocity = 0.3", "marching.angular_velocity", "motion-parameters"),
    ("leader = 1", 'kind = "motion-parameters"\nleader = 2', "marching.leader", "every robot"),
])  # fmt: skip
def test_bad_values_name_their_key_and_line(old, new, key, words):
    text = BASE.replace(old, new)
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, "s.toml")
    assert info.value.key == key
    assert f"s.toml: {key} (line " in str(info.value) and words in str(info.value)


def test_keys_of_another_model_or_transform_are_warnings():
    text = BASE.replace("offset = 0.1", "offset = 0.1\ndamping = 2.0\nvelocities = [0.0, 0.0]")
    with pytest.warns(IgnoredKeyWarning, match="line 8.*damping, velocities have no effect"):
        sc = parse_scenario(text, "s.toml")
    assert sc.model.name == "unicycle"
    heading = BASE.replace('mapping = "near-identity"', 'mapping = "heading"')
    with pytest.warns(IgnoredKeyWarning, match="line 7.*offset has no effect with mapping"):
        parse_scenario(heading, "s.toml")
    si = BASE.replace('model = "unicycle"\n', "")
    with pytest.warns(IgnoredKeyWarning) as record:
        parse_scenario(si, "s.toml")
    text = " ".join(str(w.message) for w in record)
    assert "headings" in text and "mapping" in text and "'unicycle'" in text


def test_motion_parameters_from_a_file():
    sc = parse_scenario(
        BASE.replace("leader = 1", 'kind = "motion-parameters"\nangular_velocity = 0.2')
    )
    assert isinstance(sc.marching, MotionParameters) and sc.marching.mu.shape == (3,)


NEW_EXAMPLES = sorted(
    p.name for p in EXAMPLES.glob("*.toml")
    if any(w in p.name for w in ("unicycle", "double-integrator", "marching", "leader"))
)  # fmt: skip


def test_the_examples_of_the_models_are_there():
    assert len(NEW_EXAMPLES) == 8


@pytest.mark.slow
@pytest.mark.parametrize("name", NEW_EXAMPLES)
def test_the_model_examples_run_to_what_they_say(name, tmp_path):
    from typer.testing import CliRunner

    _load_commands()
    out = tmp_path / "run"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = CliRunner().invoke(app, ["run", str(EXAMPLES / name), "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    sc = load_scenario(EXAMPLES / name)
    assert summary["model"]["name"] == sc.model.name
    if "leader" in name:  # the followers' steady pull distorts the shape a little
        assert 0 < summary["max_distance_error"] < 0.2 / 4.0  # |v_ref| / k_c
    else:
        assert summary["outcome"] == "desired"
    import xarray as xr

    with xr.open_dataset(out / "trajectory.nc") as ds:
        if sc.model.name != "single-integrator":
            assert list(ds["state"].values) == list(type(sc.model).state_names)
            np.testing.assert_allclose(ds["x"].values[0], sc.x0)
        if "marching" in name:
            c = ds["q"].values.mean(axis=1)
            np.testing.assert_allclose(c[-1] - c[0], [0.2 * float(ds["time"][-1]), 0.0],
                                       atol=1e-9)  # fmt: skip
        if "leader" in name:
            np.testing.assert_allclose(ds["u"].values[-1], [[0.2, 0.0]] * 3, atol=1e-3)
