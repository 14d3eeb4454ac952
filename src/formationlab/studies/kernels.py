"""Numba kernels of the batched Euler stepping (the numpy specification is the stepping driver).

Layout: every chunk of trials keeps its states as ``(n, k, C)`` (``k`` numbers
per robot, positions first, as the robot model's state) with the trials on the
innermost, contiguous axis, so that each loop over trials is a plain SIMD loop.
Chunks run in parallel (``prange``); inside a chunk, trials that stop are
swapped out of the live range (compaction), so that early stopping saves work
instead of masking it.

The law enters as a :class:`~formationlab.controllers.terms.KernelTerms`, the
named arrays and numbers each law builds (``Law.kernel_terms``), so one
compiled kernel serves every law and formation. Each pair contributes
``u_i += g (q_j - q_i)``, ``u_j -= g (q_j - q_i)``: ``g = k_c phi'(r) / r``
(eq. 8), ``g = k (r^2 - d^2)`` (squared distance) or ``g = k_r gamma'(r - a) / r``
(repulsion). Each switching surface is decided with the arithmetic of
:func:`formationlab.potentials.triangle_products` and
``beta_s c_abc + theta``, so the kernel switches exactly where the numpy law
does; elsewhere trajectories agree with :func:`formationlab.simulate` to rounding.

The robot model enters as a :class:`~formationlab.studies.model_terms.ModelTerms`
(single integrators, unicycles through either transform, double integrators,
each with its limits): :func:`_points` gives the points the law acts on,
:func:`_rates` the state's rate from the law's control (``RobotModel.derivative``),
:func:`_speed` the stop rule's speed (``RobotModel.speed``). No loop over trials calls
the C library in a unicycle's step (a call, or a branch that calls, keeps a loop from
being vectorised; :mod:`.kernel_trig`): each unicycle's ``cos theta`` and ``sin theta``
are taken from the library once, at the start, and then carried from step to step
(:func:`_turn`), turned by each Euler step's angle with a short series and an exact sum
(the library again only for a turn above ``SMALL_TURN`` in one step), and the heading
transform's ``atan2`` is a branch-free rational approximation; both are within about an
ulp of the library's values, so the trials still agree with the driver to rounding. So
the law's loops (:func:`_controls`) compute the control only, and contact is decided
apart, on the centres, for every model (:func:`_contact`; near-identity unicycles' law
acts on the hand points).

The step rule is the one of :meth:`formationlab.dynamics.System.step_verdict`:
a step is rejected when it is not finite, when it ends with a pair in contact
(``Status.COLLISION``) or when the straight path of the step passes through
contact (``Status.STEP_TOO_LARGE``). The swept test is computed only for pairs
whose end clearance is below twice the largest displacement of the step
(farther pairs cannot have met during it).

What a trial-step costs, per model: ``benchmarks/bench_models.py`` and
docs/robot-models.md. Whether the compiler vectorises a loop is measured, not assumed:
the unicycle's loops were not vectorised while they read and wrote the rows of one
``(n, 4, C)`` array or stored a heavy computation into three rows of ``f``; so the
carried headings are four arrays and a unicycle's rates take three short passes.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..controllers.kinds.edges import edge_gain
from ..controllers.kinds.khatib import repulsion_gain
from ..controllers.kinds.restriction import (
    restriction_force,
    switched_on,
    switching,
    triangle_product,
)
from ..controllers.kinds.signed_area import area_force, area_gain, signed_area
from ..status import Status
from .kernel_trig import SMALL_TURN, atan2_poly, turn_small
from .model_terms import DOUBLE, HEADING, NEAR_IDENTITY, SINGLE

__all__ = ["run_chunks"]

_END = Status.SUCCESS.code
_CONVERGED = Status.CONVERGED.code
_COLLISION = Status.COLLISION.code
_TOO_LARGE = Status.STEP_TOO_LARGE.code
_NON_FINITE = Status.NON_FINITE.code
#: pairs closer than this many times the largest displacement of a step get the swept test
_SWEPT_MARGIN = 2.01


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def segment_clearance(x0, y0, ex, ey, a):
    """Least ``|(x0, y0) + s (ex, ey)| - a`` over ``s`` in ``[0, 1]``.

    A pair's clearance along a straight step: ``(x0, y0) = q_j - q_i`` at its start,
    ``(ex, ey)`` the change of ``q_j - q_i`` over the step, ``a = a_ij``.
    """
    dd = ex * ex + ey * ey
    s = min(max(-(x0 * ex + y0 * ey) / (dd if dd > 0 else 1.0), 0.0), 1.0)
    mx = x0 + s * ex
    my = y0 + s * ey
    return math.sqrt(mx * mx + my * my) - a


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _swept(q, qp, i, j, b, a):
    """Least ``r_ij - a_ij`` along the straight step ``qp -> q`` (``System.swept_clearance``)."""
    x0 = qp[j, 0, b] - qp[i, 0, b]
    y0 = qp[j, 1, b] - qp[i, 1, b]
    ex = (q[j, 0, b] - q[i, 0, b]) - x0
    ey = (q[j, 1, b] - q[i, 1, b]) - y0
    return segment_clearance(x0, y0, ex, ey, a)


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _controls(q, u, sigma, nact, terms):
    """``u = f(q)`` for the first ``nact`` trials of a chunk.

    Plain arithmetic, no branch that calls: every loop over trials is vectorised
    (:func:`_contact` decides contact, in loops of its own).
    """
    t = terms
    n = q.shape[0]
    for i in range(n):
        for b in range(nact):
            u[i, 0, b] = 0.0
            u[i, 1, b] = 0.0
    s0 = t.repulsion_influence
    # (arrays are indexed directly, without views: a view costs reference counting; one
    # loop over trials per kind of pair, so that each is a plain loop)
    for p in range(t.pair_i.shape[0]):
        i = t.pair_i[p]
        j = t.pair_j[p]
        a = t.pair_contact[p]
        if t.pair_is_edge[p]:
            d = t.pair_distance[p]
            for b in range(nact):
                dx = q[j, 0, b] - q[i, 0, b]
                dy = q[j, 1, b] - q[i, 1, b]
                g = edge_gain(t.kind, dx * dx + dy * dy, d, a, t.edge_gain)  # eq. (8)
                u[i, 0, b] += g * dx
                u[i, 1, b] += g * dy
                u[j, 0, b] -= g * dx
                u[j, 1, b] -= g * dy
        else:
            for b in range(nact):
                dx = q[j, 0, b] - q[i, 0, b]
                dy = q[j, 1, b] - q[i, 1, b]
                r = math.sqrt(dx * dx + dy * dy)
                g = repulsion_gain(r, r - a, t.repulsion_gain, t.repulsion_eta, s0)  # Khatib
                u[i, 0, b] += g * dx
                u[i, 1, b] += g * dy
                u[j, 0, b] -= g * dx
                u[j, 1, b] -= g * dy
    # eqs. (11), (13), (14), (23): per switching surface sigma = beta c_abc + theta; each
    # term (i, j, k) of the surface adds -w Upsilon(sigma) k x r_jk to u_i,
    # w = 2 k_a alpha_ijk (eq. 13's pairs (j, k), (k, j))
    for sf in range(t.surface_a.shape[0]):
        ia = t.surface_a[sf]
        ib = t.surface_b[sf]
        ic = t.surface_c[sf]
        beta = t.surface_beta[sf]
        for b in range(nact):
            cab = triangle_product(
                q[ia, 0, b], q[ia, 1, b], q[ib, 0, b], q[ib, 1, b], q[ic, 0, b], q[ic, 1, b]
            )
            sigma[b] = switched_on(switching(beta, cab, t.theta))  # eq. (14)
        for v in range(t.term_start[sf], t.term_start[sf + 1]):
            i = t.term_i[v]
            j = t.term_j[v]
            k = t.term_k[v]
            w0 = t.term_weight[v]
            for b in range(nact):
                fx, fy = restriction_force(
                    w0 * sigma[b], q[k, 0, b] - q[j, 0, b], q[k, 1, b] - q[j, 1, b]
                )  # eq. (23)
                u[i, 0, b] += fx
                u[i, 1, b] += fy
    for m in range(t.area_a.shape[0]):  # signed-area penalty, grad_a A_abc = 1/2 k x r_bc
        ia = t.area_a[m]
        ib = t.area_b[m]
        ic = t.area_c[m]
        target = t.area_target[m]
        for b in range(nact):
            xa, ya = q[ia, 0, b], q[ia, 1, b]
            xb, yb = q[ib, 0, b], q[ib, 1, b]
            xc, yc = q[ic, 0, b], q[ic, 1, b]
            g = area_gain(signed_area(xa, ya, xb, yb, xc, yc), target, t.area_gain)
            fx, fy = area_force(g, xb, yb, xc, yc)
            u[ia, 0, b] += fx
            u[ia, 1, b] += fy
            fx, fy = area_force(g, xc, yc, xa, ya)
            u[ib, 0, b] += fx
            u[ib, 1, b] += fy
            fx, fy = area_force(g, xa, ya, xb, yb)
            u[ic, 0, b] += fx
            u[ic, 1, b] += fy


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _contact(x, xp, disp, gap, swept, near, nact, terms):
    """Clearances of the centres ``x`` for the step rule (``System.step_verdict``).

    ``gap``: least ``r_ij - a_ij`` at ``x``; ``swept``: least clearance along the
    straight step from ``xp`` to ``x`` of the pairs within ``_SWEPT_MARGIN disp``
    (``disp`` is each trial's largest displacement, 0 before the first step). Two
    passes: every trial's least clearance, flagging in ``near`` the trials with such a
    pair (plain arithmetic, vectorised); then the swept test of those pairs of the
    flagged trials (rare: a pair about to touch). A call in the first loop would keep
    it, and the law's loops if they held it, from being vectorised.
    """
    for b in range(nact):
        gap[b] = np.inf
        swept[b] = np.inf
        near[b] = 0.0
    for p in range(terms.pair_i.shape[0]):
        i = terms.pair_i[p]
        j = terms.pair_j[p]
        a = terms.pair_contact[p]
        for b in range(nact):
            dx = x[j, 0, b] - x[i, 0, b]
            dy = x[j, 1, b] - x[i, 1, b]
            clr = math.sqrt(dx * dx + dy * dy) - a
            gap[b] = min(gap[b], clr)
            near[b] = 1.0 if clr <= _SWEPT_MARGIN * disp[b] else near[b]
    for b in range(nact):
        if near[b] == 0.0:
            continue
        for p in range(terms.pair_i.shape[0]):
            i = terms.pair_i[p]
            j = terms.pair_j[p]
            a = terms.pair_contact[p]
            dx = x[j, 0, b] - x[i, 0, b]
            dy = x[j, 1, b] - x[i, 1, b]
            if math.sqrt(dx * dx + dy * dy) - a <= _SWEPT_MARGIN * disp[b]:
                swept[b] = min(swept[b], _swept(x, xp, i, j, b, a))


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _headings(x, hc, hs, hcl, hsl, nact):
    """``hc, hs = cos theta, sin theta`` ``(n, C)`` of the first ``nact`` trials (library).

    ``hcl``, ``hsl``: what rounding left out of them, taken as 0 here (:func:`_turn`).
    """
    for i in range(x.shape[0]):
        for b in range(nact):
            th = x[i, 2, b]
            hc[i, b] = math.cos(th)
            hs[i, b] = math.sin(th)
            hcl[i, b] = 0.0
            hsl[i, b] = 0.0


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _turn(x, xp, hc, hs, hcl, hsl, wide, nact):
    """Carry the headings of the states ``xp`` to the states ``x`` one Euler step later.

    Each heading turns by its step's angle ``x_theta - xp_theta`` (exact when the two are
    within a factor 2, Sterbenz; across 0 it may round by half an ulp of the angle) with
    :func:`.kernel_trig.turn_small` (no library call, vectorised); the trials with a robot
    that turned by more than ``SMALL_TURN`` (``wide``, rare) take the library's ``cos``
    and ``sin`` of their new headings. The four parts are four arrays: as four rows of
    one array, read and written in this loop, the compiler did not vectorise it (measured:
    9-10 ns per robot against 3-4).
    """
    for b in range(nact):
        wide[b] = 0.0
    for i in range(x.shape[0]):
        for b in range(nact):
            a = x[i, 2, b] - xp[i, 2, b]
            hc[i, b], hs[i, b], hcl[i, b], hsl[i, b] = turn_small(
                hc[i, b], hs[i, b], hcl[i, b], hsl[i, b], a
            )
            wide[b] = wide[b] if abs(a) <= SMALL_TURN else 1.0
    for b in range(nact):
        if wide[b] != 0.0:
            for i in range(x.shape[0]):
                hc[i, b] = math.cos(x[i, 2, b])
                hs[i, b] = math.sin(x[i, 2, b])
                hcl[i, b] = 0.0
                hsl[i, b] = 0.0


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _points(x, hc, hs, p, nact, model):
    """Near-identity hand points ``p = q + l h`` (``Unicycle.points``); ``h``: :func:`_turn`."""
    ell = model.offset
    for i in range(x.shape[0]):
        for b in range(nact):
            p[i, 0, b] = x[i, 0, b] + ell * hc[i, b]
            p[i, 1, b] = x[i, 1, b] + ell * hs[i, b]


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _limit_unicycle(v, w, vmax, wmax):
    """``(s v, s omega)``, ``s = min(1, v_max / |v|, omega_max / |omega|)`` (``limit_unicycle``)."""
    av = abs(v)
    aw = abs(w)
    s = vmax / av if av > vmax else 1.0
    s2 = wmax / aw if aw > wmax else 1.0
    s = min(s, s2)
    return v * s, w * s


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _rates(x, hc, hs, u, f, vel, nact, model):
    """``f = x_dot`` from the law's controls ``u`` (``RobotModel.derivative``, with limits).

    ``hc``, ``hs``: the unicycles' ``cos theta`` and ``sin theta`` ``(n, C)`` (:func:`_turn`);
    ``vel`` ``(C,)``: room for their speeds.
    """
    n = x.shape[0]
    vmax = model.max_speed
    wmax = model.max_turn_rate
    limited = vmax < np.inf or wmax < np.inf  # no limit: no scaling (limit_unicycle)
    if model.kind == SINGLE:
        for i in range(n):
            for b in range(nact):
                ux = u[i, 0, b]
                uy = u[i, 1, b]
                size = math.sqrt(ux * ux + uy * uy)
                s = vmax / size if size > vmax else 1.0  # limit_speed
                f[i, 0, b] = ux * s
                f[i, 1, b] = uy * s
    elif model.kind == DOUBLE:
        kd = model.damping
        for i in range(n):
            for b in range(nact):
                wx = x[i, 2, b]
                wy = x[i, 3, b]
                ax = -kd * wx + u[i, 0, b]
                ay = -kd * wy + u[i, 1, b]
                w2 = wx * wx + wy * wy
                push = wx * ax + wy * ay
                if w2 >= vmax * vmax and push > 0:  # extra damping at the limit
                    brake = push / w2 if w2 > 0 else 0.0
                    ax -= brake * wx
                    ay -= brake * wy
                size = math.sqrt(w2)
                s = vmax / size if size > vmax else 1.0
                f[i, 0, b] = wx * s
                f[i, 1, b] = wy * s
                f[i, 2, b] = ax
                f[i, 3, b] = ay
    else:  # unicycles: per robot the speed (in `vel`) and the turn rate (f's third row),
        # then the velocity (measured: the heading transform's rates in one loop that
        # stores the three rows of f cost twice as much, 15 against 7 ns per robot)
        ell = model.offset
        kv = model.linear_gain
        kw = model.turn_gain
        back = model.backwards
        for i in range(n):
            if model.kind == NEAR_IDENTITY:  # v = u . h, omega = u . h_perp / l (NearIdentity)
                for b in range(nact):
                    c = hc[i, b]
                    sn = hs[i, b]
                    along = c * u[i, 0, b] + sn * u[i, 1, b]
                    across = -sn * u[i, 0, b] + c * u[i, 1, b]
                    v, w = along, across / ell
                    if limited:
                        v, w = _limit_unicycle(v, w, vmax, wmax)
                    vel[b] = v
                    f[i, 2, b] = w
            else:  # the Robotarium's si_to_uni (HeadingTransform): the angle to u first
                for b in range(nact):
                    c = hc[i, b]
                    sn = hs[i, b]
                    along = c * u[i, 0, b] + sn * u[i, 1, b]
                    across = -sn * u[i, 0, b] + c * u[i, 1, b]
                    if back:  # atan(across / along); +-pi/2 (0 if across is 0) where along is 0
                        level = along == 0.0
                        turn = atan2_poly(across / (1.0 if level else along), 1.0)
                        edge = math.copysign(0.5 * math.pi, across) if across != 0.0 else 0.0
                        f[i, 2, b] = edge if level else turn
                    else:
                        f[i, 2, b] = atan2_poly(across, along)
                for b in range(nact):
                    along = hc[i, b] * u[i, 0, b] + hs[i, b] * u[i, 1, b]
                    v, w = kv * along, kw * f[i, 2, b] / (math.pi / 2)
                    if limited:
                        v, w = _limit_unicycle(v, w, vmax, wmax)
                    vel[b] = v
                    f[i, 2, b] = w
            for b in range(nact):
                f[i, 0, b] = vel[b] * hc[i, b]
                f[i, 1, b] = vel[b] * hs[i, b]


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _speed(f, b, model):
    """Largest robot speed of trial ``b`` (``RobotModel.speed``) from its rates ``f``."""
    top = 0.0
    for i in range(f.shape[0]):
        s = math.sqrt(f[i, 0, b] * f[i, 0, b] + f[i, 1, b] * f[i, 1, b])
        if model.kind == NEAR_IDENTITY or model.kind == HEADING:
            s += model.offset * abs(f[i, 2, b])
        elif model.kind == DOUBLE:
            tx = f[i, 0, b] + f[i, 2, b] / model.damping
            ty = f[i, 1, b] + f[i, 3, b] / model.damping
            s = max(s, math.sqrt(tx * tx + ty * ty))
        top = max(top, s)
    return top


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def _run_chunk(
    x0, start, stop, terms, model, dt, n_steps, check_every, speed,
    x_out, v_out, steps_out, status_out, mc_out, ns_out, window_step, qw_out,
):  # fmt: skip
    n = x0.shape[1]
    k = x0.shape[2]
    m = stop - start
    hand = model.kind == NEAR_IDENTITY  # the law acts on points other than the centres
    turns = hand or model.kind == HEADING  # the state has a heading
    # double buffers: (x, f) at step k, (xp, fp) at step k - 1; u the law's control at x
    x = np.empty((n, k, m))
    f = np.empty((n, k, m))
    xp = np.empty((n, k, m))
    fp = np.empty((n, k, m))
    u = np.empty((n, 2, m))
    p = np.empty((n, 2, m) if hand else (1, 2, 1))  # hand points
    # cos theta, sin theta at x, and what rounding left out of them (_turn)
    hshape = (n, m) if turns else (1, 1)
    hc = np.empty(hshape)
    hs = np.empty(hshape)
    hcl = np.empty(hshape)
    hsl = np.empty(hshape)
    wide = np.empty(m)  # 1: a robot turned by more than SMALL_TURN in the last step
    ids = np.arange(start, stop)
    mc = np.full(m, np.inf)  # least clearance over accepted states
    gap = np.empty(m)  # clearance of the current state
    swept = np.empty(m)  # least clearance along the step to the current state
    near = np.empty(m)  # 1: a pair may have met during the step to the current state
    disp = np.zeros(m)  # largest displacement of the step to the current state
    sigma = np.empty(m)  # switching function of one surface (_rates: unicycle speeds)
    fin = np.zeros(m)  # 0 while the last Euler step was finite
    code = np.full(m, -1, dtype=np.int8)  # -1: still running
    qc = np.empty((n, 2, m))  # positions at the previous convergence check
    ns = np.full(m, np.nan)  # net speed over the last check interval (NaN: none yet)
    dbuf = np.empty(m)  # largest squared displacement since the previous check
    for b in range(m):
        for i in range(n):
            for d in range(k):
                x[i, d, b] = x0[start + b, i, d]
                xp[i, d, b] = x[i, d, b]
    nact = m
    step = 0
    kc = -1  # step of the previous check (the same for every live trial)
    if turns:  # then carried from step to step (_turn)
        _headings(x, hc, hs, hcl, hsl, nact)
    while nact > 0:
        if hand:
            _points(x, hc, hs, p, nact, model)
            _controls(p, u, sigma, nact, terms)
        else:
            _controls(x, u, sigma, nact, terms)
        _contact(x, xp, disp, gap, swept, near, nact, terms)
        _rates(x, hc, hs, u, f, sigma, nact, model)
        stopping = 0
        if step > 0:  # reject the step that led here (System.step_verdict)
            for b in range(nact):
                if fin[b] != 0.0:
                    code[b] = _NON_FINITE
                    stopping += 1
                elif not gap[b] > 0.0:
                    code[b] = _COLLISION
                    stopping += 1
                elif not swept[b] > 0.0:
                    code[b] = _TOO_LARGE
                    stopping += 1
        for b in range(nact):
            mc[b] = min(mc[b], gap[b]) if code[b] < 0 else mc[b]
        if step == window_step:  # start of the drift window (the driver's q_window)
            for b in range(nact):
                if code[b] < 0:
                    for i in range(n):
                        qw_out[ids[b], i, 0] = x[i, 0, b]
                        qw_out[ids[b], i, 1] = x[i, 1, b]
        if step % check_every == 0 or step == n_steps:
            # stopped: instantaneous speed (RobotModel.speed) or net speed of the positions
            # since the previous check, max |q_i(k) - q_i(kc)| / ((k - kc) dt), at most `speed`
            for b in range(nact):
                dbuf[b] = 0.0
            if kc >= 0:
                for i in range(n):
                    for b in range(nact):
                        dx = x[i, 0, b] - qc[i, 0, b]
                        dy = x[i, 1, b] - qc[i, 1, b]
                        dbuf[b] = max(dbuf[b], dx * dx + dy * dy)
            elapsed = (step - kc) * dt
            for b in range(nact):
                if code[b] >= 0:  # the step to this state was rejected
                    continue
                top = _speed(f, b, model)
                net = math.sqrt(dbuf[b]) / elapsed if kc >= 0 else np.nan
                ns[b] = net
                if top <= speed or net <= speed:
                    code[b] = _CONVERGED
                    stopping += 1
            for i in range(n):
                for d in range(2):
                    for b in range(nact):
                        qc[i, d, b] = x[i, d, b]
            kc = step
        if step == n_steps:
            for b in range(nact):
                if code[b] < 0:
                    code[b] = _END
            stopping = nact
        if stopping:
            # write out the stopped trials, then compact the live range
            for b in range(nact - 1, -1, -1):
                if code[b] < 0:
                    continue
                g = ids[b]
                rejected = code[b] == _COLLISION or code[b] == _TOO_LARGE or code[b] == _NON_FINITE
                for i in range(n):
                    for d in range(k):
                        # a rejected step ends the trial at the previous, accepted state
                        x_out[g, i, d] = xp[i, d, b] if rejected else x[i, d, b]
                        v_out[g, i, d] = fp[i, d, b] if rejected else f[i, d, b]
                steps_out[g] = step - 1 if rejected else step
                status_out[g] = code[b]
                mc_out[g] = mc[b]
                ns_out[g] = ns[b]
                last = nact - 1
                if b != last:  # the trial at `last` is running (visited already)
                    for i in range(n):
                        for d in range(k):
                            x[i, d, b] = x[i, d, last]
                            f[i, d, b] = f[i, d, last]
                        for d in range(2):
                            qc[i, d, b] = qc[i, d, last]
                        if turns:
                            hc[i, b] = hc[i, last]
                            hs[i, b] = hs[i, last]
                            hcl[i, b] = hcl[i, last]
                            hsl[i, b] = hsl[i, last]
                    ids[b] = ids[last]
                    mc[b] = mc[last]
                    ns[b] = ns[last]
                code[b] = -1
                code[last] = -1
                nact -= 1
        if nact == 0:
            break
        for b in range(nact):
            fin[b] = 0.0
            disp[b] = 0.0
        for i in range(n):
            for b in range(nact):
                nx = x[i, 0, b] + dt * f[i, 0, b]  # explicit Euler
                ny = x[i, 1, b] + dt * f[i, 1, b]
                ex = nx - x[i, 0, b]
                ey = ny - x[i, 1, b]
                disp[b] = max(disp[b], ex * ex + ey * ey)
                xp[i, 0, b] = nx  # the next state, written over the older one
                xp[i, 1, b] = ny
                fin[b] += (nx + ny) * 0.0  # NaN unless x and y are finite
            for d in range(2, k):
                for b in range(nact):
                    z = x[i, d, b] + dt * f[i, d, b]
                    xp[i, d, b] = z
                    fin[b] += z * 0.0
        for b in range(nact):
            disp[b] = math.sqrt(disp[b])
        if turns:
            _turn(xp, x, hc, hs, hcl, hsl, wide, nact)
        x, xp = xp, x
        f, fp = fp, f
        step += 1


@njit(cache=True, fastmath=False, error_model="numpy", parallel=True)
def run_chunks(
    x0, chunk, terms, model, dt, n_steps, check_every, speed,
    x_out, v_out, steps_out, status_out, mc_out, ns_out, window_step, qw_out,
):  # fmt: skip
    """Step every trial of ``x0`` ``(B, n, k)``; chunks of ``chunk`` trials run in parallel.

    ``terms`` is the law's :class:`~formationlab.controllers.terms.KernelTerms`,
    ``model`` the robot model's :class:`~formationlab.studies.model_terms.ModelTerms`.
    Fills ``x_out``, ``v_out`` ``(B, n, k)`` (final states and their rates),
    ``steps_out`` (int64), ``status_out`` (int8, :attr:`formationlab.status.Status.code`),
    ``mc_out`` (least clearance) and ``ns_out`` (net speed over the last check
    interval), all of length ``B``;
    ``qw_out`` ``(B, n, 2)`` (filled with NaN by the caller) gets the positions of the
    trials still running at step ``window_step``, the start of the drift window.
    """
    n_trials = x0.shape[0]
    n_chunks = (n_trials + chunk - 1) // chunk
    for c in prange(n_chunks):
        start = c * chunk
        stop = min(n_trials, start + chunk)
        _run_chunk(
            x0, start, stop, terms, model, dt, n_steps, check_every, speed,
            x_out, v_out, steps_out, status_out, mc_out, ns_out, window_step, qw_out,
        )  # fmt: skip
