"""Post-processing at scale: the same numbers as the plain evaluation, in bounded memory.

The vectorised switching diagnostics against :class:`SwitchMonitor` fed one state at a
time; ``V`` and ``sigma`` evaluated slice by slice against the whole history at once;
the sparse contact test of the outcome against all pairs.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

import formationlab as fl
from formationlab.formation.chunked import over_time, row_bytes, time_slices
from formationlab.integrators.diagnostics import SwitchMonitor, switching_diagnostics


def _monitored(t: np.ndarray, sigma: np.ndarray) -> dict[str, float]:
    mon = SwitchMonitor(sigma0=sigma[0], t0=float(t[0]))
    for tk, sk in zip(t[1:], sigma[1:], strict=True):
        mon.record(float(tk), sk)
    return mon.stats()


def _same(a: dict[str, float], b: dict[str, float]) -> None:
    assert a.keys() == b.keys()
    for key in a:
        assert a[key] == b[key] or (np.isnan(a[key]) and np.isnan(b[key])), key


@pytest.mark.parametrize("seed", range(12))
def test_vectorised_switching_diagnostics_equal_the_monitor(seed: int) -> None:
    """Random walks around the surfaces: chatter, rests at exactly 0, long excursions."""
    rng = np.random.default_rng(seed)
    T, s = int(rng.integers(2, 400)), int(rng.integers(1, 6))
    step = rng.choice([1e-3, 1e-2, 0.2], size=s)
    sigma = np.cumsum(rng.normal(size=(T, s)) * step, axis=0) + rng.normal(size=s) * 0.01
    sigma[rng.random((T, s)) < 0.1] = 0.0  # on the surface now and then
    sigma[: T // 3] *= rng.choice([-1.0, 1.0], size=(T // 3, s))  # sign flips: chatter
    t = np.cumsum(rng.uniform(0.001, 0.01, size=T))
    _same(switching_diagnostics(t, sigma), _monitored(t, sigma))


def test_diagnostics_of_a_compiled_chattering_run_equal_the_monitor() -> None:
    """Figure 3's mechanism (tests/test_sliding.py): robot 1 slides along a surface."""
    table = {(1, 2, 3): -1, (3, 1, 2): -1, (2, 1, 3): 1}
    f = fl.Formation.from_alpha_table(table, n=3, distances=1.0, diameters=0.2)
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    res = fl.simulate(f, law, [[5.0, -2.0], [-1.5, 0.0], [1.5, 0.0]], duration=3.0)
    assert res.stats["switch_count"] > 0 and res.stats["sliding_time"] > 0  # a real test
    _same(switching_diagnostics(res.t, res.sigma), _monitored(res.t, res.sigma))


# ------------------------------------------------ lists and slices against the dense whole


def _ten_robots() -> tuple[fl.Formation, fl.Law, np.ndarray]:
    """examples/ten-robots.toml: ten robots on 20 of 45 pairs, paths crossing."""
    from formationlab.io.scenario import load_scenario

    sc = load_scenario(Path(__file__).resolve().parents[1] / "examples" / "ten-robots.toml")
    return sc.formation, sc.law, sc.q0


@pytest.fixture(scope="module")
def ten_run():
    f, law, q0 = _ten_robots()
    return fl.simulate(f, law, q0, duration=3.0, save_every=3)


def test_sliced_sparse_postprocessing_equals_the_dense_whole(ten_run, monkeypatch):
    """V, sigma, distance errors, speeds and the outcome: over the lists (DENSE_LIMIT
    patched to 0) and seven states at a time, against the dense arithmetic at once."""
    from formationlab.controllers import angle_restricted, distance
    from formationlab.formation import chunked
    from formationlab.outcomes import analysis

    res = ten_run
    f, law = res.formation, res.law
    assert np.any(res.sigma >= 0) and res.V.size > 500  # restrictions on; many states
    dense_V, dense_sigma = law.potential(f, res.q), law.switching(f, res.q)
    dense_err = analysis.distance_errors(f, res.q)
    dense_summary = res.summary()
    system = fl.System(formation=f, law=law)
    for mod in (angle_restricted, distance, analysis):
        monkeypatch.setattr(mod, "DENSE_LIMIT", 0)
    monkeypatch.setattr(chunked, "BUDGET", 7 * chunked.row_bytes(f))
    np.testing.assert_allclose(system.potential(res.x), dense_V, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(system.sigma(res.x), dense_sigma, rtol=0, atol=1e-12)
    again = fl.simulate(f, law, res.q[0], duration=3.0, save_every=3)  # V, sigma in slices
    np.testing.assert_allclose(again.V, dense_V, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(again.distance_errors, dense_err, rtol=0, atol=1e-12)
    sliced = again.summary()
    assert sliced["outcome"] == dense_summary["outcome"]
    assert sliced["converged_time"] == dense_summary["converged_time"]
    for key in ("net_speed", "final_speed", "max_distance_error"):
        assert sliced[key] == pytest.approx(dense_summary[key], rel=1e-12, abs=1e-12), key
    assert sliced["diagnostics"]["switch_count"] == dense_summary["diagnostics"]["switch_count"]


def test_slices_cover_the_rows_once_and_respect_the_budget() -> None:
    parts = list(time_slices(103, per_row=10.0, budget=95.0))
    assert [p.stop - p.start for p in parts] == [9] * 11 + [4]
    assert parts[0].start == 0 and parts[-1].stop == 103
    assert all(a.stop == b.start for a, b in itertools.pairwise(parts))
    x = np.arange(40.0).reshape(10, 2, 2)
    calls = []

    def fn(s):
        calls.append(len(s))
        return s.sum(axis=(1, 2))

    np.testing.assert_array_equal(over_time(fn, x, per_row=4.0, budget=12.0), x.sum(axis=(1, 2)))
    assert calls == [3, 3, 3, 1]
    assert row_bytes(fl.Formation.from_distances(3, distances=1.0)) > 0


def test_the_slice_budget_follows_the_saved_states() -> None:
    """A slice's scratch: SCALE times the states it reads, between FLOOR and BUDGET."""
    from formationlab.formation import chunked

    def states(t: int, n: int) -> np.ndarray:
        return np.broadcast_to(0.0, (t, n, 2))  # the size without the memory

    assert chunked.FLOOR < chunked.BUDGET and chunked.SCALE >= 1
    assert chunked.slice_budget(states(3, 1000)) == chunked.FLOOR  # 48 KB of states
    mid = states(200, 1000)  # 3.2 MB of states
    assert chunked.slice_budget(mid) == chunked.SCALE * mid.nbytes
    assert chunked.slice_budget(states(100_000, 1000)) == chunked.BUDGET
    calls = []

    def fn(s):
        calls.append(len(s))
        return s.sum(axis=(1, 2))

    per_row = 1e6  # scratch bytes per state
    over_time(fn, mid, per_row=per_row)
    assert set(calls[:-1]) == {int(chunked.SCALE * mid.nbytes // per_row)} and sum(calls) == 200


@pytest.mark.parametrize("seed", range(8))
def test_sparse_contact_test_equals_all_pairs(seed: int, monkeypatch) -> None:
    from formationlab.outcomes import analysis

    rng = np.random.default_rng(seed)
    n = 40
    f = fl.Formation.from_distances(n, distances=1.0, diameters=rng.uniform(0.1, 0.4, n))
    q = rng.uniform(0, 4.0, (n, 2))  # crowded: some pairs touch, some do not
    if seed % 2:
        q = q * 10.0  # spread out: no pair touches
    dense = analysis.touching(f, q)
    monkeypatch.setattr(analysis, "DENSE_LIMIT", 0)
    assert analysis.touching(f, q) == dense
    iu, ju = np.triu_indices(n, 1)
    r = np.linalg.norm(q[iu] - q[ju], axis=1)
    assert dense == bool(np.any(r <= 0.5 * (f.diameters[iu] + f.diameters[ju])))


# ------------------------------------------------------------------ summary statistics


def test_error_statistics_against_numbers_by_hand() -> None:
    from formationlab.outcomes.analysis import error_statistics

    e = [-0.3, 0.1, 0.0, 0.2, -0.05]  # |e| sorted: 0, 0.05, 0.1, 0.2, 0.3
    s = error_statistics(e, tolerance=0.1)
    assert s["edges"] == 5 and s["within_tolerance"] == 3  # 0, 0.05 and 0.1
    assert s["max_abs"] == 0.3 and s["min"] == -0.3 and s["max"] == 0.2
    assert s["mean_abs"] == pytest.approx(0.65 / 5, rel=1e-15)
    assert s["rms"] == pytest.approx(np.sqrt(0.1425 / 5), rel=1e-15)
    assert s["p50_abs"] == pytest.approx(0.1, rel=1e-15)  # the middle one
    assert s["p90_abs"] == pytest.approx(0.2 + 0.6 * 0.1, rel=1e-12)  # rank 3.6 of 0..4
    assert s["p99_abs"] == pytest.approx(0.2 + 0.96 * 0.1, rel=1e-12)  # rank 3.96
    a = np.abs(np.asarray(e))
    assert s["p90_abs"] == pytest.approx(float(np.percentile(a, 90)), rel=1e-15)


def test_the_summary_lists_up_to_the_limit_and_counts_beyond(ten_run, monkeypatch) -> None:
    from formationlab.simulation import run as simulation

    res = ten_run
    full = res.summary()
    m = len(res.formation.edges)
    err = res.distance_errors[-1]
    assert full["n_edges"] == m == 20 and full["n_robots"] == 10
    assert list(full["distance_errors"].values()) == err.tolist()
    assert full["distance_error_stats"]["max_abs"] == full["max_distance_error"]
    assert full["distance_error_stats"]["mean_abs"] == pytest.approx(np.mean(np.abs(err)))
    on = int(np.count_nonzero(res.sigma[-1] >= 0))
    assert full["active_restrictions_final_count"] == on == len(full["active_restrictions_final"])
    monkeypatch.setattr(simulation, "LIST_LIMIT", 9)  # fewer than the robots and the edges
    short = res.summary()
    for key in ("distance_errors", "final_positions", "active_restrictions_final"):
        assert key not in short, key
    assert short["distance_error_stats"] == full["distance_error_stats"]
    table = res.edge_table()
    assert table["edge"].tolist() == res.edge_labels
    np.testing.assert_array_equal(table["distance_error"], err)
    np.testing.assert_array_equal(table["distance"] - table["desired_distance"], err)
    np.testing.assert_array_equal(table["i"], res.formation.edges[:, 0] + 1)
