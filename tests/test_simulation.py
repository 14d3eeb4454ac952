"""The simulator: Lyapunov decrease (10), centroid, contact handling, eq. (26), RK4 order."""

import numpy as np
import pytest

import formationlab as fl
from formationlab.paper import PAPER_Q0, paper_formation, paper_law


def test_V_non_increasing_along_simulation_1():
    """Eq. (10): V (here V_n, restrictions inactive) never rises along simulation 1."""
    res = fl.simulate(paper_formation(1), paper_law(), PAPER_Q0, duration=5.0)
    assert not res.active.any()  # "restrictions not active" all along
    dv = np.diff(res.V)
    # explicit Euler's decrease differs from the exact one by O(dt^2 |grad V|^2); no rise
    assert dv.max() <= 1e-12
    # and the decrease rate matches eq. (10): dV/dt = -(2/k_c) sum |u|^2 (first order in dt)
    rate = dv / np.diff(res.t)
    expected = -(2 / 2.0) * np.sum(res.u[:-1] ** 2, axis=(-1, -2))
    k = slice(100, None)  # away from the stiff first steps
    np.testing.assert_allclose(rate[k], expected[k], rtol=2e-2, atol=1e-9)


def test_distance_law_conserves_centroid():
    f = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], diameters=0.2)
    q0 = np.array([[-2.0, 0.3], [2.5, -1.0], [0.7, 3.0], [-1.0, -2.2]])
    res = fl.simulate(f, fl.DistanceLaw(), q0, duration=3.0)
    drift = res.q.mean(axis=1) - q0.mean(axis=0)
    assert np.abs(drift).max() < 1e-12


def test_too_large_step_stops_with_contact_status():
    f = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    # each Euler step of 0.05 s would carry the robots 4.5 units towards each other,
    # through each other: the swept clearance catches it
    res = fl.simulate(
        f, fl.DistanceLaw(k_c=50.0), [[0, 0], [3.0, 0]], duration=1.0, integrator=fl.Euler(dt=0.05)
    )
    assert res.status == "step-collision"
    assert "robots 1 and 2" in res.message and "reduce dt" in res.message
    assert res.outcome() == "collision"
    assert np.all(np.linalg.norm(res.q[:, 1] - res.q[:, 0], axis=-1) > 0.2)  # never stored
    ok = fl.simulate(
        f, fl.DistanceLaw(k_c=50.0), [[0, 0], [3.0, 0]], duration=1.0, integrator=fl.Euler(dt=1e-3)
    )
    assert ok.status == "success" and ok.outcome() == "desired"


def test_rk4_is_fourth_order_and_euler_first_order():
    f = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
    law = fl.DistanceLaw()
    q0 = np.array([[-1.0, -0.5], [1.2, -0.3], [0.1, 1.4]])
    ref = fl.simulate(f, law, q0, duration=0.5, integrator=fl.RK4(dt=1e-4)).final
    for cls, order in ((fl.Euler, 1), (fl.RK4, 4)):
        dts = np.array([0.01, 0.005, 0.0025])
        errs = [
            np.abs(fl.simulate(f, law, q0, duration=0.5, integrator=cls(dt=dt)).final - ref).max()
            for dt in dts
        ]
        slope = np.polyfit(np.log(dts), np.log(errs), 1)[0]
        assert slope == pytest.approx(order, abs=0.25), (cls.name, errs)


def _sliding_phase(dt):
    """The start of the paper's figure 3: robot 3 far from robots 1 and 2, slightly on
    the wrong side; the distance term pulls it back across the surface, the
    angular term pushes it away: it slides along s while it approaches."""
    res = fl.simulate(
        paper_formation(2),
        paper_law(),
        np.array([[-0.5, 0.0], [0.5, 0.0], [6.0, 0.2]]),
        duration=1.0,
        integrator=fl.Euler(dt=dt),
    )
    sig = res.sigma[:, 0]
    switches = np.flatnonzero(np.diff((sig >= 0).astype(int)))
    return res, sig, switches


def test_sliding_line_distance_eq26():
    """Eq. (26): on the surface alpha c_ijk + theta = 0, robot i is theta / r_jk from line jk."""
    bands = []
    for dt in (1e-4, 5e-5):
        res, sig, switches = _sliding_phase(dt)
        assert len(switches) > 50  # explicit Euler keeps crossing s: a sliding phase
        window = slice(switches[5], switches[-5])
        q = res.q[window]
        r12 = q[:, 1] - q[:, 0]
        rel = q[:, 2] - q[:, 0]
        r = np.linalg.norm(r12, axis=-1)
        dist = np.abs(r12[:, 0] * rel[:, 1] - r12[:, 1] * rel[:, 0]) / r
        predicted = paper_law().theta / r  # eq. (26)
        assert np.ptp(predicted) > 0.01  # r_12 changes while it slides: the line moves
        # explicit Euler chatters in a band of one step's jump of sigma below the surface
        band = np.abs(np.diff(sig[window])).max()
        np.testing.assert_array_less(np.abs(dist - predicted), band / r + 1e-12)
        assert np.mean(np.abs(dist / predicted - 1)) < 0.05
        # the kick of each step that turns the restriction on
        on = switches[(sig[switches] >= 0) & (sig[switches + 1] < 0)]
        bands.append(np.median(sig[on] - sig[on + 1])[()])
    # the chattering amplitude is O(k_a dt): halving dt halves the typical kick
    assert bands[1] / bands[0] == pytest.approx(0.5, rel=0.05)


def test_result_summary_keys():
    res = fl.simulate(paper_formation(1), paper_law(), PAPER_Q0, duration=4.0, save_every=50)
    s = res.summary()
    assert s["outcome"] == "desired" and s["orientation"] == "ccw"
    assert set(s["distance_errors"]) == {"1-2", "1-3", "2-3"}
    assert len(res.t) == 4000 // 50 + 1
    assert s["max_distance_error"] < 1e-3
