"""Contract tests over the registries: every law x every integrator x every robot model.

What every combination must do, whatever its mathematics: a translated start gives the
translated run; a batch of trials steps as each trial alone; a step into contact ends with
a contact status and a finite last state; the same input gives the same result.
"""

import numpy as np
import pytest

import formationlab as fl
from formationlab.controllers import LAWS, laws_in
from formationlab.dynamics import System
from formationlab.integrators import INTEGRATORS, FixedStepIntegrator, StopRule, drive
from formationlab.integrators.base import steps_for
from formationlab.models import MODELS
from formationlab.status import Status

#: the paper's triangle with its orientation from a template (every law can run on it)
TRIANGLE = fl.Formation.from_template(
    [[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]], diameters=0.2
)
START = np.array([[-1.2, -0.9], [1.4, -0.7], [0.1, 1.3]])
FIXED = sorted(n for n, c in INTEGRATORS.items() if issubclass(c, FixedStepIntegrator))


def integrator(name: str, dt: float = 2e-3):
    return fl.get_integrator(name) if name == "filippov" else fl.get_integrator(name, dt=dt)


#: the extra initial state each model is run from (headings that are not all alike,
#: velocities that are not zero), so that the extra state takes part in every check
EXTRA = {
    "single-integrator": {},
    "unicycle": {"headings": [0.3, 2.0, -1.9]},
    "double-integrator": {"velocities": [[0.2, -0.1], [0.0, 0.3], [-0.2, 0.0]]},
    "quadrotor": {"velocities": [[0.2, -0.1], [0.0, 0.3], [-0.2, 0.0]]},
}


def initial(model: str, q0):
    """The model's full initial state from positions ``q0`` (..., n, 2)."""
    return fl.models.get_model(model).initial_state(q0, **EXTRA[model])


def test_the_registries_hold_what_the_contract_runs_over():
    assert {"distance", "angle-restricted", "squared-distance", "signed-area"} <= set(LAWS)
    assert {"euler", "rk4", "implicit-euler"} <= set(FIXED) and "filippov" in INTEGRATORS
    assert {"single-integrator", "unicycle", "double-integrator"} <= set(MODELS)
    assert set(EXTRA) == set(MODELS)  # every model has its start here


@pytest.mark.parametrize("model", sorted(MODELS))
@pytest.mark.parametrize("integ", sorted(INTEGRATORS))
@pytest.mark.parametrize("law", laws_in(2))
def test_a_translated_start_gives_the_translated_run(law, integ, model):
    shift = np.array([40.0, -25.0])
    runs = [
        fl.simulate(
            TRIANGLE,
            fl.get_law(law),
            q0,
            duration=0.3,
            integrator=integrator(integ),
            model=model,
            **EXTRA[model],
        )
        for q0 in (START, START + shift)
    ]
    a, b = runs
    assert a.status == b.status == "success"
    assert a.model.name == model and a.x.shape[-1] == MODELS[model].state_size()
    np.testing.assert_allclose(b.t, a.t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.q - shift, a.q, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.x[..., 2:], a.x[..., 2:], rtol=0, atol=1e-7)
    np.testing.assert_allclose(b.u, a.u, rtol=0, atol=1e-7)
    assert np.all(np.isfinite(a.x)) and np.abs(a.q[-1] - a.q[0]).max() > 1e-3  # it moved


@pytest.mark.parametrize("model", sorted(MODELS))
@pytest.mark.parametrize("integ", FIXED)
@pytest.mark.parametrize("law", laws_in(2))
def test_a_batch_steps_as_each_trial_alone(law, integ, model):
    rng = np.random.default_rng(3)
    starts = START + rng.normal(0.0, 0.3, size=(5, 3, 2))
    starts[4] = [[-0.3, 0.0], [0.3, 0.0], [0.0, 3.0]]  # robots 1 and 2 close: fast, may collide
    starts = initial(model, starts)
    system = System(formation=TRIANGLE, law=fl.get_law(law), model=fl.models.get_model(model))
    stepper = integrator(integ, dt=5e-3)
    n_steps = steps_for(0.5, stepper.dt)
    stop = StopRule(speed=1e-3, check_every=10)
    batch = drive(system, stepper, starts, n_steps=n_steps, stop=stop)
    for b in range(len(starts)):
        alone = drive(system, stepper, starts[b : b + 1], n_steps=n_steps, stop=stop)
        assert batch.status[b] == alone.status[0] and batch.steps[b] == alone.steps[0]
        np.testing.assert_allclose(batch.x[b], alone.x[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(batch.v[b], alone.v[0], rtol=0, atol=1e-9)
        assert batch.message[b] == alone.message[0]


#: gains with which one step of 0.05 s from START_APART moves robots 1 and 2 about 2 each
#: towards each other: an explicit step carries them through each other
STRONG = {
    "distance": {"k_c": 45.0},
    "angle-restricted": {"k_c": 45.0, "k_a": 0.5},
    "bearing": {"k": 100.0},
}
START_APART = np.array([[0.0, 0.0], [3.0, 0.0], [1.5, 5.0]])
#: the bearing law moves robots across their own bearing only (it keeps the scale): robot 3
#: between and just above robots 1 and 2 turns both its bearings, which moves 1 and 2
#: towards each other at 0.48 k with no relative motion across (g_12 stays g*_12)
STARTS_APART = {"bearing": np.array([[0.0, 0.0], [1.4, 0.0], [0.7, 0.3]])}


@pytest.mark.parametrize("integ", sorted(INTEGRATORS))
@pytest.mark.parametrize("law", laws_in(2))
def test_a_step_into_contact_ends_with_a_contact_status_and_finite_states(law, integ):
    gains = STRONG.get(law, {"k": 2.0})
    res = fl.simulate(
        TRIANGLE, fl.get_law(law, **gains), STARTS_APART.get(law, START_APART), duration=1.0,
        integrator=integrator(integ, dt=0.05),
    )  # fmt: skip
    assert np.all(np.isfinite(res.q))  # states are always finite
    # so are velocities, but for the last one of a run whose next step blew up
    assert np.all(np.isfinite(res.u[:-1])) and (
        np.all(np.isfinite(res.u[-1])) or res.status == "non-finite"
    )
    system = System(formation=TRIANGLE, law=fl.get_law(law))
    assert np.all(system.clearance(res.q) > 0)  # no stored state is in contact
    if integ != "filippov":  # saved every step: no accepted step passed through contact
        assert np.all(system.swept_clearance(res.q[:-1], res.q[1:]) > 0)
    if integ == "euler":  # the first step overshoots through contact
        assert res.status == "step-too-large" and len(res.t) == 1
    if Status(res.status).contact:
        assert res.outcome() == "collision"
        assert "robots 1 and 2" in res.message and "dt" in res.message
    elif res.status == "non-finite":  # the cubic laws' explicit steps diverge first
        assert law in ("squared-distance", "signed-area") and "reduce dt" in res.message
    else:  # an accurate scheme follows the flow, which keeps them apart here
        assert res.status == "success"


@pytest.mark.parametrize("model", sorted(MODELS))
@pytest.mark.parametrize("integ", sorted(INTEGRATORS))
@pytest.mark.parametrize("law", laws_in(2))
def test_the_same_input_gives_the_same_run(law, integ, model):
    rng = np.random.default_rng(11)
    q0 = START + rng.normal(0.0, 0.2, size=(3, 2))
    a, b = (
        fl.simulate(
            TRIANGLE,
            fl.get_law(law),
            q0,
            duration=0.2,
            integrator=integrator(integ),
            model=model,
            **EXTRA[model],
        )
        for _ in range(2)
    )
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.u, b.u)
    assert a.summary()["outcome"] == b.summary()["outcome"]


@pytest.mark.parametrize("model", sorted(MODELS))
@pytest.mark.parametrize("integ", sorted(INTEGRATORS))
@pytest.mark.parametrize("law", laws_in(2))
def test_no_model_ever_stores_a_state_in_contact(law, integ, model):
    # strong gains from a start where robots 1 and 2 rush at each other: whatever the
    # model does, every stored state is finite and clear, and a contact ends the run
    # (the cubic laws with a gain whose explicit steps do not blow up)
    gains = STRONG.get(law, {"k": 0.2})
    res = fl.simulate(
        TRIANGLE, fl.get_law(law, **gains), START_APART, duration=1.0,
        integrator=integrator(integ, dt=0.05), model=model, **EXTRA[model],
    )  # fmt: skip
    assert np.all(np.isfinite(res.x))
    system = System(formation=TRIANGLE, law=fl.get_law(law), model=res.model)
    assert np.all(system.clearance(res.x) > 0)
    if integ != "filippov":
        assert np.all(system.swept_clearance(res.x[:-1], res.x[1:]) > 0)
    if Status(res.status).contact:
        assert res.outcome() == "collision" and "dt" in res.message
    s = res.summary()
    assert s["model"]["name"] == model and s["state_names"] == list(MODELS[model].state_names)


@pytest.mark.parametrize("law", laws_in(2))
def test_every_law_summarises_on_an_oriented_formation(law):
    # the summary of a law without switching surfaces on a formation with an orientation
    # lists no active restrictions (it used to crash matching labels against no surfaces)
    res = fl.simulate(TRIANGLE, fl.get_law(law), START, duration=0.2)
    s = res.summary()
    assert isinstance(s["active_restrictions_final"], list)
    surfaces = res.sigma.shape[-1]
    assert (surfaces > 0) == (law == "angle-restricted")
    assert len(res.restriction_labels) == surfaces


@pytest.mark.parametrize("integ", sorted(INTEGRATORS))
def test_an_interrupted_run_keeps_the_states_so_far(integ):
    law = fl.AngleRestrictedLaw()

    def ctrl_c(t):  # what the terminal's Ctrl-C does, raised from inside the time loop
        if t >= 0.05:
            raise KeyboardInterrupt

    def run(**kwargs):
        return fl.simulate(
            TRIANGLE, law, START, duration=5.0, integrator=integrator(integ, dt=1e-3), **kwargs
        )

    with pytest.raises(KeyboardInterrupt):
        run(progress=ctrl_c)
    res = run(progress=ctrl_c, interruptible=True)
    assert res.status == "interrupted" and "interrupted" in res.message
    assert 0.05 <= res.t[-1] < 1.0 and np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.u))
    full = run()
    stop = len(res.t) - 1  # the states so far are those of the uninterrupted run
    if integ != "filippov":
        np.testing.assert_array_equal(res.q[:stop], full.q[:stop])


#: every sensing key and a fault at once (the sensed closed loop's contract)
SENSED = fl.Sensing(frames="local", noise=0.005, range=4.0, delay=0.004, drop=0.2, mismatch=0.01)
STOPS = fl.Faults(stop=[fl.Stop(robot=3, at=0.05)])
EXPLICIT = sorted(n for n, c in INTEGRATORS.items() if getattr(c, "explicit", False))


@pytest.mark.parametrize("model", sorted(MODELS))
@pytest.mark.parametrize("integ", EXPLICIT)
@pytest.mark.parametrize("law", laws_in(2))
def test_the_sensed_loop_keeps_the_contract(law, integ, model):
    """Sensed, faulty runs: translation invariance, a seed fixes the run, and finite states."""
    shift = np.array([40.0, -25.0])
    kw = {"duration": 0.2, "integrator": integrator(integ), "model": model,
          "sensing": SENSED, "faults": STOPS, **EXTRA[model]}  # fmt: skip
    a = fl.simulate(TRIANGLE, fl.get_law(law), START, **kw)
    b = fl.simulate(TRIANGLE, fl.get_law(law), START + shift, **kw)
    again = fl.simulate(TRIANGLE, fl.get_law(law), START, **kw)
    np.testing.assert_array_equal(a.x, again.x)
    np.testing.assert_allclose(b.q - shift, a.q, atol=1e-9)
    assert np.all(np.isfinite(a.x)) and a.status in (Status.SUCCESS, Status.COLLISION)
    k = int(np.searchsorted(a.t, 0.05))
    assert np.all(a.q[k:, 2] == a.q[k, 2])  # robot 3 stopped
