"""Single runs of every robot model on the engine's compiled loop against the numpy driver.

The compiled single run (``simulate`` with ``backend="numba"``: the engine's loop,
:func:`formationlab.engine.loop.step_chunk`, on its lists layout) steps unicycles (both
mappings), double integrators and speed-limited robots, not only the paper's single
integrators. Each is compared with the stepping driver (``backend="numpy"``, the readable
specification) on formations whose repulsion acts and whose restrictions switch, below and
above the dense limit, with the robots renumbered, to rounding (1e-12 of the positions'
scale over short runs; the switching laws' chatter re-draws a last bit into larger
differences over long ones, hence the short runs).
"""

import numpy as np
import pytest
from test_compiled import TRIANGLE, ladder

import formationlab as fl
from formationlab.formation.spec import DENSE_LIMIT
from formationlab.integrators import compiled
from formationlab.marching import Marching
from formationlab.models import DoubleIntegrator, SingleIntegrator, Unicycle

MODELS = {
    "single-limited": SingleIntegrator(max_speed=0.5),
    "double": DoubleIntegrator(damping=2.0),
    "double-limited": DoubleIntegrator(damping=2.0, max_speed=0.4),
    "unicycle-heading": Unicycle(mapping="heading"),
    "unicycle-near-identity": Unicycle(mapping="near-identity", offset=0.1),
    "unicycle-limited": Unicycle(mapping="heading", max_speed=0.3, max_turn_rate=2.0),
    "unicycle-backwards": Unicycle(mapping="heading", backwards=True),
}


def both(formation, law, q0, model, **kw):
    a = fl.simulate(formation, law, q0, model=model, backend="numba", **kw)
    b = fl.simulate(formation, law, q0, model=model, backend="numpy", **kw)
    return a, b


def assert_follows(a, b, scale, tol=1e-12):
    assert a.stats["backend"] == "numba" and "backend" not in b.stats
    assert a.status == b.status, (a.message, b.message)
    assert a.message == b.message
    np.testing.assert_array_equal(a.t, b.t)
    assert a.x.shape == b.x.shape
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=tol * scale)
    np.testing.assert_allclose(a.xdot, b.xdot, rtol=0, atol=tol * scale / 1e-3)


@pytest.mark.parametrize("model", sorted(MODELS))
@pytest.mark.parametrize("law", ["distance", "angle-restricted"])
def test_every_model_follows_the_driver_on_the_paper_triangle(model, law):
    q0 = np.array([[-1.2, -0.9], [1.4, -0.7], [0.1, 1.3]])
    a, b = both(TRIANGLE, fl.get_law(law), q0, MODELS[model], duration=1.0, save_every=7)
    assert_follows(a, b, scale=2.0)
    assert np.ptp(a.q[:, :, 0]) > 0.1  # the robots moved


@pytest.mark.parametrize("renumbered", [False, True])
@pytest.mark.parametrize("n", [12, DENSE_LIMIT + 16])
@pytest.mark.parametrize("model", sorted(MODELS))
def test_every_model_on_ladders_with_repulsion_and_switching(model, n, renumbered, monkeypatch):
    if renumbered:  # the robots' order of large formations, on these
        monkeypatch.setattr(compiled, "REORDER_FROM", 8)
    f, q0 = ladder(n, seed=n)
    lw = fl.get_law("angle-restricted", k_a=0.3, theta=0.58)
    a, b = both(f, lw, q0, MODELS[model], duration=0.1, save_every=20)
    assert_follows(a, b, scale=float(np.abs(q0).max()))
    q = a.q[0]
    r = np.linalg.norm(q[:, None] - q[None], axis=-1) - 0.3 + 2 * np.eye(n)
    assert np.any((r < lw.repulsion.influence) & ~f.adjacency)  # repulsion is at work
    sigma = lw.switching(f, MODELS[model].points(a.x))
    assert np.any(sigma >= 0) and np.any(sigma < 0)  # restrictions on and off


def test_a_thousand_unicycles_follow_the_driver():
    tpl = fl.lattice("triangular", 1000, 1.0)
    f = fl.Formation.from_template(
        tpl, edges=fl.build_edges("delaunay", tpl), diameters=0.2, one_based=False
    )
    q0 = tpl + np.random.default_rng(3).normal(0.0, 0.05, tpl.shape)
    a, b = both(f, "distance", q0, Unicycle(mapping="heading"), duration=0.05, save_every=25)
    assert_follows(a, b, scale=float(np.abs(q0).max()))


@pytest.mark.parametrize("model", ["unicycle-near-identity", "double"])
def test_a_rejected_step_ends_both_paths_alike(model):
    f = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    law = fl.get_law("squared-distance", k=300.0)
    a, b = both(
        f, law, [[0.0, 0.0], [0.35, 0.0]], MODELS[model], duration=1.0,
        integrator=fl.Euler(dt=0.02),
    )  # fmt: skip
    assert a.status in ("step-collision", "step-too-large")  # (contact, or through it)
    assert_follows(a, b, scale=1.0)
    assert a.stats["steps"] == b.stats["steps"]


def test_what_the_compiled_run_refuses_it_names():
    law = fl.AngleRestrictedLaw()
    q0 = np.array([[-1.2, -0.9], [1.4, -0.7], [0.1, 1.3]])
    kw = {"duration": 0.1, "backend": "numba"}
    for model in MODELS.values():  # every model runs compiled
        assert fl.simulate(TRIANGLE, law, q0, model=model, **kw).stats["backend"] == "numba"
    with pytest.raises(fl.errors.ParameterError, match=r"explicit Euler .* got 'rk4'"):
        fl.simulate(TRIANGLE, law, q0, integrator=fl.RK4(dt=1e-3), **kw)

    class Sluggish(SingleIntegrator):  # a model of the user's own: the numpy driver's
        name = "sluggish"

    with pytest.raises(fl.errors.ParameterError, match="'sluggish'"):
        fl.simulate(TRIANGLE, law, q0, model=Sluggish(), **kw)
    auto = fl.simulate(TRIANGLE, law, q0, model=Sluggish(), duration=0.1)
    assert "backend" not in auto.stats  # the numpy driver runs it
    walk = Marching(velocity=[0.1, 0.0])  # marching runs compiled (test_compiled_stages.py)
    assert fl.simulate(TRIANGLE, law, q0, marching=walk, **kw).stats["backend"] == "numba"
