"""The simulator: Lyapunov decrease (10), centroid, contact handling, eq. (26), RK4 order."""

import numpy as np
import pytest

import formationlab as fl
from formationlab.studies.paper import PAPER_Q0, paper_formation, paper_law


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


def test_a_step_through_each_other_stops_with_the_step_too_large_status():
    f = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    # each Euler step of 0.05 s would carry the robots 4.5 units towards each other,
    # through each other: the swept clearance catches it
    res = fl.simulate(
        f, fl.DistanceLaw(k_c=50.0), [[0, 0], [3.0, 0]], duration=1.0, integrator=fl.Euler(dt=0.05)
    )
    # both ends of the rejected step are clear: the robots jumped through each other
    assert res.status == "step-too-large"
    assert "robots 1 and 2 pass through each other" in res.message and "reduce dt" in res.message
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


# ------------------------------------------------------------- stopped: net speed
# The scalar picture of Euler chattering on a switching surface: a relay
# x_dot = -g sign(x - c) stepped by explicit Euler from x0 = c + g dt / 2 alternates
# between c + g dt / 2 and c - g dt / 2: |u| = g at every step, no net motion (the
# Filippov velocity at x = c is 0). A constant velocity v moves by v T in any window T.


class _Relay(fl.DistanceLaw):
    """Every robot: ``u = (-g sign(x_1 - c), 0)`` (robot 1's abscissa decides)."""

    name = "relay-for-test"
    g, c = 1.0, 0.25

    def control(self, formation, q):
        q = np.asarray(q, dtype=float)
        u = np.zeros_like(q)
        u[..., 0] = -self.g * np.sign(q[..., :1, 0] - self.c)
        return u


class _Drift(fl.DistanceLaw):
    """Every robot: ``u = (v, 0)``, a smooth motion at constant speed ``v``."""

    name = "drift-for-test"
    v = 2e-3

    def control(self, formation, q):
        u = np.zeros_like(np.asarray(q, dtype=float))
        u[..., 0] = self.v
        return u


def _pair():
    """Two robots 2 apart with d_12 = 1: distances not met wherever they stop."""
    f = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    return f, np.array([[0.25 + 5e-4, 0.0], [2.25 + 5e-4, 0.0]])


def test_net_speed_of_sampled_chatter_and_of_steady_motion():
    dt = 1e-3
    t = dt * np.arange(40)
    chatter = np.zeros((40, 1, 2))
    chatter[:, 0, 0] = 0.25 + 5e-4 * (-1.0) ** np.arange(40)
    ns = fl.outcomes.analysis.net_speed(t, chatter, 0.01)  # 10 steps back: an even number
    assert np.isnan(ns[:10]).all()  # no sample 10 ms back: unknown
    assert np.all(ns[10:] < 1e-12)
    odd = fl.outcomes.analysis.net_speed(t, chatter, 0.009)  # 9 steps: one kick of 1e-3 remains
    np.testing.assert_allclose(odd[9:], 1e-3 / 0.009, rtol=1e-9)
    steady = np.zeros((40, 2, 2))
    steady[:, :, 1] = 0.3 * t[:, None]
    np.testing.assert_allclose(fl.outcomes.analysis.net_speed(t, steady, 0.01)[10:], 0.3, rtol=1e-9)
    # samples sparser than the window: over the shortest saved interval >= window
    sparse = fl.outcomes.analysis.net_speed(t[::4], steady[::4], 0.01)
    assert np.isnan(sparse[:3]).all()
    np.testing.assert_allclose(sparse[3:], 0.3, rtol=1e-9)


def test_chatter_at_rest_is_stopped_and_steady_motion_is_not():
    f, q0 = _pair()
    res = fl.simulate(f, _Relay(), q0, duration=1.0, integrator=fl.Euler(dt=1e-3))
    assert np.all(np.linalg.norm(res.u, axis=-1).max(axis=-1) == 1.0)  # never slow
    np.testing.assert_allclose(res.q[-1, 0, 0] - 0.25, 5e-4 * (-1) ** 1000, atol=1e-12)
    assert res.net_speed() < 1e-9
    assert res.outcome() == "incorrect"  # stopped, distances not met
    # stopped from the first time a sample lies one window back: t = 10 ms
    assert res.converged_time() == pytest.approx(0.01)
    # over an odd number of steps the net displacement is one kick: 1e-3 / 9e-3 > speed
    odd = fl.Tolerances(window=0.009)
    assert res.net_speed(odd) == pytest.approx(1e-3 / 0.009)
    assert res.outcome(odd) == "not-converged" and res.converged_time(odd) is None
    s = res.summary()
    assert s["net_speed"] < 1e-9 and s["final_speed"] == 1.0 and s["tolerances"]["window"] == 0.01

    drift = fl.simulate(f, _Drift(), q0, duration=1.0, integrator=fl.Euler(dt=1e-3))
    assert drift.net_speed() == pytest.approx(2e-3)
    assert drift.outcome() == "not-converged" and drift.converged_time() is None
    # a run shorter than the window has no net speed: only |u| decides
    short = fl.simulate(f, _Relay(), q0, duration=0.005, integrator=fl.Euler(dt=1e-3))
    assert short.net_speed() is None and short.outcome() == "not-converged"


def test_window_must_be_positive():
    with pytest.raises(fl.errors.ParameterError, match="window"):
        fl.Tolerances(window=0.0)


def test_the_api_refuses_unknown_keywords_and_warns_about_another_models_state():
    from formationlab.errors import IgnoredKeyWarning, ParameterError

    f = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
    q0 = [[0.0, 0.0], [2.0, 0.1], [1.0, 1.5]]
    with pytest.raises(ParameterError, match="unknown keyword 'durration'") as exc:
        fl.simulate(f, "distance", q0, duration=0.1, durration=3.0)  # a typo is not state
    assert exc.value.key == "durration"
    assert "'headings' for 'unicycle'" in str(exc.value)
    assert "'velocities' for 'double-integrator' and 'quadrotor'" in str(exc.value)
    with pytest.raises(ParameterError, match="backend must be 'auto', 'numpy' or 'numba'"):
        fl.simulate(f, "distance", q0, duration=0.1, backend="gpu")  # type: ignore[arg-type]
    with pytest.warns(IgnoredKeyWarning, match="headings is the initial state of the 'unicycle'"):
        res = fl.simulate(f, "distance", q0, duration=0.1, headings=[0.0, 1.0, 2.0])
    plain = fl.simulate(f, "distance", q0, duration=0.1)
    np.testing.assert_array_equal(res.q, plain.q)  # ignored: the same run
    uni = fl.simulate(f, "distance", q0, duration=0.1, model="unicycle", headings=[0.0, 1.0, 2.0])
    np.testing.assert_array_equal(uni.x[0, :, 2], [0.0, 1.0, 2.0])  # its own key is taken


def test_the_api_refuses_runs_too_long_or_too_large_before_allocating():
    from formationlab.errors import ParameterError
    from formationlab.resources import available_memory

    f = fl.Formation.from_distances(3, distances=1.0, diameters=0.2)
    q0 = [[0.0, 0.0], [2.0, 0.1], [1.0, 1.5]]
    for kw in ({"integrator": fl.Euler(dt=1e-300)}, {"duration": 1e300}):
        with pytest.raises(ParameterError, match=r"steps, more than 1e\+13") as exc:
            fl.simulate(f, "distance", q0, **{"duration": 1.0, **kw})
        assert exc.value.key == "duration"
    memory = available_memory()
    if memory is None:
        pytest.skip("the memory available is not known here")
    dt = 1e-6
    duration = 2 * memory / 56 * dt  # each saved state of 3 robots takes 56 bytes
    with pytest.raises(ParameterError, match="keep fewer") as exc:
        fl.simulate(f, "distance", q0, duration=duration, integrator=fl.Euler(dt=dt))
    assert exc.value.key == "save_every"
    every = int(str(exc.value).split("save_every = ")[-1].split(")")[0])
    from formationlab.simulation.run import _check_size, build_system

    system = build_system(f, fl.get_law("distance"), fl.SingleIntegrator(), np.asarray(q0))
    _check_size(system, fl.Euler(dt=dt), duration, every)  # the advice is accepted
