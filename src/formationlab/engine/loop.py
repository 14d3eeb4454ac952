"""The one compiled stepping loop: explicit Euler over chunks of trials, stage by stage.

The compiled twin of the stepping driver (:func:`formationlab.integrators.drive`) for
batches of trials. Every chunk of ``C`` trials keeps its states as ``(n, k, C)`` (``k``
numbers per robot, positions first, as the robot model's state) with the trials on the
innermost, contiguous axis, so that each loop over trials is a plain SIMD loop. Per step
``k`` of the live trials of a chunk, the stages in order:

1. **model**: the points the law acts on (:func:`formationlab.models.stage.points`;
   unicycles' headings carried from step to step, :func:`~formationlab.models.stage.turn`);
2. **law**: its field over every pair (:func:`formationlab.controllers.stage.law_field`,
   the law's :class:`~formationlab.controllers.terms.KernelTerms`) or over its lists
   (:func:`.lists.list_field`); or, when the robots sense each other (local frames, noise,
   delay, losses, range, mismatch, faults), every robot's command from its own
   measurements (:func:`formationlab.sensing.stage.sensed_field`);
3. **marching**: the reference velocity, the leader's or the motion parameters' term
   (:func:`formationlab.marching.stage.march`; nothing when the run does not march);
4. **obstacles and filter** (only when the run has them), trial by trial
   (:func:`formationlab.safety.stage.filter_command`); a trial whose QP rounding defeats
   pauses its chunk, and the host answers (:mod:`.trials`);
5. **model**: the state's rate from the command
   (:func:`formationlab.models.stage.rates`); zero for robots stopped by a fault
   (:func:`formationlab.sensing.stage.halt`);
6. **drift window**: the positions at ``window_step`` (``Stepped.q_window``);
7. **stop rule** (:class:`~formationlab.integrators.StopRule`): at a check, the
   instantaneous speed (:func:`formationlab.models.stage.speed`) or the net speed since
   the previous check at most ``speed`` (with sensing, only while every robot sees its
   neighbours, now and at the previous check);
8. **step and verdict**: the Euler step, judged by the contact rule
   (:mod:`.contact`, and :func:`formationlab.safety.stage.obstacle_contact`): not finite,
   contact at its end, contact along it; a rejected step is not taken;
9. **bookkeeping**: the trials that ended are written out and swapped out of the live
   range (compaction), so that early stopping saves work instead of masking it.

Everything a chunk carries from one call to the next is in :class:`ChunkState` (so the loop
can stop at a pause, or at the end of a block of steps, and go on), and what it returns is
in :class:`TrialOutputs`. Chunks run side by side on threads in :func:`run_chunks`.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, types
from numba.extending import overload
from numpy.typing import NDArray

from ..controllers.stage import law_field
from ..marching.stage import march
from ..marching.terms import STILL
from ..models.stage import headings, points, rates, speed, turn
from ..models.terms import HEADING, NEAR_IDENTITY, SINGLE
from ..outcomes.tolerances import NET_STEPS
from ..safety.stage import CENTRALIZED, WAIT, filter_command, filter_scratch, obstacle_contact
from ..sensing.stage import halt, informed, sensed_field
from .contact import (
    CONVERGED,
    END,
    SWEPT_MARGIN,
    contact,
    verdict,
)
from .euler import PLANE, euler
from .lists import list_contact, list_field, list_step
from .saving import save

__all__ = [
    "DONE",
    "GROW",
    "PAUSED",
    "RUNNING",
    "ChunkState",
    "RunNumbers",
    "TrialOutputs",
    "run_chunks",
    "step_chunk",
]

#: A chunk's status in ``ChunkState.meta[:, 4]``: running, done, paused for QP solves, or
#: paused for a close list that needs more room (the lists layout, :mod:`.lists`)
RUNNING, DONE, PAUSED, GROW = -1, 0, -2, -3


class RunNumbers(NamedTuple):
    """The run's numbers: step, steps, stop rule, drift window."""

    dt: float
    n_steps: int
    check_every: int  #: steps between the stop rule's checks (0: no stop rule)
    speed: float  #: the stop rule's speed
    window_step: int  #: start of the drift window (negative: never)
    k_end: int  #: the chunks stop (and stay running) at this step: the end of a block
    #: the positions' dimension as ``axes.ndim`` (:data:`.euler.PLANE` or
    #: :data:`.euler.SPACE`), a constant for numba, which compiles the loop once for each
    axes: NDArray[np.float64] = PLANE


class ChunkState(NamedTuple):
    """What every chunk of ``C`` trials carries from one call to the next (``G`` chunks).

    ``x`` and ``xn`` are the double buffer of the states (``meta[c, 3]`` says which holds
    the current ones); ``meta[c]`` is ``(live trials, step, step of the previous check,
    current buffer, status, headings set)``.
    """

    x: NDArray[np.float64]  #: (G, n, k, C)
    xn: NDArray[np.float64]  #: (G, n, k, C)
    qc: NDArray[np.float64]  #: (G, n, d, C) positions at the previous check
    hc: NDArray[np.float64]  #: (G, n, C) unicycles' cos theta (else (G, 1, 1))
    hs: NDArray[np.float64]  #: sin theta
    hcl: NDArray[np.float64]  #: what rounding left out of them (models.stage.turn)
    hsl: NDArray[np.float64]
    ids: NDArray[np.int64]  #: (G, C) the trial in each slot
    mc: NDArray[np.float64]  #: (G, C) least robot-robot clearance over accepted states
    mo: NDArray[np.float64]  #: (G, C) least robot-obstacle clearance over accepted states
    md: NDArray[np.float64]  #: (G, C) least squared distance of two filtered points (inf)
    ns: NDArray[np.float64]  #: (G, C) net speed over the last check interval
    meta: NDArray[np.int64]  #: (G, 6)
    need: NDArray[np.bool_]  #: (G, C) the slot's trial waits for a QP solve
    need_p: NDArray[np.float64]  #: (G, C, n, 2) its points (centralized filter; else 1 x 1)
    need_u: NDArray[np.float64]  #: (G, C, n, 2) its command before the filter
    given: NDArray[np.bool_]  #: (G, C) the QP's answer is in given_u
    given_u: NDArray[np.float64]  #: (G, C, n, 2)


class TrialOutputs(NamedTuple):
    """How each of ``B`` trials ended."""

    x: NDArray[np.float64]  #: (B, n, k) final states
    v: NDArray[np.float64]  #: (B, n, k) their rates
    steps: NDArray[np.int64]  #: (B,) accepted steps
    status: NDArray[np.int8]  #: (B,) Status.code
    mc: NDArray[np.float64]  #: (B,) least robot-robot clearance over accepted states
    mo: NDArray[np.float64]  #: (B,) least robot-obstacle clearance over accepted states
    #: (B,) least squared distance of two points the safety filter keeps apart (pairs
    #: within its sensing radius) over accepted states; inf without a filter
    md: NDArray[np.float64]
    ns: NDArray[np.float64]  #: (B,) net speed over the last check interval
    qw: NDArray[np.float64]  #: (B, n, d) positions at the start of the drift window


@njit(cache=True, error_model="numpy", nogil=True)
def step_chunk(c, law, model, mt, obs, flt, sn, ss, st, out, run, lists, sv):
    """Steps of chunk ``c`` until every trial has ended, one needs a QP, or ``run.k_end``.

    ``mt`` is the run's marching (:class:`~formationlab.marching.terms.MarchTerms`; kind
    STILL when it does not march: a stage small enough to compile into every run, so that
    marching needs no loop of its own);
    ``obs`` and ``flt`` are the run's obstacle and filter terms, or both None when it has
    neither obstacles nor a filter; ``sn`` and ``ss`` its sensing terms and state
    (:mod:`formationlab.sensing.stage`), or None when its robots see the true positions:
    numba then compiles this function without that stage (a ``None`` argument prunes the
    branches that test it), so a run compiles only what it uses. The law's field comes from
    one of two layouts: its pairs (``law``, its
    :class:`~formationlab.controllers.terms.KernelTerms`; ``lists`` None), or its lists
    (``lists``: its :class:`~formationlab.engine.layout.RunLayout`, the
    :class:`~.lists.ListStage` and the passes' chunks on numba's threads, or None for one
    thread; ``law`` None, and the chunk one trial of any model, without sensing). ``sv``:
    the saving stage (:class:`~.saving.Saving`); when it saves nothing
    (:func:`~.saving.no_saving`) only how each trial ended is kept (``out.x``, ``out.v``;
    with saving, the saved rows hold the last state). The positions are the first
    ``dim = run.axes.ndim`` numbers of a state (2 or 3, :data:`.euler.PLANE` or
    :data:`.euler.SPACE`): numba compiles the loop once for each dimension, from this source
    (in space the single integrator, without marching, obstacles, filter or sensing, which
    the hosts keep on the numpy path).
    """
    axes = run.axes
    dim = axes.ndim  # (a constant where numba compiles the loop)
    n = st.x.shape[1]
    kk = st.x.shape[2]
    C = st.x.shape[3]
    hand = model.kind == NEAR_IDENTITY  # the law acts on points other than the centres
    turns = hand or model.kind == HEADING  # the state has a heading
    # f = u: the single integrator's rates are its commands (no copy)
    same = model.kind == SINGLE and model.max_speed == np.inf and sn is None
    saves = sv.every > 0  # the run keeps its path (else how each trial ended)
    ids = st.ids[c]
    mc = st.mc[c]
    mo = st.mo[c]
    md = st.md[c]
    ns = st.ns[c]
    qc = st.qc[c]
    hc, hs, hcl, hsl = st.hc[c], st.hs[c], st.hcl[c], st.hsl[c]
    x, xn = (st.x[c], st.xn[c]) if st.meta[c, 3] == 0 else (st.xn[c], st.x[c])
    u = np.empty((n, dim, C))
    f = u if same else np.empty((n, kk, C))
    p = np.empty((n, 2, C) if hand else (1, 2, 1))  # hand points
    scratch = np.empty(C)  # the law's surface decisions, the unicycles' speeds
    gap = np.empty(C)  # clearance of the next state
    swept = np.empty(C)  # least clearance along the step to it
    near = np.empty(C)  # 1: a pair may have met during the step
    disp = np.zeros(C)  # largest displacement of the step
    fin = np.zeros(C)  # 0 while the step is finite
    wide = np.empty(C)  # 1: a robot turned by more than SMALL_TURN in the step
    code = np.full(C, -1, dtype=np.int8)  # -1: still running
    if obs is not None:
        S = filter_scratch(n, obs, flt)
    if sn is not None:
        ul = np.empty((n, 2))  # one trial's commands in its robots' frames
    acc = np.empty((n, 2))  # one trial's motion-parameter sums
    if lists is not None:  # (taken apart once: each taking apart counts its arrays' uses)
        lay, ls, par = lists
    radius = robot_radii(law, lists)
    rr = np.empty((1, 1))  # each pair's length at the current state (the law's pairs)
    if law is not None:
        rr = np.empty((law.pair_i.shape[0], C))
    # rr holds the current state's lengths (the contact rule's, last step); a bool, not the
    # literal False, which would compile the law's field a second time
    known = np.bool_(False)
    dt = run.dt
    nact = st.meta[c, 0]
    step = st.meta[c, 1]
    kc = st.meta[c, 2]
    if turns and st.meta[c, 5] == 0:  # then carried from step to step (models.stage.turn)
        headings(x, hc, hs, hcl, hsl, nact)
        st.meta[c, 5] = 1
    while nact > 0:
        if step >= run.k_end:  # the end of a block of steps: the chunk goes on later
            _pause(st, c, nact, step, kc, RUNNING)
            return
        k = step
        src = x
        if hand:
            points(x, hc, hs, p, nact, model)
            src = p
        if lists is not None:  # the law over its lists (one trial)
            room, start = list_field(x, src, u, ls, lay, par, hand, axes)
            if not room:  # the close list needs more room: the host grows it
                _pause(st, c, nact, step, kc, GROW)
                return
            mc[0] = min(mc[0], start)  # (the least clearance of the start)
        if law is not None:  # the law over its pairs
            if sn is not None and sn.measured:  # each robot's command from its measurements
                sensed_field(src, x, hc, hs, u, ul, nact, ids, k, law, sn, ss)
            else:
                law_field(src, u, scratch, nact, law, rr, known, axes)
        if mt.kind != STILL:  # the formation marches
            march(src, u, nact, k, mt, acc)
        if obs is not None:  # obstacles' repulsion and the filter, trial by trial
            pause = False
            for b in range(nact):
                given_u = st.given_u[c, b] if flt.kind == CENTRALIZED else st.given_u[0, 0]
                answer = filter_command(src, u, b, radius, obs, flt, st.given[c, b], given_u, S)
                md[b] = min(md[b], S.least[0])  # (x is accepted: the filter's pairs at it)
                if answer == WAIT:  # the host solves this trial's QP
                    st.need[c, b] = True
                    for i in range(n):
                        st.need_p[c, b, i, 0] = S.pq[i, 0]
                        st.need_p[c, b, i, 1] = S.pq[i, 1]
                        st.need_u[c, b, i, 0] = S.uq[i, 0]
                        st.need_u[c, b, i, 1] = S.uq[i, 1]
                    pause = True
                st.given[c, b] = False
            if pause:  # the step is computed again, with the QPs' answers, when resumed
                _pause(st, c, nact, step, kc, PAUSED)
                return
        if not same:
            rates(x, hc, hs, u, f, scratch, nact, model, axes)
        if sn is not None:  # robots stopped by a fault
            halt(f, k * dt, sn, nact)
        if k == run.window_step:  # start of the drift window (the driver's q_window)
            for b in range(nact):
                for i in range(n):
                    for d in range(dim):
                        out.qw[ids[b], i, d] = x[i, d, b]
        # (code[b] is -1 for every live trial here: compaction keeps it so)
        ended = 0  # trials that end at this step
        checked = run.check_every > 0 and (k % run.check_every == 0 or k == run.n_steps)
        if checked:  # the stop rule
            for b in range(nact):
                gap[b] = 0.0  # (here: the largest squared move since the previous check)
            if kc >= 0:
                for i in range(n):
                    for b in range(nact):
                        dx = x[i, 0, b] - qc[i, 0, b]
                        dy = x[i, 1, b] - qc[i, 1, b]
                        if dim == 3:
                            dz = x[i, 2, b] - qc[i, 2, b]
                            gap[b] = max(gap[b], dx * dx + dy * dy + dz * dz)
                        else:
                            gap[b] = max(gap[b], dx * dx + dy * dy)
            for b in range(nact):
                nan = False
                for i in range(n):
                    for d in range(kk):
                        nan = nan or f[i, d, b] != f[i, d, b]
                still = (not nan) and speed(f, b, model, axes) <= run.speed
                if kc >= 0:
                    net = math.sqrt(gap[b]) / ((k - kc) * dt)
                    ns[b] = net
                    if k - kc >= NET_STEPS:  # (the driver's rule)
                        still = still or net <= run.speed
                if sn is not None and sn.measured:  # robots waiting for a measurement
                    seen = informed(ids[b], law, ss)
                    still = still and seen and ss.seen_c[ids[b]]
                    ss.seen_c[ids[b]] = seen
                if still:
                    code[b] = CONVERGED
                    ended += 1
        if k == run.n_steps:
            for b in range(nact):
                if code[b] < 0:
                    code[b] = END
            ended = nact
        else:  # explicit Euler, judged by the contact rule (System.step_verdict)
            for b in range(nact):
                fin[b] = 0.0
                disp[b] = 0.0
            if lists is not None:
                list_step(x, f, xn, dt, ls, disp, fin, par, axes)
            else:
                euler(x, f, xn, dt, 0, n, nact, disp, fin, axes)
            for b in range(nact):
                disp[b] = math.sqrt(disp[b])
            if law is not None:
                contact(xn, x, disp, gap, swept, near, nact, law, rr, axes)
                known = not hand  # (the law acts on the centres, whose lengths these are)
            if lists is not None and fin[0] == 0.0:  # (not finite: judged before the list)
                room, gap[0], swept[0] = list_contact(xn, x, disp[0], ls, lay, par, axes)
                if not room:  # the step is taken again, with room for the list
                    _pause(st, c, nact, step, kc, GROW)
                    return
            bad = 0  # trials whose step is not finite or ends in or passes through contact
            if obs is None and ended == 0:  # (the common case, as one vectorised loop)
                for b in range(nact):
                    ok = (gap[b] > 0.0) & (swept[b] > 0.0) & (fin[b] == 0.0)
                    bad += 0 if ok else 1
                    mc[b] = min(mc[b], gap[b]) if ok else mc[b]
            for b in range(nact if obs is not None or ended > 0 or bad > 0 else 0):
                if code[b] >= 0:
                    continue
                ended += 1
                end = np.inf  # the least robot-obstacle clearance at xn
                if fin[b] == 0.0 and obs is not None:  # the obstacles' clearances join in
                    if obs.radius.shape[0] > 0:
                        reach = SWEPT_MARGIN * disp[b]
                        end, sw = obstacle_contact(obs, radius, x, xn, b, reach, mo[b])
                        swept[b] = min(swept[b], sw)
                # (the step's verdict, in one place)
                said = verdict(fin[b], min(gap[b], end), swept[b])
                if said != 0:
                    code[b] = said
                else:
                    ended -= 1
                    mo[b] = min(mo[b], end)
                    if bad == 0:  # (else the vectorised loop above took it)
                        mc[b] = min(mc[b], gap[b])
            if turns:  # the headings of the next states
                turn(xn, x, hc, hs, hcl, hsl, wide, nact)
        if checked:  # (after the verdict: a chunk paused before here takes the step again)
            for i in range(n):
                for d in range(dim):
                    for b in range(nact):
                        qc[i, d, b] = x[i, d, b]
            kc = k
        # trials that end here end at x (a rejected step is not taken), with the rates f
        for b in range(nact if saves or ended > 0 else 0):
            if saves and (code[b] >= 0 or k % sv.every == 0):
                save(sv, x, f, b, ids[b], k)
            if code[b] >= 0:
                g = ids[b]
                if not saves:  # (with saving, the last saved row is this state)
                    for i in range(n):
                        for d in range(kk):
                            out.x[g, i, d] = x[i, d, b]
                            out.v[g, i, d] = f[i, d, b]
                out.steps[g] = k
                out.status[g] = code[b]
                out.mc[g] = mc[b]
                out.mo[g] = mo[b]
                out.md[g] = md[b]
                out.ns[g] = ns[b]
        x, xn = xn, x  # the live trials' next states are current now
        st.meta[c, 3] = 1 - st.meta[c, 3]
        for b in range(nact - 1 if ended > 0 else -1, -1, -1):  # compact the live range
            if code[b] < 0:
                continue
            last = nact - 1
            if b != last:  # the trial at `last` is running (visited already)
                for i in range(n):
                    for d in range(kk):
                        x[i, d, b] = x[i, d, last]
                    for d in range(dim):
                        qc[i, d, b] = qc[i, d, last]
                    if turns:
                        hc[i, b] = hc[i, last]
                        hs[i, b] = hs[i, last]
                        hcl[i, b] = hcl[i, last]
                        hsl[i, b] = hsl[i, last]
                if law is not None:
                    for e in range(rr.shape[0]):
                        rr[e, b] = rr[e, last]
                ids[b] = ids[last]
                mc[b] = mc[last]
                mo[b] = mo[last]
                md[b] = md[last]
                ns[b] = ns[last]
                code[b] = code[last]
            nact -= 1
        step += 1
    st.meta[c, 0] = 0
    st.meta[c, 4] = DONE


def robot_radii(law, lists):
    """The robots' radii: the law's (its pairs layout) or the lists layout's."""
    raise NotImplementedError  # (numba's: the overload below, chosen by the arguments' types)


@overload(robot_radii, inline="always")
def _robot_radii(law, lists):
    if isinstance(law, types.NoneType):  # (a None argument: the lists layout)
        return lambda law, lists: lists[0].radius
    return lambda law, lists: law.radius


@njit(cache=True, error_model="numpy", nogil=True, inline="always")
def _pause(st, c, nact, step, kc, status):
    """Chunk ``c`` stops at ``step`` (not taken yet) with ``status``; it goes on from there."""
    st.meta[c, 0] = nact
    st.meta[c, 1] = step
    st.meta[c, 2] = kc
    st.meta[c, 4] = status


def run_chunks(law, model, mt, obs, flt, sn, ss, st, out, run, sv) -> None:
    """Every running chunk until it ends, pauses or reaches ``run.k_end``, on numba's
    number of threads (:func:`numba.get_num_threads`).

    Each chunk is one call of :func:`step_chunk`, which releases the GIL, from a pool of
    Python threads: the chunks share nothing they write (each its own slots of ``st``, its
    own trials' rows of ``out`` and of the sensing state), so they run side by side. It is
    the same compiled version of the loop as a batch of one chunk's (a ``prange`` loop
    around it would be compiled apart, with the loop inside it compiled twice more: about
    half a minute per variant of the loop), and the threads take the next chunk as they
    finish one, so that chunks whose trials stop early do not leave a thread idle.
    """
    todo = [
        c for c in range(st.x.shape[0])
        if st.meta[c, 4] == RUNNING and st.meta[c, 1] < run.k_end
    ]  # fmt: skip
    threads = min(numba.get_num_threads(), len(todo))
    if threads <= 1:
        for c in todo:
            step_chunk(c, law, model, mt, obs, flt, sn, ss, st, out, run, None, sv)
        return
    with ThreadPoolExecutor(threads) as pool:
        done = [
            pool.submit(step_chunk, c, law, model, mt, obs, flt, sn, ss, st, out, run, None, sv)
            for c in todo
        ]
        for d in done:  # (an error in a chunk is raised here)
            d.result()
