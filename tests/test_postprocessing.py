"""Post-processing at scale: the same numbers as the plain evaluation, in bounded memory.

The vectorised switching diagnostics against :class:`SwitchMonitor` fed one state at a
time; ``V`` and ``sigma`` evaluated slice by slice against the whole history at once;
the sparse contact test of the outcome against all pairs.
"""

from __future__ import annotations

import numpy as np
import pytest

import formationlab as fl
from formationlab.chunked import over_time, row_bytes, time_slices
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
