"""Compiled explicit-Euler runs of one formation, from three robots to a hundred thousand.

:func:`run_compiled` is the fast path of ``simulate`` for explicit Euler on
single integrators with a law that gives its data (``Law.kernel_terms``): the
whole time loop in numba, with the stepping driver's semantics (the same step
rule, saving every ``save_every`` steps and the last state, the velocity each
saved state was left with). Nothing in it is ``n x n``, and nothing is allocated
per step:

* the law's data as lists by robot (:mod:`.layout`), evaluated in two passes
  (:mod:`.field`): each edge force, close pair's repulsion, switching surface and
  area term once per step, then each robot gathers its own in a fixed order;
* **non-neighbour repulsion and contact** through a close-pair list
  (:mod:`formationlab.verlet`): Khatib's ``gamma_ij`` acts only within clearance
  ``s0``, contact needs clearance 0, and a step can only have carried two robots
  through each other if they end closer than twice the step's largest move, so
  every step needs the pairs of clearance below ``max(s0, 2.01 move)``. The list
  holds the pairs below that plus a skin of ``(s0 + max a_ij) / 2`` and is rebuilt
  (on a cell grid) only when some robot has moved more than half the skin since
  the last build;
* on numba's threads or on one, with the same numbers bit for bit: from
  :data:`PARALLEL_FROM` robots the run measures a segment on each and keeps the faster
  (on a busy machine the threads can be the slower), or as asked.

Memory is ``O(n + edges + restricted triples + close pairs)`` plus the saved states
(the states to be saved, exactly). The numpy driver
(:func:`formationlab.integrators.drive`) is the specification it is tested
against, to rounding.
"""

from __future__ import annotations

import math
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, NamedTuple

import numba
import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..controllers.terms import KernelTerms
from ..dynamics import System
from ..engine.contact import COLLISION, NON_FINITE, TOO_LARGE
from ..errors import ParameterError
from ..status import Status
from ..verlet import build_close_list, list_holds, pair_rows
from .base import RawSolution, steps_for
from .diagnostics import switching_diagnostics
from .field import items, items_parallel, robots, robots_parallel
from .layout import REORDER_FROM, RunLayout, robot_order, run_layout

__all__ = [
    "PARALLEL_FROM",
    "CompiledRun",
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
    least clearance, wall time and the threads the run ended on."""

    def __init__(self, k, x, v, status, steps, min_clearance, wall, threads=1):
        self.k, self.x, self.v = k, x, v
        self.status, self.steps, self.min_clearance, self.wall = status, steps, min_clearance, wall
        self.threads = threads


class _Work(NamedTuple):
    """The run's scratch space, allocated once (the close list's grows when it must)."""

    qp: NDArray[np.float64]  #: (n, 2) the other state buffers
    qn: NDArray[np.float64]
    u: NDArray[np.float64]  #: (n, 2) the velocity buffers
    un: NDArray[np.float64]
    qb: NDArray[np.float64]  #: (n, 2) the state the close list was built at
    fe: NDArray[np.float64]  #: (3, m) edge forces (x, y) and clearances
    on: NDArray[np.uint8]  #: (s,) surfaces switched on
    area_g: NDArray[np.float64]  #: (r,)
    least: NDArray[np.float64]  #: (chunks, 2)
    moves: NDArray[np.float64]  #: (chunks, 2)
    p_ptr: NDArray[np.int32]  #: (n + 1,) rows of the close list
    cell_of: NDArray[np.int32]  #: (n,) cell grid scratch
    items: NDArray[np.int32]
    start: NDArray[np.int32]  #: (4 n + 17,)
    stamp: NDArray[np.int32]
    cand: NDArray[np.int32]


def _work(layout: RunLayout, n: int, chunks: int) -> _Work:
    return _Work(
        qp=np.zeros((n, 2)),
        qn=np.zeros((n, 2)),
        u=np.zeros((n, 2)),
        un=np.zeros((n, 2)),
        qb=np.zeros((n, 2)),
        fe=np.zeros((3, layout.edge_i.size)),
        on=np.zeros(layout.surf_a.size, np.uint8),
        area_g=np.zeros(layout.area_a.size),
        least=np.zeros((chunks, 2)),
        moves=np.zeros((chunks, 2)),
        p_ptr=np.zeros(n + 1, np.int32),
        cell_of=np.zeros(n, np.int32),
        items=np.zeros(n, np.int32),
        start=np.zeros(4 * n + 17, np.int32),
        stamp=np.zeros(n, np.int32),
        cand=np.zeros(n, np.int32),
    )


def saved_rows(n_steps: int, save_every: int) -> int:
    """States a run of ``n_steps`` keeps: every ``save_every``-th step and the last one.

    A run that ends early keeps its last accepted state in the room of the final one.
    """
    return n_steps // save_every + 1 + (1 if n_steps % save_every else 0)


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
) -> CompiledRun:
    """Step one state ``q0`` ``(n, 2)`` with explicit Euler (module docstring).

    The loop runs in compiled segments of about a quarter of a second, between which
    ``progress`` is called with the simulated time and Ctrl-C (or SIGTERM, if its handler
    raises KeyboardInterrupt) is seen: a signal that comes during a segment is held until
    the segment ends (:func:`_signals_between_segments`). With ``interruptible`` the run
    so far is returned with status ``"interrupted"``.
    ``parallel``: on numba's threads or on one; by default one thread, and from
    :data:`PARALLEL_FROM` robots the faster of the two as measured on the second and
    third segments (the same numbers either way).
    """
    layout = terms if isinstance(terms, RunLayout) else run_layout(terms)
    n = q0.shape[0]
    threads = numba.get_num_threads()
    # None: one thread, or (large formations) the faster of one thread and the threads
    # as measured on the second and third segments (the first builds the close list)
    probe = parallel is None and threads > 1 and n >= PARALLEL_FROM
    use = bool(parallel) and threads > 1
    chunks = threads * _CHUNKS_PER_THREAD
    work = _work(layout, n, chunks)
    lists = [np.zeros((16, 2), np.int32), np.zeros((16, 2)), np.zeros(32, np.int32)]
    rows = saved_rows(n_steps, save_every)
    k_out = np.zeros(rows, np.int64)
    x_out = np.zeros((rows, n, 2))
    v_out = np.zeros((rows, n, 2))
    info = np.zeros(3)  # status, last accepted step, saved rows
    clear = np.full(1, np.inf)
    kept = np.array([0.0, np.inf, 0.0])  # the close list's reach, drift since, pairs
    q = np.ascontiguousarray(q0, dtype=float)  # the run's own copy, in the layout's numbers
    q = q[layout.perm] if layout.perm.size else q.copy()
    k0, status = 0, Status.SUCCESS
    # progress at least every 1 % of the run, as the driver (without progress, segments of
    # a quarter of a second: each costs a call and a copy of the state)
    step_cap = max(1, n_steps // 100) if progress is not None else n_steps

    def segment(k_begin: int, k_end: int) -> None:
        pairs, fp, p_rows = lists
        lists[:] = _run(
            q, layout, work, pairs, fp, p_rows, dt, k_begin, k_end, n_steps, save_every,
            k_out, x_out, v_out, info, clear, kept, use, chunks if use else 1,
        )  # fmt: skip

    def keep_reached(k: int) -> None:
        """Keep the state the loop has reached (step ``k``, in ``q``) and its velocity as the
        next saved row: a call from step 0 to step 0 on scratch outputs saves exactly that."""
        part = (np.zeros(1, np.int64), np.zeros((1, n, 2)), np.zeros((1, n, 2)))
        pairs, fp, p_rows = lists
        reach = np.array([0.0, np.inf, 0.0])  # a close list of its own, built afresh
        lists[:] = _run(
            q, layout, work, pairs, fp, p_rows, dt, 0, 0, n_steps, save_every, *part,
            np.zeros(3), np.full(1, np.inf), reach, False, 1,
        )  # fmt: skip
        row = int(info[2])
        k_out[row], x_out[row], v_out[row] = k, part[1][0], part[2][0]
        info[2] = row + 1

    chunk = min(256, step_cap)
    segments = 0
    per_step: dict[bool, float] = {}  # seconds per step of the probed segments, by threads
    start = time.perf_counter()
    with _signals_between_segments() as deliver:
        try:
            while True:
                k_end = min(n_steps, k0 + chunk)
                began = time.perf_counter()
                segment(k0, k_end)
                spent = time.perf_counter() - began
                deliver()  # a Ctrl-C during the segment: KeyboardInterrupt here
                status = Status.from_code(int(info[0]))
                segments += 1
                if probe and segments > 1 and len(per_step) < 2 and int(info[1]) > k0:
                    per_step[use] = spent / (int(info[1]) - k0)  # one thread, then the threads
                    use = len(per_step) == 1 or per_step[True] < per_step[False]
                k0 = int(info[1])
                if status is not Status.SUCCESS or k0 >= n_steps:
                    break
                if progress is not None:
                    progress(k0 * dt)
                chunk = int(min(max(chunk * 0.25 / max(spent, 1e-6), 16), 1 << 20, step_cap))
        except KeyboardInterrupt:
            if not interruptible:
                raise
            status = Status.INTERRUPTED
            k0 = int(info[1])  # the loop's own count (it may have returned just before Ctrl-C)
            if int(info[2]) == 0 or k_out[int(info[2]) - 1] != k0:
                keep_reached(k0)  # the run ends where it was, not at the last saved step
    wall = time.perf_counter() - start
    saved = int(info[2])
    return CompiledRun(
        k_out[:saved], x_out[:saved], v_out[:saved], status, k0, float(clear[0]), wall,
        threads if use else 1,
    )  # fmt: skip


@contextmanager
def _signals_between_segments() -> Iterator[Callable[[], None]]:
    """Hold SIGINT and SIGTERM while a compiled segment runs; ``deliver()`` them between.

    A signal that arrives inside numba code runs its Python handler as the segment hands its
    results back: Ctrl-C's KeyboardInterrupt raised there became a ``SystemError`` ("returned
    a result with an exception set") and the run was lost. Inside the block the handlers
    only note the signal, and ``deliver()`` calls the handler that was in place (for
    Ctrl-C, Python's: KeyboardInterrupt). Only in the main thread (where signals are
    handled) and for handlers that are Python functions; restored on leaving (a signal
    held then is raised again, unless the block ended with an exception).
    """
    held: list[tuple[int, Any]] = []
    previous: dict[int, Callable[[int, Any], Any]] = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            handler = signal.getsignal(sig)
            if callable(handler):
                previous[sig] = handler
                signal.signal(sig, lambda s, frame: held.append((s, frame)))

    def deliver() -> None:
        while held:  # delivered here and now: from the caller's frame
            sig, _ = held.pop(0)
            previous[sig](sig, sys._getframe(1))

    try:
        yield deliver
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    for sig, _ in held:  # one that came after the last delivery: as if it came now
        signal.raise_signal(sig)


@njit(cache=True, fastmath=False, error_model="numpy")
def _keep(x_out, v_out, row, q, u, perm):
    """Save state ``q`` and velocity ``u`` as row ``row``, in the robots' own numbers."""
    if perm.size == 0:
        x_out[row] = q
        v_out[row] = u
        return
    for r in range(q.shape[0]):
        x_out[row, perm[r], 0] = q[r, 0]
        x_out[row, perm[r], 1] = q[r, 1]
        v_out[row, perm[r], 0] = u[r, 0]
        v_out[row, perm[r], 1] = u[r, 1]


@njit(cache=True, fastmath=False, error_model="numpy")
def _run(
    q0, L, W, pairs, fp, p_rows, dt, k0, k_end, n_steps, save_every, k_out, x_out, v_out,
    info, clear, kept, parallel, chunks,
):  # fmt: skip
    """The time loop from step ``k0`` (an accepted state) to ``k_end`` of ``n_steps``.

    At each step: the close list rebuilt if it may miss a pair that matters, the
    items at ``x_k`` and the verdict on the step that led there, the robots' field
    and Euler step, saving (every ``save_every`` steps, the last step, and a trial's
    last state). ``info`` returns status, last accepted step and rows saved (appended
    after ``info[2]`` rows); ``clear`` the least clearance so far (over the edges and
    the close pairs); ``q0`` the state of step ``info[1]`` (in the layout's numbers; the
    saved states in the robots' own). The close list lasts from
    segment to segment: its buffers (``pairs``, ``fp``, ``p_rows``) are returned,
    ``kept`` holds its reach, the drift since it was built and its length.
    """
    n = q0.shape[0]
    # three state buffers take turns (q_k, q_{k-1}, q_{k+1}) and two velocity buffers
    # (u_{k-1}, u_k): a rejected step ends at q_{k-1} with the velocity it was left with
    q, qp, qn = q0, W.qp, W.qn
    qp[:] = q0
    u, un = W.u, W.un
    disp = 0.0
    reach, drift, n_pairs = kept[0], kept[1], int(kept[2])
    saved = int(info[2])
    status = 0
    least = clear[0]
    k = k0
    while True:
        need = max(L.influence, 2.01 * disp)
        if not list_holds(drift, reach, need):
            reach = need + L.skin
            pairs, n_pairs = build_close_list(
                q, L.radius, reach, L.nbr_ptr, L.nbr, pairs, W.cell_of, W.items, W.start,
                W.stamp, W.cand,
            )  # fmt: skip
            p_rows = pair_rows(pairs, n_pairs, n, W.p_ptr, p_rows)
            if fp.shape[0] < pairs.shape[0]:
                fp = np.zeros((pairs.shape[0], 2))
            W.qb[:] = q
            drift = 0.0
        if parallel:
            items_parallel(
                q, qp, 2.01 * disp, L, pairs, n_pairs, W.fe, fp, W.on, W.area_g, W.least, chunks
            )  # fmt: skip
        else:
            items(q, qp, 2.01 * disp, L, pairs, n_pairs, W.fe, fp, W.on, W.area_g, W.least)
        g = W.least[:chunks, 0].min()
        if k > k0:  # the step rule of System.step_verdict
            if not g > 0.0:
                status = COLLISION
            elif not W.least[:chunks, 1].min() > 0.0:
                status = TOO_LARGE
            if status:  # end at the last accepted state, with the velocity it was left with
                if saved == 0 or k_out[saved - 1] != k - 1:
                    k_out[saved] = k - 1
                    _keep(x_out, v_out, saved, qp, u, L.perm)
                    saved += 1
                q = qp
                k -= 1
                break
            least = min(least, g)
        elif k == 0:
            least = g
        if parallel:
            robots_parallel(
                q, qn, W.qb, dt, L, W.p_ptr, p_rows, W.fe, fp, W.on, W.area_g, un, W.moves,
                chunks,
            )  # fmt: skip
        else:
            robots(q, qn, W.qb, dt, L, W.p_ptr, p_rows, W.fe, fp, W.on, W.area_g, un, W.moves)
        u, un = un, u  # u_k
        if (k % save_every == 0 or k == n_steps) and (k > k0 or k == 0):
            k_out[saved] = k
            _keep(x_out, v_out, saved, q, u, L.perm)
            saved += 1
        if k == n_steps or k == k_end:
            break
        qp, q, qn = q, qn, qp  # x_{k+1} is in qn
        k += 1
        largest = W.moves[:chunks, 0].max()
        if not math.isfinite(largest):  # not finite: judged before the list sees it
            status = NON_FINITE
            if saved == 0 or k_out[saved - 1] != k - 1:
                k_out[saved] = k - 1
                _keep(x_out, v_out, saved, qp, u, L.perm)
                saved += 1
            q = qp
            k -= 1
            break
        disp = math.sqrt(largest)
        drift = math.sqrt(W.moves[:chunks, 1].max())
    q0[:] = q  # (q0 itself or the other buffer)
    kept[0], kept[1], kept[2] = reach, drift, n_pairs
    info[0] = status
    info[1] = k
    info[2] = saved
    clear[0] = least
    return pairs, fp, p_rows


def compiled_terms(system: System, integrator: object) -> RunLayout | None:
    """The law's kernel data laid out for the compiled run (:func:`.layout.run_layout`) when
    ``system`` under ``integrator`` can run compiled, else None.

    Explicit Euler (exactly, not a subclass) on the paper's single integrators
    (no speed limit) without marching, with a law whose ``kernel_terms`` describe
    its control.
    """
    from ..models import SingleIntegrator
    from .explicit import Euler

    if type(integrator) is not Euler or system.model != SingleIntegrator():  # no limits
        return None
    if system.marching is not None or system.obstacles or system.filtered:
        return None
    if system.sensed or (system.faults is not None and system.faults.any):
        return None
    f = system.formation
    # the robots' order first: its scratch is gone before the law's arrays are made
    order = robot_order(f.edges[:, 0], f.edges[:, 1], f.n) if f.n >= REORDER_FROM else False
    try:
        terms = system.law.compiled_terms(f, pairs=False)._asdict()
    except ParameterError:
        return None
    return run_layout(terms, reorder=order)  # emptied as it is laid out


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
        interruptible=interruptible,
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
    return RawSolution(t=t, x=out.x, v=out.v, status=out.status, message=message, stats=stats)
