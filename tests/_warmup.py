"""Fill the numba cache before the test workers start (see ``conftest.pytest_configure``).

Each of the two parts compiles some of the package's kernels through the public API, on a
tiny problem, about a minute and a half each on a quiet machine; ``python
tests/_warmup.py PART`` runs one part.
Run in parallel by the controlling process, they compile each kernel once instead of once
per test worker.
"""

from __future__ import annotations

import sys
import warnings

import numpy as np


def _triangle():
    import formationlab as fl

    f = fl.Formation.from_template([[0, 0], [1, 0], [0.5, 0.8]], diameters=0.2)
    q0 = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]])
    q0 = q0 + 0.05 * np.random.default_rng(0).normal(size=(2, 3, 2))
    return fl, f, q0


def part0() -> None:
    """The batch kernel of obstacles and safety filters (the longest compilation), and the
    loop in space on both layouts (``tests/test_compiled_space.py``)."""
    fl, f, q0 = _triangle()
    from formationlab.engine.layout import PAIRS_UP_TO
    from formationlab.formation.graphs import delaunay_edges
    from formationlab.formation.templates import lattice
    from formationlab.safety import Circle, SafetyFilter
    from formationlab.studies.batch import run_batch

    disc = (Circle(center=[5.0, 5.0], radius=0.5),)
    for kind in ("barrier-decentralized", "barrier"):
        cfg = SafetyFilter(filter=kind, distance=0.25)
        run_batch(f, fl.get_law("distance"), q0, dt=1e-2, duration=0.05, safety=cfg,
                  obstacles=disc)  # fmt: skip
    for count in (4, PAIRS_UP_TO + 8):  # the pairs layout, then the lists layout
        tpl = lattice("fcc", count)
        edges = "complete" if count <= PAIRS_UP_TO else delaunay_edges(tpl)
        space = fl.Formation.from_template(tpl, edges=edges, one_based=False)
        fl.simulate(space, fl.get_law("distance"), tpl, duration=0.05)


def part1() -> None:
    """The study kernel for every robot model, the sensed kernel, compiled single runs of
    both kinds of law (one by one and as a batch), the rigidity check."""
    fl, f, q0 = _triangle()
    from formationlab.formation.rigidity import is_generically_rigid
    from formationlab.models import DoubleIntegrator, Unicycle
    from formationlab.sensing import Sensing
    from formationlab.simulation.batch import simulate_batch
    from formationlab.studies.batch import run_batch

    law = fl.get_law("angle-restricted")
    run_batch(f, law, q0, dt=1e-2, duration=0.05)
    for model in (Unicycle(), Unicycle(mapping="heading"), DoubleIntegrator()):
        x0 = np.stack([model.initial_state(q) for q in q0])
        run_batch(f, law, x0, dt=1e-2, duration=0.05, model=model)
    seeds = [(1, t) for t in range(len(q0))]
    run_batch(f, law, q0, dt=1e-2, duration=0.05, sensing=Sensing(noise=0.01), seeds=seeds)
    for name in ("distance", "angle-restricted"):
        fl.simulate(f, fl.get_law(name), q0[0], duration=0.05)
    # a formation larger than PAIRS_UP_TO: the lists layout of single runs
    from formationlab.engine.layout import PAIRS_UP_TO
    from formationlab.formation.graphs import delaunay_edges
    from formationlab.formation.templates import lattice

    tpl = lattice("triangular", PAIRS_UP_TO + 8)
    big = fl.Formation.from_template(tpl, edges=delaunay_edges(tpl), one_based=False)
    fl.simulate(big, law, tpl, duration=0.05)
    simulate_batch(f, law, q0, duration=0.05)  # compiled single runs as one batch
    # (single runs under a filter use the loop of part 0's batches under a filter)
    is_generically_rigid(f.edges, f.n)


if __name__ == "__main__":
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (part0, part1)[int(sys.argv[1])]()
