"""The viewer's live session and replay, against the package's own simulator."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _viewer import SIM2, sim2_session

import formationlab as fl
from formationlab.cli import main
from formationlab.errors import ParameterError, ViewerWarning
from formationlab.io.netcdf import load_trajectory
from formationlab.scenario import parse_scenario
from formationlab.viewer import Controller, ReplaySession, SessionError
from formationlab.viewer.messages import decode_binary, encode_binary
from formationlab.viewer.sources import open_session


def test_steps_equal_the_simulator():
    s = sim2_session()
    assert s.step(200) == 200
    sc = s.scenario
    ref = fl.simulate(sc.formation, sc.law, sc.q0, duration=0.2, integrator=sc.integrator)
    np.testing.assert_array_equal(s.q, ref.q[-1])
    assert s.t == pytest.approx(0.2, abs=1e-12)


def test_advance_runs_speed_times_wall_time():
    s = sim2_session(step_budget_s=10.0)
    assert s.advance(0.05) == 50  # dt = 1e-3, speed 1: 0.05 s of wall time is 50 steps
    s.set_speed(0.1)
    assert s.advance(0.05) == 5
    s.set_paused(True)
    assert s.advance(0.05) == 0
    assert s.steps == 55


def test_drag_holds_the_robot_and_the_others_respond():
    s = sim2_session()
    s.drag(1, -1.0, 0.5)
    np.testing.assert_array_equal(s.q[0], [-1.0, 0.5])
    q_before = s.q.copy()
    s.step(50)
    np.testing.assert_array_equal(s.q[0], [-1.0, 0.5])  # pinned while dragged
    assert np.linalg.norm(s.q[1:] - q_before[1:]) > 1e-3
    s.release()
    s.step(50)
    assert np.linalg.norm(s.q[0] - [-1.0, 0.5]) > 1e-4  # moves under its control again
    with pytest.raises(SessionError, match="would overlap robot 2"):
        s.drag(1, *s.q[1])
    with pytest.raises(SessionError, match=r"robots are 1\.\.3"):
        s.drag(4, 0.0, 0.0)


def test_set_law_and_params_change_the_field():
    s = sim2_session()
    f, q = s.formation, s.q.copy()
    s.set_law("distance")
    assert s.law == fl.DistanceLaw(k_c=2.0)  # k_c and the repulsion carry over
    np.testing.assert_allclose(s.system.rhs(q), fl.DistanceLaw(k_c=2.0).control(f, q))
    s.set_law("angle-restricted", {"k_a": 5.0})
    assert (s.law.k_a, s.law.k_c, s.law.theta) == (5.0, 2.0, 0.5)
    with pytest.raises(ParameterError):
        s.set_params({"k_c": 0.0})
    with pytest.raises(SessionError, match="has no parameter 'k'"):
        s.set_params({"k": 1.0})
    assert s.law.k_c == 2.0


def test_integrators_and_filippov_mapping():
    s = sim2_session()
    s.set_integrator("rk4", 2e-3)
    assert (s.integrator.name, s.integrator.dt) == ("rk4", 2e-3)
    s.set_integrator("filippov", 1e-3)
    assert s.integrator.name == "implicit-euler" and "event-driven" in s.notices[-1]
    with pytest.raises(SessionError, match="cannot step live"):
        s.set_integrator("leapfrog", 1e-3)
    raw = dict(parse_scenario(SIM2.read_text()).raw)
    raw["simulation"] = {"integrator": "filippov", "duration": 1.0}
    with pytest.warns(ViewerWarning, match=r"integrator = 'filippov'.*implicit-euler"):
        live = open_session(parse_scenario(raw))
    assert live.integrator.name == "implicit-euler" and live.notices


def test_collision_pauses_with_a_message():
    s = sim2_session()
    s.set_integrator("euler", 0.5)  # far too large a step: robots jump through each other
    s.step(20)
    # the package's contact rule (System.step_verdict) and its message
    assert s.paused and s.status in ("step-collision", "step-too-large", "non-finite")
    assert "reduce dt" in s.message


def test_export_is_a_valid_scenario_of_the_state_now(tmp_path):
    s = sim2_session()
    s.step(100)
    s.set_params({"k_a": 4.0})
    name, text = s.export_scenario()
    assert name.endswith(".toml")
    sc = parse_scenario(text)
    np.testing.assert_array_equal(sc.q0, s.q)
    assert sc.law == s.law and sc.integrator == s.integrator
    np.testing.assert_array_equal(sc.formation.alpha, s.formation.alpha)


def test_perturb_moves_every_robot_reproducibly():
    a, b = sim2_session(), sim2_session()
    a.perturb(0.2)
    b.perturb(0.2)
    np.testing.assert_array_equal(a.q, b.q)  # same seed
    assert np.all(np.linalg.norm(a.q - a.scenario.q0, axis=-1) > 0)


def test_frames_carry_v_errors_and_active_surfaces():
    s = sim2_session()
    fr = s.frame()
    f, law, q = s.formation, s.law, s.q
    assert fr.header["V"] == pytest.approx(float(law.potential(f, q)))
    r = np.linalg.norm(q[f.edges[:, 1]] - q[f.edges[:, 0]], axis=-1) - f.distances
    np.testing.assert_allclose(fr.header["errors"], r)
    assert fr.header["active"] == (np.flatnonzero(law.switching(f, q) >= 0) + 1).tolist()
    assert fr.header["active"] == [1]  # c_123 = +36 with beta = +1: the restriction is on
    np.testing.assert_array_equal(fr.positions, q.astype(np.float32))


def test_controller_frames_round_trip_through_binary():
    ctl = Controller(sim2_session())
    info, frame = ctl.hello()
    assert info.header["type"] == "info" and info.header["n"] == 3
    assert info.header["surfaces"] == {"triangles": [[1, 2, 3]], "beta": [1.0]}
    header, bufs = decode_binary(encode_binary(frame.header, frame.buffers))
    np.testing.assert_array_equal(
        np.frombuffer(bufs[0], "<f4").reshape(3, 2), ctl.session.q.astype(np.float32)
    )
    assert header["heading"] is False
    (err,) = ctl.handle(json.dumps({"type": "seek", "index": 3}))
    assert err.header["type"] == "error" and "replay only" in err.header["message"]


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    raw = dict(parse_scenario(SIM2.read_text()).raw)
    raw["simulation"] = {**raw["simulation"], "duration": 0.5}
    sc_path = tmp_path_factory.mktemp("sc") / "short.toml"
    import tomli_w

    sc_path.write_text(tomli_w.dumps(raw))
    out = tmp_path_factory.mktemp("run") / "sim2"
    with pytest.raises(SystemExit) as exc:
        main(["run", str(sc_path), "--out", str(out), "--save-every", "10", "--quiet"])
    assert exc.value.code in (0, None)
    return out


def test_replay_plays_the_stored_run(run_folder):
    ds = load_trajectory(run_folder / "trajectory.nc")
    s = open_session(run_folder)
    assert isinstance(s, ReplaySession) and len(s.t) == 51
    s.seek(20)
    fr = s.frame()
    np.testing.assert_array_equal(fr.positions, ds["q"].values[20].astype(np.float32))
    assert fr.header["t"] == pytest.approx(0.2) and fr.header["index"] == 20
    assert fr.header["V"] == pytest.approx(float(ds["V"].values[20]))
    s.set_speed(1.0)
    assert s.advance(0.1) == 10  # 0.1 s of the run at 0.01 s a frame
    assert s.info()["surfaces"]["triangles"] == [[1, 2, 3]]
    with pytest.raises(SessionError, match="replay cannot move robots"):
        s.drag(1, 0.0, 0.0)
    _, text = s.export_scenario()
    np.testing.assert_array_equal(parse_scenario(text).q0, ds["q"].values[30])
    s.advance(100.0)
    assert s.index == 50 and s.paused  # stops at the end


def test_a_state_the_page_cannot_draw_pauses_the_stream_with_a_message():
    """Positions go to the page as float32: a robot beyond its range (finite in float64,
    infinite in float32) pauses the session and says so, and no inf is streamed."""
    import warnings

    s = sim2_session()
    s.state[0] = [1e39, 0.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (no overflow warning from the cast either)
        assert s.step(5) == 0
        fr = s.frame()
    assert s.paused and fr.header["status"] == "out-of-range"
    assert "lower the gains" in fr.header["message"] and s.steps == 0  # refused before a step
    assert np.all(np.isfinite(fr.positions))
