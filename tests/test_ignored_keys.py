"""Keys of another law or integrator warn and have no effect; unknown keys still fail.

A user who switches ``law = "angle-restricted"`` to ``"distance"`` (or the
integrator to ``"filippov"``) and leaves the other keys in the file gets one
warning line naming them, exit status 0 and the results of the file without
them; a study gives each of its laws the keys it takes, whatever the file's
law. A key that no law or integrator has is still an error with a suggestion.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import xarray as xr

import formationlab as fl
from formationlab.errors import IgnoredKeyWarning, ScenarioError
from formationlab.scenario import parse_scenario

BASE = """\
name = "keys"
[robots]
positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]
[formation]
distances = 1.0
[controller]
law = "distance"
k_c = 2.0
[simulation]
integrator = "euler"
dt = 1e-2
duration = 0.5
"""
OTHER_LAW = "k_c = 2.0\nk_a = 1.5\ntheta = 0.25"
ALPHA = "[[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]]"


def cli(*args: object) -> int:
    from formationlab.cli import main

    with pytest.raises(SystemExit) as exit_:
        main([str(a) for a in args])
    return int(exit_.value.code or 0)


def final_positions(out: Path) -> np.ndarray:
    with xr.open_dataset(out / "trajectory.nc", engine="h5netcdf") as ds:
        return ds["q"].values[-1]


def run_both(tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str) -> tuple[str, Path]:
    """Run ``text`` and BASE; return the first run's stderr and output folder."""
    (tmp_path / "with.toml").write_text(text)
    (tmp_path / "without.toml").write_text(BASE)
    assert cli("run", tmp_path / "with.toml", "--out", tmp_path / "a", "-q") == 0
    err = capsys.readouterr().err
    assert cli("run", tmp_path / "without.toml", "--out", tmp_path / "b", "-q") == 0
    capsys.readouterr()
    np.testing.assert_array_equal(final_positions(tmp_path / "a"), final_positions(tmp_path / "b"))
    return err, tmp_path / "a"


def test_keys_of_another_law_warn_and_have_no_effect(tmp_path, capsys):
    err, out = run_both(tmp_path, capsys, BASE.replace("k_c = 2.0", OTHER_LAW))
    lines = [x for x in err.splitlines() if "no effect" in x]
    assert len(lines) == 1, err
    assert lines[0].startswith("warning: ") and "[controller] (line 9)" in lines[0]
    assert "k_a, theta have no effect" in lines[0]
    assert "not parameters of the law 'distance'" in lines[0]
    assert "'angle-restricted'" in lines[0]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["parameters"]["law"] == {"name": "distance", **summary["parameters"]["law"]}
    assert "k_a" not in summary["parameters"]["law"]
    assert any("k_a, theta have no effect" in w for w in summary["warnings"])


def test_filippov_with_dt_warns_and_runs_as_without_it(tmp_path, capsys):
    base = BASE.replace('integrator = "euler"\ndt = 1e-2\n', 'integrator = "filippov"\n')
    text = base.replace('integrator = "filippov"\n', 'integrator = "filippov"\ndt = 1e-2\n')
    (tmp_path / "with.toml").write_text(text)
    (tmp_path / "without.toml").write_text(base)
    assert cli("run", tmp_path / "with.toml", "--out", tmp_path / "a", "-q") == 0
    err = capsys.readouterr().err
    assert cli("run", tmp_path / "without.toml", "--out", tmp_path / "b", "-q") == 0
    np.testing.assert_array_equal(final_positions(tmp_path / "a"), final_positions(tmp_path / "b"))
    assert "warning: " in err and "[simulation] (line 11)" in err
    assert "dt has no effect: it is not a parameter of the integrator 'filippov'" in err


def test_python_api_warns_with_its_own_category():
    with pytest.warns(IgnoredKeyWarning, match="k_a, theta have no effect"):
        sc = parse_scenario(BASE.replace("k_c = 2.0", OTHER_LAW), source="keys.toml")
    assert sc.law == fl.DistanceLaw(k_c=2.0)
    assert sc.controller == {"k_c": 2.0, "k_a": 1.5, "theta": 0.25}
    assert sc.law_named("angle-restricted") == fl.AngleRestrictedLaw(k_c=2.0, k_a=1.5, theta=0.25)
    with pytest.warns(IgnoredKeyWarning, match="dt has no effect"):
        integrator = fl.get_integrator("filippov", dt=1e-3)
    assert integrator == fl.Filippov()


STUDY = """
[study]
trials = 12
chunk_size = 5
laws = ["distance", "angle-restricted"]
backend = "numpy"
duration = 2.0
"""


def test_study_gives_each_law_its_keys_whatever_the_files_law(tmp_path, capsys):
    """Base law "distance" with k_a, theta: the same study as base law "angle-restricted"."""
    table = 'distances = 1.0\norientation = "table"\nalpha = ' + ALPHA
    base_distance = BASE.replace("k_c = 2.0", OTHER_LAW).replace("distances = 1.0", table) + STUDY
    base_angle = base_distance.replace('law = "distance"', 'law = "angle-restricted"')
    for name, text in (("d", base_distance), ("a", base_angle)):
        (tmp_path / f"{name}.toml").write_text(text)
        assert cli("study", tmp_path / f"{name}.toml", "--out", tmp_path / name) == 0
        assert "no effect" not in capsys.readouterr().err  # the study uses the keys
    d = pd.read_parquet(tmp_path / "d" / "trials.parquet")
    a = pd.read_parquet(tmp_path / "a" / "trials.parquet")
    pd.testing.assert_frame_equal(d, a, check_exact=True)
    groups = json.loads((tmp_path / "d" / "summary.json").read_text())["groups"]
    assert [g["law"] for g in groups] == ["distance", "angle-restricted"]
    assert (
        groups[1]["law_parameters"]["k_a"] == 1.5 and groups[1]["law_parameters"]["theta"] == 0.25
    )


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (("k_c = 2.0", "k_aa = 2.0"), ["controller.k_aa (line 8)", "Did you mean 'k_a'"]),
        (('law = "distance"', 'law = "angle-restricted"\nthetta = 0.5'), ["Did you mean 'theta'"]),
        (("dt = 1e-2", "dtt = 1e-2"), ["simulation.dtt (line 11)", "Did you mean 'dt'"]),
    ],
)
def test_a_key_no_law_or_integrator_has_is_still_an_error(tmp_path, capsys, edit, words):
    text = BASE.replace(*edit)
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, source="keys.toml")
    for w in words:
        assert w in str(info.value)
    (tmp_path / "typo.toml").write_text(text)
    assert cli("run", tmp_path / "typo.toml", "--out", tmp_path / "out") == 2
    err = capsys.readouterr().err
    assert words[-1] in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()
