"""Compiled explicit-Euler runs of one formation, from three robots to a hundred thousand.

:func:`run_compiled` is the fast path of ``simulate`` for explicit Euler on
single integrators with a law that gives its data (``Law.kernel_terms``): the
engine's one compiled loop (:func:`formationlab.engine.loop.step_chunk`) on one trial,
with its lists layout (:mod:`formationlab.engine.lists`: the law's data as lists by robot,
:mod:`formationlab.engine.layout`, and a close-pair list on a cell grid for Khatib's
repulsion and contact) and its saving stage (:mod:`formationlab.engine.saving`): the
stepping driver's semantics (the same step rule, saving every ``save_every`` steps and
the last state, the rates each saved state was left with). Nothing in it is ``n x n``,
and nothing is allocated per step.

The loop runs in segments of steps (:class:`SingleRun`), between which the host reports
progress, sees Ctrl-C and chooses the threads: from :data:`PARALLEL_FROM` robots the run
measures a segment on numba's threads and one on a single thread and keeps the faster
(on a busy machine the threads can be the slower), with the same numbers bit for bit.

Memory is ``O(n + edges + restricted triples + close pairs)`` plus the saved states
(the states to be saved, exactly). The numpy driver
(:func:`formationlab.integrators.drive`) is the specification it is tested
against, to rounding.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from ..controllers.terms import KernelTerms
from ..dynamics import System
from ..engine.euler import axes_for
from ..engine.layout import PAIRS_UP_TO, REORDER_FROM, RunLayout, robot_order, run_layout
from ..engine.lists import grow, list_stage
from ..engine.loop import DONE, GROW, PAUSED, RUNNING, RunNumbers, step_chunk
from ..engine.saving import saving
from ..engine.signals import held_signals
from ..engine.trials import chunk_state, safety_stage, sensing_channel, trial_outputs
from ..errors import ParameterError
from ..marching.terms import march_terms, with_references
from ..models import SingleIntegrator
from ..models.terms import HEADING, NEAR_IDENTITY, POINT_KINDS, model_terms
from ..safety import barrier_filter
from ..safety.stage import CENTRALIZED
from ..sensing import BLOCK
from ..sensing.stage import sensing_arrays
from ..status import Status
from .base import RawSolution, steps_for
from .diagnostics import switching_diagnostics
from .driver import position_dim
from .explicit import Euler

__all__ = [
    "PARALLEL_FROM",
    "CompiledRun",
    "SingleRun",
    "compiled_terms",
    "raw_solution",
    "run_compiled",
    "run_euler_compiled",
]

#: From this many robots a run measures numba's threads against one thread and keeps the
#: faster; below, one thread (a parallel pass costs microseconds to start).
PARALLEL_FROM = 20_000

#: chunks per thread of a parallel pass (balance between threads)
_CHUNKS_PER_THREAD = 4


class CompiledRun:
    """Saved steps ``k``, states ``x`` ``(T, n, 2)``, velocities ``v``, status, steps,
    least robot-robot clearance, wall time, the threads the run ended on and the least
    distance of two points the safety filter keeps apart (NaN without a filter)."""

    def __init__(self, k, x, v, status, steps, min_clearance, wall, threads=1,
                 min_pair_distance=math.nan, min_obstacle_clearance=math.inf):  # fmt: skip
        self.k, self.x, self.v = k, x, v
        self.status, self.steps, self.min_clearance, self.wall = status, steps, min_clearance, wall
        self.threads = threads
        self.min_pair_distance = min_pair_distance
        self.min_obstacle_clearance = min_obstacle_clearance


def run_compiled(
    terms: KernelTerms | RunLayout,
    q0: NDArray[np.float64],
    *,
    dt: float,
    n_steps: int,
    save_every: int,
    progress: Callable[[float], None] | None = None,
    interruptible: bool = False,
    parallel: bool | None = None,
    system: System | None = None,
) -> CompiledRun:
    """Step one state ``q0`` ``(n, k)`` of the closed loop ``system`` (its robot model,
    obstacles and filter; default single integrators and neither) with explicit Euler
    (module docstring).

    The loop runs in compiled segments of about a quarter of a second, between which
    ``progress`` is called with the simulated time and Ctrl-C (or SIGTERM, if its handler
    raises KeyboardInterrupt) is seen: a signal that comes during a segment is held until
    the segment ends (:func:`held_signals`). With ``interruptible`` the run
    so far is returned with status ``"interrupted"``.
    ``parallel``: on numba's threads or on one; by default one thread, and from
    :data:`PARALLEL_FROM` robots the faster of the two as measured on the second and
    third segments (the same numbers either way).
    """
    n = q0.shape[0]
    # a layout as given; the law's pairs as they are for a small or sensing formation, else
    # its lists laid out (terms built with pairs=False have no pairs: always laid out)
    lists = isinstance(terms, RunLayout)
    pairs = not lists and terms.pair_i.size > 0 and (n <= PAIRS_UP_TO or _measuring(system))
    layout = terms if lists or pairs else run_layout(terms)  # type: ignore[arg-type]
    threads = numba.get_num_threads()
    # None: one thread, or (large formations) the faster of one thread and the threads
    # as measured on the second and third segments (the first builds the close list)
    probe = parallel is None and threads > 1 and n >= PARALLEL_FROM
    use = bool(parallel) and threads > 1
    chunks = threads * _CHUNKS_PER_THREAD
    run = SingleRun(
        layout, q0, dt=dt, n_steps=n_steps, save_every=save_every, chunks=chunks, system=system
    )
    k0, status = 0, Status.SUCCESS
    # progress at least every 1 % of the run, as the driver (without progress, segments of
    # a quarter of a second: each costs a call)
    step_cap = max(1, n_steps // 100) if progress is not None else n_steps
    chunk = min(256, step_cap)
    segments = 0
    per_step: dict[bool, float] = {}  # seconds per step of the probed segments, by threads
    start = time.perf_counter()
    with held_signals() as deliver:
        try:
            while True:
                k_end = min(n_steps, k0 + chunk)
                began = time.perf_counter()
                run.advance(k_end, chunks if use else 1)
                spent = time.perf_counter() - began
                deliver()  # a Ctrl-C during the segment: KeyboardInterrupt here
                segments += 1
                if probe and segments > 1 and len(per_step) < 2 and run.step > k0:
                    per_step[use] = spent / (run.step - k0)  # one thread, then the threads
                    use = len(per_step) == 1 or per_step[True] < per_step[False]
                k0 = run.step
                if run.done:
                    status = run.status
                    break
                if progress is not None:
                    progress(k0 * dt)
                chunk = int(min(max(chunk * 0.25 / max(spent, 1e-6), 16), 1 << 20, step_cap))
        except KeyboardInterrupt:
            if not interruptible:
                raise
            status = Status.INTERRUPTED
            k0 = run.step  # the loop's own count (it may have returned just before Ctrl-C)
            run.keep_reached()  # the run ends where it was, not at the last saved step
    wall = time.perf_counter() - start
    k, x, v = run.saved()
    return CompiledRun(
        k, x, v, status, k0, run.min_clearance, wall, threads if use else 1,
        run.min_pair_distance, float(run.st.mo[0, 0]),
    )  # fmt: skip


class SingleRun:
    """One formation's run on the compiled loop (:func:`formationlab.engine.loop.step_chunk`),
    one chunk of one trial with its saving stage: the state between segments of steps
    (:meth:`advance`).

    The law's field comes from its lists (``layout`` a :class:`RunLayout`: any size), or
    from its pairs (``layout`` the law's :class:`KernelTerms` of every pair, the layout of
    batches: :func:`compiled_terms` chooses it for formations of at most
    :data:`PAIRS_UP_TO` robots, and whenever the robots sense each other or a fault stops
    one, when each robot commands from its own measurements); the noise and losses of each block of
    :data:`~formationlab.sensing.BLOCK` steps are drawn here, between calls, from the
    sensing's seed (the driver's draws). ``system`` (default: single integrators and the
    law alone) gives the robot model, the marching (a reference that is a function of time
    is tabulated here, segment by segment), the obstacles and the filter.
    """

    def __init__(
        self, layout: RunLayout | KernelTerms, x0: NDArray[np.float64], *, dt: float,
        n_steps: int, save_every: int, chunks: int = 1, system: System | None = None,
    ) -> None:  # fmt: skip
        n, k = x0.shape
        x = np.array(x0, dtype=float, order="C")  # the run's own (writable) copy
        self.pairs = isinstance(layout, KernelTerms)
        perm = np.zeros(0, np.int32) if self.pairs else layout.perm  # type: ignore[union-attr]
        x = x[perm] if perm.size else x  # in the layout's numbers
        self.layout = layout
        model = system.model if system is not None else SingleIntegrator()
        self.model = model_terms(model)
        kind = self.model.kind
        # (without a system, single integrators: the state is the positions)
        dim = system.formation.dim if system is not None else x0.shape[1]
        self.obstacles = tuple(system.obstacles) if system is not None else ()
        self.safety = (  # (its rows guard steps of dt)
            system.at_step(dt).safety if system is not None and system.filtered else None
        )
        self.stage = (
            safety_stage(system.law, self.obstacles, self.safety)
            if system is not None
            else (None, None)
        )
        self.march = system.marching if system is not None else None
        self.mt = march_terms(
            self.march, system.formation if system is not None else None,
            model.velocity_gain, perm,
        )  # fmt: skip
        self.st = chunk_state(
            x[None, :, :, None], stop_rule=False, turns=kind in (HEADING, NEAR_IDENTITY),
            centralized=self.stage[1] is not None and self.stage[1].kind == CENTRALIZED, dim=dim,
        )  # fmt: skip
        if self.pairs:  # the start's clearance of the robots (the lists layout's loop finds it)
            self.st.mc[0, 0] = _start_clearance(layout, x0, system)
        if self.obstacles:  # the start's clearance to the obstacles
            assert system is not None
            self.st.mo[0, 0] = np.min(system.obstacle_clearances(x0), initial=np.inf)
        self.out = trial_outputs(1, n, k, kept=False, dim=dim)
        self.sense: tuple[Any, ...] = (None, None)
        self.channel = None
        self.blocks = -1  # the last block of steps whose noise and losses are drawn
        self.ls = None
        if _measuring(system):
            assert system is not None
            self.channel, stop_at, headed = sensing_channel(system, None, 1, float(dt))
            self.sense = sensing_arrays(self.channel, np.zeros(1, np.intp), stop_at, headed)
        elif not self.pairs:
            extra = 2.0 * self.model.offset if kind == NEAR_IDENTITY else 0.0
            self.ls = list_stage(layout, n, max(1, chunks), extra, dim)
        self.sv = saving(1, n, k, n_steps, save_every, perm)
        self.numbers = RunNumbers(
            float(dt), int(n_steps), 0, -1.0, -1, int(n_steps) + 1, axes_for(dim)
        )

    @property
    def step(self) -> int:
        """The step the run has reached (its last accepted state)."""
        return int(self.out.steps[0]) if self.done else int(self.st.meta[0, 1])

    @property
    def done(self) -> bool:
        return int(self.st.meta[0, 4]) == DONE

    @property
    def status(self) -> Status:
        return Status.from_code(int(self.out.status[0]))

    @property
    def min_clearance(self) -> float:
        """Least robot-robot clearance over the accepted states so far."""
        return float(self.st.mc[0, 0])

    @property
    def min_pair_distance(self) -> float:
        """Least distance of two points the safety filter keeps apart over the accepted
        states so far (:meth:`formationlab.safety.SafetyFilter.least_distance`); NaN
        without a filter."""
        return math.sqrt(float(self.st.md[0, 0])) if self.safety is not None else math.nan

    def advance(self, k_end: int, chunks: int = 1) -> None:
        """Steps until the run ends or reaches step ``k_end`` (from the last step, until it
        ends: that step is judged, not taken), the passes in ``chunks``."""
        k_end = int(k_end) if k_end < self.numbers.n_steps else self.numbers.n_steps + 1
        self._call(self.numbers._replace(k_end=k_end), chunks)

    def keep_reached(self) -> None:
        """End the run at the state it has reached (it is saved, with its rates)."""
        if self.done:
            return
        k = self.step
        if int(self.sv.rows[0]) and int(self.sv.k[0, int(self.sv.rows[0]) - 1]) == k:
            return
        self._call(self.numbers._replace(n_steps=k, k_end=k + 1), 1)

    def _call(self, numbers: RunNumbers, chunks: int) -> None:
        """The loop from the step reached to ``numbers.k_end``, block by block of sensing
        draws, answering its pauses."""
        sn = self.sense[0]
        blocks = sn is not None and (sn.noise > 0 or sn.drop > 0)
        while not self.done and self.step < numbers.k_end:
            k0 = self.step
            run = numbers
            if blocks:  # this block's draws, from the trial's own generator
                block = k0 // BLOCK
                if block > self.blocks:
                    assert self.channel is not None
                    one = np.zeros(1, np.intp)
                    if sn.noise > 0:
                        sn.noise_block[:] = self.channel.block("noise", one)
                    if sn.drop > 0:
                        sn.drop_block[:] = self.channel.block("drop", one)
                    self.blocks = block
                run = numbers._replace(k_end=min(numbers.k_end, (block + 1) * BLOCK))
            self._segment(run, chunks)

    def _segment(self, numbers: RunNumbers, chunks: int) -> None:
        par = chunks if chunks > 1 else None  # (None: the threads' code is not compiled)
        st = self.st
        law, lists = (self.layout, None) if self.pairs else (None, (self.layout, self.ls, par))
        last = min(numbers.k_end, numbers.n_steps)  # v_ref of the segment's steps (a function
        mt = with_references(self.mt, self.march, self.step, last, numbers.dt)  # of time)
        while True:
            step_chunk(
                0, law, self.model, mt, *self.stage, *self.sense, st, self.out, numbers,
                lists, self.sv,
            )  # fmt: skip
            status = int(st.meta[0, 4])
            if status == GROW:
                self.ls = grow(self.ls)  # room for the close list, and the step again
                lists = (self.layout, self.ls, par)
            elif status == PAUSED:  # the centralized QP that rounding defeated: Clarabel's
                res = barrier_filter(self.safety, st.need_p[0, :1], st.need_u[0, :1],
                                     self.obstacles)  # fmt: skip
                st.given_u[0, 0] = res.u[0]
                st.given[0, 0] = True
                st.need[0, 0] = False
            else:
                return
            st.meta[0, 4] = RUNNING

    def saved(self) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """The saved steps, states and rates (in the robots' own numbers)."""
        rows = int(self.sv.rows[0])
        return self.sv.k[0, :rows], self.sv.x[0, :rows], self.sv.v[0, :rows]


def compiled_terms(system: System, integrator: object) -> RunLayout | KernelTerms | None:
    """The law's kernel data laid out for the compiled run when ``system`` under
    ``integrator`` can run compiled, else None: its lists (:func:`.layout.run_layout`), or,
    when its robots sense each other or a fault stops one, its terms over every pair (the
    sensing stage measures every pair; sensing is for at most
    :data:`~formationlab.sensing.SENSING_LIMIT` robots).

    Explicit Euler (exactly, not a subclass) on any robot model the compiled loop steps
    (:func:`formationlab.models.terms.model_terms`: single integrators, unicycles of both
    mappings, double integrators, quadrotors, with their limits), marching or not, among
    obstacles and under a safety filter or not, sensing and with faults or not, with a law whose
    ``kernel_terms`` describe its control. In space (``Formation.dim == 3``): single and
    double integrators and quadrotors (with their limits or not), without sensing or
    faults, marching, obstacles or a filter, under a law of ``Law.compiled_dims``.
    """
    if type(integrator) is not Euler:
        return None
    try:
        robots = model_terms(system.model)
    except ParameterError:  # (a model of the user's own)
        return None
    f = system.formation
    if f.dim == 3 and (robots.kind not in POINT_KINDS or _measuring(system) or _acted_on(system)):
        return None  # (in space the loop steps the models of points on the true positions)
    if _measuring(system) or f.n <= PAIRS_UP_TO:
        try:
            return system.law.compiled_terms(f).writable()
        except ParameterError:
            return None
    # the robots' order first: its scratch is gone before the law's arrays are made
    order = (  # (in space along a curve through the template, where there is one)
        robot_order(f.edges[:, 0], f.edges[:, 1], f.n, f.template if f.dim == 3 else None)
        if f.n >= REORDER_FROM
        else False
    )
    try:
        terms = system.law.compiled_terms(f, pairs=False)._asdict()
    except ParameterError:
        return None
    return run_layout(terms, reorder=order)  # emptied as it is laid out


def _acted_on(system: System) -> bool:
    """Whether marching, obstacles or a safety filter act on the command of ``system`` (in
    space these run on the numpy path)."""
    return system.marching is not None or bool(system.obstacles) or system.filtered


def _measuring(system: System | None) -> bool:
    """Whether the robots of ``system`` command from their measurements or a fault stops one
    (the sensing stage, on the pairs layout)."""
    if system is None:
        return False
    return system.sensed or (system.faults is not None and system.faults.any)


def _start_clearance(terms: KernelTerms, x0: NDArray[np.float64], system: System | None) -> float:
    """Least robot-robot clearance ``r_ij - a_ij`` of the start ``x0`` ``(n, k)``."""
    if system is not None:
        return float(system.clearances(x0)[0])
    q = x0  # (single integrators: the state is the positions)
    r = np.linalg.norm(q[terms.pair_j] - q[terms.pair_i], axis=-1)
    return float(np.min(r - terms.pair_contact, initial=np.inf))


def run_euler_compiled(
    terms: KernelTerms | RunLayout,
    system: System,
    x0: NDArray[np.float64],
    *,
    dt: float,
    duration: float,
    save_every: int,
    progress: Callable[[float], None] | None = None,
    interruptible: bool = False,
    diagnostics: bool = True,
) -> RawSolution:
    """:meth:`Euler.run` on the compiled path: the same :class:`RawSolution`.

    The switching diagnostics are computed from the switching functions at the saved
    states (exact with ``save_every = 1``, as the driver records them; from the saved
    states only otherwise, which ``stats["diagnostics_from"]`` says): ``sigma(t)``
    gives them (``simulate`` computes them once, after the run's lists are let go),
    by default ``system.sigma`` of the saved states.
    """
    n_steps = steps_for(duration, dt)
    out = run_compiled(
        terms, x0, dt=dt, n_steps=n_steps, save_every=save_every, progress=progress,
        interruptible=interruptible, system=system,
    )  # fmt: skip
    return raw_solution(out, system, dt=dt, save_every=save_every, diagnostics=diagnostics)


def raw_solution(
    out: CompiledRun, system: System, *, dt: float, save_every: int, diagnostics: bool = True
) -> RawSolution:
    """The :class:`RawSolution` of a compiled run (:func:`run_euler_compiled`)."""
    t = out.k * dt
    if out.status is Status.SUCCESS:
        message = f"integrated {out.steps} steps of dt = {dt:g} s"
    elif out.status is Status.INTERRUPTED:
        message = f"interrupted by the user at t = {out.steps * dt:g} s"
    else:  # the rejected step: from the last accepted state, once more in numpy for the words
        x_last = out.x[-1]
        x_next = x_last + dt * out.v[-1]
        message = system.step_message(x_last, x_next, out.status, (out.steps + 1) * dt, dt)
    stats: dict[str, Any] = {
        "steps": int(out.steps),
        "rhs_evaluations": int(out.steps) + 1,
        "wall_time_s": out.wall,
        "step_cost_s": out.wall / max(out.steps, 1),
        **(switching_diagnostics(t, system.sigma(out.x)) if diagnostics else {}),
        "diagnostics_from": "every step" if save_every == 1 else f"every {save_every} steps",
        "backend": "numba",
        "threads": out.threads,
    }
    return RawSolution(
        t=t, x=out.x, v=out.v, status=out.status, message=message, stats=stats,
        min_pair_distance=out.min_pair_distance, min_robot_clearance=float(out.min_clearance),
        min_obstacle_clearance=float(out.min_obstacle_clearance), dim=position_dim(system),
    )  # fmt: skip
