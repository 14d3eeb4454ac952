"""The quadrotor model: a velocity that lags the command, within speed and acceleration limits.

Its module docstring (``formationlab.models.quadrotor``) gives the model and the energy
that certifies it without limits; these tests check both, in the plane and in space.
"""

from __future__ import annotations

import numpy as np
import pytest

import formationlab as fl
from formationlab.models import Quadrotor, quadrotor_energy
from formationlab.studies.batch import run_batch

TETRA = np.array(
    [[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0], [0.5, np.sqrt(3) / 6, np.sqrt(2 / 3)]]
)
TRIANGLE = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]])


class Constant(fl.Law):
    """The same command for every robot (a step input)."""

    name = "constant-test"

    def control(self, formation, q):
        return np.broadcast_to(self.u, q.shape).copy()

    def potential(self, formation, q):
        return np.zeros(q.shape[:-2])


@pytest.mark.parametrize("dim", [2, 3])
def test_without_limits_the_velocity_is_a_first_order_lag(dim) -> None:
    """A step command ``u``: ``w(t) = u (1 - exp(-t / tau))``, ``q(t) = u (t - tau (1 -
    exp(-t / tau)))`` from rest (RK4 at 1 ms: to 1e-9)."""
    tau = 0.3
    model = Quadrotor(time_constant=tau, max_accel=None, max_speed=None)
    law = Constant()
    u = np.array([0.4, -0.2, 0.1][:dim])
    object.__setattr__(law, "u", u)
    tpl = TETRA if dim == 3 else TRIANGLE
    f = fl.Formation.from_template(tpl, orientation="free")
    r = fl.simulate(f, law, 3 * tpl, duration=1.0, model=model,
                    integrator=fl.get_integrator("rk4", dt=1e-3))  # fmt: skip
    t = r.t[:, None, None]
    lag = 1.0 - np.exp(-t / tau)
    w, moved = r.x[..., dim:], r.q - 3 * tpl
    np.testing.assert_allclose(w, np.broadcast_to(u * lag, w.shape), atol=1e-9)
    np.testing.assert_allclose(moved, np.broadcast_to(u * (t - tau * lag), moved.shape), atol=1e-9)
    assert r.summary()["state_names"] == list("xyz"[:dim]) + ["v" + a for a in "xyz"[:dim]]


@pytest.mark.parametrize("dim", [2, 3])
def test_without_limits_the_energy_falls_as_the_docstring_says(dim) -> None:
    tau, k_c = 0.25, 2.0
    model = Quadrotor(time_constant=tau, max_accel=None, max_speed=None)
    law = fl.DistanceLaw(k_c=k_c)
    tpl = TETRA if dim == 3 else TRIANGLE
    f = fl.Formation.from_template(tpl, orientation="free", diameters=0.2)
    rng = np.random.default_rng(4)
    q0 = 2.5 * tpl + rng.normal(scale=0.3, size=tpl.shape)
    x0 = model.initial_state(q0, velocities=rng.normal(scale=0.3, size=tpl.shape))
    r = fl.simulate(f, law, x0, duration=3.0, model=model,
                    integrator=fl.get_integrator("rk4", dt=1e-3))  # fmt: skip
    E = quadrotor_energy(r.V, r.x, k_c, tau)
    w = r.x[..., dim:]
    rate = -(2.0 / k_c) * np.sum(w * w, axis=(-2, -1))  # E_dot of the docstring
    dE = np.gradient(E, r.t)
    np.testing.assert_allclose(dE[2:-2], rate[2:-2], rtol=1e-3, atol=1e-6)
    assert np.all(np.diff(E) <= 1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_the_limits_hold_along_a_run(dim) -> None:
    model = Quadrotor(time_constant=0.2, max_accel=1.5, max_speed=0.6)
    tpl = TETRA if dim == 3 else TRIANGLE
    f = fl.Formation.from_template(tpl, diameters=0.2)
    law = fl.ChiralityRestrictedLaw() if dim == 3 else fl.AngleRestrictedLaw()
    r = fl.simulate(f, law, 4 * tpl, duration=4.0, model=model,
                    integrator=fl.get_integrator("euler", dt=1e-3))  # fmt: skip
    w, a = r.xdot[..., :dim], r.xdot[..., dim:]
    assert np.max(np.linalg.norm(w, axis=-1)) <= 0.6 * (1 + 1e-12)
    assert np.max(np.linalg.norm(a, axis=-1)) <= 1.5 * (1 + 1e-12)
    assert np.max(np.linalg.norm(a, axis=-1)) > 1.4  # the limit was reached, not idle


def test_a_drone_formation_in_space_reaches_its_chirality_with_lag_and_limits(tmp_path) -> None:
    from pathlib import Path

    from typer.testing import CliRunner

    from formationlab.cli import _load_commands, app

    _load_commands()
    path = Path(__file__).parents[1] / "examples" / "space" / "drones-quadrotor.toml"
    res = CliRunner().invoke(app, ["run", str(path), "--out", str(tmp_path / "o"), "--quiet"])
    assert res.exit_code == 0, res.output
    import json

    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["outcome"] == "desired", s
    assert s["model"]["name"] == "quadrotor"
    assert s["state_names"] == ["x", "y", "z", "vx", "vy", "vz"]


def test_a_batch_of_quadrotors_runs_compiled_as_its_single_runs() -> None:
    from formationlab.studies.batch import batch_backend

    model = Quadrotor()
    assert batch_backend("numba", model=model) == ("numba", "")
    f = fl.Formation.from_template(TRIANGLE, diameters=0.2)
    rng = np.random.default_rng(2)
    q0 = np.stack([3 * TRIANGLE + rng.normal(scale=0.5, size=(3, 2)) for _ in range(3)])
    x0 = model.initial_state(q0)
    kw = {"dt": 1e-2, "duration": 15.0, "model": model}
    res = run_batch(f, fl.AngleRestrictedLaw(), x0, backend="numba", **kw)
    slow = run_batch(f, fl.AngleRestrictedLaw(), x0, backend="numpy", **kw)
    assert "desired" in list(res.outcome)
    assert list(res.outcome) == list(slow.outcome)
    np.testing.assert_array_equal(res.steps, slow.steps)
    for b in range(3):  # each trial is its single run (the numpy driver's)
        one = fl.simulate(f, fl.AngleRestrictedLaw(), x0[b], duration=15.0, model=model,
                          integrator=fl.Euler(dt=1e-2), backend="numpy")  # fmt: skip
        np.testing.assert_allclose(one.x[int(res.steps[b])], res.x_final[b], atol=1e-9)


def test_double_integrators_in_space_descend_their_energy() -> None:
    """The double integrator's energy (``models.double_integrator``) in space: ``E = V +
    sum |q_dot|^2 / k_c`` falls along a run of the distance law on the tetrahedron."""
    from formationlab.models import DoubleIntegrator, energy

    model = DoubleIntegrator(damping=2.0)
    f = fl.Formation.from_template(TETRA, orientation="free", diameters=0.2)
    rng = np.random.default_rng(8)
    x0 = model.initial_state(2.5 * TETRA, velocities=rng.normal(scale=0.3, size=(4, 3)))
    assert x0.shape == (4, 6)
    r = fl.simulate(f, fl.DistanceLaw(k_c=2.0), x0, duration=8.0, model=model,
                    integrator=fl.get_integrator("rk4", dt=1e-3))  # fmt: skip
    E = energy(r.V, r.x, 2.0)
    assert np.all(np.diff(E) <= 1e-12)
    assert r.summary()["outcome"] in ("desired", "mirror")
    assert r.summary()["state_names"] == ["x", "y", "z", "vx", "vy", "vz"]
