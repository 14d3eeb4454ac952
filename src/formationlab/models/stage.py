"""The robot models as a stage of the compiled loop (:mod:`formationlab.engine.loop`).

The model enters as a :class:`~formationlab.models.terms.ModelTerms` (single integrators,
unicycles through either transform, double integrators, quadrotors, each with its limits;
in space all but the unicycles):
:func:`points` gives the points the law acts on (``RobotModel.points``), :func:`rates` the
state's rate from the law's control (``RobotModel.derivative``), :func:`speed` the stop
rule's speed (``RobotModel.speed``). States are ``(n, k, C)``, the trials innermost.

No loop over trials calls the C library in a unicycle's step (a call, or a branch that
calls, keeps a loop from being vectorised; :mod:`.trig`): each unicycle's ``cos theta``
and ``sin theta`` are taken from the library once, at the start (:func:`headings`), and
then carried from step to step (:func:`turn`), turned by each Euler step's angle with a
short series and an exact sum (the library again only for a turn above ``SMALL_TURN`` in
one step), and the heading transform's ``atan2`` is a branch-free rational approximation;
both are within about an ulp of the library's values, so the trials still agree with the
driver to rounding. Whether the compiler vectorises a loop is measured, not assumed: the
unicycle's loops were not vectorised while they read and wrote the rows of one
``(n, 4, C)`` array or stored a heavy computation into three rows of ``f``; so the carried
headings are four arrays and a unicycle's rates take three short passes.

What a trial-step costs, per model: ``benchmarks/bench_models.py`` and
docs/robot-models.md. A new model adds its kind in :mod:`.terms` and its branch here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .terms import DOUBLE, HEADING, NEAR_IDENTITY, QUADROTOR, SINGLE
from .trig import SMALL_TURN, atan2_poly, turn_small

__all__ = ["headings", "points", "rates", "speed", "turn"]


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def headings(x, hc, hs, hcl, hsl, nact):
    """``hc, hs = cos theta, sin theta`` ``(n, C)`` of the first ``nact`` trials (library).

    ``hcl``, ``hsl``: what rounding left out of them, taken as 0 here (:func:`turn`).
    """
    for i in range(x.shape[0]):
        for b in range(nact):
            th = x[i, 2, b]
            hc[i, b] = math.cos(th)
            hs[i, b] = math.sin(th)
            hcl[i, b] = 0.0
            hsl[i, b] = 0.0


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def turn(x, xp, hc, hs, hcl, hsl, wide, nact):
    """Carry the headings of the states ``xp`` to the states ``x`` one Euler step later.

    Each heading turns by its step's angle ``x_theta - xp_theta`` (exact when the two are
    within a factor 2, Sterbenz; across 0 it may round by half an ulp of the angle) with
    :func:`.trig.turn_small` (no library call, vectorised); the trials with a robot
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
def points(x, hc, hs, p, nact, model):
    """Near-identity hand points ``p = q + l h`` (``Unicycle.points``); ``h``: :func:`turn`."""
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
def rates(x, hc, hs, u, f, vel, nact, model, axes):
    """``f = x_dot`` from the law's controls ``u`` (``RobotModel.derivative``, with limits).

    ``hc``, ``hs``: the unicycles' ``cos theta`` and ``sin theta`` ``(n, C)`` (:func:`turn`);
    ``vel`` ``(C,)``: room for their speeds. ``axes``: the positions' (the loop's
    ``run.axes``); in space the single and double integrators and the quadrotor.
    """
    n = x.shape[0]
    vmax = model.max_speed
    wmax = model.max_turn_rate
    limited = vmax < np.inf or wmax < np.inf  # no limit: no scaling (limit_unicycle)
    if model.kind == SINGLE and not limited:  # f = u (the same numbers as a scale of 1)
        for i in range(n):
            for d in range(axes.ndim):
                for b in range(nact):
                    f[i, d, b] = u[i, d, b]
    elif model.kind == SINGLE and axes.ndim == 3:  # (a constant: compiled in space only)
        for i in range(n):
            for b in range(nact):
                ux = u[i, 0, b]
                uy = u[i, 1, b]
                uz = u[i, 2, b]
                size = math.sqrt(ux * ux + uy * uy + uz * uz)
                s = vmax / size if size > vmax else 1.0  # limit_speed
                f[i, 0, b] = ux * s
                f[i, 1, b] = uy * s
                f[i, 2, b] = uz * s
    elif model.kind == SINGLE:
        for i in range(n):
            for b in range(nact):
                ux = u[i, 0, b]
                uy = u[i, 1, b]
                size = math.sqrt(ux * ux + uy * uy)
                s = vmax / size if size > vmax else 1.0  # limit_speed
                f[i, 0, b] = ux * s
                f[i, 1, b] = uy * s
    elif model.kind == QUADROTOR:
        _quadrotor(x, u, f, nact, model, axes)
    elif model.kind == DOUBLE:
        _double(x, u, f, nact, model, axes)
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
def _double(x, u, f, nact, model, axes):
    """The double integrator's rates (``DoubleIntegrator.derivative``): state ``(p, w)``,
    ``w_dot = -k_d w + u`` with the extra damping at the speed limit, in the plane or in
    space (``axes``)."""
    dim = axes.ndim
    kd = model.damping
    vmax = model.max_speed
    for i in range(x.shape[0]):
        for b in range(nact):
            w2 = 0.0
            push = 0.0
            for d in range(dim):
                w = x[i, dim + d, b]
                a = -kd * w + u[i, d, b]  # q_ddot = -k_d q_dot + u
                f[i, dim + d, b] = a
                w2 += w * w
                push += w * a
            if w2 >= vmax * vmax and push > 0:  # extra damping at the limit
                brake = push / w2 if w2 > 0 else 0.0
                for d in range(dim):
                    f[i, dim + d, b] -= brake * x[i, dim + d, b]
            size = math.sqrt(w2)
            s = vmax / size if size > vmax else 1.0
            for d in range(dim):
                f[i, d, b] = x[i, dim + d, b] * s


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _quadrotor(x, u, f, nact, model, axes):
    """The quadrotor's rates (``Quadrotor.derivative``): ``q_dot = w``, ``w_dot =
    sat_a((sat_v(u) - w) / tau)``, in the plane or in space (``axes``)."""
    dim = axes.ndim
    tau = model.time_constant
    vmax = model.max_speed
    amax = model.max_accel
    for i in range(x.shape[0]):
        for b in range(nact):
            uu = 0.0
            for d in range(dim):
                uu += u[i, d, b] * u[i, d, b]
            size = math.sqrt(uu)
            s = vmax / size if size > vmax else 1.0  # sat_v: limit_speed
            aa = 0.0
            for d in range(dim):
                w = x[i, dim + d, b]
                f[i, d, b] = w
                a = (u[i, d, b] * s - w) / tau  # the lag
                f[i, dim + d, b] = a
                aa += a * a
            size = math.sqrt(aa)
            s = amax / size if size > amax else 1.0  # sat_a: limit_speed
            for d in range(dim):
                f[i, dim + d, b] *= s


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def speed(f, b, model, axes):
    """Largest robot speed of trial ``b`` (``RobotModel.speed``) from its rates ``f``
    (``axes``: the positions')."""
    top = 0.0
    for i in range(f.shape[0]):
        if axes.ndim == 3:  # (a constant: compiled in space only)
            fx, fy, fz = f[i, 0, b], f[i, 1, b], f[i, 2, b]
            s = math.sqrt(fx * fx + fy * fy + fz * fz)
        else:
            s = math.sqrt(f[i, 0, b] * f[i, 0, b] + f[i, 1, b] * f[i, 1, b])
        if model.kind == NEAR_IDENTITY or model.kind == HEADING:
            s += model.offset * abs(f[i, 2, b])
        elif model.kind == DOUBLE or model.kind == QUADROTOR:
            # the velocity it tends to: w + w_dot / k_d (DoubleIntegrator.speed) or
            # w + tau w_dot (Quadrotor.speed)
            dim = axes.ndim
            tt = 0.0
            for d in range(dim):
                a = f[i, dim + d, b]
                t = f[i, d, b] + (
                    a / model.damping if model.kind == DOUBLE else model.time_constant * a
                )
                tt += t * t
            s = max(s, math.sqrt(tt))
        top = max(top, s)
    return top
