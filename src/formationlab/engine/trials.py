"""Batches of trials on the one compiled loop: the host side of :mod:`.loop`.

:func:`run_trials` lays the trials out in chunks (``(n, k, C)``, the trials innermost),
builds each stage's numbers (the law's :class:`~formationlab.controllers.terms.KernelTerms`,
the robot model's :class:`~formationlab.models.terms.ModelTerms`, the obstacles' and the
filter's terms), runs the chunks in parallel (a single chunk on the calling thread, so that a
small batch does not compile the threads' version of the loop) until every trial has ended,
and answers the
rare pauses of a centralized filter whose QP rounding defeats (Clarabel, through
:func:`formationlab.safety.barrier_filter`, between calls). With sensing, it draws each
block's noise and losses between calls (:class:`~formationlab.sensing.Channel`), and runs
the trials in groups that bound the memory of their measurement arrays. It returns a
:class:`TrialRun`: how each trial ended, by name.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..controllers import Law
from ..dynamics import System
from ..errors import ParameterError
from ..formation.spec import Formation
from ..marching.terms import march_terms
from ..models import RobotModel
from ..models.terms import HEADING, NEAR_IDENTITY, POINT_KINDS, model_terms
from ..outcomes.analysis import Tolerances
from ..safety import barrier_filter
from ..safety.obstacle_terms import obstacle_terms
from ..safety.stage import CENTRALIZED, NONE, filter_terms
from ..sensing import BLOCK, Channel, Faults, Seed, Sensing
from ..sensing.stage import sensing_arrays, trial_bytes
from .euler import axes_for
from .loop import DONE, RUNNING, ChunkState, RunNumbers, TrialOutputs, run_chunks
from .saving import no_saving

__all__ = [
    "GROUP_BYTES",
    "TrialRun",
    "chunk_state",
    "run_trials",
    "safety_stage",
    "sensing_channel",
    "trial_outputs",
]

#: bytes of per-trial sensing arrays (noise and loss blocks, delay ring) a group may hold
GROUP_BYTES = 64 * 2**20


class TrialRun(NamedTuple):
    """How each of ``B`` trials ended (``run_trials``)."""

    x: NDArray[np.float64]  #: (B, n, k) final states (the last accepted ones)
    v: NDArray[np.float64]  #: (B, n, k) their rates
    status: NDArray[np.int8]  #: (B,) Status.code
    steps: NDArray[np.int64]  #: (B,) accepted steps
    min_clearance: NDArray[np.float64]  #: (B,) least robot-robot clearance over accepted states
    net_speed: NDArray[np.float64]  #: (B,) net speed over the last check interval
    q_window: NDArray[np.float64]  #: (B, n, d) positions at the start of the drift window
    window_step: int  #: that step (negative: never reached)
    #: (B,) least robot-obstacle clearance over accepted states (inf without obstacles)
    min_obstacle_clearance: NDArray[np.float64]
    #: (B,) least distance of two points the filter keeps apart (NaN without a filter:
    #: :meth:`formationlab.safety.SafetyFilter.least_distance`) over accepted states
    min_pair_distance: NDArray[np.float64]


def run_trials(
    formation: Formation,
    law: Law,
    model: RobotModel,
    q0: NDArray[np.float64],
    *,
    dt: float,
    n_steps: int,
    check_every: int,
    tol: Tolerances,
    chunk: int,
    obstacles: Sequence[Any] = (),
    safety: Any = None,
    sensing: Sensing | None = None,
    faults: Faults | None = None,
    seeds: Sequence[Seed] | None = None,
) -> TrialRun:
    """Step the trials ``q0`` ``(B, n, k)`` with explicit Euler on the compiled loop.

    Trial by trial the stepping driver's run with a :class:`~formationlab.integrators.StopRule`
    (``speed`` of ``tol``, every ``check_every`` steps) and the drift window of ``tol``;
    ``chunk`` trials per chunk of parallel work. With ``sensing`` or ``faults`` the robots
    command from their own measurements (``seeds``: each trial's, default the sensing's).
    """
    obstacles = tuple(obstacles)
    safety = safety.at_step(dt) if safety is not None else None  # (the rows guard dt)
    system = System(
        formation=formation, law=law, model=model, obstacles=obstacles, safety=safety,
        sensing=sensing, faults=faults,
    )  # fmt: skip
    terms = law.compiled_terms(formation).writable()  # one signature for every law
    robots = model_terms(model)
    sensed = (sensing is not None and not sensing.ideal) or (faults is not None and faults.any)
    if formation.dim == 3 and (robots.kind not in POINT_KINDS or sensed):
        raise ParameterError(
            "the compiled loop steps formations in space on single and double integrators "
            f"and quadrotors without sensing or faults; run this one ({model.name!r}) with "
            'backend="numpy"'
        )
    stage = safety_stage(law, obstacles, safety)
    B, n, k = q0.shape
    window_step = n_steps - tol.drift_steps(dt)  # negative: never reached
    # (mc and mo start as the least clearances of the starts, as the driver starts them)
    dim = formation.dim
    out = trial_outputs(B, n, k, dim=dim)
    out.mc[:], out.mo[:] = system.clearances(q0)
    numbers = RunNumbers(float(dt), int(n_steps), int(check_every), float(tol.speed),
                         int(window_step), int(n_steps) + 1, axes_for(dim))  # fmt: skip
    if not sensed:
        _run_group(q0, out, chunk, terms, robots, stage, None, numbers, safety, obstacles)
        return _trial_run(out, window_step, system)
    channel, stop_at, headed = sensing_channel(system, seeds, B, dt)
    group = int(min(B, max(64, GROUP_BYTES // trial_bytes(channel))))
    for g0 in range(0, B, group):
        ids = np.arange(g0, min(B, g0 + group))
        sense = (channel, ids, *sensing_arrays(channel, ids, stop_at, headed))
        part = TrialOutputs(*(a[g0 : g0 + ids.size] for a in out))  # views
        _run_group(q0[ids], part, chunk, terms, robots, stage, sense, numbers, safety, obstacles)
    return _trial_run(out, window_step, system)


def _trial_run(out: TrialOutputs, window_step: int, system: System) -> TrialRun:
    """The :class:`TrialRun` of the loop's outputs ``out`` (distances, not their squares)."""
    least = np.sqrt(out.md) if system.filtered else np.full(out.md.shape, np.nan)
    return TrialRun(
        out.x, out.v, out.status, out.steps, out.mc, out.ns, out.qw, window_step, out.mo, least
    )


def sensing_channel(
    system: System, seeds: Sequence[Seed] | None, B: int, dt: float
) -> tuple[Channel, NDArray[np.float64], bool]:
    """The measurement channel of ``B`` trials of ``system`` (``seeds``: each trial's,
    default the sensing's), when each robot stops (inf: never) and whether the robots
    measure in the frames of their headings: what :func:`~formationlab.sensing.stage.
    sensing_arrays` makes the loop's sensing stage of."""
    sensing = system.sensing or Sensing()  # (faults alone: an ideal channel, for its numbers)
    channel = Channel(
        sensing, system.formation, system.law, system.model,
        [sensing.seed] * B if seeds is None else list(seeds), dt,
    )  # fmt: skip
    if channel.B != B:
        raise ValueError(f"{channel.B} seeds for {B} trials")
    stop_at = np.full(system.formation.n, np.inf)
    for s in (system.faults or Faults()).stop:
        stop_at[s.robot - 1] = s.at
    return channel, stop_at, system.model.has_heading and channel.fixed_angles is None


def safety_stage(law: Law, obstacles: Sequence[Any], safety: Any) -> tuple[Any, Any]:
    """The loop's obstacle and filter terms of a closed loop of ``law`` among ``obstacles``
    under the filter ``safety`` (or None), or ``(None, None)`` when it has neither (the loop
    is then compiled without that stage)."""
    d_o, gamma, step = (
        (safety.d_obstacle, safety.gamma, safety.rows_step) if safety is not None else (0, 0, 0)
    )
    rep = law.obstacle_repulsion() if obstacles else None
    obs = obstacle_terms(
        obstacles, d_obstacle=d_o, gamma=gamma, step=step,
        gain=rep.gain if rep else 0.0, eta=rep.repulsion.eta if rep else 1.0,
        influence=rep.repulsion.influence if rep else 1.0,
    )  # fmt: skip
    flt = filter_terms(safety)
    return (obs, flt) if obstacles or flt.kind != NONE else (None, None)


def _run_group(
    q0: NDArray[np.float64], out: TrialOutputs, chunk: int, terms: Any, robots: Any,
    stage: tuple[Any, Any], sense: tuple[Any, ...] | None, numbers: RunNumbers, safety: Any,
    obstacles: tuple[Any, ...],
) -> None:  # fmt: skip
    """Step the trials ``q0`` in chunks until each has ended, writing ``out`` (by trial).

    ``sense``: ``(channel, trial numbers in the channel, SensingTerms, SensingState)``, or
    None. With noise or losses the chunks stop at the end of each block of steps, and the
    next block's draws of the trials still running are made here (:meth:`Channel.block`).
    """
    B, n, k = q0.shape
    C = int(max(1, min(chunk, B)))
    G = -(-B // C)
    x = np.zeros((G, n, k, C))
    for g in range(G):
        sel = np.arange(g * C, min(B, (g + 1) * C))
        x[g, :, :, : sel.size] = np.moveaxis(q0[sel], 0, -1)
    flt = stage[1]
    still = march_terms(None)  # (a batch does not march)
    kept = no_saving()  # (how each trial ended)
    st = chunk_state(
        x, B=B, mc=out.mc, mo=out.mo, turns=robots.kind in (HEADING, NEAR_IDENTITY),
        centralized=flt is not None and flt.kind == CENTRALIZED, dim=numbers.axes.ndim,
    )  # fmt: skip
    sn = ss = None
    blocks = False
    if sense is not None:
        channel, trials, sn, ss = sense
        blocks = sn.noise > 0 or sn.drop > 0
    k_end = BLOCK if blocks else numbers.k_end
    while True:
        if blocks:  # this block's draws, from each running trial's own generator
            live = np.concatenate(
                [st.ids[g, : st.meta[g, 0]] for g in range(G) if st.meta[g, 4] != DONE]
            )
            if sn.noise > 0:
                sn.noise_block[live] = channel.block("noise", trials[live])
            if sn.drop > 0:
                sn.drop_block[live] = channel.block("drop", trials[live])
        run = numbers._replace(k_end=min(k_end, numbers.k_end))
        while True:
            # the running chunks, side by side on threads (one chunk: on this thread)
            run_chunks(terms, robots, still, *stage, sn, ss, st, out, run, kept)
            wait_g, wait_b = np.nonzero(st.need)  # chunks paused, and their slots needing a QP
            if wait_g.size == 0:
                break
            res = barrier_filter(safety, st.need_p[wait_g, wait_b], st.need_u[wait_g, wait_b],
                                 obstacles)  # fmt: skip
            st.given_u[wait_g, wait_b] = res.u
            st.given[wait_g, wait_b] = True
            st.need[wait_g, wait_b] = False
            st.meta[np.unique(wait_g), 4] = RUNNING
        if np.all(st.meta[:, 4] == DONE):
            return
        k_end += BLOCK


def chunk_state(
    x: NDArray[np.float64], *, B: int | None = None, mc: NDArray[np.float64] | None = None,
    mo: NDArray[np.float64] | None = None, turns: bool = False, centralized: bool = False,
    stop_rule: bool = True, dim: int = 2,
) -> ChunkState:  # fmt: skip
    """The chunks' state at the start, from the starts ``x`` ``(G, n, k, C)``: the ``B``
    trials (default all) in order, chunk by chunk; ``mc`` and ``mo`` ``(B,)`` their
    robot-robot and robot-obstacle clearances (default +inf); ``turns``: room for headings;
    ``centralized``: room for QP pauses; ``stop_rule``: room for the positions (``dim``
    numbers) at the stop rule's checks."""
    G, n, _, C = x.shape
    B = G * C if B is None else B
    ids = np.zeros((G, C), np.int64)
    least = np.full((G, C), np.inf)
    least_o = np.full((G, C), np.inf)
    meta = np.zeros((G, 6), np.int64)
    for g in range(G):
        sel = np.arange(g * C, min(B, (g + 1) * C))
        ids[g, : sel.size] = sel
        if mc is not None:
            least[g, : sel.size] = mc[sel]
        if mo is not None:
            least_o[g, : sel.size] = mo[sel]
        meta[g] = (sel.size, 0, -1, 0, RUNNING, 0)
    hshape = (G, n, C) if turns else (G, 1, 1)
    qp = (G, C, n, 2) if centralized else (1, 1, n, 2)
    qc = np.array(x[:, :, :dim], order="C") if stop_rule else np.zeros((G, 1, dim, C))
    return ChunkState(
        x=x, xn=np.zeros_like(x), qc=qc,
        hc=np.zeros(hshape), hs=np.zeros(hshape), hcl=np.zeros(hshape), hsl=np.zeros(hshape),
        ids=ids, mc=least, mo=least_o, md=np.full((G, C), np.inf), ns=np.full((G, C), np.nan),
        meta=meta, need=np.zeros((G, C), bool),
        need_p=np.zeros(qp), need_u=np.zeros(qp), given=np.zeros((G, C), bool),
        given_u=np.zeros(qp),
    )  # fmt: skip


def trial_outputs(B: int, n: int, k: int, *, kept: bool = True, dim: int = 2) -> TrialOutputs:
    """Room for how ``B`` trials of ``n`` robots (``k`` numbers each, ``dim`` of them the
    position) end; without ``kept`` none for their final states and drift windows (a run
    that saves its path has them)."""
    m = n if kept else 1
    return TrialOutputs(
        x=np.empty((B, m, k)), v=np.full((B, m, k), np.nan), steps=np.zeros(B, np.int64),
        status=np.zeros(B, np.int8), mc=np.full(B, np.inf), mo=np.full(B, np.inf),
        md=np.full(B, np.inf), ns=np.full(B, np.nan),
        qw=np.full((B, m, dim), np.nan),
    )  # fmt: skip
