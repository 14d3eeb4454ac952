"""The notebook widget's Python side: traitlets and the run stay in sync, both ways."""

from __future__ import annotations

import numpy as np
import pytest
from _viewer import SIM2

import formationlab as fl
from formationlab.io.scenario import load_scenario
from formationlab.viewer import SessionError


@pytest.fixture
def widget():
    v = fl.Viewer(load_scenario(SIM2), seed=3)
    v.sent = []
    v.send = lambda content, buffers=None: v.sent.append((content, buffers))
    return v


def front_end(v, msg):
    v._on_front_end(v, msg, [])
    return [c["type"] for c, _ in v.sent]


def test_initial_traits_mirror_the_scenario(widget):
    v = widget
    assert (v.name, v.mode, v.n, v.t, v.paused) == ("paper-simulation-2", "live", 3, 0.0, False)
    assert (v.law, v.law_params) == ("angle-restricted", {"k_c": 2.0, "k_a": 3.0, "theta": 0.5})
    assert (v.integrator, v.dt) == ("euler", 1e-3)
    assert "export default { render }" in v._esm  # the page's own front end


def test_front_end_messages_update_the_traits(widget):
    v = widget
    assert front_end(v, {"type": "hello"}) == ["info", "frame"]
    _, buffers = v.sent[-1]
    np.testing.assert_array_equal(np.frombuffer(buffers[0], "<f4"), v.positions.ravel())
    front_end(v, {"type": "step", "count": 40})
    assert v.t == pytest.approx(0.04)
    front_end(v, {"type": "drag", "robot": 2, "x": 1.0, "y": 1.0})
    np.testing.assert_array_equal(v.positions[1], [1.0, 1.0])
    front_end(v, {"type": "pause", "paused": True})
    assert v.paused
    front_end(v, {"type": "set_law", "name": "distance"})
    assert (v.law, v.law_params) == ("distance", {"k_c": 2.0})
    assert front_end(v, {"type": "drag", "robot": 9, "x": 0, "y": 0})[-1] == "error"


def test_python_changes_drive_the_run_and_reach_the_front_end(widget):
    v = widget
    v.law_params = {"k_a": 6.0}
    assert v.session.law.k_a == 6.0 and v.law_params["k_a"] == 6.0
    assert [c["type"] for c, _ in v.sent] == ["settings", "frame"]
    v.paused = True
    assert v.session.paused
    v.integrator = "rk4"
    assert v.session.integrator == fl.RK4(dt=1e-3)
    v.speed = 4.0
    assert v.session.speed == 4.0
    with pytest.raises(SessionError, match="unknown law"):
        v.law = "no-such-law"
    assert v.law == "angle-restricted"  # back to the law in force
    with pytest.raises(SessionError, match="k_c"):
        v.law_params = {"k_c": -1.0}
    assert v.law_params["k_c"] == 2.0 and v.session.law.k_c == 2.0


def test_stepped_from_python_without_a_browser(widget):
    """step / t / positions / state / history from Python: the run of `simulate`."""
    v = widget
    assert v.step(25) == 25 and v.t == pytest.approx(0.025, abs=1e-12)
    sc = v.session.scenario
    ref = fl.simulate(sc.formation, sc.law, sc.q0, duration=0.025, integrator=sc.integrator,
                      backend="numpy")  # fmt: skip
    np.testing.assert_array_equal(v.positions, ref.q[-1])
    np.testing.assert_array_equal(v.state, ref.x[-1])
    hist = v.history
    assert hist.positions.shape == (26, 3, 2) and hist.t.shape == (26,)
    np.testing.assert_allclose(hist.t, ref.t, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(hist.positions, ref.q)
    v.session.reset()
    assert v.history.positions.shape == (1, 3, 2)
    with pytest.raises(SessionError, match="whole number"):
        v.step(-1)


def test_the_front_end_bundle_has_only_a_default_render(widget):
    """anywidget deprecates a named ``render`` export: the module's default is ``{ render }``."""
    esm = widget._esm
    assert "export default { render }" in esm
    assert "export { socketModel }" in esm and "export { render" not in esm


def test_odd_arguments_get_the_packages_error_with_their_name():
    """An unknown keyword (silently accepted by the widget base class) and a seed numpy
    would refuse with its own words: the package's ParameterError, naming the argument."""
    with pytest.raises(fl.errors.ParameterError, match="no argument 'foo'") as info:
        fl.Viewer(SIM2, foo=1)
    assert info.value.key == "foo" and "law_params" in str(info.value)
    with pytest.raises(fl.errors.ParameterError, match="seed must be a whole number") as info:
        fl.Viewer(SIM2, seed=-1)
    assert info.value.key == "seed"
    with pytest.raises(fl.errors.ParameterError, match="no argument 't'"):
        fl.Viewer(SIM2, t=3.0)  # read from the session, not set
    # a setting reaches the session (the widget's traits alone were overwritten by it)
    v = fl.Viewer(SIM2, seed=3, paused=True, law_params={"k_a": 5.0}, speed=2.0)
    assert v.paused and v.session.paused and v.session.seed == 3
    assert v.session.law.k_a == 5.0 and v.law_params["k_a"] == 5.0 and v.speed == 2.0
