"""The compiled single-run path (integrators/compiled.py) against the numpy stepping driver.

Trial by trial and step by step to rounding: every law the kernels know, formations with
repulsion active and restrictions switching, formations above the dense limit (where the
numpy laws also take their sparse paths), steps rejected for contact, saving every K steps,
interruption; and a cell grid that finds exactly the pairs that matter.
"""

import numpy as np
import pytest

import formationlab as fl
from formationlab.controllers import laws_in
from formationlab.formation.spec import DENSE_LIMIT

TRIANGLE = fl.Formation.from_template(
    [[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]], diameters=0.2
)


def ladder(n: int, seed: int) -> tuple[fl.Formation, np.ndarray]:
    """``n`` robots in two rows 0.75 apart, tied along the rows and across diagonals.

    The robots facing each other across the rows are not neighbours and closer than
    ``a + s0``: Khatib's repulsion acts between them.
    """
    rng = np.random.default_rng(seed)
    idx = np.arange(n)
    tpl = np.stack([(idx // 2) * 0.8, (idx % 2) * 0.75], axis=1)
    edges = [(i, i + s) for i in range(n) for s in (2, 3) if i + s < n]
    f = fl.Formation.from_template(tpl, edges=edges, diameters=0.3, one_based=False)
    q0 = tpl + rng.normal(0.0, 0.03, tpl.shape)
    return f, q0


def both(formation, law, q0, **kw):
    a = fl.simulate(formation, law, q0, backend="numba", **kw)
    b = fl.simulate(formation, law, q0, backend="numpy", **kw)
    return a, b


@pytest.mark.parametrize("law", laws_in(2))
def test_the_compiled_run_follows_the_driver_on_the_paper_triangle(law):
    q0 = np.array([[-1.2, -0.9], [1.4, -0.7], [0.1, 1.3]])
    a, b = both(TRIANGLE, fl.get_law(law), q0, duration=2.0, save_every=7)
    assert a.stats["backend"] == "numba" and "backend" not in b.stats
    assert a.status == b.status == "success"
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-10)
    np.testing.assert_allclose(a.u, b.u, rtol=0, atol=1e-8)
    np.testing.assert_allclose(a.V, b.V, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("n", [12, DENSE_LIMIT + 16])
@pytest.mark.parametrize("law", ["distance", "angle-restricted", "squared-distance"])
def test_long_ladders_with_repulsion_and_switching(n, law):
    f, q0 = ladder(n, seed=n)
    lw = fl.get_law(law, **({"k_a": 0.3, "theta": 0.58} if law == "angle-restricted" else {}))
    a, b = both(f, lw, q0, duration=0.2, save_every=50)
    assert a.status == b.status
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-9)
    q = a.q[0]
    r = np.linalg.norm(q[:, None] - q[None], axis=-1) - 0.3 + 2 * np.eye(n)
    assert np.any((r < lw.repulsion.influence) & ~f.adjacency)  # repulsion is at work
    if law == "angle-restricted":
        sigma = lw.switching(f, a.q)
        assert np.any(sigma >= 0) and np.any(sigma < 0)  # restrictions on and off


@pytest.mark.parametrize(("dt", "status"), [(0.05, "step-too-large"), (0.02, "step-collision")])
def test_a_rejected_step_ends_both_paths_alike(dt, status):
    f = fl.Formation.from_distances(2, distances=1.0, diameters=0.2)
    start = [[0.0, 0.0], [3.0, 0.0]] if status == "step-too-large" else [[0.0, 0.0], [0.35, 0.0]]
    law = (
        fl.DistanceLaw(k_c=50.0)
        if status == "step-too-large"
        else fl.get_law("squared-distance", k=300.0)
    )
    a, b = both(f, law, start, duration=1.0, integrator=fl.Euler(dt=dt))
    assert a.status == b.status
    assert a.message == b.message
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-12)
    assert a.stats["steps"] == b.stats["steps"]


def test_the_compiled_path_is_the_default_where_it_applies():
    q0 = np.array([[-1.2, -0.9], [1.4, -0.7], [0.1, 1.3]])
    law = fl.AngleRestrictedLaw()
    assert fl.simulate(TRIANGLE, law, q0, duration=0.1).stats["backend"] == "numba"
    rk4 = fl.simulate(TRIANGLE, law, q0, duration=0.1, integrator=fl.RK4(dt=1e-3))
    assert "backend" not in rk4.stats
    with pytest.raises(fl.errors.ParameterError, match="backend"):
        fl.simulate(TRIANGLE, law, q0, duration=0.1, integrator=fl.RK4(dt=1e-3), backend="numba")


def test_an_interrupted_compiled_run_keeps_its_states():
    q0 = np.array([[-1.2, -0.9], [1.4, -0.7], [0.1, 1.3]])
    calls = []

    def ctrl_c(t):
        calls.append(t)
        raise KeyboardInterrupt

    res = fl.simulate(
        TRIANGLE, fl.DistanceLaw(), q0, duration=2e3, progress=ctrl_c, interruptible=True
    )
    assert res.status == "interrupted" and calls and res.t[-1] == pytest.approx(calls[0])
    ref = fl.simulate(TRIANGLE, fl.DistanceLaw(), q0, duration=res.t[-1], backend="numpy")
    np.testing.assert_allclose(res.q[-1], ref.q[-1], rtol=0, atol=1e-10)
