"""Single runs among obstacles and under safety filters on the engine's compiled loop,
against the numpy driver.

``simulate`` with ``backend="numba"`` runs the engine's loop on its lists layout with the
obstacles' repulsion and the filter as a stage (``safety/stage.py``, the batches' stage):
the decentralized filter over each robot's neighbours within its sensing radius (all pairs
below ``DENSE_BELOW`` robots, a grid of cells from there, as ``decentralized_filter``), the
centralized filter by its exact active-set method with Clarabel between calls when
rounding defeats it. Compared with the stepping driver (``backend="numpy"``) to rounding,
from starts where the unfiltered law collides (Krick et al. 2009's squared-distance law),
for every robot model the filters hold, and on a 300-robot lattice (the grid).
"""

import warnings

import numpy as np
import pytest
from test_compiled_models import assert_follows

import formationlab as fl
from formationlab.errors import FormationlabWarning
from formationlab.models import DoubleIntegrator, SingleIntegrator, Unicycle
from formationlab.safety import SafetyFilter
from formationlab.safety.obstacles import Circle, Polygon

SQUARE = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], diameters=0.2)
#: a start from which the squared-distance law brings two robots into contact (t = 0.42 s)
START = np.array([[0.23, -0.28], [-0.89, 1.63], [0.4, 0.64], [-0.03, 1.25]])
OBSTACLES = (
    Circle(center=[-0.6, 0.5], radius=0.15),
    Polygon(vertices=[[0.9, 0.3], [1.4, 0.4], [1.1, 0.9]]),
)
MODELS = {
    "single": SingleIntegrator(),
    "single-limited": SingleIntegrator(max_speed=0.8),
    "unicycle-near-identity": Unicycle(mapping="near-identity", offset=0.05),
    "unicycle-heading": Unicycle(mapping="heading"),
}
FILTERS = ["none", "barrier-decentralized", "barrier"]


def both(formation, law, q0, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FormationlabWarning)  # heading-mapped unicycles
        a = fl.simulate(formation, law, q0, backend="numba", **kw)
        b = fl.simulate(formation, law, q0, backend="numpy", **kw)
    return a, b


@pytest.mark.parametrize("obstacles", [False, True])
@pytest.mark.parametrize("kind", FILTERS)
@pytest.mark.parametrize("model", sorted(MODELS))
def test_every_filter_and_model_follows_the_driver(model, kind, obstacles):
    law = fl.get_law("squared-distance")
    safety = SafetyFilter(filter=kind, distance=0.25, gamma=100.0)
    obs = OBSTACLES if obstacles else ()
    kw = {"duration": 0.5, "save_every": 10, "model": MODELS[model], "obstacles": obs}
    a, b = both(SQUARE, law, START, safety=safety, **kw)
    assert_follows(a, b, scale=2.0)
    if kind == "none" and not obstacles and model == "single":  # the unfiltered law collides
        assert a.status == "step-collision"


def test_the_filter_acts_in_the_compiled_run():
    law = fl.get_law("squared-distance")
    kw = {"duration": 0.5, "backend": "numba"}
    free = fl.simulate(SQUARE, law, START, **kw)
    safe = fl.simulate(
        SQUARE, law, START, safety=SafetyFilter(filter="barrier-decentralized", distance=0.25),
        **kw,
    )  # fmt: skip
    assert free.status == "step-collision" and safe.status == "success"
    assert safe.stats["backend"] == "numba"
    q = safe.q
    r = np.linalg.norm(q[:, :, None] - q[:, None], axis=-1) + 9 * np.eye(4)
    assert r.min() >= 0.25 - 1e-9  # the safety distance held at every saved step


def test_a_lattice_of_300_under_the_decentralized_filter_and_an_obstacle():
    tpl = fl.lattice("triangular", 300, 1.0)
    f = fl.Formation.from_template(
        tpl, edges=fl.build_edges("delaunay", tpl), diameters=0.2, one_based=False
    )
    q0 = tpl + np.random.default_rng(5).normal(0.0, 0.12, tpl.shape)
    wall = Circle(center=[float(tpl[:, 0].mean()), float(tpl[:, 1].min()) - 0.6], radius=0.3)
    safety = SafetyFilter(filter="barrier-decentralized", distance=0.3, gamma=100.0)
    a, b = both(f, "distance", q0, safety=safety, obstacles=(wall,), duration=0.05,
                save_every=25)  # fmt: skip
    assert_follows(a, b, scale=float(np.abs(q0).max()))
    assert a.safety is not None


def test_what_a_filter_refuses_both_paths_refuse():
    law = fl.get_law("squared-distance")
    safety = SafetyFilter(filter="barrier-decentralized", distance=0.25)
    for backend in ("numba", "numpy"):
        with pytest.raises(fl.errors.ParameterError, match="force"):
            fl.simulate(SQUARE, law, START, model=DoubleIntegrator(), safety=safety,
                        duration=0.1, backend=backend)  # fmt: skip
