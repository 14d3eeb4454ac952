"""Monte-Carlo studies: configuration, sampling, Wilson intervals, determinism, resume, dask.

Every study here uses the numpy backend of the batched kernel (no compilation),
dt = 1e-2 and a few seconds of simulated time, so the file runs in seconds.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

import formationlab as fl
from formationlab.errors import ParameterError, ScenarioError
from formationlab.io.trials import ChunkFolder, read_trials, write_trials
from formationlab.outcomes.analysis import OUTCOMES
from formationlab.studies import parse_study, run_study, study_groups, wilson_interval
from formationlab.studies.config import BoxInitial, GaussianInitial
from formationlab.studies.runner import StudySetup, study_identity
from formationlab.studies.sampling import SEED_BLOCK, trial_initial_states

Z2 = 1.959963984540054**2

# The paper's triangle with simulation 2's table (alpha_123 = alpha_312 = -alpha_213 = 1).
TRIANGLE = fl.Formation.from_alpha_table({(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}, n=3)
LAW = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
DT, DURATION = 1e-2, 4.0


def small(**over: object) -> fl.studies.StudyConfig:
    table = {
        "trials": 24,
        "chunk_size": 10,
        "laws": ["distance", "angle-restricted"],
        "sweep": {"k_a": [0.5, 3.0]},
        "backend": "numpy",
    }
    table.update(over)
    return parse_study(table)


def study(formation, law, config, *, dt=DT, duration=DURATION, center=None, **kw):
    """run_study of a study given in Python (not from a scenario)."""
    setup = StudySetup(
        formation=formation, law=law, config=config, dt=dt, duration=duration, center=center
    )
    return run_study(setup, **kw)


# ----------------------------------------------------------------------------- Wilson


def test_wilson_interval_matches_closed_forms():
    # k = 0: [0, z^2 / (n + z^2)]; k = n: [n / (n + z^2), 1] (set p = 0 or 1 in the formula)
    lo, hi = wilson_interval([0, 10], [10, 10])
    assert lo[0] == 0.0 and hi[0] == pytest.approx(Z2 / (10 + Z2), rel=1e-12)
    assert lo[1] == pytest.approx(10 / (10 + Z2), rel=1e-12) and hi[1] == 1.0
    # k = 5, n = 10, by hand: centre 1/2, half-width z sqrt(1/40 + z^2/400) / (1 + z^2/10)
    lo, hi = wilson_interval(5, 10)
    half = math.sqrt(Z2) * math.sqrt(0.025 + Z2 / 400) / (1 + Z2 / 10)
    assert (lo, hi) == (pytest.approx(0.5 - half, rel=1e-12), pytest.approx(0.5 + half, rel=1e-12))
    assert float(lo) == pytest.approx(0.2366, abs=1e-4)  # tabulated value for 5/10


def test_wilson_interval_is_mirror_symmetric_and_rejects_bad_counts():
    lo1, hi1 = wilson_interval(3, 17)
    lo2, hi2 = wilson_interval(14, 17)
    assert lo1 == pytest.approx(1 - hi2) and hi1 == pytest.approx(1 - lo2)
    with pytest.raises(ValueError):
        wilson_interval(4, 3)


# ----------------------------------------------------------------------------- config


def test_study_table_defaults_and_overrides():
    c = parse_study(None)
    assert c.trials == 1000 and isinstance(c.initial, BoxInitial) and c.initial.half_width == 3.0
    assert c.laws is None and c.sweep == {} and c.tol == fl.Tolerances()
    c = parse_study({"trials": 10, "initial": {"kind": "gaussian", "sigma": 0.5}}, trials=7)
    assert c.trials == 7 and isinstance(c.initial, GaussianInitial) and c.initial.sigma == 0.5
    c = parse_study({"tolerances": {"speed": 2e-3, "window": 0.5}})
    assert c.tol == fl.Tolerances(distance=1e-2, speed=2e-3, window=0.5)
    assert c.settle.model_dump() == {"enabled": False, "duration": 5.0, "dt": 0.01}
    c = parse_study({"settle": {"enabled": True, "dt": 0.02}})
    assert c.settle.model_dump() == {"enabled": True, "duration": 5.0, "dt": 0.02}


@pytest.mark.parametrize(
    ("table", "words"),
    [
        ({"trails": 10}, ["study.trails", "unknown key", "trials"]),
        ({"initial": {"kind": "box", "half_width": -1}}, ["study.initial.half_width"]),
        ({"initial": {"kind": "disc"}}, ["study.initial"]),
        ({"sweep": {"k_a": []}}, ["sweep.k_a is empty"]),
        ({"laws": ["distance", "distance"]}, ["listed twice"]),
        ({"chunk_size": 0}, ["study.chunk_size"]),
        ({"tolerances": {"window": 0.0}}, ["study.tolerances.window"]),
        ({"settle": {"enabled": "maybe"}}, ["study.settle.enabled", "boolean"]),
        ({"settle": {"durration": 5.0}}, ["study.settle.durration", "unknown key", "duration"]),
        ({"settle": {"duration": 0.0}}, ["study.settle.duration", "must be > 0"]),
        ({"settle": {"duration": 1e4}}, ["study.settle.duration", "must be <= 1000, got 10000.0"]),
        ({"settle": {"dt": -0.01}}, ["study.settle.dt"]),
        ({"settle": {"dt": 1.0, "duration": 0.5}}, ["study.settle", "longer than duration"]),
        ({"settle": {"dt": 1e-9}}, ["study.settle", "at most 1e6"]),
    ],
)
def test_bad_study_tables_name_the_key(table, words):
    with pytest.raises(ScenarioError) as err:
        parse_study(table)
    for w in words:
        assert w in str(err.value)


def test_groups_are_laws_times_their_own_sweep_points():
    law = fl.AngleRestrictedLaw(k_c=5.0, k_a=3.0)
    config = parse_study(
        {"laws": ["distance", "angle-restricted"], "sweep": {"k_a": [0.5, 1.0], "eta": [2.0]}}
    )
    groups = study_groups(TRIANGLE, law, config)
    # the distance law has no k_a: it runs once per eta, not once per (k_a, eta)
    assert [(g.law.name, g.parameters) for g in groups] == [
        ("distance", {"eta": 2.0}),
        ("angle-restricted", {"k_a": 0.5, "eta": 2.0}),
        ("angle-restricted", {"k_a": 1.0, "eta": 2.0}),
    ]
    assert groups[0].law.k_c == 5.0  # shared parameters come from the scenario's law
    assert groups[2].law.k_a == 1.0 and groups[2].law.repulsion.eta == 2.0
    d = study_groups(TRIANGLE, law, parse_study({"sweep": {"diameter": [0.1, 0.4]}}))
    assert [g.formation.contact_matrix[0, 1] for g in d] == [0.1, 0.4]


def test_sweep_keys_no_law_has_are_refused():
    with pytest.raises(ParameterError, match="k_a"):
        study_groups(TRIANGLE, LAW, parse_study({"laws": ["distance"], "sweep": {"k_a": [1.0]}}))
    with pytest.raises(ParameterError, match="unknown law"):
        study_groups(TRIANGLE, LAW, parse_study({"laws": ["nope"]}))
    with pytest.raises(ParameterError, match="diameter"):  # a_ij = 1.2 > d_ij = 1
        study_groups(TRIANGLE, LAW, parse_study({"sweep": {"diameter": [1.2]}}))


# ----------------------------------------------------------------------------- sampling


def test_box_draws_are_inside_uniform_and_never_overlap():
    f = fl.Formation.from_distances(4, distances=1.0, diameters=0.8)
    q = trial_initial_states(f, BoxInitial(half_width=1.0), seed=3, trials=range(4000))
    assert q.shape == (4000, 4, 2) and np.abs(q).max() <= 1.0
    iu, ju = np.triu_indices(4, k=1)
    assert np.min(np.linalg.norm(q[:, ju] - q[:, iu], axis=-1)) > 0.8
    # a single robot's coordinate is not uniform after rejection, but by the symmetry
    # x -> -x of box and rejection rule its mean is 0 (5 standard errors, sd <= 1)
    assert abs(q[..., 0].mean()) < 5 / math.sqrt(q[..., 0].size)


def test_gaussian_draws_centre_and_spread():
    centre = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])  # far apart: no rejections
    q = trial_initial_states(
        TRIANGLE, GaussianInitial(kind="gaussian", sigma=0.5), 1, range(3000), center=centre
    )
    dev = (q - centre).reshape(-1)
    assert abs(dev.mean()) < 5 * 0.5 / math.sqrt(dev.size)
    # the sample variance of N(0, s^2) has standard error s^2 sqrt(2 / (m - 1))
    assert abs(dev.var(ddof=1) - 0.25) < 5 * 0.25 * math.sqrt(2 / (dev.size - 1))


def test_trial_states_depend_on_seed_and_trial_only():
    box = BoxInitial(half_width=3.0)
    every = trial_initial_states(TRIANGLE, box, 11, range(3 * SEED_BLOCK))
    picked = trial_initial_states(TRIANGLE, box, 11, [150, 3, 64])
    np.testing.assert_array_equal(picked, every[[150, 3, 64]])
    other = trial_initial_states(TRIANGLE, box, 12, [3])
    assert not np.array_equal(other[0], every[3])


def test_impossible_box_is_a_clear_error():
    f = fl.Formation.from_distances(3, distances=1.0, diameters=0.5)
    with pytest.raises(ParameterError, match=r"widen study\.initial"):
        trial_initial_states(f, BoxInitial(half_width=0.01), 0, [0])


# ----------------------------------------------------------------------------- running


@pytest.fixture(scope="module")
def reference_run() -> pd.DataFrame:
    """One chunk per group, in this process: the table every other run must equal."""
    config = small(chunk_size=1000)
    return study(TRIANGLE, LAW, config, seed=5, dt=DT, duration=DURATION).trials


def test_trials_table_rows_and_columns(reference_run):
    t = reference_run
    assert len(t) == 3 * 24
    assert list(t.groupby("group").size()) == [24, 24, 24]
    assert set(t["outcome"]) <= set(OUTCOMES)
    assert np.isnan(t.loc[t["law"] == "distance", "k_a"]).all()
    assert set(t.loc[t["law"] == "angle-restricted", "k_a"]) == {0.5, 3.0}
    for i in (1, 2, 3):
        assert {f"x{i}", f"y{i}", f"x{i}_init", f"y{i}_init"} <= set(t.columns)
    # the net speed between the last two convergence tests (every dt = 1e-2 here):
    # unknown only for a trial that stopped at its first test, step 0
    assert t["net_speed"].dtype == float and np.all(t["net_speed"].fillna(0.0) >= 0)
    np.testing.assert_array_equal(np.isnan(t["net_speed"]), t["steps"] == 0)
    end = t[np.isnan(t["converged_time"]) & (t["outcome"] != "collision")]
    assert np.all(end["net_speed"] > 1e-3)  # ran to the end: no test passed
    # every group starts trial t from the same state (paired comparison)
    starts = t.pivot(index="trial", columns="group", values="x2_init").to_numpy()
    assert (starts == starts[:, :1]).all()


def test_a_trial_reruns_with_the_one_by_one_simulator(reference_run):
    """The runner hands each group its own law: rerun trials of k_a = 0.5 with simulate."""
    t = reference_run[(reference_run["law"] == "angle-restricted") & (reference_run["k_a"] == 0.5)]
    law = LAW.with_params(k_a=0.5)
    for _, row in t.head(3).iterrows():
        q0 = trial_initial_states(TRIANGLE, BoxInitial(), int(row["seed"]), [int(row["trial"])])[0]
        np.testing.assert_array_equal(q0[:, 0], row[["x1_init", "x2_init", "x3_init"]])
        res = fl.simulate(TRIANGLE, law, q0, duration=DURATION, integrator=fl.Euler(dt=DT))
        assert res.outcome() == row["outcome"]
        if row["outcome"] != "not-converged":
            final = row[["x1", "y1", "x2", "y2", "x3", "y3"]].to_numpy(float).reshape(3, 2)
            # the batch stops once |u| < 1e-3, the simulator goes on: a speed of 1e-3
            # decaying at rate >= 1 moves a robot by at most about 1e-3 more
            np.testing.assert_allclose(res.q[-1], final, atol=5e-3)


def test_same_seed_same_trials_whatever_chunks_and_workers(reference_run):
    chunked = study(
        TRIANGLE, LAW, small(chunk_size=7), seed=5, dt=DT, duration=DURATION, workers=2
    ).trials
    pd.testing.assert_frame_equal(chunked, reference_run, check_exact=True)


def test_different_seed_different_trials(reference_run):
    other = study(TRIANGLE, LAW, small(chunk_size=1000), seed=6, dt=DT, duration=DURATION)
    assert not np.array_equal(other.trials["x1_init"], reference_run["x1_init"])


class Interrupt:
    """A store that saves like ChunkFolder, then interrupts after ``after`` chunks."""

    def __init__(self, folder: ChunkFolder, after: int) -> None:
        self.folder, self.after, self.saved = folder, after, 0

    def load(self, chunk_id):
        return self.folder.load(chunk_id)

    def save(self, chunk_id, frame):
        self.folder.save(chunk_id, frame)
        self.saved += 1
        if self.saved == self.after:
            raise KeyboardInterrupt


def test_resume_after_interruption_gives_the_uninterrupted_parquet(tmp_path, reference_run):
    config = small()
    groups = study_groups(TRIANGLE, LAW, config)
    ident = study_identity(groups, config, seed=5, dt=DT, duration=DURATION)
    folder = ChunkFolder(tmp_path / "study", ident)
    folder.start()
    with pytest.raises(KeyboardInterrupt):
        study(
            TRIANGLE, LAW, config, seed=5, dt=DT, duration=DURATION,
            store=Interrupt(folder, after=4),
        )  # fmt: skip
    assert folder.check_resumable() == 4
    res = study(TRIANGLE, LAW, config, seed=5, dt=DT, duration=DURATION, store=folder, resume=True)
    assert res.summary["chunks"] == {"total": 9, "resumed": 4}
    write_trials(res.trials, tmp_path / "resumed.parquet")
    write_trials(reference_run, tmp_path / "whole.parquet")
    pd.testing.assert_frame_equal(
        read_trials(tmp_path / "resumed.parquet"),
        read_trials(tmp_path / "whole.parquet"),
        check_exact=True,
    )
    # another seed is another study: its chunks are not mixed in
    other = ChunkFolder(tmp_path / "study", {**ident, "seed": 6, "fingerprint": "x"})
    with pytest.raises(ParameterError, match="seed"):
        other.check_resumable()


def test_study_on_a_dask_local_cluster_of_processes(reference_run):
    pytest.importorskip("distributed")
    res = study(
        TRIANGLE, LAW, small(chunk_size=12), seed=5, dt=DT, duration=DURATION,
        scheduler="local", workers=1,
    )  # fmt: skip
    pd.testing.assert_frame_equal(res.trials, reference_run, check_exact=True)


def test_study_on_a_dask_scheduler_given_by_its_address(reference_run):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        res = study(
            TRIANGLE, LAW, small(chunk_size=5), seed=5, dt=DT, duration=DURATION,
            scheduler=cluster.scheduler_address,
        )  # fmt: skip
    pd.testing.assert_frame_equal(res.trials, reference_run, check_exact=True)


def test_summary_counts_fractions_and_intervals(reference_run):
    config = small(chunk_size=1000)
    res = study(TRIANGLE, LAW, config, seed=5, dt=DT, duration=DURATION)
    assert res.summary["trial_steps"] == int(reference_run["steps"].sum())
    for g, entry in enumerate(res.summary["groups"]):
        rows = reference_run[reference_run["group"] == g]
        assert entry["trials"] == len(rows) == sum(entry["counts"].values())
        # no trial drifts or rotates here: the outcomes of the tables before those existed
        classic = [o for o in OUTCOMES if o not in ("drifting", "rotating", "diverged")]
        assert res.summary["outcomes"] == classic
        assert list(entry["counts"]) == classic == list(entry["fractions"])
        for o in classic:
            k = int((rows["outcome"] == o).sum())
            assert entry["counts"][o] == k and entry["fractions"][o] == k / len(rows)
            lo, hi = entry["ci95"][o]
            assert lo <= k / len(rows) <= hi


# ----------------------------------------------------------------------------- command


SCENARIO = """
name = "tiny-study"
[robots]
positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]
[formation]
orientation = "table"
alpha = [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]]
[controller]
law = "angle-restricted"
[simulation]
dt = 1e-2
duration = 4.0
[study]
trials = 24
chunk_size = 10
laws = ["distance", "angle-restricted"]
backend = "numpy"
[study.sweep]
k_a = [0.5, 3.0]
"""


def cli(*args: str) -> int:
    """Run ``formationlab ARGS``; its exit status."""
    from formationlab.cli import main

    with pytest.raises(SystemExit) as exit_:
        main(list(args))
    return int(exit_.value.code or 0)


def test_study_command_writes_trials_summary_and_figures(tmp_path, capsys, reference_run):
    import json

    path = tmp_path / "tiny.toml"
    path.write_text(SCENARIO, encoding="utf-8")
    out = tmp_path / "out"
    args = [str(path), "--seed", "5", "--out", str(out), "--workers", "1"]
    assert cli("study", *args) == 0
    trials = read_trials(out / "trials.parquet")
    pd.testing.assert_frame_equal(trials, reference_run, check_exact=True)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scenario"] == "tiny-study" and summary["seed"] == 5
    assert [g["law"] for g in summary["groups"]] == ["distance", *["angle-restricted"] * 2]
    assert summary["trial_steps"] == int(trials["steps"].sum()) and summary["wall_time_s"] > 0
    assert summary["settle"] == {"enabled": False, "duration": 5.0, "dt": 0.01}
    assert trials["settled"].dtype == bool and not trials["settled"].any()
    for stem in ("fractions", "desired"):
        assert (out / f"{stem}.png").stat().st_size > 0
    # a second run refuses the folder, and --resume finds every chunk done
    capsys.readouterr()
    assert cli("study", *args) == 2 and "--force" in capsys.readouterr().err
    assert cli("study", *args, "--resume") == 0
    again = json.loads((out / "summary.json").read_text())
    assert again["chunks"] == {"total": 9, "resumed": 9}
    pd.testing.assert_frame_equal(read_trials(out / "trials.parquet"), trials, check_exact=True)
    # resuming with another seed is refused with a message, not a traceback
    capsys.readouterr()
    assert cli("study", str(path), "--seed", "6", "--out", str(out), "--resume") == 2
    assert "differs in: seed" in capsys.readouterr().err


def test_docstring_examples_of_the_study_modules():
    import doctest

    import formationlab.studies.sampling

    result = doctest.testmod(formationlab.studies.sampling)
    assert result.attempted > 0 and result.failed == 0


def test_gaussian_starts_around_the_template_end_in_the_template():
    """Starts within a few hundredths of the desired square stay there (it is stable)."""
    square = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], diameters=0.2)
    config = parse_study(
        {"trials": 16, "initial": {"kind": "gaussian", "sigma": 0.02}, "backend": "numpy"}
    )
    res = study(square, LAW, config, seed=2, dt=DT, duration=DURATION)
    assert (res.trials["outcome"] == "desired").all()
    start = res.trials[[f"{c}{i}_init" for i in range(1, 5) for c in "xy"]].to_numpy()
    assert np.abs(start - square.template.reshape(-1)).max() < 5 * 0.02
    with pytest.raises(ParameterError, match="centre"):  # no template, no centre given
        study(TRIANGLE, LAW, config, seed=2, dt=DT, duration=DURATION)


def test_study_command_refuses_a_bad_study_table_before_writing(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(SCENARIO.replace("trials = 24", "trails = 24"), encoding="utf-8")
    out = tmp_path / "out"
    assert cli("study", str(path), "--out", str(out)) == 2
    err = capsys.readouterr().err
    assert "study.trails" in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("name", "n_groups"),
    # four laws, only angle-restricted has k_a (5 values): 3 + 5; one law, 5 thetas x 3 diameters
    [
        ("study-triangle", 8),
        ("study-square", 8),
        ("study-square-theta", 15),
        ("study-triangle-million", 1),
    ],
)
def test_example_study_tables_are_valid(name, n_groups):
    from pathlib import Path

    from formationlab.io.scenario import load_scenario

    sc = load_scenario(Path(__file__).resolve().parents[1] / "examples" / f"{name}.toml")
    groups = study_groups(sc.formation, sc.law, parse_study(sc.study, source=sc.source))
    assert len(groups) == n_groups


# ----------------------------------------------------------------------------- settling

SLIDING_TRIAL = 5  # of the square study (seed 1, k_a = 1): docs/studies.md, tests/test_batch.py


def test_settling_labels_the_square_sliding_equilibrium_incorrect():
    """Trial 5 (seed 1, k_a = 1) of the square ends at a sliding-mode equilibrium.

    Explicit Euler chatters there and the kernel says ``not-converged``; implicit
    Euler lands on the two switching surfaces and stops, far from the square:
    ``incorrect`` (tests/test_batch.py shows with the Filippov integrator that the
    state is at rest). Same table whatever the chunks and workers.
    """
    from formationlab.io.scenario import load_scenario

    sc = load_scenario("examples/study-square.toml")
    table = {
        "trials": SLIDING_TRIAL + 1,
        "laws": ["distance", "angle-restricted"],
        "sweep": {"k_a": [1.0]},
    }
    on = {"enabled": True, "duration": 5.0, "dt": 0.01}
    run = {"seed": 1, "dt": 1e-3, "duration": 5.0}
    whole = study(sc.formation, sc.law, parse_study({**table, "settle": on}), **run)
    t = whole.trials
    ar = t[(t["law"] == "angle-restricted") & (t["trial"] == SLIDING_TRIAL)].iloc[0]
    assert ar["outcome"] == "not-converged" and ar["max_distance_error"] > 0.9
    assert ar["settled"] and ar["settled_outcome"] == "incorrect"
    rest = t.drop(index=ar.name)
    assert not rest["settled"].any() and (rest["settled_outcome"] == rest["outcome"]).all()
    # the summary keeps the kernel's counts and adds those after settling
    g = whole.summary["groups"][1]
    assert g["counts"]["not-converged"] == 1 and g["counts"]["incorrect"] == 0
    assert g["settled"] == 1 and whole.summary["settled_trials"] == 1
    assert g["settled_counts"]["not-converged"] == 0 and g["settled_counts"]["incorrect"] == 1
    assert g["settled_fractions"]["incorrect"] == 1 / (SLIDING_TRIAL + 1)
    # Wilson interval of 1 in 6 by hand: (p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)
    n, z = SLIDING_TRIAL + 1, math.sqrt(Z2)
    half = z * math.sqrt(5 / n**3 + Z2 / (4 * n * n))
    want = [(1 / n + Z2 / (2 * n) + s * half) / (1 + Z2 / n) for s in (-1, 1)]
    np.testing.assert_allclose(g["settled_ci95"]["incorrect"], want, rtol=1e-12)
    # chunks of 2 in two processes: the same table, byte for byte
    chunked = study(
        sc.formation, sc.law, parse_study({**table, "settle": on, "chunk_size": 2}),
        workers=2, **run,
    )  # fmt: skip
    pd.testing.assert_frame_equal(chunked.trials, t, check_exact=True)
    # settling off (the default): nothing settled, the kernel's columns unchanged
    off = study(sc.formation, sc.law, parse_study(table), **run).trials
    assert not off["settled"].any() and (off["settled_outcome"] == off["outcome"]).all()
    kernel = [c for c in t.columns if c not in ("settled", "settled_outcome")]
    pd.testing.assert_frame_equal(off[kernel], t[kernel], check_exact=True)


def test_smooth_laws_are_never_settled(tmp_path, capsys):
    """After 0.05 s every trial is still moving: only the switching law's are settled."""
    import json

    path = tmp_path / "settle.toml"
    settle = "[study.settle]\nduration = 0.2\ndt = 0.01\n"  # enabled by --settle
    path.write_text(SCENARIO.replace("trials = 24", "trials = 6") + settle, encoding="utf-8")
    out = tmp_path / "out"
    capsys.readouterr()
    args = ["--out", str(out), "--duration", "0.05", "--seed", "5", "--settle"]
    assert cli("study", str(path), *args) == 0
    printed = capsys.readouterr().out
    t = read_trials(out / "trials.parquet")
    assert (t["outcome"] == "not-converged").all()
    smooth = t["law"] == "distance"
    assert smooth.sum() == 6 and not t.loc[smooth, "settled"].any()
    assert (t.loc[smooth, "settled_outcome"] == "not-converged").all()
    assert t.loc[~smooth, "settled"].all() and t["settled"].dtype == bool
    assert set(t["settled_outcome"]) <= set(OUTCOMES)
    summary = json.loads((out / "summary.json").read_text())
    assert [g["settled"] for g in summary["groups"]] == [0, 6, 6]
    assert summary["settled_trials"] == 12
    assert summary["settle"] == {"enabled": True, "duration": 0.2, "dt": 0.01}
    assert printed.count("settled 6") == 2 and "12 not-converged trials" in printed
