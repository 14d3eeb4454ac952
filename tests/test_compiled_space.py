"""The compiled loop in space: 3-D runs and batches against the numpy driver.

The loop (``engine/loop.py``) reads the positions' dimension from ``RunNumbers.axes`` and
compiles once for each; these tests hold its 3-D version (single integrators, the laws of
distances) against the stepping driver, the specification, on both layouts of the law:
its pairs (a tetrahedron, an octahedron) and its lists (an fcc patch larger than
``PAIRS_UP_TO``, Delaunay edges). The plane's results are held bit for bit by the
recorded-results tests (``test_engine_reference.py``, ``test_paper.py``,
``test_core_identity.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import formationlab as fl
from formationlab.dynamics import System
from formationlab.engine.layout import PAIRS_UP_TO
from formationlab.errors import ParameterError
from formationlab.integrators.compiled import compiled_terms, run_compiled
from formationlab.models import DoubleIntegrator, Quadrotor, SingleIntegrator, Unicycle
from formationlab.studies.batch import batch_backend, run_batch

TETRAHEDRON = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.8660254038, 0.0],
               [0.5, 0.2886751346, 0.8164965809]]  # fmt: skip
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
OCTAHEDRON = [[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 1.0], [0, 0, -1.0]]


def _start(template: list[list[float]] | np.ndarray, sigma: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.asarray(template, dtype=float) + sigma * rng.standard_normal(np.shape(template))


def _both(formation, law, q0, duration, **kw):
    a = fl.simulate(formation, law, q0, duration=duration, backend="numba", **kw)
    b = fl.simulate(formation, law, q0, duration=duration, backend="numpy", **kw)
    return a, b


@pytest.mark.parametrize(
    ("template", "edges", "law"),
    [
        (TETRAHEDRON, "complete", fl.DistanceLaw()),
        (OCTAHEDRON, "complete", fl.get_law("squared-distance")),
    ],
)
def test_a_run_in_space_on_the_pairs_layout_is_the_drivers(template, edges, law) -> None:
    formation = fl.Formation.from_template(template, edges=edges, diameters=0.2)
    q0 = _start(template, 0.3, seed=3)
    a, b = _both(formation, law, q0, 2.0, integrator=fl.Euler(dt=1e-2), save_every=10)
    assert a.stats["backend"] == "numba" and b.stats.get("backend", "numpy") != "numba"
    assert a.q.shape == b.q.shape and a.q.shape[-1] == 3
    assert a.status == b.status
    scale = np.max(np.abs(b.q))
    assert np.max(np.abs(a.q - b.q)) <= 1e-12 * scale
    assert np.max(np.abs(a.u - b.u)) <= 1e-10 * np.max(np.abs(b.u))
    # it moved in space: the start's third coordinates changed, and the distances converged
    assert np.max(np.abs(a.q[-1, :, 2] - q0[:, 2])) > 1e-2
    assert np.max(np.abs(a.q[-1] - a.q[0])) > 1e-2


def test_a_swarm_in_space_on_the_lists_layout_is_the_drivers() -> None:
    tpl = fl.lattice("fcc", PAIRS_UP_TO + 100)
    formation = fl.Formation.from_template(
        tpl, edges=fl.build_edges("delaunay", tpl), diameters=0.2, one_based=False
    )
    q0 = _start(tpl, 0.05, seed=1)
    a, b = _both(formation, fl.DistanceLaw(), q0, 0.3, integrator=fl.Euler(dt=1e-2), save_every=5)
    assert a.stats["backend"] == "numba"
    assert a.status == b.status
    assert np.max(np.abs(a.q - b.q)) <= 1e-12 * np.max(np.abs(b.q))
    assert np.max(np.abs(a.q[-1] - a.q[0])) > 1e-3
    # the run without a system (the benchmarks' call): single integrators in space
    law = fl.DistanceLaw()
    layout = compiled_terms(System(formation=formation, law=law), fl.Euler(dt=1e-2))
    out = run_compiled(layout, q0, dt=1e-2, n_steps=30, save_every=5)
    np.testing.assert_array_equal(out.x, a.q)


def test_a_swarm_in_space_numbered_along_the_curve_is_the_same_run(monkeypatch) -> None:
    # from REORDER_FROM robots the run numbers a swarm in space along the Morton curve of
    # its template (engine/layout.space_order): each robot keeps its rows in their order,
    # so the run is the one numbered as given, bit for bit, and the driver's
    from formationlab.integrators import compiled

    tpl = fl.lattice("fcc", PAIRS_UP_TO + 100)
    rng = np.random.default_rng(4)
    shuffle = rng.permutation(len(tpl))  # (numbered at random: far from the curve)
    tpl = tpl[shuffle]
    edges = fl.build_edges("delaunay", tpl)
    formation = fl.Formation.from_template(tpl, edges=edges, diameters=0.2, one_based=False)
    q0 = _start(tpl, 0.05, seed=2)
    system = System(formation=formation, law=fl.DistanceLaw())
    plain = compiled_terms(system, fl.Euler(dt=1e-2))
    monkeypatch.setattr(compiled, "REORDER_FROM", 8)
    curved = compiled_terms(system, fl.Euler(dt=1e-2))
    assert plain.perm.size == 0 and sorted(curved.perm.tolist()) == list(range(len(tpl)))
    gap = [np.abs(lay.edge_i - lay.edge_j) for lay in (plain, curved)]
    assert np.median(gap[1]) < np.median(gap[0]) / 4  # neighbours have near numbers
    a = run_compiled(plain, q0, dt=1e-2, n_steps=40, save_every=5)
    b = run_compiled(curved, q0, dt=1e-2, n_steps=40, save_every=5)
    assert a.status == b.status and np.max(np.abs(b.x[-1] - q0)) > 1e-3
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.v, b.v)
    ref = fl.simulate(formation, fl.DistanceLaw(), q0, duration=0.4, backend="numpy",
                      integrator=fl.Euler(dt=1e-2), save_every=5)  # fmt: skip
    assert np.max(np.abs(b.x - ref.q)) <= 1e-12 * np.max(np.abs(ref.q))


def test_a_swarm_in_space_sees_contact_in_all_three_axes() -> None:
    # two robots one above the other, pulled together along z: the step into contact is
    # rejected as the driver rejects it (a loop that measured x and y only would not)
    tpl = fl.lattice("fcc", PAIRS_UP_TO + 8)
    formation = fl.Formation.from_template(
        tpl, edges=fl.build_edges("delaunay", tpl), diameters=0.2, one_based=False
    )
    q0 = tpl.copy()
    top = int(np.argmax(q0[:, 2]))
    below = int(
        np.argmin(np.linalg.norm(q0[:, :2] - q0[top, :2], axis=1) + 100 * (q0[:, 2] >= q0[top, 2]))
    )
    q0[top] = q0[below] + [0.0, 0.0, 0.21]
    law = fl.DistanceLaw()
    a, b = _both(formation, law, q0, 0.5, integrator=fl.Euler(dt=2e-2), save_every=1)
    assert a.status == b.status and str(a.status) == "step-too-large"  # (along z)
    assert a.q.shape == b.q.shape
    assert np.max(np.abs(a.q - b.q)) <= 1e-12 * np.max(np.abs(b.q))


def test_a_batch_in_space_runs_compiled_with_the_drivers_outcomes() -> None:
    formation = fl.Formation.from_template(
        TETRAHEDRON, edges="complete", diameters=0.2, orientation="template"
    )
    rng = np.random.default_rng(5)
    q0 = rng.uniform(-1.5, 1.5, size=(12, 4, 3))
    law = fl.DistanceLaw()
    kw = {"dt": 1e-2, "duration": 10.0}
    a = run_batch(formation, law, q0, backend="numba", **kw)
    b = run_batch(formation, law, q0, backend="numpy", **kw)
    assert list(a.outcome) == list(b.outcome)
    np.testing.assert_array_equal(a.steps, b.steps)
    assert np.max(np.abs(a.q_final - b.q_final)) <= 1e-9
    assert batch_backend("numba", dim=3, laws=[law]) == ("numba", "")


#: the models of points in space, each with its limits active (a drone's velocity lag)
SPACE_MODELS = {
    "single-limited": SingleIntegrator(max_speed=0.4),
    "double": DoubleIntegrator(damping=2.0),
    "double-limited": DoubleIntegrator(damping=1.0, max_speed=0.3),
    "quadrotor": Quadrotor(time_constant=0.3, max_accel=1.5, max_speed=0.5),
}


def _moving(model, q0: np.ndarray, seed: int) -> np.ndarray:
    """The model's state at ``q0``, moving (velocities drawn) where it has velocities."""
    x0 = model.initial_state(q0)
    if x0.shape[-1] == 6:
        x0[:, 3:] = 0.4 * np.random.default_rng(seed).standard_normal(q0.shape)
    return x0


@pytest.mark.parametrize("model", sorted(SPACE_MODELS))
def test_every_model_of_points_in_space_is_the_drivers(model) -> None:
    # the pairs layout (a tetrahedron) and the lists layout (an fcc patch past PAIRS_UP_TO)
    m = SPACE_MODELS[model]
    tpl = fl.lattice("fcc", PAIRS_UP_TO + 40)
    swarm = fl.Formation.from_template(
        tpl, edges=fl.build_edges("delaunay", tpl), diameters=0.2, one_based=False
    )
    tet = fl.Formation.from_template(TETRAHEDRON, edges="complete", diameters=0.2)
    for formation, q0, duration in ((tet, _start(TETRAHEDRON, 0.3, 2), 3.0),
                                    (swarm, _start(tpl, 0.05, 4), 0.4)):  # fmt: skip
        x0 = _moving(m, q0, seed=7)
        kw = {"integrator": fl.Euler(dt=1e-2), "save_every": 5, "model": m}
        a, b = _both(formation, fl.DistanceLaw(), x0, duration, **kw)
        assert a.stats["backend"] == "numba" and b.stats.get("backend", "numpy") != "numba"
        assert a.status == b.status and a.x.shape == b.x.shape and a.x.shape[-1] == x0.shape[-1]
        assert np.max(np.abs(a.x - b.x)) <= 1e-12 * np.max(np.abs(b.x))
        assert np.max(np.abs(a.x[-1, :, :3] - a.x[0, :, :3])) > 1e-3  # (it moved)
    # the limits held between saved states (5 steps of 1e-2 s) of the swarm's run
    if model == "quadrotor":  # the velocities change within the acceleration limit
        dw = np.linalg.norm(np.diff(a.x[..., 3:], axis=0), axis=-1)
        assert dw.max() <= 5e-2 * m.max_accel * (1 + 1e-9)
    elif m.max_speed is not None:  # the positions move within the speed limit
        moves = np.linalg.norm(np.diff(a.q, axis=0), axis=-1)
        assert moves.max() <= 5e-2 * m.max_speed * (1 + 1e-9)


@pytest.mark.parametrize("model", ["double", "quadrotor"])
def test_a_batch_of_drones_in_space_runs_compiled_with_the_drivers_outcomes(model) -> None:
    m = SPACE_MODELS[model]
    formation = fl.Formation.from_template(TETRAHEDRON, edges="complete", diameters=0.2)
    rng = np.random.default_rng(8)
    q0 = rng.uniform(-1.5, 1.5, size=(8, 4, 3))
    x0 = np.stack([_moving(m, q, seed=i) for i, q in enumerate(q0)])
    kw = {"dt": 1e-2, "duration": 8.0, "model": m}
    assert batch_backend("numba", model=m, dim=3) == ("numba", "")
    a = run_batch(formation, fl.DistanceLaw(), x0, backend="numba", **kw)
    b = run_batch(formation, fl.DistanceLaw(), x0, backend="numpy", **kw)
    assert list(a.outcome) == list(b.outcome)
    np.testing.assert_array_equal(a.steps, b.steps)
    assert np.max(np.abs(a.q_final - b.q_final)) <= 1e-9


def test_what_the_loop_does_not_step_in_space_runs_on_numpy_or_is_refused() -> None:
    formation = fl.Formation.from_template(TETRAHEDRON, edges="complete", diameters=0.2)
    chiral = fl.get_law("chirality-restricted")
    backend, note = batch_backend("numba", dim=3, laws=[chiral])
    assert backend == "numpy" and "chirality-restricted" in note
    backend, note = batch_backend("numba", model=Unicycle(), dim=3)
    assert backend == "numpy" and "unicycle" in note
    q0 = _start(TETRAHEDRON, 0.3, 1)
    with pytest.raises(ParameterError, match="chirality-restricted"):
        run_batch(formation, chiral, q0[None], dt=1e-2, duration=0.1)
    res = fl.simulate(formation, chiral, q0, duration=0.1, integrator=fl.Euler(dt=1e-2))
    assert res.stats.get("backend") != "numba"


def test_the_tetrahedron_study_has_the_same_outcomes_on_both_backends() -> None:
    # examples/space/study-tetrahedron.toml with few trials: the distance law's trials run
    # on the compiled loop (the note names the laws that stay on numpy), the same outcomes
    import warnings

    from formationlab.io.scenario import load_scenario
    from formationlab.studies.config import parse_study
    from formationlab.studies.runner import StudySetup, run_study

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = load_scenario(EXAMPLES / "space" / "study-tetrahedron.toml")
        table = {**sc.study, "laws": ["distance", "squared-distance"]}
        got = {}
        for backend in ("numba", "numpy"):
            config = parse_study({**table, "backend": backend}, trials=16, duration=8.0)
            setup = StudySetup.from_scenario(sc, config)
            assert setup.backend == (backend, "")
            res = run_study(setup, seed=7)
            got[backend] = res.trials.sort_values(["law", "trial"])
    a, b = got["numba"], got["numpy"]
    assert list(a["outcome"]) == list(b["outcome"])
    assert list(a["steps"]) == list(b["steps"])
    assert {"desired", "mirror"} & set(a["outcome"])  # (trials that converged, both ways)
    cols = [c for c in a.columns if c[:1] in "xyz" and c[1:].isdigit()]
    assert len(cols) == 12
    assert np.max(np.abs(a[cols].to_numpy() - b[cols].to_numpy())) <= 1e-9
