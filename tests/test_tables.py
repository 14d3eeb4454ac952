"""The [study] and [equilibria] tables: one place for their defaults, checked by validate."""

from __future__ import annotations

import numpy as np
import pytest

import formationlab as fl
from formationlab.equilibria import EquilibriaConfig, parse_equilibria
from formationlab.errors import ScenarioError
from formationlab.scenario import parse_scenario
from formationlab.studies.runner import DEFAULT_DT, StudySetup

BASE = """\
[robots]
positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]
[formation]
distances = 1.0
[controller]
law = "distance"
[simulation]
integrator = "rk4"
dt = 2e-3
duration = 3.0
"""


def scenario(extra: str = "", base: str = BASE):
    return parse_scenario(base + extra, source="t.toml")


def test_study_defaults_come_from_the_scenario():
    setup = StudySetup.from_scenario(scenario("[study]\ntrials = 5\n"))
    assert (setup.dt, setup.duration, setup.center) == (2e-3, 3.0, None)  # box: no centre
    setup = StudySetup.from_scenario(scenario("[study]\ndt = 1e-2\nduration = 1.0\n"))
    assert (setup.dt, setup.duration) == (1e-2, 1.0)
    filippov = BASE.replace('integrator = "rk4"\ndt = 2e-3\n', 'integrator = "filippov"\n')
    assert StudySetup.from_scenario(scenario(base=filippov)).dt == DEFAULT_DT == 1e-3


def test_gaussian_starts_centre_on_the_template_else_on_the_positions():
    gauss = '[study]\ninitial = { kind = "gaussian", sigma = 0.1 }\n'
    sc = scenario(gauss)
    np.testing.assert_array_equal(StudySetup.from_scenario(sc).center, sc.q0)
    tpl = BASE.replace("distances = 1.0", "template = [[0, 0], [1, 0], [0.5, 0.8]]")
    sc = scenario(gauss, base=tpl)
    np.testing.assert_array_equal(StudySetup.from_scenario(sc).center, sc.formation.template)
    # the same rule in Python: the template, and a clear error without one
    with pytest.raises(fl.errors.ParameterError, match="centre shape"):
        StudySetup(
            formation=fl.Formation.from_distances(3),
            law=fl.DistanceLaw(),
            config=StudySetup.from_scenario(scenario(gauss)).config,
            dt=1e-3,
            duration=1.0,
        )


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        ("[study]\ntrails = 100\n", ["study.trails (line 12)", "did you mean 'trials'?"]),
        ("[study]\nsweep = { kA = [1.0] }\n", ["study.sweep.kA (line 12)", "did you mean 'k_a'"]),
        ('[study]\nlaws = ["distanse"]\n', ["study.laws (line 12)", "did you mean 'distance'?"]),
        (
            '[equilibria]\nduration = "long"\n',
            ["equilibria.duration (line 12)", "expected a number"],
        ),
        ("[equilibria]\nstart = 3\n", ["equilibria.start (line 12)", "did you mean 'starts'?"]),
        ('[equilibria]\nintegrator = "filippov"\n', ["cannot settle a batch"]),
    ],
)
def test_validate_checks_every_table(tmp_path, capsys, extra, words):
    from formationlab.cli import main

    path = tmp_path / "t.toml"
    path.write_text(BASE + extra)
    with pytest.raises(SystemExit) as exit_:
        main(["validate", str(path)])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    for w in words:
        assert w in err, err


def test_validate_accepts_good_tables(tmp_path, capsys):
    from formationlab.cli import main

    path = tmp_path / "t.toml"
    path.write_text(BASE + '[study]\nlaws = ["distance"]\n[equilibria]\nstarts = 4\n')
    with pytest.raises(SystemExit) as exit_:
        main(["validate", str(path)])
    assert exit_.value.code in (0, None)
    assert capsys.readouterr().out.startswith("ok: ")


def test_equilibria_table_is_a_validated_config():
    sc = scenario('[equilibria]\nstarts = 12\nduration = 30.0\nfollow = "k_c=1:3"\n')
    config = parse_equilibria(sc, starts=None, seed=4)
    assert config == EquilibriaConfig(starts=12, duration=30.0, follow="k_c=1:3", seed=4)
    assert config.follow_spec == ("k_c", 1.0, 3.0)
    assert config.settler(fl.DistanceLaw()) == fl.RK4(dt=0.01)
    assert config.settler(fl.AngleRestrictedLaw()) == fl.ImplicitEuler(dt=0.01)
    with pytest.raises(ScenarioError) as info:  # a bare ValueError and a traceback before
        parse_equilibria(scenario('[equilibria]\nduration = "60"\n'))
    assert info.value.key == "equilibria.duration"
    with pytest.raises(ScenarioError, match=r"^command line: --follow-steps: "):
        parse_equilibria(sc, follow_steps=1)
