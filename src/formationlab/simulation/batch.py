"""Several runs of one formation from different starts as one compiled batch.

:func:`simulate_batch` is :func:`~formationlab.simulation.run.simulate` for ``B`` starts of
the same formation, law and step: the law's data are laid out once
(:func:`formationlab.integrators.compiled.compiled_terms`), each start runs on the compiled
single-run path (:func:`~formationlab.integrators.compiled.run_euler_compiled`, the engine's
loop) from that layout, and each comes back as the
:class:`~formationlab.simulation.run.SimulationResult` its own ``simulate`` call returns,
the same numbers bit for bit (tested). For the paper's symmetry scan and other small
batches whose paths are wanted; many trials that need only their final states are the
study kernel's (:func:`formationlab.studies.run_batch`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..controllers import LAWS, Law
from ..dynamics import System
from ..errors import FormationError, ParameterError
from ..formation.spec import Formation
from ..integrators import INTEGRATORS, Euler, Integrator
from ..integrators.compiled import compiled_terms, run_euler_compiled
from ..models import SingleIntegrator
from ..registry import resolve
from ..validation import whole
from .run import SimulationResult, _result, initial_state

__all__ = ["simulate_batch"]


def simulate_batch(
    formation: Formation,
    law: Law | str,
    q0: ArrayLike,
    *,
    duration: float,
    integrator: Integrator | str | None = None,
    save_every: int = 1,
) -> list[SimulationResult]:
    """Simulate ``law`` on ``formation`` from each start of ``q0``, as one compiled batch.

    Parameters
    ----------
    formation : Formation
        Robots, graph, desired distances and orientation.
    law : Law or str
        A law with kernel data (``Law.kernel_terms``), or its name.
    q0 : array_like, shape (B, n, 2)
        Initial positions of the ``B`` runs, each validated as :func:`simulate` does.
    duration : float
        Simulated time of every run, seconds.
    integrator : Euler or str, optional
        Explicit Euler (default ``Euler(dt=1e-3)``): the compiled path's scheme.
    save_every : int
        Keep every K-th step of each run.

    Returns
    -------
    list of SimulationResult
        One per start, each equal to ``simulate(formation, law, q0[b], duration=duration,
        integrator=integrator, save_every=save_every)``.

    Raises
    ------
    ParameterError
        When the compiled path does not apply (another scheme, a law without kernel data).
    """
    save_every = whole(save_every, "save_every")
    law, integrator = resolve(LAWS, law), resolve(INTEGRATORS, integrator or Euler(dt=1e-3))
    robot = SingleIntegrator()
    starts = np.asarray(q0, dtype=float)
    if starts.ndim != 3 or starts.shape[0] == 0:
        raise FormationError(
            f"initial positions must have shape (B, {formation.n}, 2) with B >= 1, "
            f"got {starts.shape}"
        )
    x0 = np.stack([initial_state(formation, robot, q) for q in starts])
    system = System(formation=formation, law=law, model=robot)
    layout = compiled_terms(system, integrator)
    if layout is None:
        raise ParameterError(
            "simulate_batch runs explicit Euler on single integrators with a law that has "
            f"kernel data; got {integrator.name!r} and {law.name!r}: use simulate for each start"
        )
    dt = float(integrator.dt)  # type: ignore[attr-defined]
    kw = {"dt": dt, "duration": float(duration), "save_every": int(save_every)}
    raws = [run_euler_compiled(layout, system, x, diagnostics=False, **kw) for x in x0]
    del layout  # the run's lists are let go before the post-processing
    return [_result(system, integrator, raw) for raw in raws]
