"""Robots that sense each other, as a stage of the compiled loop (:mod:`formationlab.engine.loop`).

The compiled twin of :meth:`formationlab.sensing.Channel.observe` and
:meth:`~formationlab.sensing.Channel.local`: with a sensing model other than the paper's
(or with faults) the law's stage of the loop is :func:`sensed_field` instead of
:func:`formationlab.controllers.stage.law_field`. Per step ``k`` of each live trial:

1. every robot ``i`` measures ``z_ij = R(-a_i) (p_j - p_i) + noise`` of every robot (zero
   on the diagonal; ``p`` the law's points, ``a_i`` its frame: a fixed random angle, or
   its heading for robot models that have one), and whether ``j`` is within ``range``
   (centre to centre);
2. the measurement it uses is the one taken at ``k - m`` (``m = delay / dt``; nothing
   has arrived for ``k < m``), from a ring of ``m + 1`` slots; a delivered measurement
   lost with probability ``drop`` leaves the last one received in place, one out of
   range clears it;
3. its command is :func:`formationlab.controllers.stage.local_field` of its own
   measurements (its own desired distances under ``mismatch``), rotated back ``R(a_i)``.

Then :func:`halt` zeroes the rates of the robots stopped by a fault, and the stop rule
counts only while every robot sees all its neighbours, now and at the previous check
(:func:`informed`).

Randomness stays the channel's: each trial's frames and mismatch come from its seed,
and its noise and losses are drawn by :meth:`Channel.block` in numpy, per block of
:data:`~formationlab.sensing.BLOCK` steps, between calls of the loop (which stops at the
end of each block). A trial's run therefore depends on its seed only. Per-trial arrays
are indexed by the trial's number, not by its slot in a chunk, so the loop's compaction
of finished trials does not move them.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from .._jit import formula
from ..controllers.stage import local_field
from .channel import BLOCK

__all__ = [
    "SensingState",
    "SensingTerms",
    "delivery",
    "halt",
    "informed",
    "measured_pair",
    "own_frame",
    "sensed_field",
    "sensing_terms",
    "within_range",
]


class SensingTerms(NamedTuple):
    """A run's sensing and faults as plain arrays and numbers (``B`` trials, ``n`` robots)."""

    measured: bool  #: robots command from measurements (False: faults alone, the law's field)
    local: bool  #: robots measure in their own frames
    headed: bool  #: those frames are the robots' headings (else the fixed angles below)
    cos_in: NDArray[np.float64]  #: cos(-a_i), (B, n) (else (1, 1))
    sin_in: NDArray[np.float64]  #: sin(-a_i)
    cos_out: NDArray[np.float64]  #: cos(a_i)
    sin_out: NDArray[np.float64]  #: sin(a_i)
    own_distance: NDArray[np.float64]  #: (B, E, 2): d_ij as robots edge_i, edge_j hold it
    noise: float
    drop: float
    ranged: bool
    range2: float  #: range**2
    stop_at: NDArray[np.float64]  #: (n,): when each robot stops (inf: never)
    noise_block: NDArray[np.float64]  #: (B, BLOCK, n, n, 2) standard normals of this block
    drop_block: NDArray[np.float64]  #: (B, BLOCK, n, n) uniforms of this block


class SensingState(NamedTuple):
    """What each trial's robots carry from one step to the next (``M = m + 1`` ring slots)."""

    ring_z: NDArray[np.float64]  #: (B, M, n, n, 2) measurements taken at the last M steps
    ring_in: NDArray[np.bool_]  #: (B, M, n, n) whether in range when taken
    held: NDArray[np.float64]  #: (B, n, n, 2) the measurement each robot uses
    has: NDArray[np.bool_]  #: (B, n, n) whether it has one
    seen_c: NDArray[np.bool_]  #: (B,) whether every robot saw its neighbours at the last check


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def own_frame(sn, hc, hs, i, b, g):
    """``(c, s) = (cos, sin)(-a_i)``: robot ``i``'s turn into its own frame in slot ``b``
    (trial or environment ``g`` of the sensing terms ``sn``): its heading's, for unicycles
    that measure in their heading's frame (``sn.headed``), else its drawn frame's; the
    identity when robots measure in the common frame."""
    if not sn.local:
        return 1.0, 0.0
    if sn.headed:
        return hc[i, b], -hs[i, b]
    return sn.cos_in[g, i], sn.sin_in[g, i]


@formula
def measured_pair(dx, dy, local, c, s, noise, wx, wy):
    """``(z_x, z_y)``: a measurement ``z_ij = R(-a_i) (p_j - p_i) + noise`` (step 1) of the
    relative position ``(dx, dy) = p_j - p_i``, turned by ``(c, s) = (cos, sin)(-a_i)``
    when robots measure in their own frames (``local``), plus ``noise`` times the standard
    normals ``(wx, wy)``."""
    zx, zy = dx, dy
    if local:
        zx = c * dx - s * dy
        zy = s * dx + c * dy
    if noise > 0:
        zx = zx + noise * wx
        zy = zy + noise * wy
    return zx, zy


@formula
def within_range(cx, cy, ranged, range2):
    """Whether a robot at ``(cx, cy)`` from another (centre to centre) is within the range
    ``sqrt(range2)`` (always, when not ``ranged``): it is seen (step 1)."""
    return (not ranged) or cx * cx + cy * cy <= range2


@formula
def delivery(arrived, lost, had):
    """``(take, has)`` of a measurement delivered at step ``k`` (step 2): whether the robot
    takes it (it ``arrived``: taken at ``k - m >= 0`` within range, and is not ``lost``) and
    whether the robot then holds one (a lost one leaves the last one received, if it
    ``had`` one; one out of range, or none yet, leaves nothing)."""
    if not arrived:
        return False, False
    if lost:
        return False, had
    return True, True


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def sensed_field(p, x, hc, hs, u, ul, nact, ids, k, terms, sn, ss):
    """``u`` ``(n, 2, C)``: every robot's command from its own measurements (steps 1-3).

    ``p`` the law's points and ``x`` the states ``(n, k, C)`` of a chunk's first ``nact``
    trials, whose numbers are ``ids``; ``hc``, ``hs`` the carried ``cos`` and ``sin`` of the
    headings (:func:`formationlab.models.stage.turn`); ``ul`` ``(n, 2)`` room for one
    trial's commands in the robots' frames.
    """
    n = p.shape[0]
    row = k % BLOCK
    slots = ss.ring_z.shape[1]
    m = slots - 1
    slot = k % slots
    back = (k - m) % slots
    for b in range(nact):
        g = ids[b]
        for i in range(n):  # 1. measure, into the ring's slot of step k
            c, s = own_frame(sn, hc, hs, i, b, g)
            for j in range(n):
                wx = wy = 0.0
                if sn.noise > 0 and i != j:
                    wx = sn.noise_block[g, row, i, j, 0]
                    wy = sn.noise_block[g, row, i, j, 1]
                zx, zy = measured_pair(
                    p[j, 0, b] - p[i, 0, b], p[j, 1, b] - p[i, 1, b], sn.local, c, s, sn.noise,
                    wx, wy,
                )  # fmt: skip
                ss.ring_z[g, slot, i, j, 0] = zx
                ss.ring_z[g, slot, i, j, 1] = zy
                ss.ring_in[g, slot, i, j] = within_range(
                    x[j, 0, b] - x[i, 0, b], x[j, 1, b] - x[i, 1, b], sn.ranged, sn.range2
                )
        for i in range(n):  # 2. deliver what was taken at k - m
            for j in range(n):
                take, has = delivery(
                    k >= m and ss.ring_in[g, back, i, j],
                    sn.drop > 0 and i != j and sn.drop_block[g, row, i, j] < sn.drop,
                    ss.has[g, i, j],
                )
                ss.has[g, i, j] = has
                if take:
                    ss.held[g, i, j, 0] = ss.ring_z[g, back, i, j, 0]
                    ss.held[g, i, j, 1] = ss.ring_z[g, back, i, j, 1]
        local_field(ss.held[g], ss.has[g], sn.own_distance[g], terms, ul)  # 3.
        for i in range(n):
            ux = ul[i, 0]
            uy = ul[i, 1]
            if sn.local:  # back to the common frame, R(a_i) u_i
                c = hc[i, b] if sn.headed else sn.cos_out[g, i]
                s = hs[i, b] if sn.headed else sn.sin_out[g, i]
                ux, uy = c * ux - s * uy, s * ux + c * uy
            u[i, 0, b] = ux
            u[i, 1, b] = uy


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def halt(f, t, sn, nact):
    """Zero the rates ``f`` ``(n, k, C)`` of the robots stopped by ``t`` (``System._faulty``)."""
    for i in range(f.shape[0]):
        if t >= sn.stop_at[i]:
            for d in range(f.shape[1]):
                for b in range(nact):
                    f[i, d, b] = 0.0


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def informed(g, terms, ss):
    """Whether every robot of trial ``g`` sees all its neighbours (``Channel.informed``)."""
    for e in range(terms.edge_i.shape[0]):
        i = terms.edge_i[e]
        j = terms.edge_j[e]
        if not (ss.has[g, i, j] and ss.has[g, j, i]):
            return False
    return True


def sensing_terms(
    channel, ids: NDArray[np.intp], stop_at: NDArray[np.float64], headed: bool
) -> SensingTerms:
    """The terms of the trials ``ids`` of ``channel`` (``ids``' rows, in their order).

    The noise and loss blocks are left to fill (:meth:`Channel.block`) at the start of
    each block of steps.
    """
    s = channel.sensing
    n = channel.n
    terms = channel.terms
    G = ids.size
    E = terms.edge_i.size
    a = channel.fixed_angles[ids] if channel.fixed_angles is not None else np.zeros((1, 1))
    own = (
        channel.own_distance[ids]
        if channel.own_distance is not None
        else np.broadcast_to(terms.edge_distance[None, :, None], (G, E, 2)).copy()
    )
    noisy, lossy = s.noise > 0, s.drop > 0
    return SensingTerms(
        measured=not s.ideal, local=s.frames == "local" or channel.fixed_angles is not None,
        headed=headed, cos_in=np.cos(-a),
        sin_in=np.sin(-a), cos_out=np.cos(a), sin_out=np.sin(a), own_distance=own,
        noise=float(s.noise), drop=float(s.drop), ranged=not math.isinf(s.range),
        range2=float(s.range**2), stop_at=stop_at,
        noise_block=np.zeros((G, BLOCK, n, n, 2) if noisy else (1, 1, 1, 1, 2)),
        drop_block=np.zeros((G, BLOCK, n, n) if lossy else (1, 1, 1, 1)),
    )  # fmt: skip


def sensing_arrays(
    channel, ids: NDArray[np.intp], stop_at: NDArray[np.float64], headed: bool
) -> tuple[SensingTerms, SensingState]:
    """The terms (:func:`sensing_terms`) and a fresh state of the trials ``ids`` of
    ``channel`` (a group of a run)."""
    n, G = channel.n, ids.size
    M = channel.m + 1
    ss = SensingState(
        ring_z=np.zeros((G, M, n, n, 2)), ring_in=np.zeros((G, M, n, n), dtype=bool),
        held=np.zeros((G, n, n, 2)), has=np.zeros((G, n, n), dtype=bool),
        seen_c=np.ones(G, dtype=bool),
    )  # fmt: skip
    return sensing_terms(channel, ids, stop_at, headed), ss


def trial_bytes(channel) -> int:
    """Bytes of one trial's sensing arrays (noise and loss blocks, ring, held values)."""
    s, n = channel.sensing, channel.n
    return 8 * n * n * (BLOCK * (2 * (s.noise > 0) + (s.drop > 0)) + 3 * (channel.m + 1) + 3)
