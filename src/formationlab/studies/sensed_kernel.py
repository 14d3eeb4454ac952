"""Numba kernel of sensed batches: single integrators under explicit Euler, robots that sense.

The compiled twin of the stepping driver (:func:`formationlab.integrators.drive`) with a
measurement channel (:class:`formationlab.sensing.Channel`) and faults, for the studies'
setting: single integrators, explicit Euler, no obstacles, no safety filter. Per step
``k`` of each trial, as the driver does it:

1. every robot ``i`` measures ``z_ij = R(-a_i) (p_j - p_i) + noise`` of every robot
   (zero on the diagonal), and whether ``j`` is within ``range`` now;
2. the measurement it uses is the one taken at ``k - m`` (``m = delay / dt``; nothing
   has arrived for ``k < m``), from a ring of ``m + 1`` slots; a delivered measurement
   lost with probability ``drop`` leaves the last one received in place (``has`` stays
   set), one out of range clears it;
3. robot ``i``'s command is :func:`formationlab.sensing.local_controls` of its own
   measurements (its own desired distances under ``mismatch``; terms that need an
   unseen robot left out), rotated back with its frame ``R(a_i)``, limited to the
   robot's ``max_speed``; the rows of robots stopped by ``t = k dt`` are zero;
4. the stop rule (instantaneous or net speed, :class:`~formationlab.integrators.StopRule`)
   counts only while every robot sees all its neighbours, at this check and at the
   previous one (:meth:`Channel.informed`); then the Euler step and the contact rule
   of :mod:`formationlab.engine.contact` (not finite, contact at the end, contact along the step).

The terms are added in the order ``local_controls`` adds them, and the frames' sines
and cosines are numpy's, so a trial follows the driver's arithmetic step for step.

Randomness stays the channel's: the frames and mismatch of each trial come from its
seed at creation, and the noise and losses are drawn by :meth:`Channel.block`, per
trial and per block of :data:`~formationlab.sensing.BLOCK` steps, in numpy, before the
kernel steps that block. A trial's run therefore depends on its seed only, not on the
batch it is in. Trials run in parallel (``prange``), each one step after the other; a
trial's state (positions, delay ring, held measurements) lives in arrays that persist
from one block to the next.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from ..analysis import Tolerances
from ..controllers import Law
from ..controllers.kinds.edges import edge_gain
from ..controllers.kinds.khatib import repulsion_gain
from ..controllers.kinds.restriction import (
    restriction_force,
    switched_on,
    switching,
    triangle_product,
)
from ..controllers.kinds.signed_area import area_force, area_gain, signed_area
from ..dynamics import System
from ..engine.contact import (
    COLLISION,
    CONVERGED,
    END,
    NON_FINITE,
    SWEPT_MARGIN,
    TOO_LARGE,
    segment_clearance,
)
from ..models import SingleIntegrator
from ..sensing import BLOCK, Channel, Faults, Seed, Sensing
from ..spec import Formation

__all__ = ["run_sensed"]

#: bytes of per-trial arrays (noise and loss blocks, delay ring) a group of trials may hold
GROUP_BYTES = 64 * 2**20


class ChannelTerms(NamedTuple):
    """A group's sensing and faults as plain arrays and numbers (``G`` trials, ``n`` robots)."""

    local: bool  #: robots measure in their own frames
    cos_in: NDArray[np.float64]  #: cos(-a_i), (G, n)
    sin_in: NDArray[np.float64]  #: sin(-a_i)
    cos_out: NDArray[np.float64]  #: cos(a_i)
    sin_out: NDArray[np.float64]  #: sin(a_i)
    own_distance: NDArray[np.float64]  #: (G, E, 2): d_ij as robots edge_i, edge_j hold it
    noise: float
    drop: float
    ranged: bool
    range2: float  #: range**2
    stop_at: NDArray[np.float64]  #: (n,): when each robot stops (inf: never)
    noise_block: NDArray[np.float64]  #: (G, BLOCK, n, n, 2) standard normals of this block
    drop_block: NDArray[np.float64]  #: (G, BLOCK, n, n) uniforms of this block


class TrialState(NamedTuple):
    """What a trial carries from one step to the next (``M = m + 1`` ring slots)."""

    x: NDArray[np.float64]  #: (G, n, 2) positions now
    ring_z: NDArray[np.float64]  #: (G, M, n, n, 2) measurements taken at the last M steps
    ring_in: NDArray[np.bool_]  #: (G, M, n, n) whether in range when taken
    held: NDArray[np.float64]  #: (G, n, n, 2) the measurement each robot uses
    has: NDArray[np.bool_]  #: (G, n, n) whether it has one
    qc: NDArray[np.float64]  #: (G, n, 2) positions at the previous check
    kc: NDArray[np.int64]  #: (G,) step of the previous check (-1: none)
    seen_c: NDArray[np.bool_]  #: (G,) whether every robot saw its neighbours then
    mc: NDArray[np.float64]  #: (G,) least clearance over accepted states
    ns: NDArray[np.float64]  #: (G,) net speed over the last check interval
    code: NDArray[np.int8]  #: (G,) -1 while running, else the Status code


class Outputs(NamedTuple):
    x: NDArray[np.float64]  #: (G, n, 2) final states
    v: NDArray[np.float64]  #: (G, n, 2) their velocities
    steps: NDArray[np.int64]  #: (G,)
    qw: NDArray[np.float64]  #: (G, n, 2) positions at the start of the drift window


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _measure(x, ring_z, ring_in, slot, cos_in, sin_in, noise, row, ch):
    """Step 1: ``ring_z[slot, i, j] = R(-a_i) (p_j - p_i) + noise``, ``ring_in`` within range.

    (One trial's arrays; views are taken once per block, not per step: each costs
    reference counting.)
    """
    n = x.shape[0]
    for i in range(n):
        for j in range(n):
            dx = x[j, 0] - x[i, 0]
            dy = x[j, 1] - x[i, 1]
            zx, zy = dx, dy
            if ch.local:
                c = cos_in[i]
                s = sin_in[i]
                zx = c * dx - s * dy
                zy = s * dx + c * dy
            if ch.noise > 0:
                wx = 0.0 if i == j else noise[row, i, j, 0]
                wy = 0.0 if i == j else noise[row, i, j, 1]
                zx = zx + ch.noise * wx
                zy = zy + ch.noise * wy
            ring_z[slot, i, j, 0] = zx
            ring_z[slot, i, j, 1] = zy
            ring_in[slot, i, j] = (dx * dx + dy * dy <= ch.range2) if ch.ranged else True


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _deliver(k, ring_z, ring_in, held, has, lost, row, ch):
    """Step 2: what arrives at ``k`` (taken at ``k - m``), with losses and held measurements."""
    n = held.shape[0]
    slots = ring_z.shape[0]
    m = slots - 1
    if k < m:  # nothing has arrived yet
        for i in range(n):
            for j in range(n):
                has[i, j] = False
        return
    back = (k - m) % slots
    for i in range(n):
        for j in range(n):
            if not ring_in[back, i, j]:
                has[i, j] = False  # out of range when taken: not seen, nothing held
            elif ch.drop > 0 and i != j and lost[row, i, j] < ch.drop:
                pass  # lost: the last one received (if any) is kept
            else:
                held[i, j, 0] = ring_z[back, i, j, 0]
                held[i, j, 1] = ring_z[back, i, j, 1]
                has[i, j] = True


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _commands(z, seen, own, t, u):
    """Step 3: ``u_i`` in robot ``i``'s frame (``local_controls``, terms in its order)."""
    n = u.shape[0]
    for i in range(n):
        u[i, 0] = 0.0
        u[i, 1] = 0.0
    for side in range(2):  # each edge from each end, with that robot's own d_ij
        for e in range(t.edge_i.shape[0]):
            obs = t.edge_i[e] if side == 0 else t.edge_j[e]
            tgt = t.edge_j[e] if side == 0 else t.edge_i[e]
            if not seen[obs, tgt]:
                continue
            vx = z[obs, tgt, 0]
            vy = z[obs, tgt, 1]
            g = edge_gain(t.kind, vx * vx + vy * vy, own[e, side], t.edge_contact[e], t.edge_gain)
            u[obs, 0] += g * vx
            u[obs, 1] += g * vy
    if t.repulsion_gain != 0:  # Khatib's repulsion between non-neighbours, each from its end
        for side in range(2):
            for p in range(t.pair_i.shape[0]):
                if t.pair_is_edge[p]:
                    continue
                obs = t.pair_i[p] if side == 0 else t.pair_j[p]
                tgt = t.pair_j[p] if side == 0 else t.pair_i[p]
                if not seen[obs, tgt]:
                    continue
                vx = z[obs, tgt, 0]
                vy = z[obs, tgt, 1]
                r = math.sqrt(vx * vx + vy * vy)
                g = repulsion_gain(
                    r, r - t.pair_contact[p], t.repulsion_gain, t.repulsion_eta,
                    t.repulsion_influence,
                )  # fmt: skip
                u[obs, 0] += g * vx
                u[obs, 1] += g * vy
    for v in range(t.term_i.shape[0]):  # eqs. (11), (13), (14), (23), from robot i's view
        i = t.term_i[v]
        j = t.term_j[v]
        k = t.term_k[v]
        if not (seen[i, j] and seen[i, k]):
            continue
        sf = t.term_surface[v]
        ia = t.surface_a[sf]
        ib = t.surface_b[sf]
        ic = t.surface_c[sf]
        cab = triangle_product(z[i, ia, 0], z[i, ia, 1], z[i, ib, 0], z[i, ib, 1], z[i, ic, 0],
                               z[i, ic, 1])  # fmt: skip
        on = switched_on(switching(t.surface_beta[sf], cab, t.theta))  # eq. (14)
        fx, fy = restriction_force(
            t.term_weight[v] * on, z[i, k, 0] - z[i, j, 0], z[i, k, 1] - z[i, j, 1]
        )  # eq. (23)
        u[i, 0] += fx
        u[i, 1] += fy
    for rot in range(3):  # signed-area penalty, grad_a A_abc = 1/2 k x r_bc, per vertex
        for m in range(t.area_a.shape[0]):
            a0, a1, a2 = t.area_a[m], t.area_b[m], t.area_c[m]
            if rot == 1:
                a0, a1, a2 = a1, a2, a0
            elif rot == 2:
                a0, a1, a2 = a2, a0, a1
            if not (seen[a0, a1] and seen[a0, a2]):
                continue
            p1x, p1y = z[a0, a1, 0], z[a0, a1, 1]
            p2x, p2y = z[a0, a2, 0], z[a0, a2, 1]
            area = signed_area(0.0, 0.0, p1x, p1y, p2x, p2y)  # the vertex at 0
            fx, fy = area_force(area_gain(area, t.area_target[m], t.area_gain), p1x, p1y, p2x, p2y)
            u[a0, 0] += fx
            u[a0, 1] += fy


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _trial(b, k0, k1, t, ch, st, out, dt, n_steps, check_every, speed, window_step, vmax):
    """Steps ``k0 <= k < k1`` of trial ``b`` (module docstring), until it ends."""
    x = st.x[b]
    held = st.held[b]
    has = st.has[b]
    ring_z = st.ring_z[b]
    ring_in = st.ring_in[b]
    own = ch.own_distance[b]
    cos_in = ch.cos_in[b]
    sin_in = ch.sin_in[b]
    noise = ch.noise_block[b]
    lost = ch.drop_block[b]
    n = x.shape[0]
    slots = ring_z.shape[0]
    u = np.empty((n, 2))
    f = np.empty((n, 2))
    xn = np.empty((n, 2))
    for k in range(k0, k1):
        row = k % BLOCK
        slot = k % slots
        _measure(x, ring_z, ring_in, slot, cos_in, sin_in, noise, row, ch)
        _deliver(k, ring_z, ring_in, held, has, lost, row, ch)
        _commands(held, has, own, t, u)
        tk = k * dt
        for i in range(n):
            ux = u[i, 0]
            uy = u[i, 1]
            if ch.local:  # back to the common frame, R(a_i) u_i
                c = ch.cos_out[b, i]
                s = ch.sin_out[b, i]
                ux, uy = c * ux - s * uy, s * ux + c * uy
            size = math.sqrt(ux * ux + uy * uy)
            scale = vmax / size if size > vmax else 1.0  # limit_speed
            f[i, 0] = ux * scale
            f[i, 1] = uy * scale
            if tk >= ch.stop_at[i]:  # a robot that has stopped
                f[i, 0] = 0.0
                f[i, 1] = 0.0
        if k == window_step:  # start of the drift window (the driver's q_window)
            for i in range(n):
                out.qw[b, i, 0] = x[i, 0]
                out.qw[b, i, 1] = x[i, 1]
        code = -1
        if k % check_every == 0 or k == n_steps:  # StopRule, only while informed
            top = 0.0
            nan = False
            for i in range(n):
                sp = math.sqrt(f[i, 0] * f[i, 0] + f[i, 1] * f[i, 1])
                nan = nan or sp != sp
                top = max(top, sp)
            still = (not nan) and top <= speed
            kc = st.kc[b]
            if kc >= 0:
                dd = 0.0
                for i in range(n):
                    dx = x[i, 0] - st.qc[b, i, 0]
                    dy = x[i, 1] - st.qc[b, i, 1]
                    dd = max(dd, dx * dx + dy * dy)
                net = math.sqrt(dd) / ((k - kc) * dt)
                st.ns[b] = net
                still = still or net <= speed
            informed = True  # every robot sees all its neighbours (Channel.informed)
            for e in range(t.edge_i.shape[0]):
                i = t.edge_i[e]
                j = t.edge_j[e]
                informed = informed and has[i, j] and has[j, i]
            still = still and informed and st.seen_c[b]
            st.seen_c[b] = informed
            for i in range(n):
                st.qc[b, i, 0] = x[i, 0]
                st.qc[b, i, 1] = x[i, 1]
            st.kc[b] = k
            if still:
                code = CONVERGED
        if code < 0 and k == n_steps:
            code = END
        if code < 0:  # explicit Euler, judged by the contact rule (System.step_verdict)
            finite = True
            disp = 0.0
            for i in range(n):
                nx = x[i, 0] + dt * f[i, 0]
                ny = x[i, 1] + dt * f[i, 1]
                xn[i, 0] = nx
                xn[i, 1] = ny
                finite = finite and math.isfinite(nx) and math.isfinite(ny)
                ex = nx - x[i, 0]
                ey = ny - x[i, 1]
                disp = max(disp, ex * ex + ey * ey)
            disp = math.sqrt(disp)
            gap = np.inf
            swept = np.inf
            if finite:
                for p in range(t.pair_i.shape[0]):
                    i = t.pair_i[p]
                    j = t.pair_j[p]
                    a = t.pair_contact[p]
                    dx = xn[j, 0] - xn[i, 0]
                    dy = xn[j, 1] - xn[i, 1]
                    clr = math.sqrt(dx * dx + dy * dy) - a
                    gap = min(gap, clr)
                    if clr <= SWEPT_MARGIN * disp:
                        x0 = x[j, 0] - x[i, 0]
                        y0 = x[j, 1] - x[i, 1]
                        swept = min(swept, segment_clearance(x0, y0, dx - x0, dy - y0, a))
            if not finite:
                code = NON_FINITE
            elif not gap > 0.0:
                code = COLLISION
            elif not swept > 0.0:
                code = TOO_LARGE
            else:
                st.mc[b] = min(st.mc[b], gap)
                for i in range(n):
                    x[i, 0] = xn[i, 0]
                    x[i, 1] = xn[i, 1]
                continue
        # the trial ends at x_k (a rejected step is not taken), with the velocity f
        for i in range(n):
            out.x[b, i, 0] = x[i, 0]
            out.x[b, i, 1] = x[i, 1]
            out.v[b, i, 0] = f[i, 0]
            out.v[b, i, 1] = f[i, 1]
        out.steps[b] = k
        st.code[b] = code
        return


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, parallel=True)
def run_block(k0, k1, terms, ch, st, out, dt, n_steps, check_every, speed, window_step, vmax):
    """Steps ``k0 <= k < k1`` of every running trial of a group, in parallel over trials."""
    for b in prange(st.x.shape[0]):
        if st.code[b] < 0:
            _trial(b, k0, k1, terms, ch, st, out, dt, n_steps, check_every, speed,
                   window_step, vmax)  # fmt: skip


def run_sensed(
    formation: Formation,
    law: Law,
    model: SingleIntegrator,
    q0: NDArray[np.float64],
    dt: float,
    n_steps: int,
    check_every: int,
    tol: Tolerances,
    sensing: Sensing | None,
    faults: Faults | None,
    seeds: Sequence[Seed] | None,
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray, NDArray, NDArray, int]:
    """Step the sensed trials ``q0`` ``(B, n, 2)``; what ``batch._run_numba`` returns.

    ``(x, v, status, steps, min_clearance, net_speed, q_window, window_step)``, trial by
    trial those of the stepping driver with a :class:`StopRule` (module docstring).
    """
    sensing = sensing if sensing is not None else Sensing()
    faults = faults if faults is not None else Faults()
    B, n, _ = q0.shape
    seeds = list(seeds) if seeds is not None else [sensing.seed] * B
    channel = Channel(sensing, formation, law, model, seeds, dt)  # frames, mismatch, draws
    terms, m = channel.terms.writable(), channel.m  # one signature for every law
    E = terms.edge_i.size
    noisy, lossy = sensing.noise > 0, sensing.drop > 0
    per_trial = 8 * n * n * (BLOCK * (2 * noisy + lossy) + 3 * (m + 1) + 3)
    group = int(min(B, max(64, GROUP_BYTES // per_trial)))
    stop_at = np.full(n, np.inf)
    for s in faults.stop:
        stop_at[s.robot - 1] = s.at
    window_step = n_steps - tol.drift_steps(dt)  # negative: never reached
    x_out, v_out = np.empty((B, n, 2)), np.full((B, n, 2), np.nan)
    steps = np.zeros(B, dtype=np.int64)
    status = np.zeros(B, dtype=np.int8)
    mc = System(formation=formation, law=law).clearance(q0)  # as the driver starts it
    ns = np.full(B, np.nan)
    qw = np.full((B, n, 2), np.nan)
    local = channel.fixed_angles is not None
    vmax = math.inf if model.max_speed is None else float(model.max_speed)
    for g0 in range(0, B, group):
        ids = np.arange(g0, min(B, g0 + group))
        G = ids.size
        a = channel.fixed_angles[ids] if channel.fixed_angles is not None else np.zeros((G, n))
        own = (
            channel.own_distance[ids]
            if channel.own_distance is not None
            else np.broadcast_to(terms.edge_distance[None, :, None], (G, E, 2)).copy()
        )
        noise = np.zeros((G, BLOCK, n, n, 2) if noisy else (G, 1, 1, 1, 2))  # (unused)
        drop = np.zeros((G, BLOCK, n, n) if lossy else (G, 1, 1, 1))
        st = TrialState(
            x=q0[ids].copy(), ring_z=np.zeros((G, m + 1, n, n, 2)),
            ring_in=np.zeros((G, m + 1, n, n), dtype=bool), held=np.zeros((G, n, n, 2)),
            has=np.zeros((G, n, n), dtype=bool), qc=q0[ids].copy(),
            kc=np.full(G, -1, dtype=np.int64), seen_c=np.ones(G, dtype=bool), mc=mc[ids].copy(),
            ns=np.full(G, np.nan), code=np.full(G, -1, dtype=np.int8),
        )  # fmt: skip
        out = Outputs(x=x_out[g0 : g0 + G], v=v_out[g0 : g0 + G], steps=steps[g0 : g0 + G],
                      qw=qw[g0 : g0 + G])  # fmt: skip
        ch = ChannelTerms(
            local=local, cos_in=np.cos(-a), sin_in=np.sin(-a), cos_out=np.cos(a),
            sin_out=np.sin(a), own_distance=own, noise=float(sensing.noise),
            drop=float(sensing.drop), ranged=not math.isinf(sensing.range),
            range2=float(sensing.range**2), stop_at=stop_at, noise_block=noise, drop_block=drop,
        )  # fmt: skip
        blocks = -(-(n_steps + 1) // BLOCK) if noisy or lossy else 1
        for blk in range(blocks):
            live = np.flatnonzero(st.code < 0)
            if live.size == 0:
                break
            if noisy:  # this block's draws, from each trial's own generator (Channel.block)
                noise[live] = channel.block("noise", ids[live])
            if lossy:
                drop[live] = channel.block("drop", ids[live])
            k0 = blk * BLOCK
            k1 = min(k0 + BLOCK, n_steps + 1) if noisy or lossy else n_steps + 1
            run_block(k0, k1, terms, ch, st, out, float(dt), int(n_steps), int(check_every),
                      float(tol.speed), int(window_step), vmax)  # fmt: skip
        status[g0 : g0 + G] = st.code
        ns[g0 : g0 + G] = st.ns
        mc[g0 : g0 + G] = st.mc
    return x_out, v_out, status, steps, mc, ns, qw, window_step
