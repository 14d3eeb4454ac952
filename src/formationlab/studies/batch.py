"""Many independent trials of one law on one formation, batched: :func:`run_batch`.

``run_batch(formation, law, q0, model=...)`` steps ``B`` initial states ``q0`` of
shape ``(B, n, k)`` (the robot model's states, positions first; ``(B, n, 2)`` for
the paper's single integrators) with explicit Euler in float64 -- the same stepping as
``formationlab.simulate(..., integrator=Euler(dt=dt))``, trial by trial -- and
stops each trial when it has stopped moving (tested every ``check_every`` steps,
``round(tolerances.window / dt)`` by default: the instantaneous speed
``max_i |u_i|`` or the net speed since the previous test,
``max_i |q_i(k) - q_i(k - check_every)| / (check_every dt)``, at most
``tolerances.speed``; the net speed catches trials at rest on a switching
surface across which Euler chatters), when a step is rejected by the contact
rule of :meth:`formationlab.dynamics.System.step_verdict` (outcome
``"collision"``, the simulator's ``"step-collision"`` or ``"step-too-large"``),
or at ``duration``. The final states are classified exactly as
:func:`formationlab.outcomes.analysis.classify` does (:func:`classify_batch` is its
vectorised twin).

Two backends compute the same thing: ``"numba"`` (compiled, parallel over
chunks of trials, for every law whose ``Law.kernel_terms`` gives its data (the
package's five: ``distance``, ``angle-restricted``, ``squared-distance``,
``signed-area`` and ``bearing``); and the robot models ``single-integrator``, ``unicycle``
and ``double-integrator``) and ``"numpy"`` (the stepping driver,
:func:`formationlab.integrators.drive`, with explicit Euler and a stop rule:
the readable specification, for any law). ``"numba"`` runs the engine's one compiled
loop (:mod:`formationlab.engine.loop`), with obstacles and a safety filter as its stage
(trial by trial the driver's run; the centralized filter's QP is solved exactly in the
loop, by a closed form for one or two active rows and a dual active-set method beyond).

With sensing other than the paper's or faults, the loop's law stage is the sensing
stage (:mod:`formationlab.sensing.stage`: the measurement channel, every robot's own
command and the stop rule only while every robot sees its neighbours, as the driver
does them, with each trial's noise and losses drawn by its own channel), under every
robot model, obstacle and filter.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..controllers import Law
from ..dynamics import System
from ..engine.trials import TrialRun, run_trials
from ..errors import FormationError, ParameterError
from ..formation.geometry import row_norms
from ..formation.spec import Formation
from ..integrators import Euler, StopRule, drive
from ..integrators.base import steps_for
from ..models import RobotModel, SingleIntegrator
from ..models.terms import POINT_KINDS, model_terms
from ..outcomes.analysis import Tolerances
from ..outcomes.batch import BatchResult, classify_batch, max_distance_errors
from ..safety import check_obstacle_starts
from ..sensing import Faults, Seed, Sensing
from ..validation import positive, whole

__all__ = [
    "BatchResult",
    "batch_backend",
    "classify_batch",
    "max_distance_errors",
    "run_batch",
]

Backend = Literal["numba", "numpy"]

#: Most trials per chunk of the numba backend (the unit of parallel work): long
#: loops over trials amortise each loop's set-up; fewer when a batch is small, so
#: that every thread gets about four chunks.
CHUNK = 256
MIN_CHUNK = 64
#: The numba kernel already uses every core, and numba's fallback threading layer
#: ("workqueue", when neither TBB nor OpenMP is found) must not be entered from two
#: threads at once: calls are serialised.
_KERNEL_LOCK = threading.Lock()


def batch_backend(
    backend: str,
    obstacles: Sequence[Any] = (),
    safety: Any = None,
    sensed: bool = False,
    model: RobotModel | None = None,
    dim: int = 2,
    laws: Sequence[Law] = (),
) -> tuple[Backend, str]:
    """The backend a batch runs on, and why it differs from ``backend`` ("" if it does not).

    Every robot model, sensing model, fault, obstacle and safety filter is a stage of the
    one compiled loop (:mod:`formationlab.engine`), so a batch runs where it is asked to;
    the reason stays in the interface (and in ``summary.json``) for a part that a future
    stage may not compile. A law of ``laws`` without kernel terms (:meth:`Law.compiles`:
    the learned law) runs on the numpy path: the batch does when all its laws are such
    (a study's chunks pass the one law of their group), else the note names them.
    """
    if dim != 2 and backend == "numba":
        why = _space_note(sensed, model, laws)
        if obstacles or (safety is not None and safety.filter != "none"):
            why = why or "the compiled loop steps formations in space without obstacles or filters"
        if why:
            return "numpy", why
    numpy_laws = sorted({law.name for law in laws if not law.compiles()})
    note = ""
    if numpy_laws and backend == "numba":
        names = ", ".join(repr(n) for n in numpy_laws)
        note = (
            f"the compiled loop has no terms of the law {names}: its trials run on the numpy path"
        )
        if all(not law.compiles() for law in laws):
            return "numpy", note
        note += "; the other laws' on the compiled loop"  # (each group's chunks choose)
    if model is not None and backend == "numba":
        try:
            model_terms(model)
        except ParameterError:  # a model without a stage of the loop (yet)
            return "numpy", f"the compiled loop has no stage for the robot model {model.name!r}"
    return backend, note  # type: ignore[return-value]


def _kind(model: RobotModel) -> int | None:
    """The compiled loop's kind of ``model`` (None: a model without a stage of it)."""
    try:
        return model_terms(model).kind
    except ParameterError:
        return None


def _space_note(sensed: bool, model: RobotModel | None, laws: Sequence[Law]) -> str:
    """Why a batch in space runs on the numpy path ("" when the compiled loop steps it):
    the loop steps single integrators on their true positions under the laws of
    ``Law.compiled_dims`` there."""
    if sensed:
        return "the compiled loop steps formations in space without sensing or faults"
    if model is not None and _kind(model) not in POINT_KINDS:
        return (
            "the compiled loop steps single and double integrators and quadrotors in space, "
            f"not {model.name!r}"
        )
    plane = sorted({law.name for law in laws if 3 not in law.compiled_dims})
    if plane:
        return (
            "the compiled loop steps formations in space under the laws of distances, not "
            + ", ".join(repr(n) for n in plane)
        )
    return ""


def run_batch(
    formation: Formation,
    law: Law,
    q0: ArrayLike,
    *,
    dt: float,
    duration: float,
    tolerances: Tolerances | None = None,
    backend: Backend = "numba",
    check_every: int | None = None,
    model: RobotModel | None = None,
    obstacles: Sequence[Any] = (),
    safety: Any = None,
    sensing: Sensing | None = None,
    faults: Faults | None = None,
    seeds: Sequence[Seed] | None = None,
) -> BatchResult:
    """Simulate ``B`` trials of ``law`` on ``formation`` with explicit Euler (module docstring).

    Parameters
    ----------
    formation : Formation
        Robots, graph, desired distances and orientation.
    law : Law
        ``DistanceLaw``, ``AngleRestrictedLaw``, ``SquaredDistanceLaw`` or
        ``SignedAreaLaw`` (any law with ``backend="numpy"``); its parameters are
        read from the object.
    q0 : array_like, shape (B, n, k)
        Initial states of ``model`` (positions first; ``k = 2`` for single
        integrators); finite, no overlapping robots.
    dt : float
        Euler step, seconds.
    duration : float
        Longest simulated time, seconds (``ceil(duration / dt)`` steps, as the simulator).
    tolerances : Tolerances, optional
        Convergence (``speed``, ``window``) and classification tolerances. Default
        ``Tolerances()``.
    backend : {"numba", "numpy"}
        Compiled kernel or the numpy reference.
    check_every : int, optional
        Test convergence every this many steps; default
        ``max(1, round(tolerances.window / dt))`` (every 10 ms of simulated time by
        default). The net speed is measured over this interval. A trial is stopped
        at the first test it passes.
    model : RobotModel, optional
        The robots; default the paper's single integrators. The outcome is judged at
        the law's points (``model.points``: near-identity hand points).
    obstacles : sequence of Circle or Polygon
        Static obstacles (:mod:`formationlab.safety`); starts must be clear of them.
    safety : SafetyFilter, optional
        Safety filter between the law and the robots (a stage of the compiled loop).
    sensing : Sensing, optional
        How the robots sense each other (:mod:`formationlab.sensing`); with a sensing
        model other than the paper's, or with ``faults``, the compiled loop's sensing
        stage (:mod:`formationlab.sensing.stage`) gives each robot its own command.
    faults : Faults, optional
        Robots that stop.
    seeds : sequence of int or tuple of int, optional
        Each trial's sensing seed (default: ``sensing.seed`` for every trial); a trial's
        noise, losses, frames and mismatch depend on its seed only.

    Returns
    -------
    BatchResult
    """
    tol = tolerances or Tolerances()
    model = model or SingleIntegrator()
    formation = law.formation_for(formation)  # as the law is judged on it (bearings)
    q0 = _check_initial(formation, q0, len(model.names_in(formation.dim)))
    dt, duration = positive(dt, "dt"), positive(duration, "duration")
    n_steps = steps_for(float(duration), float(dt))
    if check_every is None:
        check_every = max(1, round(tol.window / dt))
    check_every = whole(check_every, "check_every")
    safe = bool(obstacles) or (safety is not None and safety.enabled)
    if backend == "numba":
        run = _run_compiled(
            formation, law, model, q0, float(dt), n_steps, int(check_every), tol,
            obstacles, safety if safe else None, sensing, faults, seeds,
        )  # fmt: skip
        x, v, status, steps, mc, ns = (
            run.x, run.v, run.status, run.steps, run.min_clearance, run.net_speed,
        )  # fmt: skip
        qw, window_step = run.q_window, run.window_step
        mo, md = run.min_obstacle_clearance, run.min_pair_distance
    elif backend == "numpy":
        system = System(formation=formation, law=law, model=model, sensing=sensing, faults=faults)
        if obstacles or safety is not None:
            check_obstacle_starts(model.positions(q0), formation.diameters / 2, tuple(obstacles))
            system = System(
                formation=formation, law=law, model=model, obstacles=tuple(obstacles),
                safety=safety, sensing=sensing, faults=faults,
            )  # fmt: skip
        out = drive(
            system, Euler(dt=float(dt)), q0, n_steps=n_steps,
            stop=StopRule(speed=tol.speed, check_every=int(check_every)),
            window=tol.drift_steps(float(dt)), seeds=None if seeds is None else list(seeds),
        )  # fmt: skip
        x, v, status, steps, mc, ns = (
            out.x, out.v, out.status, out.steps, out.min_clearance, out.net_speed,
        )  # fmt: skip
        qw, window_step = out.q_window, out.window_step
        mo, md = out.min_obstacle_clearance, out.min_pair_distance
    else:
        raise ParameterError(f'backend must be "numba" or "numpy", got {backend!r}')
    at = {"q": model.points(x), "u": model.point_rates(x, v)}  # where the law acts
    return BatchResult.from_final(
        formation, x=x, v=v, status=status, steps=steps, min_clearance=mc, net_speed=ns,
        dt=float(dt), tolerances=tol, q_window=qw, window_step=window_step,
        min_obstacle_clearance=mo, min_pair_distance=md,
        below_safety_distance=safety.below(md) if safety is not None and safety.enabled else None,
        **at,
    )  # fmt: skip


def _check_initial(formation: Formation, q0: ArrayLike, k: int = 2) -> NDArray[np.float64]:
    """``q0`` as a C-contiguous float array ``(B, n, k)``; finite, no overlapping robots."""
    q = np.require(np.asarray(q0, dtype=float), requirements=["C", "W"])  # one kernel signature
    n = formation.n
    if q.ndim != 3 or q.shape[1:] != (n, k) or q.shape[0] == 0:
        what = "positions" if k == formation.dim else "states"
        raise FormationError(f"initial {what} must have shape (B, {n}, {k}), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise FormationError("initial positions hold NaN or infinite numbers")
    for i, j in zip(*np.triu_indices(n, k=1), strict=True):
        d = q[:, j, :] - q[:, i, :]
        gap = row_norms(d[..., : formation.dim]) - formation.contact_matrix[i, j]
        if np.any(gap <= 0):
            b = int(np.argmax(gap <= 0))
            raise FormationError(
                f"robots {i + 1} and {j + 1} overlap in trial {b + 1} of the initial positions "
                f"(clearance {gap[b]:g} <= 0); draw them apart or use smaller diameters"
            )
    return q


def _run_compiled(
    formation: Formation, law: Law, model: RobotModel, q0: NDArray[np.float64], dt: float,
    n_steps: int, check_every: int, tol: Tolerances, obstacles: Sequence[Any], safety: Any,
    sensing: Sensing | None, faults: Faults | None, seeds: Sequence[Seed] | None,
) -> TrialRun:  # fmt: skip
    """The trials on the engine's compiled loop (:func:`formationlab.engine.trials.run_trials`)."""
    import numba

    if obstacles:
        check_obstacle_starts(model.positions(q0), formation.diameters / 2, tuple(obstacles))
    chunk = _chunk_size(q0.shape[0], numba.get_num_threads())
    with _one_chunk_at_a_time():
        return run_trials(
            formation, law, model, q0, dt=dt, n_steps=n_steps, check_every=check_every,
            tol=tol, chunk=chunk, obstacles=obstacles, safety=safety, sensing=sensing,
            faults=faults, seeds=seeds,
        )  # fmt: skip


@contextmanager
def _one_chunk_at_a_time() -> Iterator[None]:
    """Hold the kernel lock and let numba hand the parallel chunks out one at a time.

    Chunks (and sensed trials) stop early by different amounts, and a busy machine may
    slow one thread down; numba's setting is per thread and is restored on the way out.
    """
    import numba

    with _KERNEL_LOCK:
        previous = numba.set_parallel_chunksize(1)
        try:
            yield
        finally:
            numba.set_parallel_chunksize(previous)


def _chunk_size(n_trials: int, threads: int) -> int:
    """Trials per chunk: about four chunks per thread, within ``[MIN_CHUNK, CHUNK]``."""
    return int(min(CHUNK, max(MIN_CHUNK, -(-n_trials // (4 * threads)))))
